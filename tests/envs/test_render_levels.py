"""Frames at altitude levels (envs/render.py): each UAV where its position is, its disc sized by its level, a tag with
the level beside it and its height in its panel row; frames at one level draw none of it."""

import numpy as np
import torch

from uavrl.envs import make_config
from uavrl.envs.render import DPI, LEVEL_DISC, RELAY_COLOUR, SENSE_COLOUR, WorldRenderer
from uavrl.envs.world import World

HEIGHTS = [30, 60, 100, 300]


def colour_at(frame, row, col, colour) -> bool:
    return bool((frame[row, col] == np.array(colour, dtype=np.uint8)).all())


def colour_near(frame, row, col, colour, radius=2) -> bool:
    patch = frame[row - radius : row + radius + 1, col - radius : col + radius + 1]
    return bool((patch == np.array(colour, dtype=np.uint8)).all(-1).any())


def placed(cfg, placements) -> World:
    """One world of ``cfg`` with its UAVs at ``placements``: (x, y, level, task) each."""
    world = World(cfg, batch_size=1, seed=0)
    world.reset()
    L1, C = cfg.grid[0], cfg.num_cells
    number = world.dynamics.positions.number
    codes = [2 * int(number[level * C + y * L1 + x]) + task for x, y, level, task in placements]
    world.start_at(torch.tensor([codes]))
    return world


def test_a_uav_at_a_known_level_shows_it_where_it_is():
    cfg = make_config("a2g_urban", grid=(4, 4), num_uavs=2, altitudes_m=HEIGHTS)
    world = placed(cfg, [(1, 1, 3, 1), (2, 3, 0, 0)])  # UAV 0 relays at 300 m, UAV 1 senses at 30 m
    renderer = WorldRenderer(world)
    frame = renderer.frame(0)
    tags = [tag.get_text() for tag in renderer._level_tags]
    rows = [row.get_text() for row in renderer._rows]
    assert tags == ["l3", "l0"] and rows[0].endswith(" 300m") and rows[1].endswith("  30m"), (tags, rows)
    full = np.sqrt(renderer._disc_area) / 2 * DPI / 72  # the highest level's disc radius, in pixels
    between = int(round((0.5 + LEVEL_DISC / 2) * full))  # inside the highest disc, outside the lowest
    for (x, y), colour, high in (((1, 1), RELAY_COLOUR, True), ((2, 3), SENSE_COLOUR, False)):
        row, col = renderer.pixel_of(x, y)
        assert colour_at(frame, row - 4, col - 4, colour)  # the disc is where its position is
        assert colour_at(frame, row, col - between, colour) == high  # and as large as its level
    tag_x, tag_y = renderer._level_tags[0].get_position()
    assert tag_x > 1 and tag_y < 1  # at the disc's upper right (y grows downwards)


def test_a_frame_follows_a_climb():
    cfg = make_config("a2g_urban", grid=(4, 4), num_uavs=2, altitudes_m=HEIGHTS)
    world = placed(cfg, [(1, 1, 0, 1), (2, 3, 0, 0)])
    renderer = WorldRenderer(world)
    before = renderer.frame(0)
    world.step(torch.tensor([[6, 4]]))  # UAV 0 climbs, UAV 1 senses on
    after = renderer.frame(0)
    assert [tag.get_text() for tag in renderer._level_tags] == ["l1", "l0"]
    assert renderer._rows[0].get_text().endswith("  60m") and not np.array_equal(before, after)


def test_a_city_at_levels_is_drawn_from_its_positions():
    """In a city the positions skip the buildings: a UAV's position index is no cell, yet it is drawn on its cell."""
    cfg = make_config(
        "a2g_urban", grid=(3, 3), num_uavs=2, altitudes_m=[20, 100, 300], city="highrise", environment="highrise"
    )
    world = World(cfg, batch_size=1, seed=0)
    world.reset()
    free = (world.dynamics.positions.number >= 0).view(3, 9)  # [level, cell]
    low_cell = int(free[0].nonzero()[-1])  # the last free cell at the lowest level
    world = placed(cfg, [(low_cell % 3, low_cell // 3, 0, 0), (0, 0, 2, 1)])
    renderer = WorldRenderer(world)
    frame = renderer.frame(0)
    row, col = renderer.pixel_of(low_cell % 3, low_cell // 3)
    assert colour_near(frame, row, col, SENSE_COLOUR)
    assert [tag.get_text() for tag in renderer._level_tags] == ["l0", "l2"]


def test_a_frame_at_one_level_draws_no_level():
    world = World(make_config("a2g_urban", grid=(4, 4), num_uavs=2), batch_size=1, seed=0)
    world.reset()
    renderer = WorldRenderer(world)
    renderer.frame(0)
    assert not renderer.levels and not hasattr(renderer, "_level_tags")
    assert all(not row.get_text().endswith("m") for row in renderer._rows)
    assert len(set(renderer._uavs.get_sizes())) == 1
