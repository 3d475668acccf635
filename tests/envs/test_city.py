"""The ITU-R P.1410 cities and their line of sight (envs/physics/city.py, docs/model.md, Cities of buildings).

Every expected value here is computed by code of this file, not by the module under test: the cities' statistics
from their boxes, line of sight by clipping each link's ground track to each footprint (Liang-Barsky) and comparing
the link's height there with the roof, and P.1410's closed form by a loop over the buildings crossed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from uavrl.envs.config import InvalidOption
from uavrl.envs.physics.city import (
    P1410,
    City,
    generate_city,
    inside_building,
    line_of_sight,
    p_los_p1410,
)
from uavrl.envs.physics.radio import AL_HOURANI

AREA_M = 5000.0  # 5 km x 5 km: any lattice offset keeps the count of building centres within 1.5% of beta


def test_the_environments_are_the_al_hourani_ones():
    assert list(P1410) == list(AL_HOURANI)
    assert P1410["urban"] == (0.3, 500.0, 15.0) and P1410["highrise"] == (0.5, 300.0, 50.0)


@pytest.mark.parametrize("environment", list(P1410))
def test_generated_cities_have_p1410_statistics(environment):
    """Built-up ratio within 0.01 of alpha, buildings per km^2 within 2% of beta, heights Rayleigh(gamma) by a
    Kolmogorov-Smirnov test at the 1% level, on 5 km x 5 km, for three seeds."""
    alpha, beta, gamma = P1410[environment]
    for seed in range(3):
        city = generate_city(alpha, beta, gamma, AREA_M, AREA_M, seed=seed)
        # built-up ratio: each footprint clipped to the area (buildings at the edge stick out of it)
        covered_x = np.clip(city.x1, 0, AREA_M) - np.clip(city.x0, 0, AREA_M)
        covered_y = np.clip(city.y1, 0, AREA_M) - np.clip(city.y0, 0, AREA_M)
        built_up = float((covered_x * covered_y).sum()) / AREA_M**2
        assert abs(built_up - alpha) <= 0.01, (seed, built_up)
        # density: the buildings whose centre lies in the area, per km^2
        cx, cy = (city.x0 + city.x1) / 2, (city.y0 + city.y1) / 2
        per_km2 = np.count_nonzero((0 <= cx) & (cx < AREA_M) & (0 <= cy) & (cy < AREA_M)) / (AREA_M / 1000) ** 2
        assert abs(per_km2 / beta - 1) <= 0.02, (seed, per_km2)
        # square footprints, no two overlapping: the side and pitch of the lattice
        np.testing.assert_allclose(city.x1 - city.x0, 1000 * math.sqrt(alpha / beta))
        np.testing.assert_allclose(city.y1 - city.y0, 1000 * math.sqrt(alpha / beta))
        assert np.unique(np.round(city.x0, 6)).size * np.unique(np.round(city.y0, 6)).size == city.x0.size
        # heights: the KS statistic against the Rayleigh CDF 1 - exp(-h^2 / (2 gamma^2)), written out here
        heights = np.sort(city.height)
        n = heights.size
        cdf = -np.expm1(-(heights**2) / (2 * gamma**2))
        ks = max((np.arange(1, n + 1) / n - cdf).max(), (cdf - np.arange(n) / n).max())
        assert ks < 1.628 / math.sqrt(n), (seed, ks)  # the asymptotic critical value at 1%
        assert stats.kstest(city.height, stats.rayleigh(scale=gamma).cdf).pvalue > 0.01


def test_the_lattice_offset_is_uniform_over_seeds():
    """The offset drawn from the seed puts the area's corner on a street as often as the street covers the land."""
    alpha, beta, gamma = P1410["dense_urban"]
    corners = np.array([[0.5, 0.5, 1.0]])
    on_roof = [inside_building(generate_city(alpha, beta, gamma, 100, 100, seed=s), corners)[0] for s in range(400)]
    assert abs(np.mean(on_roof) - alpha) < 0.08  # 400 draws of Bernoulli(0.5): sd 0.025


def test_same_seed_same_city_bit_for_bit_and_different_seeds_differ():
    args = (*P1410["urban"], 700.0, 400.0)
    one, again, other = generate_city(*args, seed=7), generate_city(*args, seed=7), generate_city(*args, seed=8)
    for name in ("x0", "y0", "x1", "y1", "height"):
        assert getattr(one, name).tobytes() == getattr(again, name).tobytes()
    assert (one.origin_x, one.origin_y, one.columns, one.rows) == (
        again.origin_x,
        again.origin_y,
        again.columns,
        again.rows,
    )
    assert not np.array_equal(one.height[: other.height.size], other.height[: one.height.size])
    assert (one.origin_x, one.origin_y) != (other.origin_x, other.origin_y)


def reference_line_of_sight(city: City, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Line of sight by another algorithm: for each building, the open interval of ``t`` where the link's ground
    track is strictly inside the footprint (Liang-Barsky clipping of the 2-D segment), then the link is blocked there
    when its height somewhere in that interval is below the roof (its height is linear in ``t``, so its smallest value
    over the interval is at one end of it).  The ends are above the ground (z > 0), so the floor is never touched."""
    assert (a[:, 2] > 0).all() and (b[:, 2] > 0).all()
    d = b - a
    blocked = np.zeros(len(a), dtype=bool)
    for k in range(city.x0.size):
        lo, hi = np.zeros(len(a)), np.ones(len(a))
        empty = np.zeros(len(a), dtype=bool)
        # Liang-Barsky: p t < q for each of the four open half-planes of the footprint
        for p, q in (
            (-d[:, 0], a[:, 0] - city.x0[k]),
            (d[:, 0], city.x1[k] - a[:, 0]),
            (-d[:, 1], a[:, 1] - city.y0[k]),
            (d[:, 1], city.y1[k] - a[:, 1]),
        ):
            empty |= (p == 0) & (q <= 0)
            safe = np.where(p == 0, 1.0, p)
            r = q / safe
            hi = np.where(p > 0, np.minimum(hi, r), hi)
            lo = np.where(p < 0, np.maximum(lo, r), lo)
        crossing = ~empty & (lo < hi)
        lowest = np.minimum(a[:, 2] + lo * d[:, 2], a[:, 2] + hi * d[:, 2])
        blocked |= crossing & (lowest < city.height[k])
    return ~blocked


def random_links(city: City, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Ground nodes at 1.5 m and UAVs at 30-300 m over the area, with links that graze: along walls, at roof height,
    axis-aligned and vertical, and ends inside buildings."""
    w, dd = city.width_m, city.depth_m
    ground = np.c_[rng.uniform(0, w, n), rng.uniform(0, dd, n), np.full(n, 1.5)]
    uav = np.c_[rng.uniform(0, w, n), rng.uniform(0, dd, n), rng.uniform(30, 300, n)]
    k = rng.integers(0, city.x0.size, n)
    kind = rng.integers(0, 8, n)
    a, b = ground.copy(), uav.copy()
    # 1: vertical links (the UAV straight above the node)
    b[kind == 1, :2] = a[kind == 1, :2]
    # 2: horizontal links at a roof's height, along x (touching or over that roof and others)
    m = kind == 2
    a[m, 2] = b[m, 2] = city.height[k[m]]
    b[m, 1] = a[m, 1]
    # 3: links in the plane of a wall (x = x0 of a building), from low to high
    m = kind == 3
    a[m, 0] = b[m, 0] = city.x0[k[m]]
    # 4: horizontal links at a roof's height along y, on a wall's plane y = y1
    m = kind == 4
    a[m, 2] = b[m, 2] = city.height[k[m]]
    a[m, 1] = b[m, 1] = city.y1[k[m]]
    # 5: one end inside a building (below its roof, off its walls)
    m = kind == 5
    a[m, 0] = city.x0[k[m]] + 0.5 * (city.x1[k[m]] - city.x0[k[m]])
    a[m, 1] = city.y0[k[m]] + 0.25 * (city.y1[k[m]] - city.y0[k[m]])
    a[m, 2] = 0.5 * city.height[k[m]]
    # 6: vertical links on a building's corner edge, through a roof's height
    m = kind == 6
    a[m, :2] = b[m, :2] = np.c_[city.x1[k[m]], city.y0[k[m]]]
    # 7: UAVs low over the roofs (the heights of the buildings themselves, up to 1.2 times)
    m = kind == 7
    b[m, 2] = np.maximum(1.5, city.height[k[m]] * rng.uniform(0.8, 1.2, m.sum()))
    return a, b


@pytest.mark.parametrize("environment", list(P1410))
def test_line_of_sight_agrees_link_by_link_with_an_independent_intersection(environment):
    """25,000 links per environment (10^5 over the four), on 500 m x 500 m cities, link by link."""
    rng = np.random.default_rng(46)
    city = generate_city(*P1410[environment], 500.0, 500.0, seed=3)
    a, b = random_links(city, rng, 25_000)
    expected = reference_line_of_sight(city, a, b)
    got = line_of_sight(city, a, b)
    assert got.shape == expected.shape and got.dtype == bool
    assert np.array_equal(got, expected), np.flatnonzero(got != expected)[:5]
    assert np.array_equal(line_of_sight(city, b, a), expected)  # a link's direction does not matter
    assert 0.05 < expected.mean() < 0.99  # both outcomes are common


def test_long_links_agree_too():
    """Links up to 1.8 km long, in every direction, across a 1.5 km x 1 km city, in any array shape."""
    rng = np.random.default_rng(7)
    for environment in ("urban", "highrise"):
        city = generate_city(*P1410[environment], 1500.0, 1000.0, seed=11)
        a, b = random_links(city, rng, 3000)
        expected = reference_line_of_sight(city, a, b)
        assert np.array_equal(line_of_sight(city, a, b), expected)
        assert np.array_equal(line_of_sight(city, b.reshape(30, 100, 3), a.reshape(30, 100, 3)).ravel(), expected)


def box_city(boxes) -> City:
    """A hand-made city of ``(x0, y0, x1, y1, height)`` boxes on a 1-site-per-box lattice of pitch 100 m."""
    x0, y0, x1, y1, h = (np.array(v, dtype=float) for v in zip(*boxes, strict=True))
    return City(x0, y0, x1, y1, h, 0.25, 100.0, 10.0, 200.0, 100.0, 0, 50.0, 100.0, 0.0, 0.0, len(boxes), 1)


def test_line_of_sight_conventions_on_a_hand_made_city():
    """Touching is not blocking; passing through the interior or starting inside is."""
    city = box_city([(0, 0, 50, 50, 20), (100, 0, 150, 50, 40)])
    links = {  # (a, b): in line of sight
        ((-10, 25, 10), (10, 25, 30)): True,  # grazes the roof edge x = 0, z = 20 exactly at t = 1/2
        ((-10, 25, 10), (10, 25, 29)): False,  # just under that edge
        ((-10, 25, 20), (60, 25, 20)): True,  # over the first roof at its height, below the second's
        ((-10, 25, 20), (120, 25, 20)): False,  # ... and on into the second building
        ((0, -10, 5), (0, 60, 5)): True,  # along the wall x = 0
        ((0, 0, 1), (0, 0, 100)): True,  # vertical, on the corner edge
        ((25, 25, 1), (25, 25, 100)): False,  # vertical, from inside the building through its roof
        ((25, 25, 20), (25, 25, 100)): True,  # vertical, from the roof up (a rooftop node)
        ((25, 25, 20), (25, 25, 20)): True,  # a point on the roof
        ((25, 25, 10), (25, 25, 10)): False,  # a point inside
        ((60, 25, 1.5), (200, 25, 41)): False,  # into the second building's wall, 12.8 m up at x = 100
        ((60, 25, 1.5), (100, 25, 41)): True,  # up to its roof edge
    }
    ends = np.array([[*a, *b] for a, b in links], dtype=float)
    got = line_of_sight(city, ends[:, :3], ends[:, 3:])
    assert got.tolist() == list(links.values())
    assert np.array_equal(got, reference_line_of_sight(city, ends[:, :3], ends[:, 3:]))


def test_inside_building_matches_a_brute_force_search():
    city = generate_city(*P1410["highrise"], 400.0, 300.0, seed=5)
    rng = np.random.default_rng(0)
    points = np.c_[rng.uniform(-50, 450, 20_000), rng.uniform(-50, 350, 20_000), rng.uniform(0, 120, 20_000)]
    points[:1000, 0] = city.x0[rng.integers(0, city.x0.size, 1000)]  # some on a wall's plane
    brute = (
        (city.x0 < points[:, :1])
        & (points[:, :1] < city.x1)
        & (city.y0 < points[:, 1:2])
        & (points[:, 1:2] < city.y1)
        & (0 < points[:, 2:])
        & (points[:, 2:] < city.height)
    ).any(axis=1)
    assert np.array_equal(inside_building(city, points), brute)
    assert 0.1 < brute.mean() < 0.5
    assert inside_building(city, points.reshape(100, 200, 3)).shape == (100, 200)
    # a link from a point inside a building is blocked, whatever its other end
    inside = points[brute][:500]
    assert not line_of_sight(city, inside, inside + [0.0, 0.0, 500.0]).any()


def reference_p_los(alpha, beta, gamma, h_tx, h_rx, r_m):
    crossed = int(r_m / 1000 * math.sqrt(alpha * beta))  # floor of a non-negative number: m + 1
    p = 1.0
    for n in range(crossed):
        h = h_tx - (n + 0.5) * (h_tx - h_rx) / crossed
        p *= 1 - math.exp(-(h * h) / (2 * gamma * gamma))
    return p


def test_p1410_closed_form():
    rng = np.random.default_rng(1)
    for environment, (alpha, beta, gamma) in P1410.items():
        h_tx, r = rng.uniform(30, 300, 200), rng.uniform(0, 3000, 200)
        got = p_los_p1410(alpha, beta, gamma, h_tx, 1.5, r)
        expected = [reference_p_los(alpha, beta, gamma, h, 1.5, d) for h, d in zip(h_tx, r, strict=True)]
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-300, err_msg=environment)
    # the same link from either end; no building between the ends at short range
    assert p_los_p1410(0.3, 500, 15, 1.5, 100.0, 400.0) == pytest.approx(p_los_p1410(0.3, 500, 15, 100.0, 1.5, 400.0))
    assert p_los_p1410(0.3, 500, 15, 100.0, 1.5, [0.0, 81.0]).tolist() == [1.0, 1.0]  # 81 m: 0.99 buildings
    # by hand: r sqrt(alpha beta) = 0.15 * sqrt(200) = 2.12, two buildings under the link at 37.875 m and 13.625 m
    by_hand = (1 - math.exp(-(37.875**2) / 800)) * (1 - math.exp(-(13.625**2) / 800))
    assert float(p_los_p1410(0.5, 400, 20, 50.0, 1.5, 150.0)) == pytest.approx(by_hand, rel=1e-14)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (dict(alpha=1.2), "alpha=1.2 is invalid: must be a finite number above 0 and below 1.0"),
        (dict(beta=-1), "beta=-1 is invalid: must be a finite number above 0"),
        (dict(gamma=float("nan")), "gamma=nan is invalid"),
        (dict(width_m="5"), "width_m='5' is invalid: must be a number"),
        (dict(seed=-1), "seed=-1 is invalid: must be an integer >= 0"),
        (dict(seed=1.5), "seed=1.5 is invalid"),
        (dict(beta=1e6, width_m=1e5, depth_m=1e5), "buildings: at most 4,000,000"),
    ],
)
def test_generate_city_refuses_bad_arguments_before_any_work(args, message):
    full = dict(alpha=0.3, beta=500.0, gamma=15.0, width_m=500.0, depth_m=500.0, seed=0) | args
    with pytest.raises(InvalidOption, match=message.replace("(", r"\(").replace(".", r"\.")):
        generate_city(**full)


def test_line_of_sight_refuses_bad_points():
    city = generate_city(*P1410["urban"], 100.0, 100.0)
    with pytest.raises(InvalidOption, match=r"a: an array of shape \(\.\.\., 3\)"):
        line_of_sight(city, [1.0, 2.0], [1.0, 2.0, 3.0])
    with pytest.raises(InvalidOption, match="b: every coordinate must be finite"):
        line_of_sight(city, [1.0, 2.0, 3.0], [1.0, float("inf"), 3.0])
