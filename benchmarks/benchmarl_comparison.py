"""Our DQN against BenchMARL's algorithms on the yardstick (BENCHMARKS.md, "BenchMARL's algorithms on the UAV task").

Each row runs as a whole process, as a user types it: ``python -m uavrl.benchmarl algorithm=<a> task=uavrl/<task>``
(BenchMARL's defaults but for the frame budget ``--frames``; our shared evaluation at each of its evaluations) or
``python -m uavrl.train agent=dqn`` (defaults, evaluated every ``--dqn-eval-every`` iterations), both with
``--starts`` held-out starts.  It prints one row per run and, per task, the target: the first time our DQN's
evaluation reaches BenchMARL's best return ratio (N = 2; at N = 6, where no exact return exists, its best step
ratio to 0.999 U* with every start reaching it) against the time BenchMARL took to its best.  Times are CPU seconds
of the process (one torch thread each), which stay comparable while other processes share the cores: BenchMARL's
as its run measured them, our evaluations excluded; the DQN's sampled from /proc every few seconds
(``cpu_samples.txt`` in its run directory) at the wall time of each evaluation event, its periodic evaluations
included (so they err against it).

Usage::

    python benchmarks/benchmarl_comparison.py --tasks paper_6x6 --seeds 0 1 2 --out runs/comparison
    python benchmarks/benchmarl_comparison.py --collect runs/comparison     # only print the finished runs
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

TASKS = {"paper_6x6": ["env.grid=[6,6]", "env.num_uavs=2"], "n6_10x10": ["env.grid=[10,10]", "env.num_uavs=6"]}
BENCHMARL = ("qmix", "vdn", "iql", "mappo")
DQN = {"dqn": [], "dqn-qmix": ["agent.mixer=qmix"]}


def command(task: str, row: str, seed: int, args, run_dir: Path) -> list[str]:
    common = [f"seed={seed}", f"eval.num_starts={args.starts}", f"run_dir={run_dir}"]
    if row in BENCHMARL:
        budget = [f"experiment.max_n_frames={args.frames}", f"experiment.evaluation_interval={args.frames // 4}"]
        return ["-m", "uavrl.benchmarl", f"algorithm={row}", f"task=uavrl/{task}", *budget, *common]
    every = f"eval.every={args.dqn_eval_every}"
    return ["-m", "uavrl.train", "agent=dqn", *TASKS[task], *DQN[row], every, "progress=false", *common]


def run_sampled(argv: list[str], samples: Path) -> subprocess.CompletedProcess:
    """Run ``argv``, writing ``<wall time> <CPU seconds>`` of the process to ``samples`` every 2 s."""
    with subprocess.Popen(argv, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as process:
        lines = []
        while process.poll() is None:
            try:
                fields = Path(f"/proc/{process.pid}/stat").read_text().rsplit(")", 1)[1].split()
                lines.append(f"{time.time()} {(int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')}")
            except (OSError, IndexError):
                pass
            time.sleep(2)
        out, err = process.communicate()
    samples.parent.mkdir(parents=True, exist_ok=True)
    samples.write_text("\n".join(lines) + "\n")
    return subprocess.CompletedProcess(argv, process.returncode, out, err)


def cpu_at(samples: list[tuple[float, float]], wall: float) -> float:
    """CPU seconds at wall time ``wall``, interpolated between the samples around it."""
    for (w0, c0), (w1, c1) in zip(samples, samples[1:], strict=False):
        if w0 <= wall <= w1:
            return c0 + (c1 - c0) * (wall - w0) / max(w1 - w0, 1e-9)
    return samples[-1][1] if wall > samples[-1][0] else samples[0][1]


def event_curve(run_dir: Path) -> list[dict]:
    """The evaluations of a run from its TensorBoard events, with the CPU seconds the process had used by then."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run_dir)).Reload()
    samples = [tuple(map(float, line.split())) for line in (run_dir / "cpu_samples.txt").read_text().splitlines()]
    tags = set(events.Tags()["scalars"])
    curve = {}
    for tag in ("eval/return_ratio", "eval/optimality", "eval/reach_999", "eval/step_ratio_999"):
        for event in events.Scalars(tag) if tag in tags else []:
            seconds = cpu_at(samples, event.wall_time)
            point = curve.setdefault(event.step, {"frames": event.step, "train_cpu_seconds": seconds})
            point[tag] = event.value
    return [curve[step] for step in sorted(curve)]


def score(point: dict) -> float | None:
    """Higher is better: the return ratio where it exists, else minus the step ratio (every start reaching)."""
    if "eval/return_ratio" in point:
        return point["eval/return_ratio"]
    if point.get("eval/reach_999", 0) >= 1 and "eval/step_ratio_999" in point:
        return -point["eval/step_ratio_999"]
    return None


def load(run_dir: Path, row: str) -> dict | None:
    """A run's final metrics and its curve; a run that did not finish (killed) shows its last evaluation."""
    finished = (run_dir / "metrics.json").exists()
    if row in BENCHMARL and finished:
        return {
            **json.loads((run_dir / "metrics.json").read_text()),
            "curve": json.loads((run_dir / "curve.json").read_text()),
        }
    if not (run_dir / "cpu_samples.txt").exists():
        return None
    curve = event_curve(run_dir)
    if not curve:
        return None
    last = json.loads((run_dir / "metrics.json").read_text()) if finished else {"env_steps": curve[-1]["frames"]}
    return {
        **curve[-1],
        **last,
        "train_cpu_seconds": curve[-1]["train_cpu_seconds"],
        "curve": curve,
        "finished": finished,
    }


def cell(metrics: dict, key: str, fmt: str) -> str:
    return format(metrics[key], fmt) if key in metrics else "-"


def print_row(task: str, row: str, seed: int, m: dict) -> None:
    print(
        f"| {task} | {row}{'' if m.get('finished', True) else ' (killed)'} | {seed} | {m['env_steps']:,} | "
        f"{cell(m, 'train_seconds', '.0f')} | {m['train_cpu_seconds']:.0f} | "
        f"{cell(m, 'eval/return_ratio', '.4f')} | {cell(m, 'eval/optimality', '.4f')} | "
        f"{cell(m, 'eval/reach_999', '.2f')} | {cell(m, 'eval/step_ratio_999', '.3f')} |",
        flush=True,
    )


def verdict(task: str, results: dict) -> None:
    """BenchMARL's best point against the first point of each of our DQN runs that matches it."""
    theirs = [
        (score(p), p["train_cpu_seconds"], row, seed)
        for (row, seed), m in results.items()
        if row in BENCHMARL
        for p in m["curve"]
        if score(p) is not None
    ]
    if not theirs:
        print(f"{task}: no BenchMARL evaluation has a score (return ratio, or every start at 0.999 U*)")
        return
    best, best_seconds, best_row, best_seed = max(theirs, key=lambda t: (t[0], -t[1]))
    print(f"{task}: BenchMARL's best score {best:.4f} ({best_row}, seed {best_seed}) after {best_seconds:.0f} CPU s")
    for (row, seed), m in results.items():
        if row in BENCHMARL:
            continue
        reached = [p["train_cpu_seconds"] for p in m["curve"] if score(p) is not None and score(p) >= best]
        if reached:
            ratio = reached[0] / best_seconds
            met = "met" if ratio <= 1 / 3 else "not met"
            print(f"  {row} seed {seed}: reached it after {reached[0]:.0f} CPU s, {ratio:.2f}x BenchMARL's ({met})")
        else:
            print(f"  {row} seed {seed}: never reached it (final score {score(m)})")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", choices=sorted(TASKS), default=["paper_6x6"])
    parser.add_argument("--rows", nargs="+", choices=[*BENCHMARL, *DQN], default=[*BENCHMARL, *DQN])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--frames", type=int, default=120_000, help="BenchMARL's budget (a multiple of 24,000)")
    parser.add_argument("--dqn-eval-every", type=int, default=25, help="iterations between the DQN's evaluations")
    parser.add_argument("--starts", type=int, default=200, help="held-out evaluation starts")
    parser.add_argument("--out", type=Path, default=Path("runs/benchmarl_comparison"))
    parser.add_argument("--collect", action="store_true", help="only print the finished runs under --out")
    args = parser.parse_args()
    print(
        "| task | row | seed | frames | train s (wall) | train CPU s | return ratio | final U/U* | reach 0.999 "
        "| step ratio 0.999 |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for task in args.tasks:
        results = {}
        for row in args.rows:
            for seed in args.seeds:
                run_dir = args.out / task / row / f"seed{seed}"
                if not args.collect:
                    done = subprocess.run(
                        [sys.executable, *command(task, row, seed, args, run_dir)], text=True, capture_output=True
                    )
                    if done.returncode != 0:
                        raise SystemExit(f"{task} {row} seed {seed} failed:\n{done.stderr[-2000:]}")
                metrics = load(run_dir, row)
                if metrics is not None:
                    results[row, seed] = metrics
                    print_row(task, row, seed, metrics)
        verdict(task, results)


if __name__ == "__main__":
    main()
