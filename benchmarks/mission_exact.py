"""Time the exact mission solver (BENCHMARKS.md, "Exact mission optimum"), and compare policies with it.

``--time``: for each case, in a fresh process (so its peak memory is its own) with one torch thread, the solver of
``uavrl.envs.solvers.mission_exact`` from the 64 evaluation starts (``eval.seed``) of rotary_wing with the base at
(-1, 0) over the default mission horizon: its estimate, the states and transitions it solved, CPU and wall seconds and
the process's peak RSS, beside the baseline of the same run: the random policy's whole evaluation on the same starts
without the solver (what an evaluation costs before the optimum is added).

``--compare``: the evaluation's delivered data of the random policy and the energy-unaware oracle on one case,
beside the exact optimum and the proved bound (the same starts for all).

``--levels H1 H2 ...``: the UAVs at those altitude levels (m; cells of 10 m), with climbs and descents
(docs/model.md, Energy and lifetime), for the cases of ``--time`` (then one UAV on 2x2 and 3x3) and
``--compare``.

Usage::

    python benchmarks/mission_exact.py --time                      # 3x3 and 4x4, N = 1, 2; 1, 1.5 and 2 Wh
    python benchmarks/mission_exact.py --time --levels 10 20 40    # N = 1 on 2x2 and 3x3 at three levels
    python benchmarks/mission_exact.py --compare --grid 4 4 --battery-wh 1.0
"""

from __future__ import annotations

import argparse
import contextlib
import json
import resource
import subprocess
import sys
import time

import torch

from uavrl.agents import references
from uavrl.agents.evaluation import EVAL_SEED, evaluate
from uavrl.envs import make_config
from uavrl.envs.limits import evaluation_horizon
from uavrl.envs.solvers.mission_exact import mission_size, optimal_mission
from uavrl.envs.world import World

CASES = [(grid, n, wh) for grid in ((3, 3), (4, 4)) for n in (1, 2) for wh in (1.0, 1.5, 2.0)]
LEVEL_CASES = [(grid, 1, wh) for grid in ((2, 2), (3, 3)) for wh in (1.0, 1.5, 2.0)]  # two UAVs: short horizons only
NUM_STARTS = 64


def config(grid, num_uavs, battery_wh, levels=None):
    return make_config(
        "paper",
        grid=tuple(grid),
        num_uavs=num_uavs,
        energy="rotary_wing",
        base=(-1, 0),
        battery_wh=battery_wh,
        altitudes_m=levels,
    )


def time_case(grid, num_uavs, battery_wh, levels=None) -> dict:
    """One case, in this process: the solver's figures and the random policy's evaluation beside it."""
    from uavrl.agents.baselines import RandomPolicy

    cfg = config(grid, num_uavs, battery_wh, levels)
    horizon = evaluation_horizon(cfg)
    began, began_cpu = time.perf_counter(), time.process_time()
    with _without_optimum():
        evaluate(RandomPolicy(seed=0), cfg, num_starts=NUM_STARTS)
    baseline = time.perf_counter() - began, time.process_time() - began_cpu
    world = World(cfg.replace(max_steps=horizon), NUM_STARTS, seed=EVAL_SEED)
    world.reset()
    states, transitions, need = mission_size(world, horizon)
    began, began_cpu = time.perf_counter(), time.process_time()
    best = optimal_mission(world, horizon, memory_budget=2**34)
    return {
        "grid": f"{grid[0]}x{grid[1]}",
        "levels": levels,
        "N": num_uavs,
        "battery_wh": battery_wh,
        "horizon": horizon,
        "estimate": [states, transitions, round(need / 2**20)],
        "states": best.states,
        "transitions": best.transitions,
        "solver_wall_s": round(time.perf_counter() - began, 2),
        "solver_cpu_s": round(time.process_time() - began_cpu, 2),
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024,
        "random_evaluation_wall_s": round(baseline[0], 2),
        "random_evaluation_cpu_s": round(baseline[1], 2),
        "optimum_mean": round(best.value.mean().item(), 3),
    }


@contextlib.contextmanager
def _without_optimum():
    """The evaluation without the exact optimum (the baseline): its references' solver call answers ``None``."""
    saved = references.mission_optimum
    references.mission_optimum = lambda world, horizon: None
    try:
        yield
    finally:
        references.mission_optimum = saved


def compare(grid, num_uavs, battery_wh, levels=None) -> None:
    from uavrl.agents.baselines import OraclePolicy, RandomPolicy

    cfg = config(grid, num_uavs, battery_wh, levels)
    print(f"{grid[0]}x{grid[1]}, N = {num_uavs}, rotary_wing, battery_wh = {battery_wh}, {NUM_STARTS} starts")
    for name, policy in (("random", RandomPolicy(seed=0)), ("oracle", OraclePolicy(cfg))):
        began = time.perf_counter()
        m = evaluate(policy, cfg, num_starts=NUM_STARTS)
        print(
            f"{name:7s} horizon {m['eval/horizon']:.0f}  delivered {m['eval/delivered_bit_per_hz']:.2f}  "
            f"optimum {m['eval/delivered_optimum']:.2f}  bound {m['eval/delivered_bound']:.2f}  "
            f"delivered/optimum {m['eval/delivered_optimality']:.4f}  optimum/bound "
            f"{m['eval/delivered_optimum'] / m['eval/delivered_bound']:.4f}  ({time.perf_counter() - began:.1f} s)"
        )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--time", action="store_true")
    parser.add_argument("--compare", action="store_true")
    parser.add_argument("--case", type=json.loads, help="one --time case as JSON [grid, N, battery_wh, levels]")
    parser.add_argument("--grid", type=int, nargs=2, default=(4, 4))
    parser.add_argument("--num-uavs", type=int, default=2)
    parser.add_argument("--battery-wh", type=float, default=1.0)
    parser.add_argument("--levels", type=float, nargs="+", default=None, help="altitude levels in m (default: one)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.case is not None:
        print(json.dumps(time_case(*args.case)))
    if args.time:
        for case in CASES if args.levels is None else LEVEL_CASES:
            out = subprocess.run(
                [sys.executable, __file__, "--case", json.dumps([*case, args.levels])],
                capture_output=True,
                text=True,
                check=True,
            )
            print(out.stdout.strip(), flush=True)
    if args.compare:
        compare(args.grid, args.num_uavs, args.battery_wh, args.levels)


if __name__ == "__main__":
    main()
