"""One small study through each launcher: wall time of the whole command, beside the basic (one job at a time) launcher.

    python benchmarks/sweep_launchers.py [--iterations 30] [--seeds 3] [--cpus 2] [--launchers basic,joblib,ray]

The study is ``agent.mixer=vdn,qmix`` (two DQN agents) x ``scenario=paper_6x6,rayleigh`` x ``--seeds`` seeds, each
job ``--iterations`` DQN iterations (a tiny budget: the scenarios' own are 500); every launcher runs the same
jobs as one ``python -m uavrl.train -m ...`` process into its own sweep directory under a temporary folder.  The
table gives each launcher's wall time (interpreter, Ray start-up and every job included), its speed-up over the
basic launcher, the mean time of one job as the job itself measured it (``metrics.json``: ``total_seconds``) and
the load average around the run; at the end, whether every launcher gave the same metrics for the same job.
Needs ``pip install -e ".[ray]"`` for ``joblib`` and ``ray``.
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

LAUNCHERS = {
    "basic": [],
    "joblib": ["hydra/launcher=joblib", "hydra.launcher.n_jobs={cpus}"],
    "ray": ["hydra/launcher=ray", "+hydra.launcher.ray.init.num_cpus={cpus}"],
}


def study(iterations: int, seeds: int) -> list[str]:
    return [
        "agent=dqn",
        "agent.mixer=vdn,qmix",
        "scenario=paper_6x6,rayleigh",
        f"seed={','.join(map(str, range(seeds)))}",
        f"agent.iterations={iterations}",
        "progress=false",
    ]


def run(launcher: str, sweep_dir: Path, args) -> dict:
    extra = [arg.format(cpus=args.cpus) for arg in LAUNCHERS[launcher]]
    argv = [sys.executable, "-m", "uavrl.train", "-m", *extra, *study(args.iterations, args.seeds)]
    load_before = os.getloadavg()[0]
    started = time.perf_counter()
    result = subprocess.run([*argv, f"sweep_dir={sweep_dir}"], capture_output=True, text=True)
    wall = time.perf_counter() - started
    if result.returncode != 0:
        raise SystemExit(f"error: the {launcher} launcher failed: {result.stderr.strip().splitlines()[-1:]}")
    metrics = {
        str(path.parent.relative_to(sweep_dir)): json.loads(path.read_text())
        for path in sweep_dir.rglob("metrics.json")
    }
    return {"wall": wall, "metrics": metrics, "load": (load_before, os.getloadavg()[0])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--iterations", type=int, default=30)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--cpus", type=int, default=2, help="Ray's CPUs and joblib's workers")
    parser.add_argument("--launchers", default="basic,joblib,ray")
    args = parser.parse_args()
    launchers = args.launchers.split(",")
    jobs = 4 * args.seeds
    print(f"study: 2 agents x 2 scenarios x {args.seeds} seeds = {jobs} jobs of {args.iterations} DQN iterations")
    results = {}
    with tempfile.TemporaryDirectory() as root:
        for launcher in launchers:
            results[launcher] = run(launcher, Path(root) / launcher, args)
            r = results[launcher]
            print(f"  {launcher}: {r['wall']:.1f} s", flush=True)
    basic = results.get("basic", {}).get("wall")
    print("| launcher | wall s | vs basic | mean job s (its own clock) | load average before, after |")
    print("|---|---|---|---|---|")
    for launcher, r in results.items():
        job = sum(m["total_seconds"] for m in r["metrics"].values()) / len(r["metrics"])
        speedup = f"{basic / r['wall']:.2f}x" if basic else "-"
        print(f"| {launcher} | {r['wall']:.1f} | {speedup} | {job:.1f} | {r['load'][0]:.1f}, {r['load'][1]:.1f} |")
    reference = next(iter(results.values()))["metrics"]
    same = all(
        {k: v for k, v in r["metrics"][job].items() if k.startswith("eval/")}
        == {k: v for k, v in reference[job].items() if k.startswith("eval/")}
        for r in results.values()
        for job in reference
    )
    print(f"same eval/ metrics for every job under every launcher: {same}")


if __name__ == "__main__":
    main()
