"""Time to the yardstick at ``scenario=n6_10x10``: an earlier commit's DQN and this checkout's, side by side.

For each seed, every variant is the training command a user types, a whole
process with one torch thread (``python -m uavrl.train agent=dqn
scenario=n6_10x10 seed=<k> eval.num_starts=200`` and the variant's
overrides); the baseline runs the code of ``--baseline REV`` (a temporary git
worktree), the others this checkout.  All variants of a seed run at the same
time, so they share the machine's load.  Printed per run: the training's wall
and CPU seconds (the periodic evaluations left out: ``train_seconds``, ``train_cpu_seconds`` of metrics.json),
the share of the 200 held-out starts that reach 0.999 U*, and the steps to
reach it over the oracle planner's from the same starts (those both reach),
as ``benchmarks/yardstick.py --paired`` computes them.  With ``--out``, a run
that already finished there (its ``metrics.json`` written) is read instead of
trained again, so an interrupted comparison continues where it stopped.

Usage::

    python benchmarks/dqn_speed.py --baseline 36027f6 --seeds 0 \\
        --variant fast agent.iterations=300 agent.lr=0.001
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from dqn_iteration import ROOT, _installed_names, checkouts_beside
from yardstick import steps_to_level

COMMAND = ["agent=dqn", "scenario=n6_10x10", "eval.num_starts=200", "progress=false"]
TRAIN = "import runpy\nrunpy.run_module('uavrl.train', run_name='__main__')\n"


def start(checkout: Path, overrides: list[str], run_dir: Path) -> subprocess.Popen:
    """``python -m uavrl.train`` of the code in ``checkout``, one torch thread."""
    code = "import sys\n" + _installed_names(checkout) + TRAIN
    argv = [*COMMAND, *overrides, f"run_dir={run_dir}"]
    env_vars = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-c", code, *argv], env={**os.environ, **env_vars}, text=True)


def oracle_ratio(run_dir: Path, starts: int = 200) -> float:
    """Steps to 0.999 U* over the oracle planner's, the starts both reach."""
    from uavrl import load_policy
    from uavrl.agents.baselines import OraclePolicy

    policy, cfg = load_policy(run_dir)
    mine, mine_reached = steps_to_level(policy, cfg, starts)
    oracle, oracle_reached = steps_to_level(OraclePolicy(cfg), cfg, starts)
    both = mine_reached & oracle_reached
    return float(mine[both].mean() / oracle[both].mean())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", required=True, help="a git revision whose defaults are today's figures")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument(
        "--variant", nargs="+", action="append", default=[], help="NAME then overrides, run with this checkout"
    )
    parser.add_argument("--out", type=Path, help="where the runs go (default: a temporary folder)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp, checkouts_beside(args.baseline) as checkouts:
        out = args.out or Path(tmp)
        variants = {f"baseline {args.baseline}": (checkouts[f"baseline {args.baseline}"], [])}
        variants |= {name: (ROOT, overrides) for name, *overrides in args.variant}
        print("| variant | seed | train s | train CPU s | reach 0.999 U* | / oracle | overrides |")
        print("|---|---|---|---|---|---|---|")
        for seed in args.seeds:
            runs = {}
            for name, (checkout, overrides) in variants.items():
                run_dir = out / f"{name.replace(' ', '_')}-seed{seed}"
                done = (run_dir / "metrics.json").exists()
                runs[name] = (run_dir, None if done else start(checkout, [*overrides, f"seed={seed}"], run_dir))
            for name, (run_dir, process) in runs.items():
                if process is not None and process.wait() != 0:
                    raise SystemExit(f"{name} seed {seed} failed")
                m = json.loads((run_dir / "metrics.json").read_text())
                print(
                    f"| {name} | {seed} | {m['train_seconds']:.0f} | {m['train_cpu_seconds']:.0f} "
                    f"| {m['eval/reach_999']:.3f} | {oracle_ratio(run_dir):.3f} "
                    f"| {' '.join(variants[name][1]) or '(defaults)'} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
