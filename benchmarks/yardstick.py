"""Every agent and baseline on the yardstick (BENCHMARKS.md, "The yardstick"): train as a user would, read metrics.json.

Each row runs ``python -m uavrl.train <overrides> seed=<seed>`` as a whole
process (Python start-up, training and the shared final evaluation on
``--starts`` held-out starts), and prints one markdown row per row name and
seed: the old final-utility measure beside the yardstick (return ratio against
the exact optimum where it exists, share of starts reaching 0.999 U*, steps to
reach it and their ratio to the fewest possible, exact or a lower bound).

Usage::

    python benchmarks/yardstick.py --table n2 --seeds 0 1 2      # N = 2 on 6x6
    python benchmarks/yardstick.py --table n6 --seeds 0 1 2      # N = 6 on 10x10
    python benchmarks/yardstick.py --rows n6-dqn n6-oracle --seeds 0
    python benchmarks/yardstick.py --paired runs/dqn/n6_10x10/<stamp> ...   # against the oracle, start by start

``--paired`` plays each saved run's greedy policy and the oracle planner from
the same held-out starts (the evaluation's) and compares their steps to 0.999
U* over the starts both reach: the ratio of the mean steps.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

N6, N6_RANDOM_LAYOUTS = ["scenario=n6_10x10"], ["scenario=random_layouts"]  # 6 UAVs on 10x10, and their budgets
ROWS = {
    "n2-random": ["agent=random"],
    "n2-oracle": ["agent=oracle"],
    "n2-tabular": ["agent=tabular"],
    "n2-tabular-tasks": ["agent=tabular", "env.state_includes_tasks=true"],
    "n2-vi": ["agent=tabular", "agent.method=value_iteration"],
    "n2-vi-tasks": ["agent=tabular", "agent.method=value_iteration", "env.state_includes_tasks=true"],
    "n2-dqn": ["agent=dqn"],
    "n2-dqn-joint": ["agent=dqn", "agent.head=joint"],
    "n6-random": ["agent=random", *N6],
    "n6-oracle": ["agent=oracle", *N6],
    "n6-dqn": ["agent=dqn", *N6],  # the scenario's mixer, QMIX
    "n6-dqn-vdn": ["agent=dqn", *N6, "agent.mixer=vdn"],
    "n6-random-layouts-random": ["agent=random", *N6_RANDOM_LAYOUTS],
    "n6-random-layouts-oracle": ["agent=oracle", *N6_RANDOM_LAYOUTS],
    "n6-random-layouts-dqn": ["agent=dqn", *N6_RANDOM_LAYOUTS],
}
TABLES = {name: [row for row in ROWS if row.startswith(name + "-")] for name in ("n2", "n6")}
DETERMINISTIC = ("oracle", "vi")  # one seed is enough


def run_row(name: str, seed: int, starts: int, out: Path) -> dict:
    overrides = [*ROWS[name], f"seed={seed}", f"eval.num_starts={starts}"]
    run_dir = out / f"{name}-seed{seed}"
    started, cpu_before = time.perf_counter(), _children_cpu_seconds()
    done = subprocess.run(
        [sys.executable, "-m", "uavrl.train", *overrides, f"run_dir={run_dir}", "progress=false"],
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise SystemExit(f"{name} seed {seed} failed:\n{done.stderr}")
    metrics = json.loads((run_dir / "metrics.json").read_text())
    return {
        "row": name,
        "seed": seed,
        "command": "python -m uavrl.train " + " ".join(overrides),
        "wall_seconds": time.perf_counter() - started,
        # the command's CPU time: on a shared machine, close to its wall time on an idle one (one torch thread)
        "cpu_seconds": _children_cpu_seconds() - cpu_before,
        **metrics,
    }


def _children_cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def steps_to_level(policy, cfg, starts: int, level: float = 0.999):
    """``[starts]`` first step at which the greedy ``policy`` reaches ``level`` U* from the evaluation's starts
    (``-1``: never within the horizon), and whether it did."""
    import torch

    from uavrl.agents.evaluation import EVAL_SEED, default_horizon
    from uavrl.envs import UAVSpectrumEnv

    horizon = default_horizon(cfg.grid)
    env = UAVSpectrumEnv(batch_size=starts, config=cfg.replace(max_steps=horizon), seed=EVAL_SEED)
    start = env.reset()
    if hasattr(policy, "bind_env"):
        policy.bind_env(env)
    with torch.no_grad():
        steps = env.rollout(horizon, policy, auto_reset=False, tensordict=start, break_when_any_done=False)["next"]
    positions = torch.cat([start["positions"].unsqueeze(1), steps["positions"]], 1)
    tasks = torch.cat([start["tasks"].unsqueeze(1), steps["tasks"]], 1)
    at = env.utility(positions, tasks)[2] >= level * env.optimum()[0].unsqueeze(-1)
    return torch.where(at.any(-1), at.double().argmax(-1), -1.0), at.any(-1)


def paired(run_dirs: list[Path], starts: int) -> None:
    """Each run's steps to 0.999 U* against the oracle planner's, over the same starts (those both reach)."""
    from uavrl import load_policy
    from uavrl.agents.baselines import OraclePolicy

    print("| run | starts both reach | mean steps | oracle's mean steps, same starts | ratio |")
    print("|---|---|---|---|---|")
    for run_dir in run_dirs:
        policy, cfg = load_policy(run_dir)
        mine, mine_reached = steps_to_level(policy, cfg, starts)
        oracle, oracle_reached = steps_to_level(OraclePolicy(cfg), cfg, starts)
        both = mine_reached & oracle_reached
        ratio = mine[both].mean() / oracle[both].mean()
        print(
            f"| {run_dir} | {int(both.sum())}/{starts} | {mine[both].mean():.3f} | {oracle[both].mean():.3f} "
            f"| {ratio:.3f} |"
        )


def cell(metrics: dict, key: str, fmt: str) -> str:
    return format(metrics[key], fmt) if key in metrics else "-"


def row(m: dict) -> str:
    fewest = "exact" if m.get("eval/min_steps_exact") == 1.0 else "bound"
    return (
        f"| {m['row']} | {m['seed']} | {cell(m, 'eval/optimality', '.4f')} | {cell(m, 'eval/return_ratio', '.4f')} "
        f"| {cell(m, 'eval/reach_999', '.2f')} | {cell(m, 'eval/steps_to_999', '.2f')} | "
        f"{cell(m, 'eval/min_steps_to_999', '.2f')} ({fewest}) "
        f"| {cell(m, 'eval/step_ratio_999', '.3f')} | {cell(m, 'eval/reach_optimum', '.2f')} | "
        f"{cell(m, 'eval/step_ratio_optimum', '.3f')} "
        f"| {m['train_seconds']:.0f} | {m.get('wall_seconds', m['total_seconds']):.0f} "
        f"| {cell(m, 'cpu_seconds', '.0f')} |"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--table", choices=sorted(TABLES), help="every row of one table")
    parser.add_argument("--rows", nargs="+", choices=sorted(ROWS), default=[])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--starts", type=int, default=200, help="held-out evaluation starts (and layouts)")
    parser.add_argument("--out", type=Path, default=None, help="where the runs go (default: a temporary directory)")
    parser.add_argument("--json", type=Path, default=None, help="also write every result here")
    parser.add_argument("--collect", type=Path, default=None, help="only print the rows of the runs in this directory")
    parser.add_argument("--paired", type=Path, nargs="+", help="saved runs to play against the oracle, start by start")
    args = parser.parse_args()
    if args.paired:
        paired(args.paired, args.starts)
        return
    print(
        "| row | seed | final U/U* | return ratio | reach 0.999 | steps to 0.999 | fewest | step ratio 0.999 "
        "| reach U* | step ratio U* | train s | wall s | cpu s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    if args.collect:  # metrics.json has no wall time of the command: the column shows the run's total_seconds
        for name in ROWS:
            for path in sorted(args.collect.glob(f"{name}-seed*/metrics.json")):
                print(
                    row(
                        {
                            "row": name,
                            "seed": int(path.parent.name.rsplit("seed", 1)[1]),
                            **json.loads(path.read_text()),
                        }
                    )
                )
        return
    rows = (TABLES[args.table] if args.table else []) + args.rows
    if not rows:
        parser.error("give --table or --rows")
    out = args.out or Path(tempfile.mkdtemp(prefix="yardstick_"))
    results = []
    for name in rows:
        for seed in args.seeds[:1] if any(k in name for k in DETERMINISTIC) else args.seeds:
            results.append(run_row(name, seed, args.starts, out))
            print(row(results[-1]), flush=True)
            if args.json:
                args.json.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
