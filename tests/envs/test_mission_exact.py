"""The exact mission solver (envs/solvers/mission_exact.py; docs/model.md, The exact mission solver): against
brute-force optimal control written out in tests/envs/test_mission.py (its own dynamics, costs and rates), under the
proved
bound, above what the random policy and the oracle deliver in the shared evaluation, its policy played through the
World, and its refusals."""

from __future__ import annotations

import pytest
import torch
from test_mission import Mission, rotary  # brute force over joint actions, written independently of envs/

from uavrl.agents.baselines import OraclePolicy, RandomPolicy
from uavrl.agents.evaluation import evaluate
from uavrl.envs import make_config
from uavrl.envs.limits import evaluation_horizon
from uavrl.envs.solvers.mission import delivered_bound, optimum_by_count, service_steps_bound
from uavrl.envs.solvers.mission_exact import MissionTooLarge, NotCovered, mission_size, optimal_mission
from uavrl.envs.world import World

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


def reset_world(cfg, num_worlds, seed, batteries=None):
    world = World(cfg, num_worlds, seed=seed)
    world.reset()
    if batteries is not None:  # the follow-up's 5000 would take thousands of steps: a few steps' worth by hand
        world._s.battery = torch.tensor([batteries] * num_worlds, dtype=torch.float64)
    return world


BRUTE_FORCE_CASES = [
    (rotary(grid=(2, 2), num_uavs=1, battery_wh=0.35), None, 10),
    (rotary(grid=(3, 3), num_uavs=1, base=(1, -1), battery_wh=0.45), None, 14),
    (rotary(grid=(2, 2), num_uavs=2, battery_wh=0.3, battery_init="uniform"), None, 9),
    (rotary(grid=(3, 3), num_uavs=2, battery_wh=0.3), None, 9),
    (rotary(grid=(3, 2), num_uavs=2, base=(3, 1), battery_wh=0.3, layout="random"), None, 9),
    (rotary(grid=(3, 3), num_uavs=2, battery_wh=0.3), None, 4),  # a horizon that cuts the mission short
    # the follow-up's units are exact in float64: batteries that tie with a reserve are decided exactly
    (make_config("paper", grid=(2, 2), num_uavs=2, energy="follow_up", base=(-1, 0)), [13.0, 15.5], 12),
    (make_config("paper", grid=(3, 2), num_uavs=2, energy="follow_up", base=(0, 2)), [14.0, 12.5], 12),
]


@pytest.mark.parametrize("case", range(len(BRUTE_FORCE_CASES)))
def test_the_optimum_is_brute_force_optimal_control(case):
    cfg, batteries, horizon = BRUTE_FORCE_CASES[case]
    world = reset_world(cfg, 3, case, batteries)
    best = optimal_mission(world, horizon)
    cells, tasks, start_battery = world._s.cell.tolist(), world._s.task.tolist(), world.battery.tolist()
    for w in range(3):
        serving = tuple(
            (c % cfg.grid[0], c // cfg.grid[0], t, b)
            for c, t, b in zip(cells[w], tasks[w], start_battery[w], strict=True)
        )
        brute, _ = Mission(cfg, world.cell_contributions[w]).best(serving, horizon)
        assert best.value[w].item() == pytest.approx(brute * cfg.slot_s, rel=1e-12, abs=1e-12), w
    assert 0 < best.states and best.states <= mission_size(world, horizon)[0]


@pytest.mark.parametrize("case", range(len(BRUTE_FORCE_CASES)))
def test_the_optimal_policy_played_in_the_world_delivers_the_optimum(case):
    cfg, batteries, horizon = BRUTE_FORCE_CASES[case]
    world = reset_world(cfg, 3, case, batteries)
    best = optimal_mission(world, horizon)
    index, delivered = best.start_index, torch.zeros(3, dtype=torch.float64)
    for step in range(horizon):
        action, index = best.actions(step, index, world._s.cell)
        if step == 0:
            assert torch.equal(action, best.first_action)
        out, _, _ = world.step(action)
        delivered += world.utility(out["positions"], out["tasks"])[2] * cfg.slot_s
        # the World is where the solver's state says: the same cells, whatever the UAVs' order
        assert torch.equal(world._s.cell.sort(-1).values, best._cells[step + 1][index].sort(-1).values)
    torch.testing.assert_close(delivered, best.value, rtol=1e-12, atol=1e-12)


SWEEP = [
    (grid, num_uavs, battery_wh, base, init)
    for grid, base in (((2, 2), (-1, 0)), ((3, 2), (3, 1)), ((3, 3), (1, -1)))
    for num_uavs in (1, 2)
    for battery_wh in (0.3, 0.45)
    for init in ("full", "uniform")
]


@pytest.mark.parametrize(("grid", "num_uavs", "battery_wh", "base", "init"), SWEEP)
def test_the_proved_bound_is_never_below_the_optimum(grid, num_uavs, battery_wh, base, init):
    cfg = rotary(grid=grid, num_uavs=num_uavs, base=base, battery_wh=battery_wh, battery_init=init)
    horizon = evaluation_horizon(cfg)
    world = reset_world(cfg.replace(max_steps=horizon), 4, seed=sum(grid) + num_uavs)
    best = optimal_mission(world, horizon)
    u_by_count = optimum_by_count(world.cell_contributions, world.direct, cfg)
    bound = delivered_bound(service_steps_bound(world.energy, world.battery), u_by_count, horizon, cfg.slot_s)
    assert (best.value > 0).all() and (best.value <= bound + 1e-9).all(), (best.value, bound)


@pytest.mark.parametrize("layout", ["line", "random"])
def test_the_optimum_is_above_random_and_the_oracle_in_the_shared_evaluation(layout):
    cfg = rotary(grid=(3, 3), num_uavs=2, battery_wh=0.4, layout=layout)
    results = {
        "random": evaluate(RandomPolicy(seed=0), cfg, num_starts=6, seed=5),
        "oracle": evaluate(OraclePolicy(cfg), cfg, num_starts=6, seed=5),
    }
    for name, metrics in results.items():
        optimum, delivered = metrics["eval/delivered_optimum"], metrics["eval/delivered_bit_per_hz"]
        assert delivered <= optimum * (1 + 1e-6) and 0 < metrics["eval/delivered_optimality"] <= 1 + 1e-9, name
        assert optimum <= metrics["eval/delivered_bound"] + 1e-9
        assert metrics["eval/delivered_optimality"] == pytest.approx(delivered / optimum, rel=1e-5)
    assert results["random"]["eval/delivered_optimum"] == results["oracle"]["eval/delivered_optimum"]


def test_where_the_solver_does_not_fit_the_evaluation_leaves_its_tags_out():
    for cfg in (
        rotary(grid=(3, 3), num_uavs=3, battery_wh=0.3),  # three UAVs
        rotary(grid=(3, 3), num_uavs=2, battery_wh=0.3, fading="rayleigh"),  # a random channel
        rotary(grid=(3, 3), num_uavs=2, battery_wh=0.3, recharge_steps=2),  # recharging
    ):
        metrics = evaluate(RandomPolicy(seed=0), cfg, num_starts=2, horizon=6)
        assert "eval/delivered_bit_per_hz" in metrics
        assert "eval/delivered_optimum" not in metrics and "eval/delivered_optimality" not in metrics


def test_refusals_come_in_one_line_before_any_work():
    world = reset_world(rotary(grid=(6, 6), num_uavs=2, battery_wh=8.0), 2, 0)
    with pytest.raises(MissionTooLarge, match=r"^the exact mission solver for 2 UAVs on 6x6 over 226 steps needs"):
        optimal_mission(world, 226)
    for cfg, reason in (
        (make_config("paper", grid=(3, 3), num_uavs=2), "needs an energy model"),
        (rotary(num_uavs=3, battery_wh=0.3), "takes 1 or 2 UAVs"),
        (rotary(battery_wh=0.3, fading="rayleigh"), "deterministic channels"),
        (rotary(battery_wh=0.3, recharge_steps=2), "no recharging"),
    ):
        with pytest.raises(NotCovered, match=reason) as caught:
            optimal_mission(reset_world(cfg, 1, 0), 5)
        assert "\n" not in str(caught.value)
    with pytest.raises(ValueError, match="horizon=0 is invalid"):
        optimal_mission(reset_world(rotary(battery_wh=0.3), 1, 0), 0)


def test_a_battery_tying_with_a_reserve_within_rounding_is_refused():
    world = reset_world(rotary(grid=(2, 2), num_uavs=1, battery_wh=0.35), 1, 0)
    cell = world._s.cell[0, 0]
    # after one hover the battery would sit 1e-9 J above the reserve of its cell: float64 rounding could decide it
    world._s.battery[0, 0] = world.energy.reserve[cell] + world.energy.stay + 1e-9
    with pytest.raises(NotCovered, match="from a reserve, within the float64 rounding"):
        optimal_mission(world, 5)
