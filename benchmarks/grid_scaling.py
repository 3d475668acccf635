"""What a larger grid costs at a fixed team: every figure on the large grid beside the same on 10x10, and the ratio.

For each team size N (``--num-uavs``) and each grid (``--grids``, the first the baseline), in CPU seconds:

* ``world build``: ``UAVSpectrumEnv(batch_size=B)`` built in a fresh process: the per-cell tables of the layout,
  built once per layout (and shared by every environment of that layout in a process);
* ``env reset``, ``env step``: one ``env.reset()`` / ``env.step(td)`` of all ``B`` worlds (every UAV senses), the
  median of ``--repeats`` after a warm-up;
* ``DQN iteration``: ``python -m uavrl.train agent=dqn`` with ``--iterations`` iterations, its ``train_cpu_seconds``
  (the evaluation left out) over the iterations;
* ``evaluate (command)``: the whole ``python -m uavrl.evaluate`` of that run's checkpoint, ``--starts`` starts, the
  same horizon on every grid (``--horizon``, 10x10's default: the default horizon, ``2 (L1 + L2)``, grows with the
  grid by definition), the child process's user + system time.

Grids are measured alternately and each figure is the median over ``--rounds`` rounds, so a machine whose load
changes during the run shifts both sides alike.  N > 2 uses the size-free network (``agent.network=set``).

Usage::

    python benchmarks/grid_scaling.py                                  # N = 2, 10x10 against 1000x1000
    python benchmarks/grid_scaling.py --num-uavs 10 50 --rounds 1
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENV_PROBE = r"""
import json, statistics, sys, time
import torch
torch.set_num_threads(1)
from uavrl.envs import UAVSpectrumEnv
grid, num_uavs, worlds, repeats = json.loads(sys.argv[1])
start = time.process_time()
env = UAVSpectrumEnv(batch_size=worlds, grid=tuple(grid), num_uavs=num_uavs, max_steps=10**6)
build = time.process_time() - start
td = env.reset()
td.set(("agents", "action"), torch.full((worlds, num_uavs), 4))  # sense: valid everywhere
env.step(td)
resets, steps = [], []
for _ in range(repeats):
    start = time.process_time(); env.reset(); resets.append(time.process_time() - start)
    start = time.process_time(); env.step(td); steps.append(time.process_time() - start)
print(json.dumps([build, statistics.median(resets), statistics.median(steps)]))
"""


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--num-uavs", type=int, nargs="+", default=[2], help="team sizes N (default 2)")
    p.add_argument("--grids", type=int, nargs="+", default=[10, 1000], help="square grid sides, baseline first")
    p.add_argument("--worlds", type=int, default=256, help="worlds B of the environment's reset and step")
    p.add_argument("--repeats", type=int, default=50, help="timed resets and steps per process")
    p.add_argument("--iterations", type=int, default=3, help="DQN iterations per training run")
    p.add_argument("--starts", type=int, default=64, help="starts of the evaluation")
    p.add_argument("--horizon", type=int, default=40, help="evaluation steps on every grid")
    p.add_argument("--rounds", type=int, default=3, help="alternating rounds; each figure is their median")
    p.add_argument("--skip-dqn", action="store_true", help="the environment's figures only")
    return p.parse_args(argv)


TRANSIENT = "Resource temporarily unavailable"  # a loaded machine out of threads for a moment: run it again


def child_cpu(command: list[str], cwd: str, tries: int = 3) -> float:
    """User + system CPU seconds of ``command`` run to completion as a child process (one line on failure)."""
    for _ in range(tries):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        env = {**os.environ, "OMP_NUM_THREADS": "1"}
        done = subprocess.run(command, cwd=cwd, capture_output=True, text=True, env=env)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if not done.returncode:
            return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        if TRANSIENT not in done.stderr:
            break
    raise SystemExit(f"{' '.join(command)} failed: {done.stderr.strip().splitlines()[-1]}")


def env_figures(side: int, num_uavs: int, args) -> dict[str, float]:
    probe = json.dumps([[side, side], num_uavs, args.worlds, args.repeats])
    done = subprocess.run([sys.executable, "-c", ENV_PROBE, probe], capture_output=True, text=True, check=True)
    build, reset, step = json.loads(done.stdout.strip().splitlines()[-1])
    return {"world build": build, "env reset": reset, "env step": step}


def dqn_figures(side: int, num_uavs: int, args, workdir: str, tag: str) -> dict[str, float]:
    run_dir = str(Path(workdir) / f"{tag}-n{num_uavs}-{side}")
    network = ["agent.network=set"] if num_uavs > 2 else []
    common = [f"env.grid=[{side},{side}]", f"env.num_uavs={num_uavs}", f"eval.horizon={args.horizon}"]
    train = [sys.executable, "-m", "uavrl.train", "agent=dqn", *network, *common]
    train += [f"agent.iterations={args.iterations}", "eval.num_starts=4", f"run_dir={run_dir}", "seed=0"]
    child_cpu(train, workdir)
    metrics = json.loads((Path(run_dir) / "metrics.json").read_text())
    evaluate = [sys.executable, "-m", "uavrl.evaluate", f"checkpoint={run_dir}", f"eval.num_starts={args.starts}"]
    evaluate += [f"eval.horizon={args.horizon}"]
    return {
        "DQN iteration": metrics["train_cpu_seconds"] / args.iterations,
        "evaluate (command)": child_cpu(evaluate, workdir),
    }


def main(argv=None) -> None:
    args = parse_args(argv)
    print(f"# {time.strftime('%Y-%m-%d')}, torch threads 1, B = {args.worlds}, {args.rounds} alternating rounds")
    with tempfile.TemporaryDirectory() as workdir:
        for num_uavs in args.num_uavs:
            figures = {side: {} for side in args.grids}
            for round_ in range(args.rounds):
                for side in args.grids:  # alternate: every grid once per round
                    measured = env_figures(side, num_uavs, args)
                    if not args.skip_dqn:
                        measured |= dqn_figures(side, num_uavs, args, workdir, f"r{round_}")
                    for name, value in measured.items():
                        figures[side].setdefault(name, []).append(value)
            base, *others = args.grids
            network = "per-size network" if num_uavs <= 2 else "size-free network"
            print(f"\nN = {num_uavs} ({network}): CPU seconds, median of {args.rounds}")
            header = f"| figure | {base}x{base} |" + "".join(f" {s}x{s} | ratio |" for s in others)
            print(header)
            print("|" + "---|" * (2 + 2 * len(others)))
            for name in figures[base]:
                base_value = statistics.median(figures[base][name])
                row = f"| {name} | {base_value:.4g} |"
                for side in others:
                    value = statistics.median(figures[side][name])
                    row += f" {value:.4g} | {value / base_value:.2f}x |"
                print(row, flush=True)


if __name__ == "__main__":
    main()
