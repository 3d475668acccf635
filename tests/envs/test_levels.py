"""Altitude levels (docs/model.md, Altitude as a decision): positions, climb and descend, the masks, what a UAV
observes of the levels, and the exact solver's moves against the World's own step, checked on small models written
out here."""

from __future__ import annotations

import itertools

import pytest
import torch

from uavrl.envs import World, make_config
from uavrl.envs.config import CLIMB, DESCEND
from uavrl.envs.physics.positions import model_positions
from uavrl.envs.solvers.exact import model_space

LEVELS = dict(channel="al_hourani", cell_size=50.0, altitude_m=100.0, altitudes_m=[30.0, 100.0, 250.0])
# a city where some low positions are inside buildings (high-rise heights: a 30 m level is often blocked)
CITY = dict(LEVELS, city="highrise", environment="highrise", altitude_m=250.0, city_seed=2)


def test_positions_are_cells_by_level_without_the_blocked_ones():
    cfg = make_config("paper", grid=(4, 3), num_uavs=2, **CITY)
    positions, C = model_positions(cfg), cfg.num_cells
    assert 0 < cfg.num_positions - len(positions) < C  # some low positions are inside buildings, not all
    assert torch.equal(positions.number[positions.level * C + positions.cell], torch.arange(len(positions)))
    # a column is free from its roof up: a free position has a free one above it
    above = positions.number[(positions.level + 1).clamp(max=2) * C + positions.cell]
    assert (above >= 0).all()
    # the moves: the same cell one level up or down, or a grid neighbour at the same level; -1 only where none
    for p in range(len(positions)):
        cell, level = int(positions.cell[p]), int(positions.level[p])
        for move, target in enumerate(positions.neighbours[p].tolist()):
            x, y = cell % 4 + (0, 0, -1, 1, 0, 0)[move], cell // 4 + (-1, 1, 0, 0, 0, 0)[move]
            to_level = level + (0, 0, 0, 0, 1, -1)[move]
            inside = 0 <= x < 4 and 0 <= y < 3 and 0 <= to_level < 3
            expected = int(positions.number[to_level * C + y * 4 + x]) if inside else -1
            assert target == expected


def test_one_level_keeps_the_model_as_it_was():
    cfg = make_config("a2g_urban", grid=(4, 4), num_uavs=2)
    world = World(cfg)
    out = world.reset()
    assert "levels" not in out and out["observation"].shape[-1] == 16 and cfg.num_actions == 6
    assert world.num_positions == cfg.num_cells


def test_climb_and_descend_change_the_level_and_keep_the_cell_and_task():
    cfg = make_config("paper", grid=(3, 3), num_uavs=2, **LEVELS)
    world = World(cfg, batch_size=1)
    world.reset()
    positions = world.dynamics.positions
    start = torch.tensor([[0 * 9 + 4, 2 * 9 + 0]])  # UAV 0 over cell 4 at 30 m, UAV 1 over cell 0 at 250 m
    world.start_at(start * 2 + torch.tensor([[1, 0]]))
    out, _, _ = world.step(torch.tensor([[CLIMB, DESCEND]]))
    assert out["levels"].tolist() == [[1, 1]] and out["tasks"].tolist() == [[1, 0]]
    assert positions.cell[world.state.cell].tolist() == [[4, 0]]
    assert out["action_mask"][0, 0].tolist() == [True] * 8  # the middle level, the middle cell: every action
    world.start_at(torch.tensor([[0, 2 * (2 * 9 + 8)]]))  # UAV 0 at the bottom, UAV 1 at the top
    out, _, _ = world.step(torch.tensor([[DESCEND, CLIMB]]))  # both nowhere: both stay
    assert out["levels"].tolist() == [[0, 2]]
    assert not out["action_mask"][0, 0, DESCEND] and not out["action_mask"][0, 1, CLIMB]


def test_two_uavs_may_share_a_cell_at_two_levels_and_clash_at_one():
    cfg = make_config("paper", grid=(3, 3), num_uavs=2, **LEVELS)
    world = World(cfg)
    world.reset()
    world.start_at(torch.tensor([[2 * 4, 2 * (9 + 4)]]))  # cell 4 at 30 m and at 100 m
    assert world.state.cell.tolist() == [[4, 13]]
    out, _, _ = world.step(torch.tensor([[CLIMB, 4]]))  # UAV 0 climbs into UAV 1's position, which stays: cancelled
    assert world.state.cell.tolist() == [[4, 13]]
    out, _, _ = world.step(torch.tensor([[4, CLIMB]]))  # UAV 1 climbs away
    assert world.state.cell.tolist() == [[4, 22]] and out["levels"].tolist() == [[0, 2]]


def test_no_uav_starts_or_moves_into_a_building():
    cfg = make_config("paper", grid=(4, 3), num_uavs=3, **CITY)
    world = World(cfg, batch_size=256, seed=5)
    out = world.reset()
    xyz = world.dynamics.positions.xyz[world.state.cell]
    assert not world.parts["city"].inside(xyz).any()
    for _ in range(30):
        out, _, _ = world.step(torch.randint(0, 8, (256, 3)))
        assert not world.parts["city"].inside(world.dynamics.positions.xyz[world.state.cell]).any()


def test_what_a_uav_observes_of_the_levels():
    cfg = make_config("paper", grid=(3, 3), num_uavs=3, **CITY)
    world = World(cfg, batch_size=4, seed=1)
    out = world.reset()
    positions, contrib = world.dynamics.positions, world.cell_contributions[0]
    scaled = contrib / contrib.amax(0)
    obs, state, cells = out["observation"], out["state"], world.state.cell
    assert obs.shape[-1] == world.observation_size == 16 + 3 + 5 + 2
    for b, i in itertools.product(range(4), range(3)):
        p = int(cells[b, i])
        expected = [float(positions.level[p]) / 2]
        for move in (4, 5):  # climb, descend
            target = int(positions.neighbours[p, move])
            expected += scaled[target].tolist() if target >= 0 else [-1.0, -1.0]
        assert torch.allclose(obs[b, i, 19:24], torch.tensor(expected, dtype=torch.float32))
        others = [float(positions.level[cells[b, (i + k) % 3]]) / 2 for k in (1, 2)]
        assert obs[b, i, 24:].tolist() == pytest.approx(others)
    assert state[:, 15:18].tolist() == (positions.level[cells] / 2).tolist()  # before the 12 node features


def test_the_exact_solvers_moves_are_the_worlds_steps():
    """Every joint action of the exact solver's configuration space leads where the World's own step leads."""
    cfg = make_config("paper", grid=(2, 2), num_uavs=2, **{**CITY, "altitudes_m": [30.0, 250.0]})
    space, world = model_space(cfg), World(cfg)
    world.reset()
    assert space.num_joint_actions == 64
    actions = torch.tensor(list(itertools.product(range(8), repeat=2)))[:, [1, 0]]  # UAV 0's action is digit 0
    for k in range(space.num_configurations):
        cells, tasks = space.cells[k], space.tasks[k]
        after, _ = world.successors({"cell": cells.expand(64, 2), "task": tasks.expand(64, 2)}, actions)
        moved = (after["cell"] != cells).any(-1)
        for a in range(64):
            target = int(space.successors[k, a])
            if target < 0:  # invalid for the solver: a move nowhere or a clash, which the World repairs by staying
                continue
            expected = space.index(after["cell"][a], after["task"][a])
            assert target == int(expected), (k, a, moved[a])
