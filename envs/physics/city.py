"""Cities of buildings: the statistical city of Recommendation ITU-R P.1410 and line of sight from its geometry
(docs/model.md, Cities of buildings); numpy (and numba for :func:`line_of_sight`'s loop), no torch.

ITU-R P.1410 (Propagation data and prediction methods required for the design of terrestrial broadband radio access
systems) describes a built-up area by three numbers: ``alpha``, the ratio of land covered by buildings; ``beta``, the
mean number of buildings per km^2; ``gamma``, the scale in metres of the Rayleigh distribution of building heights,
``P(h) = h / gamma^2 exp(-h^2 / (2 gamma^2))``.  :func:`generate_city` lays such a city out as a Manhattan grid of
square buildings (side ``1000 sqrt(alpha / beta)`` m, pitch ``1000 / sqrt(beta)`` m: the city of Al-Hourani,
Kandeepan, Lardner 2014, section II-B, and of Holis and Pechac 2008), :func:`line_of_sight` tells which straight
links clear every building, and :func:`p_los_p1410` is the Recommendation's closed-form line-of-sight probability.

Example:
    >>> city = generate_city(*P1410["urban"], width_m=500.0, depth_m=500.0, seed=0)
    >>> round(city.side_m, 2), round(city.pitch_m, 2)  # 1000 sqrt(0.3 / 500), 1000 / sqrt(500)
    (24.49, 44.72)
    >>> line_of_sight(city, [[250.0, 250.0, 1000.0]], [[260.0, 240.0, 2000.0]]).tolist()  # above every roof
    [True]
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidOption
from .radio import P1410 as P1410  # the standard environments, kept here beside the cities they describe

MAX_BUILDINGS = 4_000_000  # 5 arrays of float64: 160 MB; a 10 km x 10 km suburban city has 75,000
_ROOF_MARGIN = 1e-9  # relative and in m: a link's part this far above the tallest roof is above it after rounding


@dataclass(frozen=True)
class City:
    """A city of box-shaped buildings on flat ground ``z = 0`` (metres; ``x`` east, ``y`` north, ``z`` up).

    Building ``k`` is the box ``[x0[k], x1[k]] x [y0[k], y1[k]] x [0, height[k]]``; the buildings sit on a square
    lattice of ``columns x rows`` sites, building ``k`` at column ``k % columns`` and row ``k // columns``, site
    ``(i, j)`` starting at ``(origin_x + i pitch_m, origin_y + j pitch_m)``.

    Args:
        x0: the buildings' west walls, float64 ``[n]``.
        y0: their south walls.
        x1: their east walls.
        y1: their north walls.
        height: their heights (roofs at ``z = height``).
        alpha: P.1410's ratio of land covered by buildings.
        beta: P.1410's buildings per km^2.
        gamma: P.1410's Rayleigh scale of the heights, m.
        width_m: the area's extent in ``x``: ``[0, width_m]``.
        depth_m: its extent in ``y``: ``[0, depth_m]``.
        seed: the city's seed (:func:`generate_city`).
        side_m: the buildings' side.
        pitch_m: the lattice's pitch (the street width is ``pitch_m - side_m``).
        origin_x: the west wall of the lattice's first column.
        origin_y: the south wall of its first row.
        columns: the lattice's columns.
        rows: its rows.
    """

    x0: np.ndarray
    y0: np.ndarray
    x1: np.ndarray
    y1: np.ndarray
    height: np.ndarray
    alpha: float
    beta: float
    gamma: float
    width_m: float
    depth_m: float
    seed: int
    side_m: float
    pitch_m: float
    origin_x: float
    origin_y: float
    columns: int
    rows: int


def _positive(name: str, value, high=math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InvalidOption(name, value, "must be a number")
    if not 0 < value < high or not math.isfinite(value):
        bound = "" if high == math.inf else f" and below {high}"
        raise InvalidOption(name, value, f"must be a finite number above 0{bound}")
    return float(value)


def _sites(shift: float, pitch: float, side: float, extent: float) -> tuple[float, int]:
    """The first wall and the number of the sites ``shift + i pitch`` (integer ``i``) of one axis whose buildings
    ``[shift + i pitch, shift + i pitch + side]`` meet the open interval ``(0, extent)``."""
    first = math.floor((-side - shift) / pitch) + 1
    last = math.ceil((extent - shift) / pitch) - 1
    return shift + first * pitch, last - first + 1


def generate_city(alpha, beta, gamma, width_m, depth_m, seed: int = 0) -> City:
    """The P.1410 city ``(alpha, beta, gamma)`` over the area ``[0, width_m] x [0, depth_m]``, fixed by ``seed``.

    Square buildings of side ``1000 sqrt(alpha / beta)`` m stand on a square lattice of pitch ``1000 / sqrt(beta)``
    m, so that they cover ``alpha`` of the land and number ``beta`` per km^2 (Al-Hourani et al. 2014, section II-B);
    their heights are independent draws of Rayleigh(``gamma``).  Every building whose footprint meets the area is
    kept whole (none is cut at the edge).  ``P1410[environment]`` gives the standard environments' parameters.

    One ``numpy.random.Generator(PCG64(seed))`` draws, in order, the lattice's offset (two uniforms) and the heights
    (row by row, west to east), so a seed gives the same city bit for bit on every machine with the same numpy.  Seeds
    are the cities' names: a set of training cities and a disjoint set of held-out ones are two sets of seeds.

    Args:
        alpha: the ratio of land covered by buildings, in (0, 1).
        beta: buildings per km^2, above 0.
        gamma: the Rayleigh scale of the heights in m, above 0.
        width_m: the area's extent in ``x`` in m, above 0.
        depth_m: its extent in ``y`` in m, above 0.
        seed: an integer >= 0.

    Raises:
        InvalidOption: an argument out of its range, or a city of more than ``MAX_BUILDINGS`` buildings.
    """
    alpha, beta, gamma = _positive("alpha", alpha, 1.0), _positive("beta", beta), _positive("gamma", gamma)
    width_m, depth_m = _positive("width_m", width_m), _positive("depth_m", depth_m)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InvalidOption("seed", seed, "must be an integer >= 0")
    pitch, side = 1000.0 / math.sqrt(beta), 1000.0 * math.sqrt(alpha / beta)
    most = (math.ceil(width_m / pitch) + 1) * (math.ceil(depth_m / pitch) + 1)  # for any offset
    if most > MAX_BUILDINGS:
        raise InvalidOption(
            "beta",
            beta,
            f"a {width_m:g} m x {depth_m:g} m city would have up to {most:,} buildings: "
            f"at most {MAX_BUILDINGS:,} (a smaller area or fewer buildings per km^2)",
        )
    rng = np.random.Generator(np.random.PCG64(int(seed)))
    # Our choice: the lattice is shifted by a uniform offset in [0, pitch)^2 drawn from the seed, so that a point of
    # the area (a cell centre, a node) is as likely to fall on a street as on a roof, as P.1410's statistical city
    # presumes; a fixed offset would give every city the same streets relative to the cells.
    shift_x, shift_y = -pitch * rng.random(2)
    (origin_x, columns), (origin_y, rows) = _sites(shift_x, pitch, side, width_m), _sites(shift_y, pitch, side, depth_m)
    heights = rng.rayleigh(gamma, size=(rows, columns))
    x0, y0 = np.meshgrid(origin_x + pitch * np.arange(columns), origin_y + pitch * np.arange(rows))  # [rows, columns]
    arrays = [x0.ravel(), y0.ravel(), x0.ravel() + side, y0.ravel() + side, heights.ravel()]
    for array in arrays:
        array.flags.writeable = False
    return City(
        *arrays, alpha, beta, gamma, width_m, depth_m, int(seed), side, pitch, origin_x, origin_y, columns, rows
    )


def _as_points(points, name: str) -> np.ndarray:
    array = np.asarray(points, dtype=np.float64)
    if array.ndim == 0 or array.shape[-1] != 3:
        raise InvalidOption(name, f"<array of shape {array.shape}>", message=f"{name}: an array of shape (..., 3)")
    if not np.isfinite(array).all():
        raise InvalidOption(name, message=f"{name}: every coordinate must be finite")
    return array


def roof_height(city: City, xy) -> np.ndarray:
    """The height of the roof over each ground point ``(..., 2)`` (metres): the building's whose footprint holds the
    point in its open interior, 0 on a street or a wall (and outside the lattice).

    Args:
        city: the city.
        xy: ground positions, an array ``(..., 2)``.
    """
    xy = np.asarray(xy, dtype=np.float64)
    flat = xy.reshape(-1, 2)
    # the lattice site under each point; only that building can hold it, since buildings do not overlap
    column = np.floor((flat[:, 0] - city.origin_x) / city.pitch_m).astype(np.int64)
    row = np.floor((flat[:, 1] - city.origin_y) / city.pitch_m).astype(np.int64)
    on_lattice = (column >= 0) & (column < city.columns) & (row >= 0) & (row < city.rows)
    k = np.where(on_lattice, row * city.columns + column, 0)
    under = (
        on_lattice
        & (city.x0[k] < flat[:, 0])
        & (flat[:, 0] < city.x1[k])
        & (city.y0[k] < flat[:, 1])
        & (flat[:, 1] < city.y1[k])
    )
    return np.where(under, city.height[k], 0.0).reshape(xy.shape[:-1])


def inside_building(city: City, points) -> np.ndarray:
    """Whether each point ``(..., 3)`` (metres) lies in the open interior of a building: ``x0 < x < x1``, ``y0 < y <
    y1`` and ``0 < z < height``.  A point on a wall or a roof is outside (a node on a rooftop stands on it).

    Args:
        city: the city.
        points: positions, an array ``(..., 3)``.
    """
    points = _as_points(points, "points")
    return (0 < points[..., 2]) & (points[..., 2] < roof_height(city, points[..., :2]))


def _clear_links(a, b, x0, y0, x1, y1, height, origin_x, origin_y, pitch, side, columns, rows, tallest):
    """:func:`line_of_sight`'s loop over the links ``a -> b`` ``[L, 3]`` (metres), compiled by numba on first use
    (:func:`_compiled`); ``x0, ..., height`` and the lattice are the city's, ``tallest`` its tallest roof."""
    clear = np.ones(len(a), dtype=np.bool_)
    for i in range(len(a)):
        if min(a[i, 2], b[i, 2]) >= tallest:  # above every roof
            continue
        # the buildings a link may pass through lie under its part below the tallest roof (and a margin): the walk
        # looks for them along that part only, from the link's lower end; the slab test takes the whole segment
        lower, upper = (a[i], b[i]) if a[i, 2] <= b[i, 2] else (b[i], a[i])
        rise = upper[2] - lower[2]
        below = (tallest * (1 + _ROOF_MARGIN) + _ROOF_MARGIN - lower[2]) / rise if rise > 0 else 1.0
        below = min(max(below, 0.0), 1.0)
        walk_x, walk_y = (upper[0] - lower[0]) * below, (upper[1] - lower[1]) * below
        # along its major ground axis u (the one it moves along more) the walk meets the sites first..last; a site is a
        # building then a street, and the last site is a margin against rounding past a building it enters
        x_major = abs(walk_x) >= abs(walk_y)
        if x_major:
            u, du, v, dv, u_origin, v_origin, u_sites, v_sites = (
                lower[0],
                walk_x,
                lower[1],
                walk_y,
                origin_x,
                origin_y,
                columns,
                rows,
            )
        else:
            u, du, v, dv, u_origin, v_origin, u_sites, v_sites = (
                lower[1],
                walk_y,
                lower[0],
                walk_x,
                origin_y,
                origin_x,
                rows,
                columns,
            )
        first = int(math.floor((min(u, u + du) - u_origin) / pitch))
        last = int(math.floor((max(u, u + du) - u_origin) / pitch)) + 1
        start, step = a[i], b[i] - a[i]
        blocked = False
        for site in range(first, last + 1):
            # over one building's extent in u the walk moves at most a side along v: it meets at most two rows, the
            # row of its lowest v there and the next (a site ends in a street, so rounding v loses no building)
            if du == 0.0:  # then dv == 0 too: a vertical link, its whole length over one point
                t_low, t_high = 0.0, 1.0
            else:
                wall = u_origin + site * pitch
                t_wall, t_far = (wall - u) / du, (wall + side - u) / du
                t_low = min(max(min(t_wall, t_far), 0.0), 1.0)
                t_high = min(max(max(t_wall, t_far), 0.0), 1.0)
            row_first = int(math.floor((v + min(t_low * dv, t_high * dv) - v_origin) / pitch))
            for row in (row_first, row_first + 1):
                if blocked or site < 0 or site >= u_sites or row < 0 or row >= v_sites:
                    continue
                k = row * columns + site if x_major else site * columns + row
                # the slab method: t in [0, 1] inside the three open slabs of the box is a non-empty interval
                enter, leave = 0.0, 1.0
                for low, high, s, d in (
                    (x0[k], x1[k], start[0], step[0]),
                    (y0[k], y1[k], start[1], step[1]),
                    (0.0, height[k], start[2], step[2]),
                ):
                    if d == 0.0:
                        inside = low < s < high
                        enter, leave = (enter, leave) if inside else (math.inf, -math.inf)
                    else:
                        t_a, t_b = (low - s) / d, (high - s) / d
                        enter, leave = max(enter, min(t_a, t_b)), min(leave, max(t_a, t_b))
                blocked = enter < leave
            if blocked:
                break
        clear[i] = not blocked
    return clear


@functools.cache
def _compiled():
    """:func:`_clear_links` compiled (numba, cached on disk): imported here, so that a model without a city, and the
    refusals, do not import numba."""
    import numba

    return numba.njit(cache=True, error_model="numpy")(_clear_links)


def line_of_sight(city: City, a, b) -> np.ndarray:
    """Whether each straight segment ``a -> b`` clears every building: a bool array of the links' shape.

    ``a`` and ``b`` are positions ``(..., 3)`` in metres that broadcast together.  A link is blocked when its segment
    passes through the open interior of a building (the slab method: the segment's ``t`` in ``[0, 1]`` inside the
    three open slabs of a box form a non-empty interval).  So a segment that only touches a building, grazing a roof
    edge, running along a wall or over a roof at roof height, is in line of sight, and one with an end inside a
    building (:func:`inside_building`) is blocked.

    Each link is tested only against the buildings its ground track may cross below the tallest roof, found by
    walking the lattice along that part of it (about two per building pitch of its length), and only until one
    blocks it; a link above every roof is not tested.  A compiled loop (numba) over the links.

    Args:
        city: the city.
        a: one end of each link, an array ``(..., 3)``.
        b: the other end.
    """
    a, b = np.broadcast_arrays(_as_points(a, "a"), _as_points(b, "b"))
    shape = a.shape[:-1]
    a, b = np.ascontiguousarray(a.reshape(-1, 3)), np.ascontiguousarray(b.reshape(-1, 3))
    lattice = (city.origin_x, city.origin_y, city.pitch_m, city.side_m, city.columns, city.rows)
    tallest = float(city.height.max(initial=0.0))
    walls = (city.x0, city.y0, city.x1, city.y1, city.height)
    return _compiled()(a, b, *walls, *lattice, tallest).reshape(shape)


def p_los_p1410(alpha, beta, gamma, h_tx, h_rx, ground_distance_m) -> np.ndarray:
    """P.1410's probability that a link of ground distance ``r`` between heights ``h_tx`` and ``h_rx`` is in line of
    sight, in the city ``(alpha, beta, gamma)``; arrays broadcast together.

        P_LoS = prod_{n=0}^{m} [1 - exp(-(h_tx - (n + 1/2) (h_tx - h_rx) / (m + 1))^2 / (2 gamma^2))]
        m = floor(r sqrt(alpha beta) - 1),  r in km

    ``m + 1 = floor(r sqrt(alpha beta))`` buildings stand, evenly spaced, between the ends; the link clears building
    ``n`` when it is lower than the link above its middle (Rayleigh CDF).  No building between the ends (``m < 0``)
    gives 1.  The form of Rec. ITU-R P.1410-5 (2012), section 2.1.5, as Al-Hourani, Kandeepan, Jamalipour
    (GLOBECOM 2014) use it, after Holis and Pechac 2008.

    Args:
        alpha: the ratio of land covered by buildings.
        beta: buildings per km^2.
        gamma: the Rayleigh scale of the heights, m.
        h_tx: one end's height, m.
        h_rx: the other end's height, m.
        ground_distance_m: the horizontal distance ``r`` between the ends, m.

    Example:
        >>> float(p_los_p1410(0.3, 500, 15, 100.0, 1.5, 50.0))  # r sqrt(alpha beta) = 0.61: no building between
        1.0
        >>> round(float(p_los_p1410(0.5, 400, 20, 50.0, 1.5, 150.0)), 6)  # 2 buildings, at heights 37.9 and 13.6 m
        0.172626
    """
    alpha, beta, gamma, h_tx, h_rx, r = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.float64) for v in (alpha, beta, gamma, h_tx, h_rx, ground_distance_m))
    )
    crossed = np.floor(r / 1000.0 * np.sqrt(alpha * beta))  # m + 1
    p_los = np.ones(r.shape)
    for n in range(int(crossed.max(initial=0))):
        with np.errstate(divide="ignore", invalid="ignore"):
            height = h_tx - (n + 0.5) * (h_tx - h_rx) / crossed
        factor = -np.expm1(-(height**2) / (2 * gamma**2))
        p_los = np.where(n < crossed, p_los * factor, p_los)
    return p_los
