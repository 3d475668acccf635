"""Costs that do not grow with the grid: the UAVs' placement, clashes, the greedy rule, the shared layout tables, the
evaluation's bounds within reach of the starts, the exact optimum's method, and the worlds' memory estimate."""

from __future__ import annotations

import itertools
import math
import random
from collections import Counter

import pytest
import torch
from scipy import stats

from uavrl.agents.dqn.networks import ValidGreedy
from uavrl.envs import make_config
from uavrl.envs.limits import KEYED_PLACEMENT_CELLS, world_bytes
from uavrl.envs.physics import streams
from uavrl.envs.physics.dynamics import Dynamics
from uavrl.envs.physics.grid import cells_or_away, grid_neighbours
from uavrl.envs.physics.positions import model_positions
from uavrl.envs.solvers import bounds, optimum
from uavrl.envs.world import World, WorldsState
from uavrl.envs.world import tables as world_tables

ONE = torch.ones(1, dtype=torch.long)


@pytest.mark.parametrize(("num_cells", "n"), [(1, 1), (7, 7), (50, 5), (10**6, 50), (2**40, 3)])
def test_distinct_cells_are_distinct_in_range_and_per_world(num_cells, n):
    keys, counters = streams.world_keys(11, 64), torch.arange(64)
    cells = streams.distinct_cells(keys, counters, streams.POSITIONS, num_cells, n)
    assert cells.shape == (64, n) and bool((cells >= 0).all() and (cells < num_cells).all())
    assert bool((cells.sort(-1).values.diff(dim=-1) > 0).all())
    for w in (0, 37, 63):  # world w of the batch is the world of a batch of one seeded 11 + w, same counter
        alone = streams.distinct_cells(
            streams.world_keys(11 + w, 1), counters[w : w + 1], streams.POSITIONS, num_cells, n
        )
        assert alone.equal(cells[w : w + 1])
    again = streams.distinct_cells(keys, counters, streams.POSITIONS, num_cells, n)
    assert again.equal(cells)


def test_distinct_cells_are_uniform_like_an_independent_sampler():
    """Ordered triples of 6 cells (120 of them): the counts of 60,000 draws against uniform, and against as many of
    Python's random.sample, by chi-square (a true sampler fails each at p < 1e-4 once in 10^4 runs)."""
    C, n, draws = 6, 3, 60_000
    keys = streams.world_keys(5, draws)
    cells = streams.distinct_cells(keys, torch.ones(draws, dtype=torch.long), streams.POSITIONS, C, n)
    tuples = list(itertools.permutations(range(C), n))
    ours = Counter(map(tuple, cells.tolist()))
    rng = random.Random(5)
    theirs = Counter(tuple(rng.sample(range(C), n)) for _ in range(draws))
    observed = [[ours[t] for t in tuples], [theirs[t] for t in tuples]]
    assert stats.chisquare(observed[0]).pvalue > 1e-4
    assert stats.chi2_contingency(observed).pvalue > 1e-4
    for uav in range(n):  # each UAV's cell alone is uniform too
        assert stats.chisquare(torch.bincount(cells[:, uav], minlength=C).tolist()).pvalue > 1e-4


def test_a_reset_places_the_uavs_apart_whatever_the_grid():
    """Up to KEYED_PLACEMENT_CELLS cells the keyed draw of every published figure, beyond it distinct_cells: distinct,
    on the grid, reproducible per world and seed, and one reset's memory does not grow with the grid."""
    small = make_config("paper", grid=(100, 100), num_uavs=5)
    keys, counters = streams.world_keys(3, 8), torch.ones(8, dtype=torch.long)
    keyed = streams.random_bits(keys, counters, streams.POSITIONS, small.num_cells).topk(5, largest=False).indices
    assert small.num_cells == KEYED_PLACEMENT_CELLS and Dynamics(small).start(keys, counters)["cell"].equal(keyed)
    large = make_config("paper", grid=(110, 100), num_uavs=5)
    serving = Dynamics(large).start(keys, counters)["cell"]
    assert bool((serving.sort(-1).values.diff(dim=-1) > 0).all() and (serving < large.num_cells).all())
    assert serving.equal(streams.distinct_cells(keys, counters, streams.POSITIONS, large.num_cells, 5))
    first = World(large, batch_size=4, seed=3).reset()["positions"]
    assert first.equal(World(large, batch_size=4, seed=3).reset()["positions"])


def test_clashes_by_sorting_are_those_by_counting():
    dynamics = Dynamics(make_config("paper", grid=(4, 3), num_uavs=5))
    target = torch.randint(0, 13, (500, 5), generator=torch.Generator().manual_seed(0))  # 12: the cell off the grid
    counted = torch.stack([torch.bincount(row, minlength=13)[row] > 1 for row in target])
    assert dynamics.clashes(target).equal(counted)


def _greedy_by_occupancy(greedy: ValidGreedy, values, allowed, positions, tasks):
    """The greedy rule as a per-cell occupancy table writes it (ValidGreedy's docstring): the reference."""
    C = len(greedy.neighbours)
    cells = cells_or_away(positions, (greedy.width, C // greedy.width)).tolist()
    out = []
    for w, row in enumerate(cells):
        targets = [
            [C] * 6 if c == C else [C if t < 0 else t for t in greedy.neighbours[c].tolist()] + [c] * 2 for c in row
        ]
        held = Counter(row)
        switched, actions = set(), []
        for i, c in enumerate(row):
            held[c] -= 1
            options = [
                a
                for a in range(6)
                if allowed[w, i, a]
                and not (targets[i][a] < C and held[targets[i][a]] > 0)
                and not (a >= 4 and tasks[w, i] != a - 4 and a in switched)
            ]
            a = max(options, key=lambda a: (values[w, i, a], -a))
            held[targets[i][a]] += 1
            if a >= 4 and tasks[w, i] != a - 4:
                switched.add(a)
            actions.append(a)
        for i in range(len(row)):
            claim = targets[i][actions[i]]
            held[claim] -= 1
            moves = [a for a in range(4) if allowed[w, i, a] and not (targets[i][a] < C and held[targets[i][a]] > 0)]
            if moves and actions[i] >= 4:
                move = max(moves, key=lambda a: (values[w, i, a], -a))
                if values[w, i, move] > values[w, i, actions[i]]:
                    actions[i], claim = move, targets[i][move]
            held[claim] += 1
        out.append(actions)
    return torch.tensor(out)


# by comparing the claims (grids of more cells than N^2 A) and by a per-row occupancy table (fewer)
@pytest.mark.parametrize(
    ("grid", "num_uavs", "away"),
    [((12, 12), 2, False), ((30, 20), 4, True), ((3, 3), 2, False), ((5, 4), 6, True), ((2, 2), 4, False)],
)
def test_the_greedy_rule_needs_no_per_cell_table(grid, num_uavs, away):
    L1, L2 = grid
    generator = torch.Generator().manual_seed(num_uavs)
    neighbours = grid_neighbours(grid)
    greedy = ValidGreedy(neighbours, L1)
    B = 200
    cells = torch.stack([torch.randperm(L1 * L2, generator=generator)[:num_uavs] for _ in range(B)])
    positions = torch.stack([cells % L1, cells // L1], -1)
    allowed = torch.cat([neighbours[cells] >= 0, torch.ones(B, num_uavs, 2, dtype=torch.bool)], -1)
    if away:  # a UAV out of service is shown off the grid and may only sense
        out = torch.rand(B, num_uavs, generator=generator) < 0.3
        positions = torch.where(out.unsqueeze(-1), torch.tensor([-1, 0]), positions)
        allowed = torch.where(out.unsqueeze(-1), torch.arange(6) == 4, allowed)
    values = torch.randint(0, 4, (B, num_uavs, 6), generator=generator).double()  # ties on purpose
    tasks = torch.randint(0, 2, (B, num_uavs), generator=generator)
    if away:
        tasks = tasks.masked_fill(out, 0)  # and senses
    assert greedy(values, allowed, positions, tasks).equal(
        _greedy_by_occupancy(greedy, values, allowed, positions, tasks)
    )


def test_worlds_of_one_model_share_its_tables_and_they_are_the_ones_built_alone():
    cfg = make_config("paper", grid=(7, 5), num_uavs=3)
    first = World(cfg, batch_size=4)
    second = World(cfg.replace(max_steps=9), batch_size=2)  # the episode length changes no table
    world_tables._SHARED_TABLES.clear()
    alone = World(cfg, batch_size=3)
    for name in ("_cell_contrib", "_code_obs", "_code_rate", "_node_obs", "_direct"):
        assert getattr(first, name) is getattr(second, name)
        assert getattr(alone, name) is not getattr(first, name) and torch.equal(
            getattr(alone, name), getattr(first, name)
        )
    assert first._code_xyt is second._code_xyt and first.dynamics.move_to is second.dynamics.move_to
    assert first.dynamics is not second.dynamics and second.dynamics.cfg is second.cfg  # each World moves its own
    assert torch.equal(alone.dynamics.move_to, first.dynamics.move_to) and torch.equal(alone._cell_xy, first._cell_xy)
    assert first.optimum()[0][:3].equal(alone.optimum()[0])
    for world in (first, second, alone):  # the same outputs from the same seed, shared or not
        world.set_seed(2)
    assert first.reset()["observation"][:2].equal(second.reset()["observation"])


def test_bounds_within_reach_of_the_starts_are_those_over_every_cell(monkeypatch):
    generator = torch.Generator().manual_seed(1)
    cases = [
        ((30, 20), 5, 3, True, {}),
        ((40, 40), 7, 2, False, {}),
        ((25, 60), 11, 4, True, {}),
        (
            (20, 20),
            4,
            3,
            False,
            dict(altitudes_m=[20, 60, 200], city="dense_urban", environment="dense_urban"),
        ),  # levels, positions blocked
    ]
    for (L1, L2), K, N, shared, model in cases:
        cfg = make_config("a2g_urban" if model else "paper", grid=(L1, L2), num_uavs=N, **model)
        positions, W = model_positions(cfg), 9
        P = len(positions)
        assert P < L1 * L2 * cfg.num_levels if model else P == L1 * L2
        cells = torch.stack([torch.randperm(P, generator=generator)[:N] for _ in range(W)])
        tasks = torch.randint(0, 2, (W, N), generator=generator)
        contributions = torch.rand(1 if shared else W, P, 2, generator=generator, dtype=torch.float64)
        assert bounds.reach_size(K, cfg.num_levels) < P
        near = bounds.reachable_best(cells, tasks, contributions, positions, (L1, L2), K)
        with monkeypatch.context() as patch:
            patch.setattr(bounds, "reach_size", lambda k, levels: math.inf)  # every position
            every = bounds.reachable_best(cells, tasks, contributions, positions, (L1, L2), K)
        assert all(a.equal(b) for a, b in zip(near, every, strict=True))
    assert len(bounds.reach_offsets(3)) == bounds.reach_size(3) == 25
    assert len(bounds.reach_offsets(3, num_levels=3)) == bounds.reach_size(3, 3) == 25 + 2 * (13 + 5)


@pytest.mark.parametrize("num_uavs", [11, 13])
def test_auto_optimum_takes_the_search_beyond_the_exchange_and_both_agree(monkeypatch, num_uavs):
    cfg = make_config("paper", grid=(12, 12), num_uavs=num_uavs, layout="random")
    world = World(cfg, batch_size=3, seed=4)
    world.reset()
    contributions, direct = world.cell_contributions, world.direct
    calls = []
    exchange = optimum._exchange
    monkeypatch.setattr(optimum, "_exchange", lambda *a: calls.append("exchange") or exchange(*a))
    auto = optimum.optimum(contributions, direct, cfg)[0]
    assert calls == []  # the search, which measured faster beyond AUTO_EXCHANGE_UAVS UAVs
    assert torch.allclose(auto, optimum.optimum(contributions, direct, cfg, method="exchange")[0], rtol=1e-12)
    search = optimum._search

    def stopped_search(*args):  # as if the search had stopped at its node limit in world 1: its bound above its best
        u, cells, tasks, upper = search(*args)
        return u, cells, tasks, upper + (torch.arange(len(u)) == 1)

    monkeypatch.setattr(optimum, "_search", stopped_search)
    u, _, _, upper = optimum.solve(contributions, direct, cfg)  # the exchange method finishes the job there
    assert calls.count("exchange") == 2 and torch.allclose(u, auto, rtol=1e-12) and upper.equal(u)


def test_the_worlds_memory_estimate_is_flat_in_the_grid_past_the_keyed_placement():
    """Per world, the estimate covers the state a World keeps (measured tensor bytes) and no longer grows with the
    grid; the layout's shared tables are estimated per cell."""
    per_world = []
    for side in (200, 1000):
        cfg = make_config("paper", grid=(side, side), num_uavs=4)
        per_world.append(world_bytes(cfg, 65) - world_bytes(cfg, 64))
    assert per_world[0] == per_world[1] < 4_000
    cfg = make_config("paper", grid=(200, 200), num_uavs=4)
    world = World(cfg, batch_size=64)
    state = sum(
        getattr(world._s, name).nbytes
        for name in WorldsState.__slots__
        if isinstance(getattr(world._s, name), torch.Tensor)
    )
    assert state / 64 <= per_world[0]
    tables = sum(t.nbytes for t in world._shared_tables.values() if isinstance(t, torch.Tensor))
    assert tables <= world_bytes(cfg, 0)
    assert world_bytes(make_config("paper", grid=(1000, 1000), num_uavs=2), 256) < 4 * 2**30  # the default budget


@pytest.mark.parametrize("num_uavs", [1, 2, 3, 5])
def test_the_assignment_bound_over_every_assignment_is_the_bottleneck_one(num_uavs):
    generator = torch.Generator().manual_seed(num_uavs)
    W, S, grid = 12, 4, (30, 17)
    C = grid[0] * grid[1]
    cells = torch.stack([torch.randperm(C, generator=generator)[:num_uavs] for _ in range(W)])
    tasks = torch.randint(0, 2, (W, num_uavs), generator=generator)
    targets = [torch.stack([torch.randperm(C, generator=generator)[:num_uavs] for _ in range(S)]) for _ in range(W)]
    target_tasks = [torch.randint(0, 2, (S, num_uavs), generator=generator) for _ in range(W)]
    positions = model_positions(make_config("paper", grid=grid, num_uavs=num_uavs))
    fast = bounds.assignment_min_steps(cells, tasks, targets, target_tasks, positions)
    by_assignment = [
        bounds.best_assignment(bounds.assignment_costs(c, t, tc, tt, positions))[0]
        for c, t, tc, tt in zip(cells, tasks, targets, target_tasks, strict=True)
    ]
    assert fast.tolist() == by_assignment
