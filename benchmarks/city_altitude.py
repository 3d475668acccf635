"""U* against the UAVs' altitude in the ITU-R P.1410 cities, beside U* with the altitude as a decision, per
environment (docs/model.md, Cities of buildings).

For each environment (``env.city`` and ``env.environment`` both set to it, ``env.channel=al_hourani``, the line
layout of ``a2g_urban``: 10x10 cells of 50 m, N = 6) and each city seed:

* **fixed altitude**: every UAV (and S and E, which fly at the UAVs' height) at one height ``h``, swept over
  ``--heights``; U* is the exact optimum over cells and tasks.  A height where a cell centre (or S or E) is inside a
  building is refused by the model (``InvalidOption``) and left out for that seed;
* **altitude as a decision**: every position ``(cell, level)`` for the levels ``--levels`` that is not inside a
  building is one row of the table the exact optimum chooses from (N distinct rows: two UAVs may share a cell at
  different levels).  The nodes are those of the model at the lowest level where it flies (PT and PR on the ground
  or a roof, whatever the height; S and E at that level).  The S and E links are air-to-air free space, so a sensing
  UAV does best at S's and E's height, and its sensing term there equals the fixed sweep's at any height (the same
  horizontal distances): the two compare relaying at free heights against relaying at one height.

The flat model (``env.city=none``, the statistical Al-Hourani channel of the same environment) is drawn against the
altitude for reference.  Prints the sweep, the best fixed altitude against the decided one, and the levels the
optimal configurations use; draws one panel per environment.

Usage::

    python benchmarks/city_altitude.py | tee benchmarks/results/city_altitude.txt  # and docs/figures/city_altitude.png
    python benchmarks/city_altitude.py --seeds 0 1 --out /tmp/city_altitude.png
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from uavrl.envs import make_config  # noqa: E402
from uavrl.envs.config import RELAYING  # noqa: E402
from uavrl.envs.errors import InvalidOption  # noqa: E402
from uavrl.envs.physics.buildings import city_part  # noqa: E402
from uavrl.envs.physics.channel import direct_terms, fixed_layout, link_gains, relay_contributions  # noqa: E402
from uavrl.envs.physics.city import P1410  # noqa: E402
from uavrl.envs.solvers.exact import fixed_layout_tables  # noqa: E402
from uavrl.envs.solvers.optimum import optimum  # noqa: E402

ENVIRONMENTS = tuple(P1410)  # suburban, urban, dense_urban, highrise
COMMON = dict(channel="al_hourani", layout="line", grid=(10, 10), cell_size=50.0, num_uavs=6)


def model(environment: str, city: str, altitude_m: float, seed: int = 0):
    """The model of ``environment`` at ``altitude_m`` (``city="none"``: the flat one, no seed)."""
    seeded = {} if city == "none" else {"city_seed": seed}
    return make_config("a2g_urban", city=city, environment=environment, altitude_m=altitude_m, **COMMON, **seeded)


def fixed_u_star(environment: str, city: str, altitude_m: float, seed: int = 0) -> float:
    """U* with every UAV at ``altitude_m``, NaN where the model refuses that height (a UAV inside a building)."""
    try:
        cfg = model(environment, city, altitude_m, seed)
        return float(optimum(*fixed_layout_tables(cfg), cfg)[0])
    except InvalidOption:
        return float("nan")


def decided_u_star(environment: str, seed: int, levels_m) -> tuple[float, list[float], list[float]]:
    """U* over every (cell, level) position outside the buildings, and the levels (m) of its relays and sensors."""
    for nodes_m in levels_m:  # the nodes of the model at its lowest level that flies (S and E at that height)
        try:
            cfg = model(environment, environment, nodes_m, seed)
            nodes = fixed_layout(cfg)
            break
        except InvalidOption:
            continue
    else:
        raise SystemExit(f"{environment} city {seed}: no level of {levels_m} clears every cell")
    L1, L2 = cfg.grid
    cell = torch.arange(L1 * L2)
    xy = torch.stack([cell % L1, cell // L1], -1).to(torch.float64)
    heights = torch.tensor([level / cfg.cell_size for level in levels_m], dtype=torch.float64)
    positions = torch.cat([xy.repeat(len(heights), 1), heights.repeat_interleave(len(cell))[:, None]], -1)
    positions = positions[~city_part(cfg).inside(positions)]  # [P, 3] in cells, none inside a building
    table = relay_contributions(link_gains(positions, nodes, cfg), cfg)  # [P, 2]
    u_star, rows, tasks = optimum(table[None], direct_terms(nodes, cfg)[None], cfg)
    flown = (positions[rows[0], 2] * cfg.cell_size).tolist()
    relays = sorted(z for z, task in zip(flown, tasks[0].tolist(), strict=True) if task == RELAYING)
    sensors = sorted(z for z, task in zip(flown, tasks[0].tolist(), strict=True) if task != RELAYING)
    return float(u_star[0]), relays, sensors


def levels_text(levels: list[float]) -> str:
    return "+".join(f"{z:g}" for z in levels) or "-"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/figures/city_altitude.png"))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4], help="city seeds")
    parser.add_argument("--heights", type=float, nargs="+", default=list(range(30, 301, 10)), help="fixed, m")
    parser.add_argument("--levels", type=float, nargs="+", default=[30, 60, 100, 150, 200, 300], help="decided, m")
    args = parser.parse_args(argv)
    began = time.perf_counter()
    heights, seeds = np.array(args.heights), args.seeds
    print(
        f"# {time.strftime('%Y-%m-%d')}, channel al_hourani, layout line, 10x10 cells of 50 m, N = 6, city seeds "
        f"{seeds}, load average {os.getloadavg()[0]:.2f}"
    )
    fixed = {e: np.array([[fixed_u_star(e, e, h, s) for h in heights] for s in seeds]) for e in ENVIRONMENTS}
    flat = {e: np.array([fixed_u_star(e, "none", h) for h in heights]) for e in ENVIRONMENTS}
    decided = {e: [decided_u_star(e, s, args.levels) for s in seeds] for e in ENVIRONMENTS}
    every_height = {e: np.array([decided_u_star(e, s, heights)[0] for s in seeds]) for e in ENVIRONMENTS}

    print("\nU* (bit/s/Hz) at a fixed altitude: the cities' mean over the seeds that fly there (how many), and flat")
    print("| altitude (m) | " + " | ".join(f"{e} city | {e} flat" for e in ENVIRONMENTS) + " |")
    print("|---|" + "---|---|" * len(ENVIRONMENTS))
    for i, h in enumerate(heights):
        cells = []
        for e in ENVIRONMENTS:
            flown = fixed[e][:, i][~np.isnan(fixed[e][:, i])]
            mean = (
                f"{flown.mean():.3f}" + ("" if len(flown) == len(seeds) else f" ({len(flown)})") if len(flown) else ""
            )
            cells.append((mean or "refused") + f" | {flat[e][i]:.3f}")
        print(f"| {h:g} | " + " | ".join(cells) + " |")

    print(
        "\nBest fixed altitude against the altitude as a decision (levels "
        f"{levels_text(args.levels)} m); per seed, then the mean [min, max] over the seeds"
    )
    print(
        "| environment | lowest altitude flown (m) | best fixed: altitude (m), U* | decided U* | gain over the "
        f"seed's best fixed | decided over every {heights[1] - heights[0]:g} m | flat: best altitude (m), U* |"
    )
    print("|---|---|---|---|---|---|---|")
    for e in ENVIRONMENTS:
        curve = fixed[e]
        flown_everywhere = ~np.isnan(curve).any(0)
        lowest = [heights[~np.isnan(row)].min() for row in curve]
        mean_curve = np.where(flown_everywhere, curve.mean(0), -np.inf)
        best_each = np.nanmax(curve, 1)
        u_decided = np.array([u for u, _, _ in decided[e]])
        gain = u_decided - best_each
        print(
            f"| {e} | {min(lowest):g}-{max(lowest):g} | {heights[mean_curve.argmax()]:g}, {mean_curve.max():.3f} | "
            f"{u_decided.mean():.3f} [{u_decided.min():.3f}, {u_decided.max():.3f}] | {gain.mean():+.3f} "
            f"[{gain.min():+.3f}, {gain.max():+.3f}] ({100 * (gain / best_each).mean():+.1f}%) | "
            f"{every_height[e].mean():.3f} ({(every_height[e] - best_each).mean():+.3f}) | "
            f"{heights[flat[e].argmax()]:g}, {flat[e].max():.3f} |"
        )

    print("\nThe levels (m) of the optimal configuration with the altitude as a decision, per seed")
    print("| environment | seed | relays | sensors | U* | best fixed: altitude (m), U* |")
    print("|---|---|---|---|---|---|")
    for e in ENVIRONMENTS:
        for s, (u, relays, sensors), row in zip(seeds, decided[e], fixed[e], strict=True):
            best = np.nanargmax(row)
            print(
                f"| {e} | {s} | {levels_text(relays)} | {levels_text(sensors)} | {u:.3f} | "
                f"{heights[best]:g}, {row[best]:.3f} |"
            )

    draw(args.out, heights, fixed, flat, decided, seeds, args.levels)
    print(f"\nwrote {args.out} in {time.perf_counter() - began:.0f} s")


def draw(out: Path, heights, fixed, flat, decided, seeds, levels) -> None:
    fig, axes = plt.subplots(2, 2, figsize=(10.5, 8), sharex=True)
    for ax, e in zip(axes.flat, ENVIRONMENTS, strict=True):
        curve = fixed[e]
        all_fly, some_fly = ~np.isnan(curve).any(0), ~np.isnan(curve).all(0)
        partial = some_fly & ~all_fly
        flown = np.where(np.isnan(curve), 0.0, curve)
        mean = flown.sum(0) / np.maximum((~np.isnan(curve)).sum(0), 1)
        low, high = np.where(all_fly, curve.min(0), 0.0), np.where(all_fly, curve.max(0), 0.0)
        u_decided = np.array([u for u, _, _ in decided[e]])
        ax.axhspan(u_decided.min(), u_decided.max(), color="#d95f02", alpha=0.12, lw=0, zorder=0)
        ax.axhline(u_decided.mean(), color="#d95f02", lw=2.2, zorder=1)
        ax.fill_between(heights, low, high, where=all_fly, color="#1b9e77", alpha=0.3, lw=0, zorder=2)
        ax.plot(heights[all_fly], mean[all_fly], "o-", color="#1b9e77", ms=3.5, lw=1.6, zorder=3)
        ax.plot(heights[partial], mean[partial], "o", color="#1b9e77", mfc="white", ms=5, zorder=3)
        ax.plot(heights, flat[e], "--", color="#555555", lw=1.6)
        refused = heights[~some_fly]
        if len(refused):
            ax.axvspan(heights[0] - 5, refused.max() + 5, color="#bbbbbb", alpha=0.35, lw=0)
            ax.text(
                (heights[0] + refused.max()) / 2,
                0.5,
                "every city refuses",
                transform=ax.get_xaxis_transform(),
                ha="center",
                va="center",
                rotation=90,
                fontsize=8.5,
                color="#444444",
            )
        alpha, beta, gamma = P1410[e]
        ax.set_title(f"{e}: alpha={alpha:g}, beta={beta:g}/km$^2$, gamma={gamma:g} m", fontsize=10.5)
        ax.grid(alpha=0.3)
        ax.set_xlim(heights[0] - 5, heights[-1] + 5)
    for ax in axes[1]:
        ax.set_xlabel("altitude of every UAV (m)")
    for ax in axes[:, 0]:
        ax.set_ylabel("U* (bit/s/Hz)")
    handles = [
        plt.Line2D([], [], color="#1b9e77", marker="o", ms=4, label=f"city, fixed altitude: mean over seeds {seeds}"),
        plt.Rectangle((0, 0), 1, 1, color="#1b9e77", alpha=0.2, label="  its range over the seeds"),
        plt.Line2D(
            [],
            [],
            color="#1b9e77",
            marker="o",
            mfc="white",
            ls="",
            label="  some seeds refuse (a cell inside a building): mean of the others",
        ),
        plt.Line2D([], [], color="#d95f02", lw=2, label=f"city, altitude decided over {levels_text(levels)} m: mean"),
        plt.Rectangle((0, 0), 1, 1, color="#d95f02", alpha=0.2, label="  its range over the seeds"),
        plt.Line2D([], [], color="#555555", ls="--", label="flat model (no city, statistical Al-Hourani)"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=9, frameon=False)
    fig.suptitle(
        "U* against the UAVs' altitude: ITU-R P.1410 cities (geometric line of sight), Al-Hourani channel,\n"
        "line layout, 10x10 cells of 50 m, N = 6; heights where a cell centre is inside a building left out",
        fontsize=11,
    )
    fig.tight_layout(rect=(0, 0.11, 1, 0.99))
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    main()
