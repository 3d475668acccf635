"""The line-of-sight probability of the generated ITU-R P.1410 cities against the elevation angle, beside
Al-Hourani's fitted S-curve and P.1410's closed form, per environment (docs/model.md, Cities of buildings).

For each environment, each UAV height and each city seed: ground nodes at 1.5 m drawn uniformly over the streets of
the central 500 m x 500 m of a 7 km x 7 km city, each linked to a UAV at a uniform azimuth and a uniform elevation
angle (up to 3 km away), the links whose UAV would be inside a building left out.  The geometric line of sight of
each link (``envs/physics/city.py``), averaged per bin of elevation angle, is drawn beside ``1 / (1 + a exp(-b (theta
- a)))`` with the environment's ``(a, b)`` of ``envs/physics/radio.py`` and P.1410's closed form at the same height.

Usage::

    python benchmarks/city_plos.py                      # writes docs/figures/city_plos.png, prints the table
    python benchmarks/city_plos.py --out /tmp/plos.png --links 5000
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from uavrl.envs.physics.city import P1410, generate_city, inside_building, line_of_sight, p_los_p1410  # noqa: E402
from uavrl.envs.physics.radio import AL_HOURANI  # noqa: E402

GROUND_M = 1.5
HEIGHTS_M = (30.0, 100.0, 300.0)
COLOURS = ("#1b9e77", "#d95f02", "#7570b3")
CITY_M = 7000.0
CENTRE_M = 500.0  # the ground nodes' square, in the middle of the city
MAX_RANGE_M = 3000.0
BINS = np.arange(0.0, 90.0 + 1e-9, 3.0)
SEEDS = (0, 1)


def street_points(city, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` ground nodes at 1.5 m, uniform over the streets of the central square."""
    low = (CITY_M - CENTRE_M) / 2
    points = np.empty((0, 3))
    while len(points) < n:
        draw = np.c_[rng.uniform(low, low + CENTRE_M, (2 * n, 2)), np.full(2 * n, GROUND_M)]
        points = np.r_[points, draw[~inside_building(city, draw)]]
    return points[:n]


def empirical(environment: str, height: float, links: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per bin of elevation angle: the geometric P_LoS of the cities, its number of links, and P.1410's mean."""
    hits, counts, closed = (np.zeros(len(BINS) - 1) for _ in range(3))
    lowest = math.degrees(math.atan((height - GROUND_M) / MAX_RANGE_M))
    for seed in SEEDS:
        city = generate_city(*P1410[environment], CITY_M, CITY_M, seed=seed)
        rng = np.random.default_rng([46, seed, int(height)])
        ground = street_points(city, rng, links)
        theta = rng.uniform(lowest, 90.0, links)
        azimuth = rng.uniform(0.0, 2 * math.pi, links)
        distance = (height - GROUND_M) / np.tan(np.radians(theta))
        uav = ground + np.c_[distance * np.cos(azimuth), distance * np.sin(azimuth), np.full(links, height - GROUND_M)]
        flying = ~inside_building(city, uav)  # a UAV inside a building is masked in the model: left out here
        los = line_of_sight(city, ground[flying], uav[flying])
        which = np.digitize(theta[flying], BINS) - 1
        hits += np.bincount(which, los, minlength=len(BINS) - 1)
        counts += np.bincount(which, minlength=len(BINS) - 1)
        p_closed = p_los_p1410(*P1410[environment], height, GROUND_M, distance[flying])
        closed += np.bincount(which, p_closed, len(BINS) - 1)
    with np.errstate(invalid="ignore"):
        return hits / counts, counts, closed / counts


def al_hourani(environment: str, theta_deg: np.ndarray) -> np.ndarray:
    a, b, _, _ = AL_HOURANI[environment]
    return 1 / (1 + a * np.exp(-b * (theta_deg - a)))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/figures/city_plos.png"))
    parser.add_argument("--links", type=int, default=30_000, help="links per environment, height and city seed")
    args = parser.parse_args(argv)
    began = time.perf_counter()
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.6), sharex=True, sharey=True)
    centres = (BINS[:-1] + BINS[1:]) / 2
    fine = np.linspace(0.05, 90.0, 2000)
    print("| environment | UAV height (m) | mean geometric P_LoS | mean P.1410 | mean Al-Hourani | links |")
    print("|---|---|---|---|---|---|")
    for ax, environment in zip(axes.flat, P1410, strict=True):
        alpha, beta, gamma = P1410[environment]
        for height, colour in zip(HEIGHTS_M, COLOURS, strict=True):
            p_los, counts, closed = empirical(environment, height, args.links)
            seen = counts > 0
            error = np.sqrt(p_los * (1 - p_los) / np.maximum(counts, 1))
            ax.errorbar(centres[seen], p_los[seen], yerr=1.96 * error[seen], fmt="o", ms=3.5, color=colour, lw=1)
            lowest = math.degrees(math.atan((height - GROUND_M) / MAX_RANGE_M))
            theta = fine[fine >= lowest]
            distance = (height - GROUND_M) / np.tan(np.radians(theta))
            ax.plot(theta, p_los_p1410(alpha, beta, gamma, height, GROUND_M, distance), "--", color=colour, lw=1.2)
            weights = counts[seen] / counts[seen].sum()
            print(
                f"| {environment} | {height:g} | {np.sum(weights * p_los[seen]):.3f} | "
                f"{np.sum(weights * closed[seen]):.3f} | {np.sum(weights * al_hourani(environment, centres[seen])):.3f}"
                f" | {int(counts.sum()):,} |"
            )
        ax.plot(fine, al_hourani(environment, fine), "-", color="black", lw=2.2)
        ax.set_title(f"{environment}: alpha={alpha:g}, beta={beta:g}/km$^2$, gamma={gamma:g} m", fontsize=10)
        ax.grid(alpha=0.3)
        ax.set_xlim(0, 90)
        ax.set_ylim(-0.02, 1.02)
    for ax in axes[1]:
        ax.set_xlabel("elevation angle from the ground node (degrees)")
    for ax in axes[:, 0]:
        ax.set_ylabel("P(line of sight)")
    handles = [plt.Line2D([], [], color="black", lw=2.2, label="Al-Hourani et al. 2014 (fitted S-curve)")]
    for height, colour in zip(HEIGHTS_M, COLOURS, strict=True):
        handles.append(
            plt.Line2D([], [], color=colour, marker="o", ls="", label=f"generated cities, UAV at {height:g} m")
        )
        handles.append(plt.Line2D([], [], color=colour, ls="--", label=f"ITU-R P.1410 closed form, {height:g} m"))
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8.5, frameon=False)
    fig.suptitle("Line of sight from a street node at 1.5 m to a UAV, by elevation angle", fontsize=12)
    fig.tight_layout(rect=(0, 0.085, 1, 0.97))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out} in {time.perf_counter() - began:.0f} s")


if __name__ == "__main__":
    main()
