"""The branch and bound of envs/solvers/optimum.py (method="search") and the bounds beyond 20 UAVs, against the exchange
method, brute force and the enumerations they replace."""

from __future__ import annotations

import itertools
import math

import pytest
import torch

from uavrl.envs import make_config
from uavrl.envs.physics.grid import cells_of
from uavrl.envs.solvers.bounds import _searched_configurations, optimal_configurations, relaxed_best_utility
from uavrl.envs.solvers.optimum import SplitSearch, optimum, optimum_bound, ratio_order, solve, split_relaxation
from uavrl.envs.world import World

VARIANTS = [
    ("paper", {"layout": "random"}),
    ("paper", {"layout": "random", "lease_rule": False}),
    ("paper", {"layout": "random", "direct_links": True}),
    ("paper", {}),
    ("reference_code", {"layout": "random"}),
    ("reference_code", {"layout": "random", "lease_rule": False}),
]
# 16 UAVs on 5x4: the exchange method's ~0.8 GB peak, beside a second test worker, exceeds the fast suite's 1 GB
SIZES = [
    *[((2, 2), 1), ((3, 3), 2), ((2, 3), 6), ((4, 4), 5), ((3, 3), 9), ((5, 4), 8), ((6, 6), 12)],
    pytest.param((5, 4), 16, marks=pytest.mark.slow),
]


def world(preset, grid, N, options, worlds, seed):
    w = World(make_config(preset, grid=grid, num_uavs=N, **options), worlds, "cpu", seed)
    w.reset()
    return w


@pytest.mark.parametrize("grid,N", SIZES)
@pytest.mark.parametrize("preset,options", VARIANTS)
def test_search_equals_the_exchange_method(grid, N, preset, options):
    if preset == "reference_code" and N < 2:
        pytest.skip("U* = 0 without both tasks")
    w = world(preset, grid, N, options, 12, 7 * N + grid[0])
    u_exchange = w.optimum("exchange")[0]
    u, cells, tasks, upper = solve(w.cell_contributions, w.direct, w.cfg, "search")
    torch.testing.assert_close(u, u_exchange, rtol=1e-12, atol=0)
    assert torch.equal(upper, u)  # the search ended: U* is exact
    # the configuration is valid and its utility (channel.rates) is U*
    assert (cells.sort(-1).values.diff(dim=-1) > 0).all() and (cells >= 0).all() and (cells < w.cfg.num_cells).all()
    positions = torch.stack([cells % grid[0], cells // grid[0]], -1)
    torch.testing.assert_close(w.utility(positions, tasks)[2], u, rtol=1e-12, atol=0)


@pytest.mark.parametrize("grid,N", [((2, 2), 2), ((3, 2), 3), ((3, 3), 4), ((4, 3), 3)])
@pytest.mark.parametrize("preset,options", VARIANTS)
def test_search_equals_brute_force(grid, N, preset, options):
    w = world(preset, grid, N, options, 6, N + 11 * grid[1])
    torch.testing.assert_close(w.optimum("search")[0], w.optimum("brute")[0], rtol=1e-12, atol=0)


def test_auto_uses_the_search_beyond_twenty_uavs_and_the_exchange_up_to_it():
    w = world("paper", (6, 6), 21, {"layout": "random"}, 3, 0)
    torch.testing.assert_close(w.optimum()[0], w.optimum("search")[0], rtol=0, atol=0)
    with pytest.raises(ValueError, match="method='search' has no such limit"):
        w.optimum("exchange")
    w = world("paper", (6, 6), 8, {"layout": "random"}, 3, 0)
    assert torch.equal(w.optimum()[0], w.optimum("exchange")[0])


def test_fifty_uavs_on_fifty_by_fifty_is_exact_and_beats_every_local_move():
    w = world("paper", (50, 50), 50, {"layout": "random"}, 4, 5)
    u, cells, tasks, upper = solve(w.cell_contributions, w.direct, w.cfg)
    assert torch.equal(upper, u)
    a, b = w.cell_contributions[..., 0], w.cell_contributions[..., 1]
    for i in range(len(u)):
        relays, sensors = cells[i][tasks[i] == 1], cells[i][tasks[i] == 0]
        used = torch.zeros(w.cfg.num_cells, dtype=torch.bool)
        used[cells[i]] = True
        # no unused cell beats a relay's or a sensor's, and no task flip helps
        assert a[i][~used].max() <= a[i][relays].min() and b[i][~used].max() <= b[i][sensors].min()
        for j in range(50):
            flipped = tasks[i].clone()
            flipped[j] = 1 - flipped[j]
            positions = torch.stack([cells[i] % 50, cells[i] // 50], -1)
            assert w.utility(positions.expand(4, -1, -1), flipped.expand(4, -1))[2][i] <= u[i] * (1 + 1e-12)


def test_a_search_stopped_early_returns_a_certified_bound():
    """Hard instances (many UAVs on few cells, overlapping best cells): with a node limit of 1 the best found is
    below or at U*, and the bound at or above it."""
    w = world("paper", (5, 4), 14, {"layout": "random"}, 8, 3)
    exact, bounded = w.optimum("exchange")[0], 0
    for i in range(len(exact)):
        c, d = w.cell_contributions[i].numpy(), w.direct[i].numpy()
        (relays, sensors), bound = SplitSearch(c[:, 0], c[:, 1], d, 14, w.cfg).best(limit=1)
        cells = torch.tensor(relays + sensors)
        tasks = torch.tensor([1] * len(relays) + [0] * len(sensors))
        positions = torch.stack([cells % 5, cells // 5], -1)
        found = w.utility(positions.expand(8, -1, -1), tasks.expand(8, -1))[2][i]
        assert found <= exact[i] * (1 + 1e-12)
        assert bound is None and found >= exact[i] * (1 - 1e-12) or bound >= exact[i] * (1 - 1e-12)
        bounded += bound is not None
    assert bounded > 0
    assert torch.equal(
        optimum_bound(w.cell_contributions, w.direct, w.cfg), optimum(w.cell_contributions, w.direct, w.cfg)[0]
    )


def test_split_relaxation_bounds_every_split_and_is_reached():
    gen = torch.Generator().manual_seed(0)
    for n in range(0, 9):
        a, b = torch.rand(n, generator=gen, dtype=torch.float64) * 5, torch.rand(n, generator=gen, dtype=torch.float64)
        a[: n // 3] = 0.0 if n > 2 else a[: n // 3]  # some items that add nothing when relaying
        x, y = torch.tensor(1.3, dtype=torch.float64), 1 + b.sum()
        order = ratio_order(a, b)
        bound, j, theta = split_relaxation(a[order], b[order], x, y, 0.5)
        best = max(
            0.5 * (math.log2(x + sum(a[i] for i in r)) + math.log2(y - sum(b[i] for i in r)))
            for m in range(n + 1)
            for r in itertools.combinations(range(n), m)
        )
        assert bound >= best - 1e-12
        # the fractional point the bound names has that utility
        moved_a, moved_b = a[order][:j].sum(), b[order][:j].sum()
        if n:
            moved_a, moved_b = moved_a + theta * a[order][j], moved_b + theta * b[order][j]
        torch.testing.assert_close(bound, 0.5 * (torch.log2(x + moved_a) + torch.log2(y - moved_b)))
        # and on a fine grid along the path nothing is higher
        for t in torch.linspace(0, n, 200, dtype=torch.float64):
            k, f = int(t.clamp(max=n - 1e-9)) if n else 0, (t - int(t.clamp(max=n - 1e-9))) if n else 0
            pa = a[order][:k].sum() + (f * a[order][k] if n else 0)
            pb = b[order][:k].sum() + (f * b[order][k] if n else 0)
            assert 0.5 * (torch.log2(x + pa) + torch.log2(y - pb)) <= bound + 1e-12


@pytest.mark.parametrize(
    "preset,grid,N,options",
    [
        ("paper", (3, 3), 2, {}),
        ("paper", (7, 7), 4, {"direct_links": True}),
        ("paper", (5, 4), 4, {}),
        ("paper", (6, 6), 3, {"layout": "random"}),
        ("paper", (4, 4), 3, {"layout": "random", "lease_rule": False}),
        ("reference_code", (8, 8), 3, {}),
        ("reference_code", (5, 4), 4, {"layout": "random"}),
    ],
)
def test_searched_optimal_sets_equal_the_enumerated_ones(preset, grid, N, options):
    """Fixed layouts are symmetric: several optimal sets (up to 8 here) tie, and the search lists them all."""
    w = world(preset, grid, N, options, 4, N + grid[0])
    u = w.optimum()[0]
    for i in range(len(u)):
        c, d = w.cell_contributions[i], w.direct[i]
        listed = optimal_configurations(c, d, w.cfg, float(u[i]))
        searched = _searched_configurations(c, d, w.cfg, (1 - 1e-9) * float(u[i]))

        def pairs(cells, tasks):
            return sorted(
                tuple(sorted(zip(x.tolist(), y.tolist(), strict=True))) for x, y in zip(cells, tasks, strict=True)
            )

        assert pairs(*listed) == pairs(*searched)


def test_split_relaxation_bound_is_at_least_every_split_beyond_ten_uavs():
    cfg = make_config("paper", grid=(20, 20), num_uavs=12, layout="random", max_steps=40)
    w = World(cfg, 3, "cpu", 2)
    start = w.reset()
    cells = cells_of(start["positions"], 20)
    import uavrl.envs.solvers.bounds as bounds

    split = relaxed_best_utility(cells, start["tasks"], w.cell_contributions, w.direct, cfg, 40)
    limit, bounds.MAX_SPLIT_UAVS = bounds.MAX_SPLIT_UAVS, 12
    try:
        every = relaxed_best_utility(cells, start["tasks"], w.cell_contributions, w.direct, cfg, 40)
    finally:
        bounds.MAX_SPLIT_UAVS = limit
    assert (split >= every - 1e-12).all()
    assert ((split - every) / every).max() < 1e-3  # and barely looser


def test_oracle_evaluation_at_fifty_uavs():
    from uavrl.agents.baselines import OraclePolicy
    from uavrl.agents.evaluation import evaluate

    cfg = make_config("paper", grid=(50, 50), num_uavs=50)
    metrics = evaluate(OraclePolicy(cfg), cfg, num_starts=2, horizon=120)
    assert metrics["eval/reach_optimum"] == 1.0 and metrics["eval/min_steps_exact"] == 0.0
    assert 1.0 <= metrics["eval/step_ratio_optimum"] < 1.2 and "eval/u_star_gap" not in metrics


def test_the_evaluation_reports_the_gap_where_the_search_stopped(monkeypatch):
    import uavrl.envs.solvers.optimum as optimum_module
    from uavrl.agents.references import u_star_gap

    w = world("paper", (5, 5), 22, {"layout": "random"}, 8, 1)  # crowded: the best cells of both networks overlap
    exact = w.optimum()[0]
    assert u_star_gap(w, exact) == 0.0
    monkeypatch.setattr(optimum_module, "SEARCH_NODE_LIMIT", 1)
    found, _, _, upper = solve(w.cell_contributions, w.direct, w.cfg)
    assert (found <= exact * (1 + 1e-12)).all() and (upper >= exact * (1 - 1e-12)).all()
    assert (upper > found).any()
    torch.testing.assert_close(u_star_gap(w, found), ((upper - found) / found).max().item())
    assert u_star_gap(w, found) > 0
