"""The yardstick: exact optimal control, lower bounds, the oracle planner and the evaluation's new metrics."""

from __future__ import annotations

import functools
import itertools
import math
import re
import subprocess
import sys

import pytest
import torch

from uavrl.agents.baselines import OraclePolicy
from uavrl.agents.episodes import episode_metrics
from uavrl.agents.evaluation import LEVELS, evaluate, yardstick_metrics
from uavrl.agents.evaluation import check_settings as check_eval_settings
from uavrl.agents.tabular import exact_q_table
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.physics.grid import cells_of
from uavrl.envs.physics.positions import model_positions
from uavrl.envs.solvers.bounds import assignment_min_steps, optimal_configurations, relaxed_min_steps
from uavrl.envs.solvers.exact import ConfigurationSpace, fixed_layout_tables, min_steps, optimal_values

MOVES = {0: (0, -1), 1: (0, 1), 2: (-1, 0), 3: (1, 0)}


class PlainModel:
    """The model worked without the solver: ordered configurations as tuples, moves by hand, U from ``env.utility``."""

    def __init__(self, grid, num_uavs, **options):
        self.env = UAVSpectrumEnv(grid=grid, num_uavs=num_uavs, **options)
        self.grid, self.N = grid, num_uavs
        cells = list(itertools.product(range(grid[0]), range(grid[1])))
        self.configs = [
            (p, t) for p in itertools.permutations(cells, num_uavs) for t in itertools.product((0, 1), repeat=num_uavs)
        ]
        pos = torch.tensor([p for p, _ in self.configs]).unsqueeze(0)
        tasks = torch.tensor([t for _, t in self.configs]).unsqueeze(0)
        self.u = dict(zip(self.configs, self.env.utility(pos, tasks)[2][0].tolist(), strict=True))
        joints = list(itertools.product(range(6), repeat=num_uavs))
        self.next = {c: [(j, self.step(c, j)) for j in joints] for c in self.configs}

    def step(self, config, joint):
        """The next configuration, or None for an invalid joint action (off the grid or two UAVs in one cell)."""
        (positions, tasks), new_pos, new_tasks = config, [], []
        for (x, y), task, a in zip(positions, tasks, joint, strict=True):
            cell = (x + MOVES[a][0], y + MOVES[a][1]) if a < 4 else (x, y)
            if not (0 <= cell[0] < self.grid[0] and 0 <= cell[1] < self.grid[1]):
                return None
            new_pos.append(cell)
            new_tasks.append(task if a < 4 else a - 4)
        return (tuple(new_pos), tuple(new_tasks)) if len(set(new_pos)) == self.N else None

    def successors(self, config):
        return self.next[config]

    def best_return(self, config, horizon, gamma):
        @functools.lru_cache(maxsize=None)
        def value(c, h):
            if h == 0:
                return 0.0
            return max(self.u[n] - self.u[c] + gamma * value(n, h - 1) for _, n in self.successors(c) if n is not None)

        return value(config, horizon)

    def q_star(self, gamma, sweeps=200):
        values = dict.fromkeys(self.configs, 0.0)
        for _ in range(sweeps):
            values = {
                c: max(self.u[n] - self.u[c] + gamma * values[n] for _, n in self.successors(c) if n is not None)
                for c in self.configs
            }
        return {
            c: {
                j: (self.u[n] - self.u[c] + gamma * values[n]) if n is not None else -math.inf
                for j, n in self.successors(c)
            }
            for c in self.configs
        }

    def solver_index(self, space, config):
        positions, tasks = config
        return int(space.index(cells_of(torch.tensor(positions), self.grid[0]), torch.tensor(tasks)))


TINY = [((2, 2), 1), ((2, 2), 2), ((3, 3), 1), ((3, 3), 2)]


@pytest.mark.parametrize("grid,N", TINY)
def test_finite_horizon_values_equal_brute_force(grid, N):
    plain = PlainModel(grid, N)
    space = ConfigurationSpace(grid, N)
    u = space.utility(plain.env.cfg, *fixed_layout_tables(plain.env.cfg))
    for horizon, gamma in ((1, 0.9), (4, 0.9), (5, 0.3), (3, 1.0)):
        v = optimal_values(space, u, gamma, horizon)[0]
        for config in plain.configs:
            assert v[plain.solver_index(space, config)].item() == pytest.approx(
                plain.best_return(config, horizon, gamma), rel=1e-12, abs=1e-12
            )


@pytest.mark.parametrize("grid,N", TINY)
@pytest.mark.parametrize("gamma", [0.3, 0.9])
def test_q_star_equals_brute_force(grid, N, gamma):
    plain = PlainModel(grid, N)
    space = ConfigurationSpace(grid, N)
    u = space.utility(plain.env.cfg, *fixed_layout_tables(plain.env.cfg))
    values = optimal_values(space, u, gamma)
    expected = plain.q_star(gamma)
    positions = torch.tensor([p for p, _ in plain.configs]).unsqueeze(0)
    tasks = torch.tensor([t for _, t in plain.configs]).unsqueeze(0)
    q = space.q_values(u, values, gamma, cells_of(positions, grid[0]), tasks)[0]
    decode = [tuple((j // 6**i) % 6 for i in range(N)) for j in range(6**N)]  # joint action j = sum_i a_i 6^i
    for row, config in zip(q, plain.configs, strict=True):
        want = torch.tensor([expected[config][joint] for joint in decode], dtype=torch.float64)
        torch.testing.assert_close(row, want, rtol=1e-10, atol=1e-10)


def test_bfs_distances_by_hand():
    # a 3x1 strip with two UAVs; target: a relay on cell 1 and a sensor on cell 2
    space = ConfigurationSpace((3, 1), 2)
    target = torch.zeros(1, space.num_configurations, dtype=torch.bool)
    target[0, space.index(torch.tensor([1, 2]), torch.tensor([1, 0]))] = True
    steps = min_steps(space, target)[0]

    def at(cells, tasks):
        return steps[space.index(torch.tensor(cells), torch.tensor(tasks))].item()

    assert at([1, 2], [1, 0]) == 0
    assert at([2, 1], [0, 1]) == 0  # the same set, UAVs named the other way round
    assert at([1, 2], [0, 0]) == 1  # one task change
    assert at([0, 2], [1, 0]) == 1  # one move right
    assert at([1, 2], [0, 1]) == 1  # both change task in one step
    # sensor on 0, relay on 1: both move right in one step (into the cell just left), then both change task
    assert at([0, 1], [0, 1]) == 2
    assert at([0, 1], [1, 0]) == 1  # relay on 0, sensor on 1: one step right together
    # one UAV: from cell 0 sensing to cell 2 relaying is two moves and a task change
    one = ConfigurationSpace((3, 1), 1)
    target = torch.zeros(1, one.num_configurations, dtype=torch.bool)
    target[0, one.index(torch.tensor([2]), torch.tensor([1]))] = True
    assert min_steps(one, target)[0, one.index(torch.tensor([0]), torch.tensor([0]))].item() == 3


BOUND_CASES = [
    ((6, 6), 2, {}),
    ((6, 6), 3, {}),
    ((4, 4), 3, {"preset": "reference_code"}),
    ((5, 4), 3, {"layout": "random"}),
    ((3, 3), 4, {}),
]


# every configuration's utility takes 0.6-1.0 GB from 3 UAVs on: those cases run with the slow tests, so that each
# process of the fast suite stays under 1 GB
LIGHT_BOUND_CASES = [case if case[1] < 3 else pytest.param(*case, marks=pytest.mark.slow) for case in BOUND_CASES]


@pytest.mark.parametrize("grid,N,options", LIGHT_BOUND_CASES)
def test_bounds_never_exceed_the_exact_minimum(grid, N, options):
    B = 12 if options.get("layout") == "random" else 40  # random layouts: one solve per world
    env = UAVSpectrumEnv(batch_size=B, grid=grid, num_uavs=N, seed=11, **options)
    start = env.reset()
    u_star = env.optimum()[0]
    space = ConfigurationSpace(grid, N)
    layouts = B if env.cfg.layout == "random" else 1
    u = space.utility(env.cfg, env.cell_contributions[:layouts], env.direct[:layouts])
    cells, tasks = cells_of(start["positions"], grid[0]), start["tasks"]
    k = space.index(cells, tasks)
    levels = torch.stack([q * u_star for q in LEVELS.values()], -1)
    relaxed = relaxed_min_steps(cells, tasks, env.cell_contributions, env.direct, env.cfg, levels, max_steps=30)
    for level in range(len(LEVELS)):
        exact = min_steps(space, u >= levels[:layouts, level : level + 1])[torch.arange(B) % layouts, k]
        assert (relaxed[:, level] <= exact).all()
    optimal = [
        optimal_configurations(env.cell_contributions[w], env.direct[w], env.cfg, float(u_star[w])) for w in range(B)
    ]
    assignment = assignment_min_steps(
        cells, tasks, [c for c, _ in optimal], [t for _, t in optimal], model_positions(env.cfg)
    )
    assert (assignment <= exact).all()
    assert (torch.maximum(assignment, relaxed[:, -1]) == exact).double().mean() >= 0.9  # and nearly always tight


@pytest.mark.parametrize("grid,N,options", LIGHT_BOUND_CASES)
def test_every_optimal_configuration_is_listed(grid, N, options):
    env = UAVSpectrumEnv(batch_size=3, grid=grid, num_uavs=N, seed=5, **options)
    env.reset()
    u_star = env.optimum()[0]
    space = ConfigurationSpace(grid, N)
    u = space.utility(env.cfg, env.cell_contributions, env.direct)
    for w in range(3):
        cells, tasks = optimal_configurations(env.cell_contributions[w], env.direct[w], env.cfg, float(u_star[w]))
        expected = (u[w] >= (1 - 1e-9) * u_star[w]).nonzero().flatten()
        assert sorted(space.index(cells, tasks).tolist()) == expected.tolist()


@pytest.mark.parametrize(
    "grid,N,options", [((6, 6), 2, {}), ((6, 6), 3, {}), ((10, 10), 6, {}), ((8, 8), 4, {"layout": "random"})]
)
def test_oracle_plans_are_valid_and_reach_the_optimum(grid, N, options):
    B, H = 24, 2 * sum(grid) + 4
    env = UAVSpectrumEnv(batch_size=B, grid=grid, num_uavs=N, max_steps=H, seed=3, **options)
    start = env.reset()
    td = env.rollout(H, OraclePolicy(env.cfg, env=env), auto_reset=False, tensordict=start, break_when_any_done=False)
    # every joint action is valid: no move is cancelled by the environment's collision rule
    assert torch.equal((td["agents", "action"] < 4).sum(-1), td["next", "moves"][..., 0])
    u_star = env.optimum()[0]
    utility = env.utility(td["next", "positions"], td["next", "tasks"])[2]
    assert (utility[:, -1] >= (1 - 1e-9) * u_star).all()


def test_value_iteration_policy_is_the_exact_greedy_policy():
    plain = PlainModel((3, 3), 2)
    for gamma in (0.3, 0.9):
        expected = plain.q_star(gamma)
        with_tasks = exact_q_table(make_config("paper", grid=(3, 3), num_uavs=2, state_includes_tasks=True), gamma)
        location_only = exact_q_table(make_config("paper", grid=(3, 3), num_uavs=2), gamma)
        by_location: dict = {}
        for config, q in expected.items():
            (p0, p1), (t0, t1) = config
            c0, c1 = p0[1] * 3 + p0[0], p1[1] * 3 + p1[0]
            want = torch.tensor([q[(j % 6, j // 6)] for j in range(36)], dtype=torch.float64)
            row = with_tasks[(2 * c0 + t0) + 18 * (2 * c1 + t1)]
            valid = want > -math.inf
            torch.testing.assert_close(row[valid], want[valid], rtol=1e-10, atol=1e-10)
            best = want.max()
            assert set((row == row[valid].max()).logical_and(valid).nonzero().flatten().tolist()) <= set(
                ((want - best).abs() <= 1e-9).nonzero().flatten().tolist()
            )
            by_location.setdefault(c0 + 9 * c1, []).append(want.masked_fill(~valid, 0.0))
        for row, qs in by_location.items():  # the paper's state: Q* averaged over the 4 task vectors a start deals
            torch.testing.assert_close(location_only[row], torch.stack(qs).mean(0), rtol=1e-10, atol=1e-10)


def test_yardstick_metrics_on_a_hand_made_trajectory():
    u_star = torch.tensor([10.0, 10.0, 10.0])
    utility = torch.tensor(
        [
            [5.0, 9.95, 10.0, 10.0],  # 0.99 U* after 1 step, U* after 2
            [10.0, 10.0, 10.0, 10.0],  # starts at the optimum
            [1.0, 2.0, 3.0, 9.0],  # never reaches 0.99 U*
        ],
        dtype=torch.float64,
    )
    references = {
        "best_return": torch.tensor([5.0, 0.0, 9.0], dtype=torch.float64),
        "min_steps": torch.tensor([[1, 1, 1], [0, 0, 0], [1, 2, 2]]),
        "exact": True,
    }
    m = yardstick_metrics(utility, u_star, references, gamma=0.5)
    returns = [4.95 + 0.5 * 0.05, 0.0, 1.0 + 0.5 * 1.0 + 0.25 * 6.0]
    assert m["eval/return"] == pytest.approx(sum(returns) / 3)
    assert m["eval/return_ratio"] == pytest.approx(sum(returns) / 14.0)
    assert m["eval/reach_99"] == pytest.approx(2 / 3) and m["eval/reach_optimum"] == pytest.approx(2 / 3)
    assert m["eval/steps_to_99"] == pytest.approx(0.5)  # 1 and 0
    assert m["eval/steps_to_optimum"] == pytest.approx(1.0)  # 2 and 0
    assert m["eval/step_ratio_99"] == pytest.approx(1.0) and m["eval/step_ratio_optimum"] == pytest.approx(
        2.0
    )  # starts needing >= 1 step
    assert m["eval/min_steps_to_optimum"] == pytest.approx(0.5)
    assert m["eval/end_at_optimum"] == pytest.approx(2 / 3) and m["eval/min_steps_exact"] == 1.0


def test_evaluation_uses_bounds_where_exact_does_not_fit():
    cfg = make_config("paper", grid=(10, 10), num_uavs=6)
    m = evaluate(OraclePolicy(cfg), cfg, num_starts=8)
    assert m["eval/min_steps_exact"] == 0.0 and "eval/return_ratio" not in m
    assert m["eval/reach_optimum"] == 1.0 and 1.0 <= m["eval/step_ratio_optimum"] <= 1.2


def test_fading_levels_use_mean_channels():
    cfg = make_config("paper", grid=(6, 6), num_uavs=2, fading="rayleigh")
    m = evaluate(OraclePolicy(cfg), cfg, num_starts=16)
    # faded utilities would almost never equal U*; the configuration's mean-channel utility does
    assert (
        m["eval/reach_optimum"] == 1.0
        and m["eval/end_at_optimum"] == 1.0
        and m["eval/return_ratio"] == pytest.approx(1.0, abs=0.02)
    )


def test_solver_too_large_is_one_clear_line():
    with pytest.raises(ValueError, match=r"needs [\d,]+ bytes .* over its budget"):
        ConfigurationSpace((10, 10), 4)


@pytest.mark.parametrize(
    "gamma,horizon,name",
    [
        (0, None, "eval.gamma=0"),
        (1.5, None, "eval.gamma=1.5"),
        (0.9, 0, "eval.horizon=0"),
        ("x", None, "eval.gamma='x'"),
    ],
)
def test_bad_eval_settings_name_the_setting(gamma, horizon, name):
    with pytest.raises(ValueError, match=f"^{re.escape(name)} is invalid: [^\n]*$"):
        check_eval_settings(gamma, horizon, 64)


def test_bad_eval_setting_on_the_command_line_is_one_line(tmp_path):
    run = subprocess.run(
        [sys.executable, "-m", "uavrl.train", "eval.gamma=0", f"run_dir={tmp_path / 'r'}"],
        capture_output=True,
        text=True,
    )
    assert run.returncode != 0 and "eval.gamma=0 is invalid" in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1 and not (tmp_path / "r").exists()


def test_steps_to_90_under_fading_uses_the_mean_channel_utility():
    faded = torch.tensor([[4.0, 5.0, 12.0, 6.0]])  # a lucky draw crosses 90% of U* = 9 at step 3
    mean = torch.tensor([[4.0, 9.5, 9.5, 9.5]])  # the configuration itself is there from step 2
    zeros = torch.zeros_like(faded)
    u_star = torch.tensor([10.0])
    assert episode_metrics(faded, zeros, zeros, zeros, u_star)["steps_to_90"].item() == 3
    assert episode_metrics(faded, zeros, zeros, zeros, u_star, mean)["steps_to_90"].item() == 2
