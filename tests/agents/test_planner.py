"""The energy-aware planner (agent=planner, agents/planner.py): its two rules against independent computations, and
what it delivers beside the energy-unaware oracle."""

import itertools

import pytest
import torch

from uavrl.agents.baselines import OraclePolicy
from uavrl.agents.evaluation import evaluate
from uavrl.agents.planner import PlannerPolicy
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.config import RETURN
from uavrl.envs.physics.energy import Energy

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

ENERGY_6X6 = dict(grid=(6, 6), num_uavs=2, energy="rotary_wing", base=(-1, 0), battery_wh=5.0)  # scenario energy_6x6


def test_the_cycle_is_the_best_neighbouring_configuration_and_pays_per_joule():
    """B is the best configuration one move from A for every UAV (brute force over the grid's coordinates here), and
    the team cycles exactly where (U_A + U_B) / 2 per moving step beats U_A per hovering step."""
    cfg = make_config("paper", **ENERGY_6X6)
    env = UAVSpectrumEnv(batch_size=1, config=cfg)
    env.reset()
    planner = PlannerPolicy(cfg)
    cells, tasks = (t[0] for t in planner._optimal_sets(0, None))
    partners, cycle = planner._partners(0, None, cells, tasks)
    width, height = cfg.grid
    xy = [(c % width, c // width) for c in cells.tolist()]
    steps = [(0, 1), (0, -1), (1, 0), (-1, 0)]
    candidates = []
    for moved in itertools.product(*[[(x + dx, y + dy) for dx, dy in steps] for x, y in xy]):
        on_grid = all(0 <= x < width and 0 <= y < height for x, y in moved)
        if on_grid and len(set(moved)) == len(moved) and not set(moved) & set(xy):
            candidates.append(moved)
    utility = env.world.utility(torch.tensor([candidates]), tasks.expand(1, len(candidates), -1))[2][0]
    u_a = env.world.utility(torch.tensor([[xy]]), tasks[None, None])[2][0, 0]
    best = utility.max()
    chosen = torch.tensor([[(c % width, c // width) for c in partners.tolist()]])
    assert env.world.utility(chosen[None], tasks[None, None])[2][0, 0] == best
    energies = cfg.step_energies
    assert cycle == bool((u_a + best) / 2 / energies.move > u_a / energies.stay)
    assert cycle and best >= 0.99 * u_a  # U_B is 0.997 U*: a move (132.8 J) delivers as much as a hover (175.3 J)


def test_follow_up_never_cycles():
    """Under the follow-up's accounting a move (1.5) costs three hovering steps (0.5): hovering always pays more."""
    cfg = make_config("paper", grid=(6, 6), num_uavs=2, energy="follow_up", base=(-1, 0))
    assert not PlannerPolicy(cfg).cycles(0, None)


def test_without_energy_the_planner_is_the_oracle():
    cfg = make_config("paper", grid=(6, 6), num_uavs=3)
    env = UAVSpectrumEnv(batch_size=4, config=cfg.replace(max_steps=15))
    td = env.rollout(15, OraclePolicy(cfg), tensordict=env.reset(), auto_reset=False)
    planned = PlannerPolicy(cfg)(td.exclude(("agents", "action")).clone())
    assert torch.equal(planned["agents", "action"], td["agents", "action"])


def _handmade(cfg, battery):
    """A tensordict of one world of ``cfg`` at its first optimal configuration, the spare at the base, with the
    batteries ``battery`` (one per UAV of the fleet)."""
    env = UAVSpectrumEnv(batch_size=1, config=cfg)
    td = env.reset().exclude(("agents", "observation"))
    cells, tasks = (t[0] for t in PlannerPolicy(cfg)._optimal_sets(0, None))
    width, fleet = cfg.grid[0], cfg.fleet_size
    td["positions"][0, : cfg.num_uavs] = torch.stack([cells % width, cells // width], -1)
    td["tasks"][0, : cfg.num_uavs] = tasks
    td["state"][0, 5 * fleet : 7 * fleet : 2] = (torch.tensor(battery) / Energy(cfg).capacity).float()
    return td


@pytest.mark.parametrize(
    "steps_left, spare_charged, returns",
    [
        ((20, 21), True, 0),  # d_2 = 21, d_1 = min(20, 21 - 7, 21 - 22) = -1: the UAV with fewer steps leaves now
        ((21, 20), True, 1),
        ((30, 40), True, None),  # d_1 = min(30, 33, 18) = 18: not yet
        ((20, 21), False, None),  # no charged spare: nobody leaves early
    ],
    ids=str,
)
def test_staggered_returns_follow_the_latest_schedule(steps_left, spare_charged, returns):
    """6x6, 2 UAVs, 1 spare, 10 steps to recharge, the base at (-1, 0): a handover takes h = 7 steps (the entry cell
    (0, 0) to the farther cell of A, (3, 3), and a task), a turnaround T = 22 (the flight home from (5, 5), 11 steps,
    the recharge and the entry)."""
    cfg = make_config("paper", **{**ENERGY_6X6, "battery_wh": 3.0}, recharge_steps=10, num_spares=1)
    energy, energies = Energy(cfg), cfg.step_energies
    planner = PlannerPolicy(cfg)
    assert planner.cycles(0, None)
    cells = planner._optimal_sets(0, None)[0][0]
    assert planner._spacing(planner._optimal_sets(0, None)[0]) == (7, 22)
    battery = [
        float(energy.reserve[c]) + (s + 0.5) * energies.move for c, s in zip(cells.tolist(), steps_left, strict=True)
    ]
    battery.append(energy.capacity if spare_charged else energy.capacity / 2)
    td = _handmade(cfg, battery)
    actions = planner(td)["agents", "action"][0]
    leaving = (actions[: cfg.num_uavs] == RETURN).nonzero().flatten().tolist()
    assert leaving == ([] if returns is None else [returns])


def test_the_planner_delivers_more_than_the_oracle_on_a_mission():
    """energy_6x6 from 8 held-out starts: moving between A and B serves longer than hovering on A (BENCHMARKS.md)."""
    cfg = make_config("paper", **ENERGY_6X6)
    oracle = evaluate(OraclePolicy(cfg), cfg, num_starts=8)
    planner = evaluate(PlannerPolicy(cfg), cfg, num_starts=8)
    assert planner["eval/delivered_bit_per_hz"] > 1.2 * oracle["eval/delivered_bit_per_hz"]
    assert planner["eval/first_leave_steps"] > oracle["eval/first_leave_steps"] + 20


def test_staggered_returns_keep_the_team_in_service():
    """A persistent mission (recharging, one spare): the oracle's UAVs, started alike, reach their reserves together
    and the team waits for a recharge; the planner sends one home early, so the spare covers."""
    cfg = make_config("paper", **{**ENERGY_6X6, "battery_wh": 3.0}, recharge_steps=30, num_spares=1)
    oracle = evaluate(OraclePolicy(cfg), cfg, num_starts=8, horizon=300)
    planner = evaluate(PlannerPolicy(cfg), cfg, num_starts=8, horizon=300)
    assert planner["eval/first_leave_steps"] < oracle["eval/first_leave_steps"]
    assert planner["eval/delivered_bit_per_hz"] > 1.1 * oracle["eval/delivered_bit_per_hz"]
