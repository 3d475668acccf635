"""How long a bad override takes to be refused: whole processes, beside Python's and torch's start-up.

    python benchmarks/bad_override_latency.py [--repeats 5] [--pythonpath DIR]

Each command runs ``--repeats`` times as a fresh process; the table gives the
median and the best wall time and the median CPU time (user + system).  ``python -c pass`` is the interpreter's own
start-up; ``import torch, tensordict, torchrl`` is what the commands imported
before checking their settings until they checked them first.  ``--pythonpath``
puts ``DIR`` first on the path of every process, to time another version of
uavrl laid out there as a package (BENCHMARKS.md says how).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMANDS = [
    ("python -c pass", ["-c", "pass"]),
    ('python -c "import torch"', ["-c", "import torch"]),
    ('python -c "import torch, tensordict, torchrl"', ["-c", "import torch, tensordict, torchrl"]),
    ("python -m uavrl.train agent.episodes=0", ["-m", "uavrl.train", "agent.episodes=0"]),
    ("python -m uavrl.train env.grid=[0,3]", ["-m", "uavrl.train", "env.grid=[0,3]"]),
    ("python -m uavrl.train train.episdoes=5 (unknown key)", ["-m", "uavrl.train", "train.episdoes=5"]),
    ("python -m uavrl.evaluate checkpoint=missing.pt", ["-m", "uavrl.evaluate", "checkpoint=missing.pt"]),
    ("python -m uavrl.reproduce table2 episodes=-5", ["-m", "uavrl.reproduce", "table2", "episodes=-5"]),
    ("python -m uavrl.train ++env.p_u=1e308 (NaN rates)", ["-m", "uavrl.train", "++env.p_u=1e308"]),
    ("python -m uavrl.train ++env.cell_size=1e-300", ["-m", "uavrl.train", "++env.cell_size=1e-300"]),
    ("python -m uavrl.train env.max_steps=10**12 (steps)", ["-m", "uavrl.train", "env.max_steps=1000000000000"]),
    ("python -m uavrl.train eval.num_starts=10**9 (memory)", ["-m", "uavrl.train", "eval.num_starts=1000000000"]),
    (
        "python -m uavrl.train agent=dqn env.max_steps=10**12",
        ["-m", "uavrl.train", "agent=dqn", "env.max_steps=1000000000000"],
    ),
    (
        "python -m uavrl.train agent=dqn env.grid=[10,10] env.num_uavs=60",
        ["-m", "uavrl.train", "agent=dqn", "env.grid=[10,10]", "env.num_uavs=60"],
    ),
    (
        "python -m uavrl.reproduce table2 steps=10**12",
        ["-m", "uavrl.reproduce", "table2", "steps=1000000000000"],
    ),
    (  # refused before the checkpoint is looked for
        "python -m uavrl.evaluate checkpoint=run eval.num_starts=10**9",
        ["-m", "uavrl.evaluate", "checkpoint=run", "eval.num_starts=1000000000"],
    ),
    (
        "python -m uavrl.render run eval.video_starts=10**9",
        ["-m", "uavrl.render", "run", "eval.video_starts=1000000000"],
    ),
    # the costs of the networks, the gradient steps and the grid, estimated before the work
    ("python -m uavrl.train agent=dqn agent.hidden=10**6", ["-m", "uavrl.train", "agent=dqn", "agent.hidden=1000000"]),
    (
        "python -m uavrl.train agent=dqn agent.updates=10**9 (time)",
        ["-m", "uavrl.train", "agent=dqn", "agent.updates=1000000000"],
    ),
    (
        "python -m uavrl.train agent=dqn env.grid=[1000,1000] (time)",
        ["-m", "uavrl.train", "agent=dqn", "env.grid=[1000,1000]"],
    ),
    # settings that cannot go together, and a size-free run's zero-shot evaluation, checked before torch
    (
        "python -m uavrl.train agent=dqn agent.network=set agent.heads=3",
        ["-m", "uavrl.train", "agent=dqn", "agent.network=set", "agent.heads=3"],
    ),
    (
        "python -m uavrl.train agent=dqn agent.layouts=[random]",
        ["-m", "uavrl.train", "agent=dqn", "agent.layouts=[random]"],
    ),
    (
        "python -m uavrl.evaluate checkpoint=<size-free run> env.grid=[10**6,10**6]",
        ["-m", "uavrl.evaluate", "checkpoint={size_free}", "env.grid=[1000000,1000000]"],
    ),
    (
        "python -m uavrl.evaluate checkpoint=<size-free run> env.max_steps=10**12",
        ["-m", "uavrl.evaluate", "checkpoint={size_free}", "env.max_steps=1000000000000"],
    ),
]


def size_free_run(root: Path) -> Path:
    """A size-free run's directory as far as the checks before torch read it: its config.yaml, and a checkpoint file
    they never open."""
    from omegaconf import OmegaConf

    from uavrl.cli import compose_config

    run = root / "size-free"
    run.mkdir()
    cfg = compose_config("config", ["agent=dqn", "agent.network=set", "agent.mixer=vdn"])
    (run / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.to_container(cfg, resolve=True)))
    (run / "checkpoint.pt").write_bytes(b"never read by the checks")
    return run


def times(args: list[str], repeats: int, env: dict) -> tuple[list[float], list[float]]:
    """Wall and CPU seconds (user + system, which other processes' load does not inflate) of each run."""
    walls, cpus = [], []
    for _ in range(repeats):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        started = time.perf_counter()
        subprocess.run([sys.executable, *args], capture_output=True, env=env)
        walls.append(time.perf_counter() - started)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    return walls, cpus


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--pythonpath", help="a directory put first on every process's path")
    args = parser.parse_args()
    env = dict(os.environ)
    if args.pythonpath:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [args.pythonpath, env.get("PYTHONPATH")]))
    # a first import fills the file cache, as on any machine that ran torch before
    subprocess.run([sys.executable, "-c", "import torch, tensordict, torchrl"], capture_output=True)
    machine = f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}, Python {sys.version.split()[0]}"
    print(f"{machine}, {args.repeats} runs each")
    print(f"uavrl from {args.pythonpath or 'the installed package'}\n")
    print("| command | median wall | best wall | median CPU |\n|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        run = size_free_run(Path(tmp))
        for name, command in COMMANDS:
            walls, cpus = times([arg.format(size_free=run) for arg in command], args.repeats, env)
            wall, best, cpu = statistics.median(walls), min(walls), statistics.median(cpus)
            print(f"| `{name}` | {wall:.2f} s | {best:.2f} s | {cpu:.2f} s |")


if __name__ == "__main__":
    main()
