"""A step of local observations against the central one, side by side in one process (BENCHMARKS.md, Local
observations): ``UAVSpectrumEnv.step`` of ``B`` worlds of the paper's model with ``env.observation=local`` (radius 2
cells, every UAV, and with messages of 4) against ``env.observation=central``, the same actions, one torch thread.

Each configuration is timed in turn, ``--rounds`` times over (so a load that comes and goes falls on all of them), and
the median of its rounds (CPU time of the process, one thread) is reported with its ratio to the central step's.

Usage::

    python benchmarks/local_step.py                         # B = 4096, N = 10 on 20x20 and N = 6 on 10x10
    python benchmarks/local_step.py --worlds 1024 --rounds 9
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from uavrl.envs import UAVSpectrumEnv

TEAMS = ((10, (20, 20)), (6, (10, 10)))
OBSERVATIONS = {
    "central": {},
    "local, radius 2": dict(observation="local", comm_radius=2.0),
    "local, every UAV": dict(observation="local"),
    "local, radius 2, messages of 4": dict(observation="local", comm_radius=2.0, message_size=4),
}


def stepper(worlds: int, num_uavs: int, grid: tuple[int, int], options: dict):
    """A function that steps the env ``steps`` times with fixed random actions (and messages)."""
    env = UAVSpectrumEnv(batch_size=worlds, grid=grid, num_uavs=num_uavs, max_steps=10**6, **options)
    td = env.reset()
    generator = torch.Generator().manual_seed(0)
    td["agents", "action"] = torch.randint(0, 6, (worlds, num_uavs), generator=generator)
    if options.get("message_size"):
        td["agents", "message"] = torch.rand(worlds, num_uavs, options["message_size"], generator=generator)

    def run(steps: int) -> float:
        start = time.process_time()  # CPU time: one thread, so a load elsewhere does not count
        for _ in range(steps):
            env.step(td)
        return (time.process_time() - start) / steps

    run(5)  # warm-up
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=4096)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"B = {args.worlds}, {args.steps} steps a round, median of {args.rounds} rounds, one torch thread")
    print("| team | observation | CPU ms a step | / central |")
    print("|---|---|---|---|")
    for num_uavs, grid in TEAMS:
        steppers = {name: stepper(args.worlds, num_uavs, grid, options) for name, options in OBSERVATIONS.items()}
        times = {name: [] for name in steppers}
        for _ in range(args.rounds):
            for name, run in steppers.items():
                times[name].append(run(args.steps))
        central = statistics.median(times["central"])
        for name, samples in times.items():
            median = statistics.median(samples)
            print(f"| N = {num_uavs} on {grid[0]}x{grid[1]} | {name} | {1e3 * median:.2f} | {median / central:.2f}x |")


if __name__ == "__main__":
    main()
