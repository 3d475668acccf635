"""A size-free checkpoint (``agent=dqn agent.network=set``) evaluated zero-shot on teams and grids, beside the random
policy and the oracle, from the same seeded starts (``eval.seed``'s default), as a Markdown table for BENCHMARKS.md.

    python benchmarks/zero_shot.py <run dir> [num_starts] [N:L1xL2[:layout] ...]

Default teams: 2:6x6, 6:10x10, 10:20x20, 20:30x30, 50:50x50 and 6:10x10:random (the run's other model options).
Per row: return ratio (the discounted gain over the exact best, where the exact solver fits), the share of starts
reaching 0.999 U* and their steps over the fewest (exact or a lower bound, ``min exact``), the final U / U*, and the
seconds the row took (the first row of a team also computes its starts' references).  Then, per team, how the
checkpoint's starts that miss 0.999 U* fail: still moving or switching in the last 10 steps (wandering near U*: action
gaps the values do not resolve, or the greedy rule's back and forth) or stuck (a configuration the values rate best),
and the best U / U* they reached.  Last, per team of a fixed layout, the checkpoint started at U*'s own configuration
(its UAVs in 16 random orders): whether its greedy policy stays there and holds 0.999 U* over the evaluation's horizon
(if it leaves U* itself, the values rate another configuration above it; if it holds, a start that misses U* fails on
the way there).
"""

from __future__ import annotations

import sys
import time

import torch

from uavrl.agents.baselines import OraclePolicy, RandomPolicy
from uavrl.agents.evaluation import EVAL_SEED, evaluate
from uavrl.config import model_config
from uavrl.envs import UAVSpectrumEnv
from uavrl.envs.limits import evaluation_horizon
from uavrl.experiment.saved import load_agent

DEFAULT_TEAMS = ["2:6x6", "6:10x10", "10:20x20", "20:30x30", "50:50x50", "6:10x10:random"]
COLUMNS = ("eval/return_ratio", "eval/reach_999", "eval/step_ratio_999", "eval/optimality")


def parse_team(text: str) -> tuple[int, tuple[int, int], str | None]:
    n, grid, *layout = text.split(":")
    l1, l2 = grid.split("x")
    return int(n), (int(l1), int(l2)), layout[0] if layout else None


def cells(metrics: dict) -> list[str]:
    out = [f"{metrics[c]:.3f}" if c in metrics else "-" for c in COLUMNS]
    return out + ["yes" if metrics.get("eval/min_steps_exact") == 1.0 else "bound"]


def main(run_dir: str, num_starts: int = 64, teams=DEFAULT_TEAMS) -> None:
    torch.set_num_threads(1)
    agent, saved, _ = load_agent(run_dir)
    run_cfg = model_config(saved)
    print("| N | grid | layout | policy | return ratio | reach 0.999 U* | steps / fewest | U / U* | min exact | s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    reasons = []
    for text in teams:
        n, grid, layout = parse_team(text)
        cfg = run_cfg.replace(num_uavs=n, grid=grid, layout=layout or run_cfg.layout)
        # the oracle first: its evaluation computes the starts' references that the others then share
        for name, policy in (("oracle", OraclePolicy(cfg)), ("random", RandomPolicy(seed=0)), ("set", None)):
            began = time.perf_counter()
            metrics = (
                agent.evaluate(cfg, num_starts=num_starts)[0]
                if policy is None
                else evaluate(policy, cfg, num_starts=num_starts)
            )
            seconds = time.perf_counter() - began
            row = [str(n), f"{grid[0]}x{grid[1]}", cfg.layout, name, *cells(metrics), f"{seconds:.0f}"]
            print("| " + " | ".join(row) + " |", flush=True)
        reasons.append(failures(agent, cfg, num_starts))
        if cfg.layout != "random":
            reasons.append(from_the_optimum(agent, cfg))
    print("\n" + "\n".join(f"- {line}" for line in reasons))


@torch.no_grad()
def failures(agent, cfg, num_starts: int) -> str:
    """How the starts that miss 0.999 U* fail (module doc), from the evaluation's starts."""
    horizon = evaluation_horizon(cfg)
    env = UAVSpectrumEnv(batch_size=num_starts, config=cfg.replace(max_steps=horizon), seed=EVAL_SEED)
    start = env.reset()
    u_star = env.optimum()[0]
    policy = agent.policy_for(cfg).bind_env(env)
    rollout = env.rollout(horizon, policy, auto_reset=False, tensordict=start, break_when_any_done=False)
    ratio = env.world.utility(rollout["next", "positions"], rollout["next", "tasks"])[2] / u_star[:, None]
    missed = ~(ratio >= 0.999).any(-1)
    acts = rollout["next", "moves"].squeeze(-1) + rollout["next", "task_switches"].squeeze(-1)
    acting = acts[:, -10:].sum(-1) > 0
    best = ratio.max(-1).values[missed]
    worst = f", best U / U* {best.mean():.4f} (min {best.min():.4f})" if missed.any() else ""
    return (
        f"{cfg.num_uavs} UAVs on {cfg.grid[0]}x{cfg.grid[1]} ({cfg.layout}): {int(missed.sum())} of {num_starts} "
        f"starts miss 0.999 U*: {int((missed & acting).sum())} still acting in the last 10 of {horizon} steps, "
        f"{int((missed & ~acting).sum())} stuck{worst}; {int((~missed & acting).sum())} that reached it still act"
    )


@torch.no_grad()
def from_the_optimum(agent, cfg, orders: int = 16) -> str:
    """The checkpoint started at U*'s configuration, its UAVs in ``orders`` random orders (module doc)."""
    horizon = evaluation_horizon(cfg)
    env = UAVSpectrumEnv(batch_size=orders, config=cfg.replace(max_steps=horizon), seed=EVAL_SEED)
    start = env.reset()
    u_star, positions, tasks = env.optimum()
    generator = torch.Generator().manual_seed(0)
    order = torch.stack([torch.randperm(cfg.num_uavs, generator=generator) for _ in range(orders)])
    code = (2 * env.cells_of(positions) + tasks).gather(1, order)
    start.update(env._outputs(env.world.start_at(code)))  # reset's done flags, the optimum's observations
    assert torch.allclose(env.world.utility(start["positions"], start["tasks"])[2], u_star)
    policy = agent.policy_for(cfg).bind_env(env)
    rollout = env.rollout(horizon, policy, auto_reset=False, tensordict=start, break_when_any_done=False)
    ratio = env.world.utility(rollout["next", "positions"], rollout["next", "tasks"])[2] / u_star[:, None]
    acts = rollout["next", "moves"].squeeze(-1) + rollout["next", "task_switches"].squeeze(-1)
    held = int((ratio >= 0.999).all(-1).sum())
    return (
        f"{cfg.num_uavs} UAVs on {cfg.grid[0]}x{cfg.grid[1]} started at U*'s configuration ({orders} orders of its "
        f"UAVs): the greedy policy moves or switches {int(acts.sum())} times in all {horizon} steps of the {orders} "
        f"({int(acts[:, 0].sum())} at the first step), holds 0.999 U* throughout in {held}, "
        f"ends there in {int((ratio[:, -1] >= 0.999).sum())}, lowest U / U* on the way {float(ratio.min()):.4f}"
    )


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 64, sys.argv[3:] or DEFAULT_TEAMS)
