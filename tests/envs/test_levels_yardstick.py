"""The yardstick with altitude levels and in cities, checked against brute force on tiny models: U* over every pair
of free (cell, level) positions, the fewest steps by a breadth-first search through the World's own step, the lower
bounds below them from every configuration, and the oracle planner's plans.

With one level and no city the bounds and the oracle are bit for bit what they were: benchmarks/fingerprint.py
holds the oracle's digests and the yardstick's numbers, and test_one_level_bounds_are_the_manhattan_ones below
recomputes the bounds by the cell formulas."""

from __future__ import annotations

import itertools
import math

import pytest
import torch

from uavrl.agents import references
from uavrl.agents.baselines import OraclePolicy, PathLengths
from uavrl.agents.references import LEVELS, placements, start_references
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.physics.buildings import city_part
from uavrl.envs.physics.channel import direct_terms, fixed_layout, link_gains, rates, relay_contributions
from uavrl.envs.physics.grid import manhattan
from uavrl.envs.physics.positions import model_positions
from uavrl.envs.solvers import bounds, exact
from uavrl.envs.world import World

LEVELS_M = [20, 60, 200]
# tiny models: (channel and city options, N); the city seeds put some low positions inside buildings
MODELS = {
    "levels": (dict(), 2),
    "urban": (dict(city="urban", environment="urban", city_seed=1), 2),  # level 0: two free cells, not adjacent
    "highrise": (dict(city="highrise", environment="highrise", city_seed=0), 2),  # blocked at two levels
}
SLOW_MODELS = {"urban-n3": (dict(city="urban", environment="urban", city_seed=2), 3)}
CASES = [*MODELS, *(pytest.param(name, marks=pytest.mark.slow) for name in SLOW_MODELS)]


def tiny(name: str):
    options, num_uavs = {**MODELS, **SLOW_MODELS}[name]
    return make_config("a2g_urban", grid=(3, 2), num_uavs=num_uavs, altitudes_m=LEVELS_M, cell_size=50, **options)


def test_the_tiny_cities_block_some_low_positions():
    for name in ("urban", "highrise"):
        cfg = tiny(name)
        assert len(model_positions(cfg)) < cfg.num_positions


@pytest.mark.parametrize("name", CASES)
def test_u_star_is_the_best_over_every_pair_of_free_positions(name):
    cfg = tiny(name)
    L1, L2 = cfg.grid
    xyz = torch.tensor(
        [(x, y, h) for h in cfg.level_heights for y in range(L2) for x in range(L1)], dtype=torch.float64
    )
    city = city_part(cfg)
    free = xyz if city is None else xyz[~city.inside(xyz)]
    nodes = fixed_layout(cfg)
    contributions = relay_contributions(link_gains(free, nodes, cfg), cfg)  # [F, 2]
    direct = direct_terms(nodes, cfg)
    N = cfg.num_uavs
    placed = torch.tensor(list(itertools.permutations(range(len(free)), N)))  # [M, N] distinct positions
    tasks = torch.tensor(list(itertools.product((0, 1), repeat=N)))  # [T, N]
    r_pu, r_se = rates(contributions[placed][:, None], tasks[None], direct, cfg)
    brute = float((r_pu + r_se).max())
    world = World(cfg, 2)
    world.reset()
    u_star, best, best_tasks = world.optimum()
    assert len(model_positions(cfg)) == len(free)
    torch.testing.assert_close(u_star, torch.full((2,), brute, dtype=torch.float64), rtol=1e-12, atol=0)
    torch.testing.assert_close(world.utility(best, best_tasks)[2], u_star, rtol=1e-12, atol=0)
    space = exact.model_space(cfg)
    assert space.num_configurations == math.comb(len(free), N) * 2**N
    assert float(space.utility(cfg, *exact.fixed_layout_tables(cfg)).max()) == pytest.approx(brute, rel=1e-12)


def brute_force_steps(world: World, start: dict, level: float) -> list[int]:
    """Fewest steps from each world's start to ``U >= level U*``: a breadth-first search over the UAVs' (position,
    task) tuples, each step every joint action through the World's own step (moves into buildings or off the
    positions stay, clashing moves cancel)."""
    cfg, N = world.cfg, world.cfg.num_uavs
    joint = torch.tensor(list(itertools.product(range(cfg.num_actions), repeat=N)))  # [A^N, N]
    target = level * float(world.optimum()[0][0])
    cells, tasks = world.cells_of(placements(start)), start["tasks"]
    start_utility = world.utility(placements(start), tasks)[2]
    out = []
    for w in range(world.num_worlds):
        frontier = {(tuple(cells[w].tolist()), tuple(tasks[w].tolist()))}
        seen, steps = set(frontier), 0
        reached = bool(start_utility[w] >= target)
        while not reached:
            assert frontier, "the target is out of reach"
            steps += 1
            now = sorted(frontier)
            cell = torch.tensor([c for c, _ in now]).repeat_interleave(len(joint), 0)
            task = torch.tensor([t for _, t in now]).repeat_interleave(len(joint), 0)
            after, r = world.successors({"cell": cell, "task": task}, joint.repeat(len(now), 1))
            reached = bool((r.sum(-1) >= target).any())
            frontier = {
                (tuple(c), tuple(t)) for c, t in zip(after["cell"].tolist(), after["task"].tolist(), strict=True)
            } - seen
            seen |= frontier
        out.append(steps)
    return out


@pytest.mark.parametrize("name", CASES)
def test_the_exact_fewest_steps_are_the_breadth_first_search_through_the_worlds_step(name):
    cfg = tiny(name)
    world = World(cfg.replace(max_steps=20), 12 if cfg.num_uavs == 2 else 3, seed=5)
    start = world.reset()
    u_star = world.optimum()[0]
    refs = start_references(world, start, u_star, 20, 0.9)
    assert refs["exact"] and refs["best_return"] is not None
    level = list(LEVELS).index("999")
    assert refs["min_steps"][:, level].tolist() == brute_force_steps(world, start, LEVELS["999"])
    assert refs["min_steps"][:, level].max() > 0  # not every start is already there


@pytest.mark.parametrize("name", CASES)
def test_every_bound_is_at_most_the_exact_fewest_steps_from_every_configuration(name, monkeypatch):
    cfg = tiny(name)
    space = exact.model_space(cfg)
    contributions, direct = exact.fixed_layout_tables(cfg)
    potential = space.utility(cfg, contributions, direct)
    u_star = potential.max()
    thresholds = torch.stack([q * u_star for q in LEVELS.values()]).expand(space.num_configurations, -1)
    fewest = torch.stack(
        [exact.min_steps(space, potential >= thresholds[:1, level, None])[0] for level in range(len(LEVELS))], -1
    ).long()
    starts = space.cells, space.tasks  # every configuration
    relaxed = bounds.relaxed_min_steps(*starts, contributions, direct, cfg, thresholds, max_steps=30)
    assert (relaxed <= fewest).all()
    optimal = bounds.optimal_configurations(contributions[0], direct[0], cfg, float(u_star))
    assert sorted(space.index(*optimal).tolist()) == (potential[0] >= (1 - bounds.OPTIMUM_RTOL) * u_star).nonzero(
    ).flatten().tolist()  # fmt: skip
    K = space.num_configurations
    assignment = bounds.assignment_min_steps(*starts, [optimal[0]] * K, [optimal[1]] * K, model_positions(cfg))
    assert (assignment <= fewest[:, -1]).all()
    # tight on most configurations: a bound that dropped the climbs (|dlevel|) would be far below
    assert (torch.maximum(assignment, relaxed[:, -1]) == fewest[:, -1]).double().mean() >= 0.6
    # the yardstick's own path where the exact solver does not fit: the same bounds from the World's starts
    world = World(cfg.replace(max_steps=20), 12, seed=7)
    start = world.reset()
    exact_refs = start_references(world, start, world.optimum()[0], 20, 0.9)
    monkeypatch.setattr(references.exact, "fits", lambda cfg: False)
    bound_refs = start_references(world, start, world.optimum()[0], 20, 0.9)
    assert not bound_refs["exact"] and (bound_refs["min_steps"] <= exact_refs["min_steps"]).all()
    assert bound_refs["min_steps"].sum() > 0


def test_the_relaxed_reach_counts_every_climb():
    """From (0, 0) at the lowest level, a relay contribution at (2, 1) on the top level is reached after
    |dx| + |dy| + |dlevel| = 5 steps, 6 with a task change (and never sooner)."""
    cfg = tiny("levels")
    positions = model_positions(cfg)
    top = int(positions.number[2 * cfg.num_cells + 1 * 3 + 2])
    contributions = torch.zeros(1, len(positions), 2, dtype=torch.float64)
    contributions[0, top, 0] = 1.0
    cells, tasks = torch.tensor([[0]]), torch.tensor([[1], [0]])  # relaying, then sensing
    best_relay, _ = bounds.reachable_best(cells.expand(2, 1), tasks, contributions, positions, cfg.grid, 8)
    assert (best_relay[:, :, 0] == 1.0).double().argmax(-1).tolist() == [5, 6]
    assert bounds.moves_apart(positions, torch.tensor(0), torch.tensor(top)) == 5


def test_path_lengths_go_around_buildings():
    """The oracle's fewest moves: the breadth-first search over the positions' moves (a plain one here), never
    below |dx| + |dy| + |dlevel|, and above it where a building is in the way."""
    positions = model_positions(tiny("urban"))
    P = len(positions)
    neighbours = positions.neighbours.tolist()
    lengths = PathLengths(positions)
    longer = 0
    for there in range(P):
        distance, queue = {there: 0}, [there]
        for p in queue:  # the queue grows while it is read
            for n in neighbours[p]:
                if n >= 0 and n not in distance:
                    distance[n] = distance[p] + 1
                    queue.append(n)
        expected = torch.tensor([distance.get(p, P) for p in range(P)])
        assert lengths(torch.arange(P), torch.tensor(there)).tolist() == expected.tolist()
        apart = bounds.moves_apart(positions, torch.arange(P), torch.tensor(there))
        assert (apart <= expected).all()
        longer += int((apart < expected).sum())
    assert longer > 0
    box = model_positions(tiny("levels"))  # no building: the fewest moves are |dx| + |dy| + |dlevel|
    every = torch.arange(len(box))
    assert PathLengths(box)(every[:, None], every).equal(bounds.moves_apart(box, every[:, None], every))


@pytest.mark.parametrize("name", CASES)
def test_the_oracle_reaches_the_optimum_in_no_fewer_than_the_fewest_steps(name):
    cfg = tiny(name)
    B, H = 12, 16
    env = UAVSpectrumEnv(batch_size=B, config=cfg.replace(max_steps=H), seed=3)
    start = env.reset()
    u_star = env.optimum()[0]
    td = env.rollout(H, OraclePolicy(cfg, env=env), auto_reset=False, tensordict=start, break_when_any_done=False)
    action = td["agents", "action"]
    moved = ((action < 4) | (action >= 6)).sum(-1)  # up, down, left, right, climb, descend
    assert torch.equal(moved, td["next", "moves"][..., 0])  # no move cancelled: every joint action valid
    placed = torch.cat([td["next", "positions"], td["next", "levels"].unsqueeze(-1)], -1)
    utility = env.world.utility(placed, td["next", "tasks"])[2]  # [B, H]
    assert (utility[:, -1] >= (1 - 1e-9) * u_star).all()
    reached = utility >= LEVELS["999"] * u_star[:, None]
    first = reached.double().argmax(-1) + 1
    fewest = start_references(env.world, start, u_star, H, 0.9)["min_steps"][:, list(LEVELS).index("999")]
    start_utility = env.world.utility(placements(start), start["tasks"])[2]
    first = torch.where(start_utility >= LEVELS["999"] * u_star, 0, first)
    assert (first >= fewest).all() and (first > 0).any()


def test_one_level_bounds_are_the_manhattan_ones():
    """Without levels or a city the bounds read the cells as before: reach and assignment costs by Manhattan."""
    cfg = make_config("paper", grid=(7, 5), num_uavs=3)
    positions = model_positions(cfg)
    generator = torch.Generator().manual_seed(0)
    cells = torch.stack([torch.randperm(35, generator=generator)[:3] for _ in range(4)])
    tasks = torch.randint(0, 2, (4, 3), generator=generator)
    contributions = torch.rand(1, 35, 2, generator=generator, dtype=torch.float64)
    distance = manhattan(cells.unsqueeze(-1), torch.arange(35), 7)  # [W, N, C]
    for K in (2, 6):  # the positions within reach (13 < 35), then every position
        best = bounds.reachable_best(cells, tasks, contributions, positions, cfg.grid, K)
        for task, column in ((1, 0), (0, 1)):
            cost = distance + (tasks != task).long().unsqueeze(-1)
            for k in range(K + 1):
                value = contributions[0, :, column].expand_as(cost).masked_fill(cost > k, -math.inf).amax(-1)
                assert best[column][:, k].equal(value)
    targets = torch.stack([torch.randperm(35, generator=generator)[:3] for _ in range(5)])
    target_tasks = torch.randint(0, 2, (5, 3), generator=generator)
    costs = bounds.assignment_costs(cells[0], tasks[0], targets, target_tasks, positions)
    expected = manhattan(cells[0][:, None, None], targets[None], 7) + (tasks[0][:, None, None] != target_tasks[None])
    assert costs.equal(expected.permute(1, 0, 2))


def test_the_oracle_flies_around_a_building():
    """Level 0 of the urban city has two free cells, (1, 0) and (0, 1), the cells between them inside buildings: the
    oracle climbs, moves twice and descends (4 steps, the fewest), where |dx| + |dy| + |dlevel| = 2 has no free move
    that shortens it."""
    from tensordict import TensorDict

    cfg = tiny("urban")
    world = World(cfg, 1)
    number = model_positions(cfg).number
    start, goal, other = (int(number[level * 6 + y * 3 + x]) for x, y, level in ((1, 0, 0), (0, 1, 0), (2, 1, 2)))
    assert min(start, goal, other) >= 0
    oracle = OraclePolicy(cfg)
    oracle._optimal_sets = lambda world, nodes: (torch.tensor([[goal, other]]), torch.tensor([[0, 1]]))
    out = world.start_at(torch.tensor([[2 * start, 2 * other + 1]]))
    for _ in range(4):
        td = TensorDict({key: out[key] for key in ("positions", "tasks", "levels")}, batch_size=[1])
        out = world.step(oracle(td)["agents", "action"])[0]
    assert world.cells_of(placements(out)).tolist() == [[goal, other]]


def test_the_lookahead_refuses_altitude_levels_in_one_line():
    from omegaconf import OmegaConf

    from uavrl.agents.lookahead import LookaheadPolicy
    from uavrl.agents.lookahead_rules import lookahead_settings

    expected = (
        "eval.lookahead=1 is invalid: the lookahead searches the cells of one altitude level, not "
        "env.altitudes_m=[20.0, 60.0, 200.0]: give eval.lookahead=0"
    )
    with pytest.raises(ValueError) as refused:
        LookaheadPolicy(None, "vdn", tiny("levels"), depth=1, width=4, gamma=0.9)
    assert str(refused.value) == expected
    cfg = OmegaConf.create({"eval": {"lookahead": 1}, "env": {"altitudes_m": [20.0, 60.0, 200.0]}})
    with pytest.raises(ValueError, match="^eval.lookahead=1 is invalid: the lookahead searches"):
        lookahead_settings(cfg)
    assert lookahead_settings(OmegaConf.create({"eval": {"lookahead": 0}, "env": {"altitudes_m": [20, 60]}})) == {}
