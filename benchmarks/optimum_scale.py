"""U* at scale: the exact optimum on 50x50 for N = 20, 30 and 50, by each method that runs, with its time (one
thread).

The fixed layout (``line``) is one table; ``layout=random`` solves 64 layouts.  Prints a Markdown table (BENCHMARKS.md,
"U*, the oracle and the bounds at 50 UAVs")::

    python benchmarks/optimum_scale.py
"""

from __future__ import annotations

import time

import torch

from uavrl.envs import make_config
from uavrl.envs.solvers.optimum import MAX_EXCHANGE_UAVS, solve
from uavrl.envs.world import World

WORLDS = 64


def main() -> None:
    torch.set_num_threads(1)
    print("| layout | N | method | worlds | U* (mean) | certified gap | seconds |")
    print("|---|---|---|---|---|---|---|")
    for layout in ("line", "random"):
        for N in (20, 30, 50):
            cfg = make_config("paper", grid=(50, 50), num_uavs=N, layout=layout)
            world = World(cfg, WORLDS, "cpu", 0)
            world.reset()
            # the exchange method takes ~2.6 s a layout at N = 20: timed on the fixed layout only
            methods = ("exchange", "search") if N <= MAX_EXCHANGE_UAVS and layout == "line" else ("search",)
            for method in methods:
                started = time.perf_counter()
                tables = slice(None) if layout == "random" else slice(0, 1)  # a fixed layout: one table
                u, _, _, upper = solve(world.cell_contributions[tables], world.direct[tables], cfg, method)
                seconds = time.perf_counter() - started
                gap = ((upper - u) / u).max().item()
                print(f"| {layout} | {N} | {method} | {len(u)} | {u.mean():.6f} | {gap:.1e} | {seconds:.3f} |")


if __name__ == "__main__":
    main()
