"""How each figure changes with N: a per-size DQN (the specialist) beside one size-free checkpoint, N = 2 to 50.

    python benchmarks/scaling.py --size-free <run> --out <dir> [--starts 64] [--only N ...]

For each size (``SIZES``: N = 2 on 6x6, 6 on 10x10, 10 on 20x20, 20 on 30x30, 50 on 50x50), the specialist is the
training command a user types (``python -m uavrl.train agent=dqn ...`` with that size's overrides, seed 0, one
thread), run as a whole process unless ``<out>/<N>uav/metrics.json`` is already there; its wall and CPU seconds and
peak resident memory come from GNU time (saved beside the run as ``resources.json``).  The size-free checkpoint
(``agent.network=set``, trained once on other teams) has its training's seconds from its ``metrics.json`` and its
peak memory from ``<run>/resources.json`` where one was written (``{"peak_mb": ...}``, e.g. from ``/usr/bin/time
-v``).  Each checkpoint is then evaluated on each size by ``python -m uavrl.evaluate checkpoint=<run>
[env.num_uavs=N env.grid=[L1,L2]] eval.num_starts=<starts>``, a whole process (its wall seconds and peak memory),
and the oracle planner from the same starts in this process; "/ oracle" is the quotient of the two
mean step counts to 0.999 U* over the fewest (each over its own reaching starts).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

from uavrl.agents.baselines import OraclePolicy
from uavrl.agents.evaluation import evaluate
from uavrl.config import model_config
from uavrl.experiment.saved import load_agent

# (N, grid, the specialist's overrides): the scenarios' budgets where one exists, else about 15-20 minutes of one core
SIZES = [
    (2, (6, 6), ["scenario=paper_6x6"]),
    (6, (10, 10), ["scenario=n6_10x10"]),
    (10, (20, 20), ["scenario=large_20x20"]),
    (20, (30, 30), ["env.grid=[30,30]", "env.num_uavs=20", "env.max_steps=60", "agent.iterations=200"]),
    (
        50,
        (50, 50),
        ["env.grid=[50,50]", "env.num_uavs=50", "env.max_steps=100", "agent.worlds=32", "agent.iterations=150"],
    ),
]
ONE_THREAD = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
GNU_TIME = "/usr/bin/time"


def run_with_usage(argv: list[str]) -> dict:
    """Run ``python <argv>`` as a whole process, one torch thread, its own report kept out of the table; wall and CPU
    seconds and peak resident memory (MB) from GNU time: ``wait4`` from this process would count this process's
    memory too (Linux keeps the larger of the two across the child's ``exec``)."""
    if not Path(GNU_TIME).exists():
        raise SystemExit(f"{GNU_TIME} not found: install GNU time (Debian: apt install time)")
    with tempfile.NamedTemporaryFile("r") as report:
        began = time.perf_counter()
        command = [GNU_TIME, "-f", "%U %S %M", "-o", report.name, sys.executable, *argv]
        done = subprocess.run(command, env={**os.environ, **ONE_THREAD}, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - began
        if done.returncode:
            raise SystemExit(f"failed: python {' '.join(argv)}")
        user, system, peak_kb = report.read().split()[-3:]
    return {"wall_s": wall, "cpu_s": float(user) + float(system), "peak_mb": int(peak_kb) / 1024}


def train_specialist(run_dir: Path, overrides: list[str]) -> dict:
    """The specialist's run (trained now unless already there) and its training's resources."""
    resources = run_dir / "resources.json"
    if not (run_dir / "metrics.json").exists():
        argv = ["-m", "uavrl.train", "agent=dqn", *overrides, "seed=0", "progress=false", f"run_dir={run_dir}"]
        resources.write_text(json.dumps(run_with_usage(argv)))
    return resources_of(run_dir)


def resources_of(run_dir: Path) -> dict:
    """The training's measured resources (``resources.json``), ``{}`` where none were written."""
    resources = run_dir / "resources.json"
    return json.loads(resources.read_text()) if resources.exists() else {}


def evaluate_on(run_dir: Path, n: int, grid: tuple[int, int], starts: int, own: bool) -> dict:
    """The run's checkpoint evaluated on ``n`` UAVs on ``grid`` (a whole process) and its metrics."""
    size = [] if own else [f"env.num_uavs={n}", f"env.grid=[{grid[0]},{grid[1]}]"]
    usage = run_with_usage(["-m", "uavrl.evaluate", f"checkpoint={run_dir}", *size, f"eval.num_starts={starts}"])
    name = "eval.json" if own else f"eval-{n}uav-{grid[0]}x{grid[1]}.json"
    return usage | json.loads((run_dir / name).read_text())


def oracle_steps(run_cfg, n: int, grid: tuple[int, int], starts: int) -> float:
    """The oracle planner's steps to 0.999 U* over the fewest, from the evaluation's starts (the run's model but for N
    and the grid)."""
    cfg = run_cfg.replace(num_uavs=n, grid=grid)
    return evaluate(OraclePolicy(cfg), cfg, num_starts=starts)["eval/step_ratio_999"]


def checkpoint_mb(run_dir: Path) -> float:
    return (run_dir / "checkpoint.pt").stat().st_size / 1e6


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size-free", type=Path, required=True, help="a run of agent.network=set")
    parser.add_argument("--out", type=Path, required=True, help="where the specialists' runs are (or go)")
    parser.add_argument("--starts", type=int, default=64)
    parser.add_argument("--only", type=int, nargs="+", help="these team sizes only")
    parser.add_argument("--train-only", action="store_true", help="train the missing specialists, evaluate nothing")
    args = parser.parse_args()
    torch.set_num_threads(1)
    sizes = [size for size in SIZES if not args.only or size[0] in args.only]
    if args.train_only:
        for n, _, overrides in sizes:
            print(n, train_specialist(args.out / f"{n}uav", overrides), flush=True)
        return
    free = args.size_free
    run_cfg = model_config(load_agent(free)[1])
    free_metrics = json.loads((free / "metrics.json").read_text())
    print(
        "| N | grid | policy | train s (CPU s) | train peak MB | checkpoint MB | eval s | eval peak MB "
        "| reach 0.999 U* | steps / fewest | / oracle |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for n, grid, overrides in sizes:
        oracle = oracle_steps(run_cfg, n, grid, args.starts)
        specialist = args.out / f"{n}uav"
        rows = [
            ("specialist", specialist, train_specialist(specialist, overrides), None, True),
            # the run's own team is evaluated as its own (eval.json), any other zero-shot (eval-<N>uav-<grid>.json)
            ("size-free", free, resources_of(free), free_metrics, (n, grid) == (run_cfg.num_uavs, tuple(run_cfg.grid))),
        ]
        for name, run_dir, usage, known, own in rows:
            metrics = known or json.loads((run_dir / "metrics.json").read_text())
            m = evaluate_on(run_dir, n, grid, args.starts, own)
            steps = m.get("eval/step_ratio_999")
            cells = [
                str(n),
                f"{grid[0]}x{grid[1]}",
                name,
                f"{metrics['train_seconds']:.0f} ({metrics['train_cpu_seconds']:.0f})",
                f"{usage['peak_mb']:.0f}" if usage.get("peak_mb") else "-",
                f"{checkpoint_mb(run_dir):.1f}",
                f"{m['wall_s']:.0f}",
                f"{m['peak_mb']:.0f}",
                f"{m['eval/reach_999']:.3f}",
                "-" if steps is None else f"{steps:.3f}",
                "-" if steps is None else f"{steps / oracle:.3f}",
            ]
            print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
