"""The learning curves of the authors' follow-up under ``env.energy=follow_up`` (docs/model.md, Energy and lifetime;
BENCHMARKS.md, The follow-up's curves).

Shamsoshoara et al., IEEE Access 8:58064-58079, 2020, learn with one independent Q-learner per UAV, each alone in
its region (their code: ``main.py``; state: the UAV's cell in its region, no energy; a reward for reaching the
episode's best utility so far; alpha 0.1, gamma 0.3, epsilon 0.1; 40 episodes, 20 runs, every episode from the same
start with the batteries of that start).  Their curves for 81x81 (9 regions of 27x27, 6000 steps an episode) show
each UAV's normalised utility near 1 within 5-10 episodes and its moves per episode falling from 2,000-2,500 to
100-600.

Here one region is our grid and one follow-up UAV is one run of a single UAV: ``num_uavs=1`` on 27x27, the team Q
learner (with one UAV, an independent learner) over the location state, ``reward=best_so_far``, their constants.
Two variants:

- ``follow_up``: ``energy=follow_up`` with full batteries (5000) and the longest episode no battery can reach its
  reserve in (``ModelConfig.steps_before_reserve``, 3325 steps): the table without the battery is then exact;
- ``none, 6000 steps``: their episode length without energy, which is what their model does when a battery is
  empty (nothing); the follow-up's accounting is then added up here (0.5 a step, 1.0 a move), where our
  ``follow_up`` would send the UAV home at its reserve.

Prints per variant: the utility per episode as a fraction of ``U*`` (the sum over the episode over ``U* T``), the
first episode whose mean over runs reaches 0.95, the moves per episode at the start and over the last 10 episodes,
and the energy spent per episode in the follow-up's units; writes a PNG (mean over runs and their min-max band).

Usage::

    python benchmarks/follow_up_curves.py                  # 20 runs x 40 episodes, about 5 s
    python benchmarks/follow_up_curves.py --png docs/figures/follow_up_curves.png
"""

from __future__ import annotations

import argparse
import time

import torch

from uavrl.agents.tabular import TeamQLearner
from uavrl.envs import make_config
from uavrl.envs.physics.power import FOLLOW_UP_MOVE, FOLLOW_UP_TRANSMISSION

REGION = (27, 27)  # one region of the follow-up's 81x81 area of 9 regions
THEIR_STEPS = 6000  # their steps per episode on 81x81 with 9 regions (their Table 2)
THEIR_LEARNER = dict(alpha=0.1, gamma=0.3, epsilon=0.1)  # their config.py, Config_RL
BASE = (-1, 0)
TARGET = 0.95


def variants() -> dict:
    """The models compared, by name."""
    model = dict(grid=REGION, num_uavs=1, reward="best_so_far")
    energy = make_config("paper", **model, energy="follow_up", base=BASE)
    return {
        f"follow_up, {energy.steps_before_reserve} steps": energy.replace(max_steps=energy.steps_before_reserve),
        f"none, {THEIR_STEPS} steps": make_config("paper", **model, max_steps=THEIR_STEPS),
    }


def learn(cfg, runs: int, episodes: int, seed: int) -> dict[str, torch.Tensor]:
    """``[episodes, runs]`` per-episode curves of ``runs`` independent tables: utility over ``U* T``, moves, and the
    follow-up's energy spent (every step transmits, every move flies)."""
    learner = TeamQLearner(cfg, runs=runs, seed=seed, **THEIR_LEARNER)
    utility, moves = [], []
    for _ in range(episodes):
        metrics = learner.run_episode()
        utility.append(metrics["sum_utility"] / (learner.model.u_star * cfg.max_steps))
        moves.append(metrics["moves"])
    utility, moves = torch.stack(utility), torch.stack(moves)
    energy = FOLLOW_UP_TRANSMISSION * cfg.max_steps + FOLLOW_UP_MOVE * moves
    # the follow-up's figure starts every UAV at 0: as if each run's curve were scaled to its own min and max
    low, high = utility.amin(0), utility.amax(0)
    return {"utility": utility, "min_max": (utility - low) / (high - low), "moves": moves, "energy": energy}


def summary(name: str, curves: dict[str, torch.Tensor]) -> str:
    utility, moves, energy = (curves[key] for key in ("utility", "moves", "energy"))
    mean = utility.mean(-1)
    reached = (mean >= TARGET).nonzero()
    first = int(reached[0]) if len(reached) else None
    min_max = curves["min_max"].mean(-1)
    return (
        f"{name}: utility / U* episode 1 {mean[0]:.3f}, 5 {mean[4]:.3f}, 10 {mean[9]:.3f}, last 10 "
        f"{mean[-10:].mean():.3f}; first episode with mean >= {TARGET}: {first if first is None else first + 1}; "
        f"min-max scaled per run: episode 5 {min_max[4]:.2f}, 10 {min_max[9]:.2f}\n"
        f"  moves per episode: episode 1 {moves[0].mean():.0f} (runs {moves[0].min():.0f}-{moves[0].max():.0f}), "
        f"last 10 {moves[-10:].mean():.0f} (runs {moves[-10:].mean(0).min():.0f}-{moves[-10:].mean(0).max():.0f})\n"
        f"  follow-up energy spent per episode: episode 1 {energy[0].mean():.0f} (max {energy[0].max():.0f}), "
        f"last 10 {energy[-10:].mean():.0f}; episodes over 4000 (their lowest battery): "
        f"{(energy > 4000).float().mean():.0%}"
    )


def plot(results: dict, path: str, runs: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8))
    axes = axes.ravel()
    panels = (
        ("utility", "utility per episode / (U* T)"),
        ("min_max", "utility scaled to each run's min and max (theirs)"),
        ("moves", "moves per episode"),
        ("energy", "energy spent per episode (follow-up units)"),
    )
    for (key, label), ax in zip(panels, axes, strict=True):
        for (name, curves), colour in zip(results.items(), ("tab:blue", "tab:orange"), strict=False):
            values = curves[key]
            episodes = torch.arange(1, len(values) + 1)
            ax.plot(episodes, values.mean(-1), color=colour, label=name)
            ax.fill_between(episodes, values.amin(-1), values.amax(-1), color=colour, alpha=0.2)
        ax.set_xlabel("episode")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].axhline(TARGET, color="grey", ls=":", lw=1)
    axes[3].axhspan(4000, 5000, color="grey", alpha=0.15, label="their battery U[4000, 5000]")
    axes[0].legend(loc="lower right")
    axes[3].legend(loc="upper right", fontsize=8)
    fig.suptitle(
        "The follow-up's learner on one 27x27 region (1 UAV, location state, best_so_far, alpha 0.1, gamma 0.3,\n"
        f"epsilon 0.1): mean and min-max band over {runs} runs"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20, help="independent runs (their NUM_RUN: 20)")
    parser.add_argument("--episodes", type=int, default=40, help="episodes per run (their NUM_EPS: 40)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--png", default=None, help="write the figure here")
    args = parser.parse_args()
    results = {}
    for name, cfg in variants().items():
        started = time.perf_counter()
        results[name] = learn(cfg, args.runs, args.episodes, args.seed)
        print(summary(name, results[name]), f"\n  ({time.perf_counter() - started:.1f} s)")
    if args.png:
        plot(results, args.png, args.runs)
        print(f"wrote {args.png}")


if __name__ == "__main__":
    main()
