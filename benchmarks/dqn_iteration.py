"""Cost of one DQN training iteration (the defaults on 10x10, N = 6 unless ``--sizes``) beside an earlier commit.

Each measurement is a whole process: build the agent, 3 warm-up iterations,
then ``--iterations`` timed ones; it prints the median CPU and wall seconds per
iteration.  ``--baseline REV`` checks REV out in a temporary git worktree and
measures it the same way, alternating with this checkout ``--rounds`` times,
so both see the same machine load; the ratio of the medians is the figure.
``--sizes`` and ``--networks`` measure every team size with each network
(``team``: the per-size network, QMIX as ``scenario=n6_10x10``; ``set``: the
size-free one, ``agent.mixer=mean``), all on 10x10.  One torch thread.

Usage::

    python benchmarks/dqn_iteration.py --baseline 3ffece7 --rounds 3
    python benchmarks/dqn_iteration.py --baseline 206506a --rounds 1 --iterations 3 --sizes 2 6 10 20 50 \
        --networks team set
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MEASURE = """
import statistics, sys, time, torch
torch.set_num_threads(1)
from hydra import compose, initialize_config_dir
from uavrl.config import config_dir, model_config
from uavrl.agents import agent_class
with initialize_config_dir(config_dir=config_dir(), version_base=None):
    cfg = compose("config", overrides=["agent=dqn", "env.grid=[10,10]", *sys.argv[2:]])
try:
    cls = agent_class("dqn", cfg.agent)
except TypeError:  # commits before the registry chose the network: DQNAgent built the size-free agent itself
    cls = agent_class("dqn")
agent = cls(model_config(cfg), cfg, torch.device("cpu"), seed=0)
for _ in range(3):
    agent.train_iteration()
cpu, wall = [], []
for _ in range(int(sys.argv[1])):
    c, w = time.process_time(), time.perf_counter()
    agent.train_iteration()
    cpu.append(time.process_time() - c)
    wall.append(time.perf_counter() - w)
print(statistics.median(cpu), statistics.median(wall))
"""


NETWORKS = {"team": ["agent.mixer=qmix"], "set": ["agent.network=set", "agent.mixer=mean"]}


def measure(checkout: Path, iterations: int, overrides: list[str] = ("env.num_uavs=6",)) -> tuple[float, float]:
    """Median (CPU, wall) seconds per iteration of the code in ``checkout`` (its folders on the import path) with
    the Hydra ``overrides``."""
    code = "import sys\n" + _installed_names(checkout) + MEASURE
    done = subprocess.run(
        [sys.executable, "-c", code, str(iterations), *overrides], capture_output=True, text=True, env={**os.environ}
    )
    if done.returncode != 0:
        raise SystemExit(f"measuring {checkout} failed:\n{done.stderr}")
    cpu, wall = map(float, done.stdout.split()[-2:])
    return cpu, wall


def _installed_names(checkout: Path) -> str:
    """Make ``uavrl``, ``uavrl.envs``, ``uavrl.agents`` and ``uavrl.configs`` the folders of ``checkout`` (as
    pyproject's package-dir does), whatever is installed: all four are registered before any of them runs."""
    folders = {"uavrl": "uavrl", "uavrl.envs": "envs", "uavrl.agents": "agents", "uavrl.configs": "configs"}
    return (
        "import importlib.util\n"
        "_modules = []\n"
        f"for name, folder in {[(n, str(checkout / f)) for n, f in folders.items()]!r}:\n"
        "    spec = importlib.util.spec_from_file_location(name, folder + '/__init__.py',"
        " submodule_search_locations=[folder])\n"
        "    sys.modules[name] = importlib.util.module_from_spec(spec)\n"
        "    _modules.append((sys.modules[name], spec))\n"
        "for module, spec in _modules:\n"
        "    spec.loader.exec_module(module)\n"
    )


@contextlib.contextmanager
def checkouts_beside(baseline: str | None):
    """``{name: folder}``: ``baseline`` (a git revision, checked out in a temporary worktree, removed after) and this
    checkout."""
    with tempfile.TemporaryDirectory() as tmp:
        if not baseline:
            yield {"this checkout": ROOT}
            return
        worktree = Path(tmp) / "baseline"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "-q", "--detach", str(worktree), baseline])
        try:
            yield {f"baseline {baseline}": worktree, "this checkout": ROOT}
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(worktree)])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", help="a git revision to measure beside this checkout")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--iterations", type=int, default=12)
    parser.add_argument("--sizes", nargs="+", type=int, help="team sizes N on 10x10: one table row per N and network")
    parser.add_argument("--networks", nargs="+", choices=list(NETWORKS), default=["team"])
    args = parser.parse_args()
    if args.sizes:
        return sizes_table(args)
    with checkouts_beside(args.baseline) as checkouts:
        print(f"load average at start: {os.getloadavg()[0]:.1f}")
        results = {name: [] for name in checkouts}
        for round_ in range(args.rounds):
            for name, checkout in checkouts.items():
                results[name].append(measure(checkout, args.iterations))
                cpu, wall = results[name][-1]
                print(f"round {round_ + 1}  {name:<22} CPU {cpu:.3f} s/iteration  wall {wall:.3f} s", flush=True)
        medians = {name: statistics.median(c for c, _ in runs) for name, runs in results.items()}
        for name, cpu in medians.items():
            print(f"median  {name:<22} CPU {cpu:.3f} s/iteration")
        if args.baseline:
            base, this = medians[f"baseline {args.baseline}"], medians["this checkout"]
            print(f"this checkout / baseline: {this / base:.2f}x CPU per iteration")
        print(f"load average at end: {os.getloadavg()[0]:.1f}")


def sizes_table(args) -> None:
    """One Markdown row per network and team size: the median CPU seconds per iteration of each checkout."""
    with checkouts_beside(args.baseline) as checkouts:
        print(f"load average at start: {os.getloadavg()[0]:.1f}")
        print("| network | N | " + " | ".join(f"{name} CPU s" for name in checkouts) + " | ratio |")
        print("|---|---|" + "---|" * len(checkouts) + "---|")
        for n in args.sizes:
            for network in args.networks:
                overrides = [f"env.num_uavs={n}", *NETWORKS[network]]
                cpu = {name: [] for name in checkouts}
                for _ in range(args.rounds):
                    for name, checkout in checkouts.items():
                        cpu[name].append(measure(checkout, args.iterations, overrides)[0])
                medians = [statistics.median(c) for c in cpu.values()]
                ratio = f"{medians[-1] / medians[0]:.2f}x" if len(medians) > 1 else "-"
                print(f"| {network} | {n} | " + " | ".join(f"{m:.3f}" for m in medians) + f" | {ratio} |", flush=True)
        print(f"load average at end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
