"""A city in the World (docs/model.md, Cities of buildings): the per-cell gains and U* against an independent
computation written here (a brute-force roof lookup and segment-box clipping over every building, the path-loss
formulas written out), the nodes on roofs and out of buildings, the city shared, and the refusals."""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
import pytest
import torch

from uavrl.envs import World, make_config
from uavrl.envs.errors import InvalidOption
from uavrl.envs.physics.buildings import city_part
from uavrl.envs.physics.radio import AL_HOURANI

CITY = dict(channel="al_hourani", cell_size=50.0, altitude_m=100.0, city="urban", environment="urban")


def frame_m(cfg, xyz: np.ndarray) -> np.ndarray:
    """The documented frame: a point ``(x, y, z)`` in cells is ``((x + L1/2 + 1) cs, (y + L2/2 + 1) cs, z cs)``."""
    L1, L2 = cfg.grid
    return (np.asarray(xyz, dtype=np.float64) + [L1 / 2 + 1, L2 / 2 + 1, 0.0]) * cfg.cell_size


def roof_brute(city, x: float, y: float) -> float:
    """The roof over a ground point: the building whose footprint holds it strictly, by looking at all of them."""
    under = (city.x0 < x) & (x < city.x1) & (city.y0 < y) & (y < city.y1)
    return float(city.height[under].max()) if under.any() else 0.0


def clears_every_box(city, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the segment a -> b misses the open interior of every building: clip it to each box in turn."""
    for k in range(len(city.x0)):
        low = (city.x0[k], city.y0[k], 0.0)
        high = (city.x1[k], city.y1[k], city.height[k])
        t0, t1 = 0.0, 1.0
        for axis in range(3):
            d = b[axis] - a[axis]
            if d == 0:
                if not low[axis] < a[axis] < high[axis]:
                    t0, t1 = 1.0, 0.0
                continue
            ta, tb = sorted(((low[axis] - a[axis]) / d, (high[axis] - a[axis]) / d))
            t0, t1 = max(t0, ta), min(t1, tb)
        if t0 < t1:
            return False
    return True


def expected_contributions(cfg, nodes_cells: np.ndarray) -> np.ndarray:
    """``[C, 2]`` what a UAV at each cell adds inside PU's and SE's logarithms, from the formulas of docs/model.md."""
    city = city_part(cfg).city
    L1, L2 = cfg.grid
    _, _, eta_los, eta_nlos = AL_HOURANI[cfg.environment]
    watts = [10 ** ((p - 30) / 10) for p in (cfg.p_pt_dbm, cfg.p_s_dbm, cfg.p_u_dbm)]
    noise = 10 ** ((-174 + 10 * math.log10(cfg.bandwidth_mhz * 1e6) + cfg.noise_figure_db - 30) / 10)
    nodes = frame_m(cfg, nodes_cells)
    rows = []
    for c in range(L1 * L2):
        uav = frame_m(cfg, [c % L1, c // L1, cfg.height])
        gains = []
        for k, node in enumerate(nodes):
            d = float(np.linalg.norm(uav - node))
            free = 20 * math.log10(4 * math.pi * cfg.carrier_ghz * 1e9 * d / 299_792_458.0)
            if k < 2:  # PT, PR: air to ground, LoS by the geometry
                free += eta_los if clears_every_box(city, uav, node) else eta_nlos
            gains.append(10 ** (-free / 10))
        g_pt, g_pr, g_s, g_e = gains
        row = []
        for g_src, p_src, g_dst in ((g_pt, watts[0], g_pr), (g_s, watts[1], g_e)):
            g1, g2 = p_src * g_src / noise, watts[2] * g_dst / noise
            row.append(g1 * g2 / (1 + g1 + g2))
        rows.append(row)
    return np.array(rows)


@pytest.mark.parametrize("city_seed", [0, 7])
def test_the_worlds_gains_are_the_geometry_and_the_formulas(city_seed):
    cfg = make_config("paper", grid=(4, 3), num_uavs=2, city_seed=city_seed, **CITY)
    world = World(cfg, batch_size=2)
    world.reset()
    nodes = world.nodes[0].numpy()
    city = city_part(cfg).city
    for x, y, z in nodes[:2]:  # PT and PR stand on the roof under them, or on the ground
        assert z * cfg.cell_size == roof_brute(city, *frame_m(cfg, [x, y, 0])[:2])
    expected = expected_contributions(cfg, nodes)
    assert np.allclose(world.cell_contributions[0].numpy(), expected, rtol=1e-9, atol=0)


def test_some_links_are_blocked_and_some_clear():
    """The test above means something: in the urban city at 100 m, the grid's links to PT and PR differ in state."""
    cfg = make_config("paper", grid=(10, 10), num_uavs=2, **CITY)
    world = World(cfg)
    world.reset()
    los = city_part(cfg).line_of_sight(world._cell_xyz, world.nodes[0])[:, :2]
    assert 0.1 < los.double().mean().item() < 0.9


def test_u_star_in_a_city_is_the_brute_force_best():
    cfg = make_config("paper", grid=(3, 3), num_uavs=2, city_seed=4, **CITY)
    world = World(cfg)
    world.reset()
    contrib = expected_contributions(cfg, world.nodes[0].numpy())
    best = 0.0
    for cells in itertools.permutations(range(cfg.num_cells), 2):
        for tasks in itertools.product((0, 1), repeat=2):
            pu = sum(contrib[c, 0] for c, t in zip(cells, tasks, strict=True) if t == 1)
            se = sum(contrib[c, 1] for c, t in zip(cells, tasks, strict=True) if t == 0)
            r_se = 0.5 * math.log2(1 + se) if any(tasks) else 0.0  # the lease rule
            best = max(best, 0.5 * math.log2(1 + pu) + r_se)
    assert world.optimum()[0][0].item() == pytest.approx(best, rel=1e-12)


def test_random_layouts_keep_s_and_e_out_of_buildings_and_pt_pr_on_roofs():
    cfg = make_config("paper", grid=(6, 6), num_uavs=3, layout="random", city="highrise", environment="highrise",
                      channel="al_hourani", cell_size=50.0, altitude_m=200.0, city_seed=1)  # fmt: skip
    world = World(cfg, batch_size=64, seed=3)
    world.reset()
    city = city_part(cfg).city
    nodes = world.nodes.numpy()
    for layout in nodes:
        for x, y, z in layout[:2]:
            assert z * cfg.cell_size == roof_brute(city, *frame_m(cfg, [x, y, 0])[:2])
        for x, y, z in layout[2:]:
            px, py, pz = frame_m(cfg, [x, y, z])
            assert not pz < roof_brute(city, px, py)
    assert (nodes[:, :2, 2] > 0).any()  # some PT or PR did stand on a roof: the rule was exercised


def test_one_city_per_model_shared_by_every_world_and_seeds_name_cities():
    cfg = make_config("paper", grid=(6, 6), num_uavs=2, **CITY)
    first, second = World(cfg), World(cfg.replace(max_steps=7))
    assert first.parts["city"] is second.parts["city"]
    other = city_part(cfg.replace(city_seed=1)).city
    assert not np.array_equal(other.height, first.parts["city"].city.height)
    assert "city" not in World(make_config("paper", grid=(6, 6), num_uavs=2)).parts


def test_statistical_los_in_a_city_is_the_flat_channel_where_no_node_is_raised():
    flat = make_config("paper", grid=(6, 6), num_uavs=2, **{**CITY, "city": "none", "environment": "urban"})
    for seed in range(20):
        cfg = flat.replace(city="urban", los="statistical", city_seed=seed)
        world = World(cfg)
        if (world.nodes[0, :2, 2] == 0).all():  # PT and PR on the street: nothing else differs
            assert torch.equal(world.cell_contributions, World(flat).cell_contributions)
            return
    pytest.fail("no city of 20 left PT and PR on the street")


@pytest.mark.parametrize(
    "overrides, option, words",
    [
        (dict(city="urban"), "city", "channel='paper' has no line-of-sight state"),
        (dict(los="statistical", channel="al_hourani"), "los", "only a city reads it"),
        (dict(city_seed=3, channel="al_hourani"), "city_seed", "only a city reads it"),
        (dict(city="dense_urban", channel="al_hourani"), "city", "give environment='dense_urban' too"),
        (dict(city="urban", channel="al_hourani", environment="suburban"), "environment", "the city is 'urban'"),
        (dict(CITY, city_alpha=1.5), "city_alpha", "above 0 and below 1"),
        (dict(CITY, city_gamma=-2), "city_gamma", "above 0"),
        (dict(CITY, city_seed=-1), "city_seed", "0 to 2**63 - 1"),
        (dict(CITY, city_seed=True), "city_seed", "0 to 2**63 - 1"),
        (dict(CITY, los="ray_traced"), "los", "'geometric', 'statistical'"),
    ],
)
def test_city_options_are_refused_in_one_line(overrides, option, words):
    with pytest.raises(InvalidOption, match=re.escape(words)) as refused:
        make_config("paper", grid=(6, 6), num_uavs=2, **overrides)
    assert refused.value.option == option and "\n" not in str(refused.value)


def test_uavs_inside_buildings_are_refused_naming_the_height():
    cfg = make_config("paper", grid=(10, 10), num_uavs=2, **{**CITY, "altitude_m": 30.0})
    with pytest.raises(InvalidOption, match=r"altitude_m=30.0 is invalid: \d+ of the 100 cells at 30 m are inside"):
        World(cfg)


def test_a_city_of_too_many_buildings_is_refused_naming_the_density_typed():
    cfg = make_config("paper", grid=(6, 6), num_uavs=2, **{**CITY, "city_beta": 1e12})
    with pytest.raises(InvalidOption, match=r"city_beta=1000000000000.0 is invalid: .* at most 4,000,000") as refused:
        World(cfg)
    assert refused.value.option == "city_beta"
