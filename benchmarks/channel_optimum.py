"""Where the optimum puts the relays and sensors on each channel model, and its utility U* (docs/model.md, Channel
models): the paper's model against ``env=a2g_urban`` and its variations, 6 UAVs on 10x10, the line layout.

Each row is one model: ``U*`` in bit/s/Hz (and, for the physical channels, in Mbit/s over the bandwidth), both
rates, and the cells (``x`` along the PT-PR line, 0..9; PT at x = 0, PR at x = 10) of the relaying and of the
sensing UAVs of one optimal configuration (:meth:`uavrl.envs.world.World.optimum`, exact).  ``--frames DIR``
writes a picture of each optimum (``envs/render.py``).

Usage::

    python benchmarks/channel_optimum.py
    python benchmarks/channel_optimum.py --frames docs/figures
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from uavrl.envs import make_config
from uavrl.envs.render import render
from uavrl.envs.world import World

MODELS = {  # name: (preset, options)
    "paper (n6_10x10)": ("paper", dict(grid=(10, 10), num_uavs=6)),
    "a2g_urban": ("a2g_urban", {}),
    "a2g_urban, suburban": ("a2g_urban", dict(environment="suburban")),
    "a2g_urban, dense_urban": ("a2g_urban", dict(environment="dense_urban")),
    "a2g_urban, highrise": ("a2g_urban", dict(environment="highrise")),
    "a2g_urban, tr36777_uma": ("a2g_urban", dict(channel="tr36777_uma")),
    "a2g_urban, tr36777_umi": ("a2g_urban", dict(channel="tr36777_umi")),
    "a2g_urban, tr36777_rma": ("a2g_urban", dict(channel="tr36777_rma")),
    "a2g_urban, tr36777_rma, UAVs at 30 m": ("a2g_urban", dict(channel="tr36777_rma", altitude_m=30.0)),
    "a2g_urban, 10 m cells": ("a2g_urban", dict(cell_size=10.0)),
    "a2g_urban, UAVs at 50 m": ("a2g_urban", dict(altitude_m=50.0)),
    "a2g_urban, PT at 23 dBm": ("a2g_urban", dict(p_pt_dbm=23.0)),
}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=Path, default=None, help="write each optimum's picture here")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    print("| model | U* (bit/s/Hz) | U* (Mbit/s) | R_PU | R_SE | relays at x | sensors at x |")
    print("|---|---|---|---|---|---|---|")
    for name, (preset, options) in MODELS.items():
        cfg = make_config(preset, **options)
        world = World(cfg)
        u_star, positions, tasks = world.optimum()
        r_pu, r_se, _ = world.utility(positions, tasks)
        xs = positions[0, :, 0].tolist()
        relays = sorted(x for x, t in zip(xs, tasks[0].tolist(), strict=True) if t == 1)
        sensors = sorted(x for x, t in zip(xs, tasks[0].tolist(), strict=True) if t == 0)
        mbits = "-" if cfg.bandwidth_hz is None else f"{u_star.item() * cfg.bandwidth_hz / 1e6:.1f}"
        print(
            f"| {name} | {u_star.item():.3f} | {mbits} | {r_pu.item():.3f} | {r_se.item():.3f} | {relays} | {sensors} |"
        )
        if args.frames is not None:
            world.start_at(2 * world.cells_of(positions) + tasks)
            import imageio.v3 as iio

            stem = name.split(" (")[0].replace(", ", "_").replace(" ", "_")
            iio.imwrite(args.frames / f"optimum_{stem}.png", render(world, "rgb_array", 0, None))


if __name__ == "__main__":
    main()
