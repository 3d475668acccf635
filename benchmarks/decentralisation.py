"""The price of decentralisation (BENCHMARKS.md): the DQN acting on what each UAV hears, against the communication
radius, with and without learned messages, beside the central DQN, the oracle planner and random.

Each row is ``python -m uavrl.train agent=dqn scenario=<n6_10x10|large_20x20> env.observation=local
env.comm_radius=<r> [env.message_size=4] seed=<s> eval.num_starts=200`` run as a whole process (the scenario's DQN
budget unchanged), or the central DQN (``env.observation=central``).  ``--collect`` reads the run directories and
prints one markdown row per run: the share of the 200 held-out starts reaching 0.999 U*, the final U/U* (the
saved greedy policy evaluated here, as the training command evaluates it at its end), the steps to 0.999 U* against
the oracle planner's from the same starts (those both reach, ``yardstick.py --paired``'s ratio) and the training CPU
seconds (the run's ``metrics.json``); the oracle's and the random policy's rows are played here from the same starts.
``--figure`` draws the share reaching 0.999 U* against the radius, per team.  A size-free run (``agent.network=set``,
``scenario=size_free``) is scored in both teams' models at its radius.

Usage::

    python benchmarks/decentralisation.py --train runs/dec --seeds 0        # every row (about 4 CPU hours)
    python benchmarks/decentralisation.py --collect runs/dec --figure docs/figures/decentralisation.png
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

import yaml

SCENARIOS = {6: "n6_10x10", 10: "large_20x20"}
SIZE_FREE_TEAMS = ((6, (10, 10)), (10, (20, 20)))  # where a size-free run (agent.network=set) is scored
RADII = (0.0, 1.0, 2.0, 4.0, None)  # cells; None: every UAV and node heard
MESSAGE_SIZE = 4
SIZE_FREE_RADII = (2.0, None)  # the size-free network's runs (scenario=size_free)


def row_name(num_uavs: int, radius: float | None, messages: bool, central: bool = False) -> str:
    team = "" if num_uavs == 6 else "n10_"
    if central:
        return f"{team}central"
    return f"{team}{'full' if radius is None else f'r{radius:g}'}{'m' if messages else ''}"


def rows() -> dict[str, list[str]]:
    """Every row's overrides by name (the sweep's ``<name>_s<seed>`` run directories)."""
    out = {}
    for num_uavs, scenario in SCENARIOS.items():
        out[row_name(num_uavs, None, False, central=True)] = [f"scenario={scenario}", "env.observation=central"]
        for radius in RADII:
            for messages in (False, True):
                if messages and radius == 0.0:  # no one hears: messages reach no one
                    continue
                overrides = [f"scenario={scenario}", "env.observation=local"]
                overrides += [] if radius is None else [f"env.comm_radius={radius}"]
                overrides += [f"env.message_size={MESSAGE_SIZE}"] if messages else []
                out[row_name(num_uavs, radius, messages)] = overrides
    for radius in SIZE_FREE_RADII:  # one size-free run per radius, scored in both teams
        name = f"set_{'full' if radius is None else f'r{radius:g}'}"
        out[name] = ["scenario=size_free", "env.observation=local"]
        out[name] += [] if radius is None else [f"env.comm_radius={radius}"]
    return out


def train(out: Path, seeds: list[int]) -> None:
    for name, overrides in rows().items():
        for seed in seeds:
            run_dir = out / f"{name}_s{seed}"
            command = [sys.executable, "-m", "uavrl.train", "agent=dqn", *overrides, f"seed={seed}"]
            command += ["eval.num_starts=200", f"run_dir={run_dir}", "progress=false"]
            print("+", " ".join(command[1:]), flush=True)
            subprocess.run(command, check=True)


def collect(runs: Path, starts: int) -> list[dict]:
    """One dict per run directory of ``runs`` (its row, seed, metrics and the paired oracle ratio), then the
    oracle's and random's rows of each team from the same starts."""
    from yardstick import steps_to_level

    from uavrl import load_policy
    from uavrl.agents.baselines import OraclePolicy, RandomPolicy
    from uavrl.agents.evaluation import evaluate

    results, models, oracles = [], {}, {}
    for run_dir in sorted(p for p in runs.iterdir() if (p / "metrics.json").is_file()):
        metrics = json.loads((run_dir / "metrics.json").read_text())
        saved = yaml.safe_load((run_dir / "config.yaml").read_text())
        env, size_free = saved["env"], saved["agent"].get("network") == "set"
        own = load_policy(run_dir)[1]
        # a size-free run acts in both teams' models (SIZE_FREE_TEAMS), a per-size one in its own
        teams = [own.replace(num_uavs=n, grid=g) for n, g in SIZE_FREE_TEAMS] if size_free else [own]
        for team in teams:
            policy, cfg = load_policy(run_dir, env_config=team)
            scores = evaluate(policy, cfg, num_starts=starts)
            mine, reached = steps_to_level(policy, cfg, starts)
            central = cfg.replace(observation="central", comm_radius=None, message_size=0)
            central = models.setdefault(cfg.num_uavs, central)
            if cfg.num_uavs not in oracles:  # the oracle reads positions and tasks alone: once per team
                oracles[cfg.num_uavs] = steps_to_level(OraclePolicy(central), central, starts)
            oracle, oracle_reached = oracles[cfg.num_uavs]
            both = reached & oracle_reached
            name, _, seed = run_dir.name.rpartition("_s")
            results.append(
                dict(
                    row=name,
                    seed=int(seed),
                    num_uavs=cfg.num_uavs,
                    observation=env.get("observation", "central") + (", size-free" if size_free else ""),
                    radius=env.get("comm_radius"),
                    message_size=env.get("message_size") or 0,
                    reach=scores["eval/reach_999"],
                    optimality=scores["eval/optimality"],
                    oracle_ratio=float(mine[both].mean() / oracle[both].mean()) if both.any() else float("nan"),
                    train_cpu_seconds=metrics["train_cpu_seconds"],
                )
            )
    for num_uavs, cfg in sorted(models.items()):
        team = "" if num_uavs == 6 else "n10_"
        for name, reached in (
            ("oracle", oracles[num_uavs][1]),
            ("random", steps_to_level(RandomPolicy(0), cfg, starts)[1]),
        ):
            results.append(dict(row=f"{team}{name}", num_uavs=num_uavs, reach=float(reached.float().mean())))
    # per team: its runs (central first, then by radius, network, messages and seed), then the oracle and random
    return sorted(
        results,
        key=lambda r: (
            r["num_uavs"],
            "seed" not in r,
            r.get("observation") != "central",
            float("inf") if r.get("radius") is None else float(r["radius"]),  # typed 1 or 1.0: one radius
            r.get("observation", ""),  # the per-size network's rows, then the size-free one's
            r.get("message_size", 0),
            r.get("seed", 0),
        ),
    )


def table(results: list[dict]) -> None:
    print(
        "| team | observation | radius (cells) | messages | seed | reach 0.999 U* | final U/U* | steps / oracle's ",
        end="",
    )
    print("| train CPU s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in results:
        if "seed" not in r:
            print(f"| N = {r['num_uavs']} | {r['row'].split('_')[-1]} | | | | {r['reach']:.3f} | | | |")
            continue
        radius = "full" if r["radius"] is None else f"{r['radius']:g}"
        local = r["observation"].startswith("local")
        print(
            f"| N = {r['num_uavs']} | {r['observation']} | {radius if local else ''} | "
            f"{r['message_size'] if local else ''} | {r['seed']} | {r['reach']:.3f} | {r['optimality']:.4f} | "
            f"{r['oracle_ratio']:.3f} | {r['train_cpu_seconds']:.0f} |"
        )


def figure(results: list[dict], path: Path) -> None:
    """Per team (a column), the share of starts reaching 0.999 U* and the steps to it over the oracle's against the
    radius: the mean over seeds joined, each seed a dot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    teams = sorted({r["num_uavs"] for r in results})
    fig, axes = plt.subplots(2, len(teams), figsize=(5.5 * len(teams), 7.6), squeeze=False, sharex=True)
    positions = {radius: k for k, radius in enumerate(RADII)}
    for column, num_uavs in enumerate(teams):
        mine = [r for r in results if r["num_uavs"] == num_uavs]
        for ax, key in ((axes[0, column], "reach"), (axes[1, column], "oracle_ratio")):
            for messages, style, colour in ((0, "o-", "tab:blue"), (MESSAGE_SIZE, "s--", "tab:orange")):
                runs = [r for r in mine if r.get("observation") == "local" and r["message_size"] == messages]
                seeds = {}  # each radius's values over its seeds
                for r in runs:
                    seeds.setdefault(positions[r["radius"]], []).append(r[key])
                label = f"local, messages of {messages}" if messages else "local, no messages"
                if runs:
                    ax.plot(
                        sorted(seeds),
                        [statistics.fmean(seeds[x]) for x in sorted(seeds)],
                        style,
                        color=colour,
                        label=label,
                    )
                    ax.plot([positions[r["radius"]] for r in runs], [r[key] for r in runs], ".", color=colour, ms=4)
            size_free = [r for r in mine if r.get("observation") == "local, size-free"]
            if size_free:
                x = [positions[r["radius"]] for r in size_free]
                ax.plot(x, [r[key] for r in size_free], "D", color="tab:purple", label="size-free network, local")
            for r in mine:
                if r.get("observation") == "central":
                    ax.axhline(r[key], color="tab:green", ls=":", lw=2, label=f"central DQN (seed {r['seed']})")
                elif r["row"].endswith("oracle"):
                    ax.axhline(1.0, color="black", lw=0.8, label="oracle planner")
                elif r["row"].endswith("random") and key == "reach":
                    ax.axhline(r["reach"], color="tab:red", lw=0.8, label="random")
            ax.grid(alpha=0.3)
        axes[0, column].set_ylabel("share of 200 held-out starts reaching 0.999 U*")
        axes[0, column].set_ylim(-0.02, 1.05)
        axes[0, column].set_title(f"N = {num_uavs} on {SCENARIOS[num_uavs]}")
        axes[0, column].legend(fontsize=8, loc="lower right")
        axes[1, column].set_ylabel("steps to 0.999 U* / the oracle's (same starts)")
        axes[1, column].set_xticks(range(len(RADII)), [("full" if r is None else f"{r:g}") for r in RADII])
        axes[1, column].set_xlabel("communication radius (cells)")
    fig.suptitle("The price of decentralisation: the DQN acting on what each UAV hears")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", type=Path, help="train every row into this directory")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--collect", type=Path, help="print the rows of the runs in this directory")
    parser.add_argument("--starts", type=int, default=200, help="held-out starts (the evaluation's)")
    parser.add_argument("--figure", type=Path, help="with --collect: draw the figure here")
    parser.add_argument("--json", type=Path, help="with --collect: also write the rows here")
    args = parser.parse_args()
    if args.train:
        train(args.train, args.seeds)
    if args.collect:
        results = collect(args.collect, args.starts)
        table(results)
        if args.json:
            args.json.write_text(json.dumps(results, indent=1))
        if args.figure:
            figure(results, args.figure)


if __name__ == "__main__":
    main()
