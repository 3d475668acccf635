"""Our DQN against BenchMARL's algorithms on the yardstick (BENCHMARKS.md, "BenchMARL's algorithms on the UAV task").

Each row runs as a whole process, as a user types it: ``python -m uavrl.benchmarl algorithm=<a> task=uavrl/<task>``
(BenchMARL's defaults but for the frame budget ``--frames``; our shared evaluation at each of its evaluations) or
``python -m uavrl.train agent=dqn scenario=<task>`` (the scenario's budget, evaluated every ``--dqn-eval-every``
iterations), both with ``--starts`` held-out starts and one torch thread.  ``--jobs`` processes run at once (one
per core).  Both commands log, beside each evaluation's ``eval/...``, the seconds they had trained by then with
their evaluations left out (``time/train_seconds``, ``time/train_cpu_seconds``:
``uavrl.agents.episodes.TrainingClock``);
the curves here are read from their TensorBoard events.  Times are CPU seconds of the process: with one thread per
process they are its wall time on a core of its own, and they stay comparable when other work shares the cores.

It prints one row per run and, per task, the target: the first evaluation at which each of our DQN runs reaches
BenchMARL's best score, against the time BenchMARL took to its best.  The score is the yardstick's objective: the
return ratio where the exact optimum exists (N = 2); at N = 6, where it does not, the discounted gain itself
(``eval/return``, the same starts for every run), with the share of starts reaching 0.999 U* and the step ratio
printed beside it.

Usage::

    python benchmarks/benchmarl_comparison.py --tasks paper_6x6 n6_10x10 --seeds 0 1 2 --jobs 2 --out runs/comparison
    python benchmarks/benchmarl_comparison.py --collect --out runs/comparison     # only print the finished runs
    python benchmarks/benchmarl_comparison.py --rows vdn mappo --benchmarl-overrides env.reward=log_gap --out ...
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

TASKS = ("paper_6x6", "n6_10x10")
BENCHMARL = ("qmix", "vdn", "iql", "mappo")
DQN = {"dqn": ["agent.mixer=vdn"], "dqn-qmix": ["agent.mixer=qmix"]}
CURVE_TAGS = (
    "eval/return_ratio",
    "eval/return",
    "eval/optimality",
    "eval/reach_999",
    "eval/steps_to_999",
    "eval/step_ratio_999",
)
HORIZONS = {"paper_6x6": 24, "n6_10x10": 40}  # the evaluation's horizon, max(20, 2 (L1 + L2))
TIME_TAGS = ("time/train_seconds", "time/train_cpu_seconds")


def command(task: str, row: str, seed: int, args, run_dir: Path) -> list[str]:
    common = [f"seed={seed}", f"eval.num_starts={args.starts}", f"run_dir={run_dir}", "num_threads=1"]
    if row in BENCHMARL:
        frames = args.frames[TASKS.index(task)] if len(args.frames) > 1 else args.frames[0]
        budget = [f"experiment.max_n_frames={frames}", f"experiment.evaluation_interval={args.eval_frames}"]
        extra = args.benchmarl_overrides
        return ["-m", "uavrl.benchmarl", f"algorithm={row}", f"task=uavrl/{task}", *budget, *extra, *common]
    every = f"eval.every={args.dqn_eval_every}"
    return ["-m", "uavrl.train", "agent=dqn", f"scenario={task}", *DQN[row], every, "progress=false", *common]


def curve(run_dir: Path) -> list[dict]:
    """Each evaluation of a run (its TensorBoard events): frames, the ``eval/...`` metrics and ``time/...``."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run_dir), size_guidance={"scalars": 0}).Reload()
    tags = set(events.Tags()["scalars"])
    points: dict[int, dict] = {}
    for tag in CURVE_TAGS + TIME_TAGS:
        for event in events.Scalars(tag) if tag in tags else []:
            points.setdefault(event.step, {"frames": event.step})[tag] = event.value
    return [points[step] for step in sorted(points) if TIME_TAGS[1] in points[step]]


def load(run_dir: Path) -> dict | None:
    """A run's final metrics and its curve; a run that did not finish shows its last evaluation."""
    points = curve(run_dir) if run_dir.exists() else []
    if not points:
        return None
    finished = (run_dir / "metrics.json").exists()
    last = json.loads((run_dir / "metrics.json").read_text()) if finished else {"env_steps": points[-1]["frames"]}
    return {**points[-1], **last, "curve": points, "finished": finished}


def score(point: dict) -> float | None:
    """Higher is better: the return ratio where it exists, else the discounted gain ``eval/return``."""
    return point.get("eval/return_ratio", point.get("eval/return"))


def cell(metrics: dict, key: str, fmt: str) -> str:
    return format(metrics[key], fmt) if key in metrics else "-"


def print_row(task: str, row: str, seed: int, m: dict) -> None:
    print(
        f"| {task} | {row}{'' if m['finished'] else ' (stopped)'} | {seed} | {m['env_steps']:,} | "
        f"{cell(m, 'time/train_seconds', '.0f')} | {cell(m, 'time/train_cpu_seconds', '.0f')} | "
        f"{cell(m, 'eval/return_ratio', '.4f')} | {cell(m, 'eval/return', '.4f')} | "
        f"{cell(m, 'eval/optimality', '.4f')} | "
        f"{cell(m, 'eval/reach_999', '.2f')} | {cell(m, 'eval/step_ratio_999', '.3f')} |",
        flush=True,
    )


def steps_to_optimum(point: dict, horizon: int) -> float:
    """Mean over all starts of the steps to 0.999 U*, a start that never gets there counted as the horizon: one
    number for how many starts reach it and how fast (lower is better)."""
    reach = point.get("eval/reach_999", 0.0)
    return reach * point.get("eval/steps_to_999", horizon) + (1 - reach) * horizon


def verdict(task: str, results: dict) -> None:
    """Per criterion, BenchMARL's best point (any algorithm, any seed) against the first point of each DQN run that is
    at least as good: the score, and at N = 6 (no exact return there) also the steps to 0.999 U* over all starts."""
    theirs = [(p, row, seed) for (row, seed), m in results.items() if row in BENCHMARL for p in m["curve"]]
    if not theirs:
        print(f"{task}: no BenchMARL evaluation")
        return
    exact = any("eval/return_ratio" in p for p, _, _ in theirs)
    horizon = HORIZONS[task]
    criteria = {  # (higher is better, shown as)
        "score": (lambda p: score(p), "{:.4f}"),
        f"steps to 0.999 U* (never: {horizon})": (lambda p: -steps_to_optimum(p, horizon), "{:.2f} steps"),
    }
    for criterion, (value, shown) in list(criteria.items())[: 1 if exact else 2]:
        best, best_row, best_seed = max(theirs, key=lambda t: (value(t[0]), -t[0][TIME_TAGS[1]]))
        seconds, best_value = best[TIME_TAGS[1]], value(best)
        if criterion.startswith("steps") and -best_value >= horizon:
            print(f"{task}: no BenchMARL evaluation reaches 0.999 U* from any start: no steps to compare")
            continue
        print(
            f"{task}: BenchMARL's best {criterion}: {shown.format(abs(best_value))} ({best_row}, seed {best_seed}) "
            f"after {seconds:.0f} CPU s"
        )
        for (row, seed), m in results.items():
            if row in BENCHMARL:
                continue
            reached = [p[TIME_TAGS[1]] for p in m["curve"] if value(p) is not None and value(p) >= best_value]
            if reached:
                ratio = reached[0] / seconds
                met = "met" if ratio <= 1 / 3 else "not met"
                print(f"  {row} seed {seed}: reached it after {reached[0]:.0f} CPU s, {ratio:.2f}x BenchMARL's ({met})")
            else:
                print(f"  {row} seed {seed}: never reached it")


def plot(task: str, results: dict, path: Path, starts: int) -> None:
    """Each run's score against its training CPU seconds (log scale), one colour per row, one line per seed; at N = 6
    (no exact return) a second panel with the steps to 0.999 U* over all starts.  Every point is inside its axes: a
    score panel whose values fall below -5 (BenchMARL's early evaluations) is drawn on a symmetric-log scale, linear
    over [-1, 1]; one legend for the figure, under the panels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import ScalarFormatter

    exact = any("eval/return_ratio" in p for m in results.values() for p in m["curve"])
    horizon = HORIZONS[task]
    panels = [(score, "return ratio (exact optimum = 1)" if exact else "discounted gain eval/return (gamma 0.9)")]
    if not exact:
        panels.append((lambda p: steps_to_optimum(p, horizon), f"steps to 0.999 U* over all starts (never: {horizon})"))
    fig, axes = plt.subplots(
        1, len(panels), figsize=(7.5 * len(panels), 4.9), dpi=110, squeeze=False, layout="constrained"
    )
    rows = list(dict.fromkeys(row for row, _ in results))
    for ax, (value, ylabel) in zip(axes[0], panels, strict=True):
        for i, row in enumerate(rows):
            for seed, m in sorted((seed, m) for (r, seed), m in results.items() if r == row):
                points = [p for p in m["curve"] if score(p) is not None]
                first_seed = seed == min(s for r, s in results if r == row)
                ax.plot(
                    [p[TIME_TAGS[1]] for p in points],
                    [value(p) for p in points],
                    color=f"C{i}",
                    lw=1.2 if row in BENCHMARL else 2.5,
                    alpha=0.8,
                    marker="o" if row in BENCHMARL else None,
                    ms=3,
                    label=(f"ours: DQN, {DQN[row][0].split('=')[1].upper()}" if row in DQN else f"BenchMARL {row}")
                    if first_seed
                    else None,
                )
        ax.set_xscale("log")
        ax.set_xticks([t for t in (10, 20, 50, 100, 200, 500, 1000) if t <= ax.get_xlim()[1]])
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set(xlabel="training CPU seconds (one thread; evaluations left out)", ylabel=ylabel)
        ax.grid(alpha=0.3, which="both")
    lowest = min(y for line in axes[0, 0].get_lines() for y in line.get_ydata())
    if lowest < -5:  # the far-below early evaluations and the differences near the top, both in view
        axes[0, 0].set_yscale("symlog", linthresh=1.0, linscale=2.0)
        axes[0, 0].yaxis.set_major_formatter(ScalarFormatter())
        axes[0, 0].set_ylabel(f"{panels[0][1]}\n(symmetric log scale below -1)")
    for ax in axes[0]:
        ax.margins(y=0.04)  # no point on an edge
    seeds = sorted({seed for _, seed in results})
    seeds_text = f"seed {seeds[0]}" if len(seeds) == 1 else f"seeds {', '.join(map(str, seeds))}, a line each"
    fig.suptitle(f"{task}: the yardstick during training, {seeds_text} ({starts} held-out starts)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    columns = len(handles) if len(panels) > 1 else 3  # one panel is too narrow for six entries in a row
    fig.legend(handles, labels, loc="outside lower center", ncol=columns, fontsize=8, frameon=False)
    fig.savefig(path)
    plt.close(fig)
    print(f"{task}: curves in {path}")


def run(argv: list[str], log: Path) -> int:
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("w") as out:
        return subprocess.run([sys.executable, *argv], stdout=out, stderr=subprocess.STDOUT).returncode


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", choices=TASKS, default=["paper_6x6"])
    parser.add_argument("--rows", nargs="+", choices=[*BENCHMARL, *DQN], default=[*BENCHMARL, *DQN])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument(
        "--frames", nargs="+", type=int, default=[300_000], help="BenchMARL's budget (one, or one per task)"
    )
    parser.add_argument("--eval-frames", type=int, default=30_000, help="frames between BenchMARL's evaluations")
    parser.add_argument(
        "--benchmarl-overrides", nargs="*", default=[], help="more overrides of the BenchMARL rows (env.reward=log_gap)"
    )
    parser.add_argument("--dqn-eval-every", type=int, default=25, help="iterations between the DQN's evaluations")
    parser.add_argument("--starts", type=int, default=200, help="held-out evaluation starts")
    parser.add_argument("--jobs", type=int, default=1, help="processes at once (one torch thread each)")
    parser.add_argument("--out", type=Path, default=Path("runs/benchmarl_comparison"))
    parser.add_argument("--collect", action="store_true", help="only print the runs under --out")
    parser.add_argument("--plot", type=Path, help="also draw each task's curves as <dir>/benchmarl_<task>.png")
    args = parser.parse_args()
    runs = [(task, row, seed) for task in args.tasks for seed in args.seeds for row in args.rows]
    if not args.collect:
        pending = [r for r in runs if not (args.out / r[0] / r[1] / f"seed{r[2]}" / "metrics.json").exists()]

        def launch(job):
            task, row, seed = job
            run_dir = args.out / task / row / f"seed{seed}"
            code = run(command(task, row, seed, args, run_dir), args.out / "logs" / f"{task}-{row}-seed{seed}.log")
            print(f"# {task} {row} seed {seed}: exit {code}", file=sys.stderr, flush=True)

        with ThreadPoolExecutor(args.jobs) as pool:
            list(pool.map(launch, pending))
    print(
        "| task | row | seed | frames | train s (wall) | train CPU s | return ratio | return | final U/U* "
        "| reach 0.999 | step ratio 0.999 |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for task in args.tasks:
        results = {}
        for _, row, seed in (r for r in runs if r[0] == task):
            metrics = load(args.out / task / row / f"seed{seed}")
            if metrics is not None:
                results[row, seed] = metrics
                print_row(task, row, seed, metrics)
        verdict(task, results)
        if args.plot and results:
            args.plot.mkdir(parents=True, exist_ok=True)
            plot(task, results, args.plot / f"benchmarl_{task}.png", args.starts)


if __name__ == "__main__":
    main()
