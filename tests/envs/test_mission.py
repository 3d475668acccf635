"""The mission under an energy model (docs/model.md, What the numbers mean): the evaluation's mission metrics against
a computation written here over a rollout, the upper bound on delivered data against brute-force optimal control
(dynamic programming over configurations and batteries, with dynamics, costs and rates written out here), the
mission's horizon, and the joint-action mask of UAVs out of service."""

from __future__ import annotations

import functools
import itertools
import math

import pytest
import torch

from uavrl.envs import make_config
from uavrl.envs.limits import evaluation_horizon, mission_steps
from uavrl.envs.solvers.mission import delivered_bound, optimum_by_count, service_steps_bound
from uavrl.envs.world import World

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

MOVES = {0: (0, -1), 1: (0, 1), 2: (-1, 0), 3: (1, 0)}  # up, down, left, right
SENSE, RELAY = 4, 5
MISSION_KEYS = (
    "eval/delivered_bit_per_hz",
    "eval/delivered_bound",
    "eval/delivered_horizon_bound",
    "eval/delivered_ratio",
    "eval/first_leave_steps",
    "eval/service_lost_steps",
    "eval/service_steps_per_uav",
    "eval/energy_per_bit",
    "eval/horizon",
)


def rotary(grid=(3, 3), num_uavs=2, base=(-1, 0), **options):
    return make_config("paper", grid=grid, num_uavs=num_uavs, energy="rotary_wing", base=base, **options)


class Mission:
    """The model of docs/model.md for a few UAVs, written out independently of envs/: moves, clashes (N <= 2), the
    step's energy, the reserve, leaving service and the rates with the lease rule (no direct links)."""

    def __init__(self, cfg, contributions):
        self.cfg, e = cfg, cfg.step_energies
        self.L1, self.L2 = cfg.grid
        self.stay, self.move, self.fly, self.arrive = e.stay, e.move, e.fly, e.arrive
        self.by_action = cfg.energy == "follow_up"
        self.contributions = contributions.tolist()  # [C][2]: relaying adds [0] to PU, sensing [1] to SE

    def flight(self, x, y):
        steps = abs(x - self.cfg.base[0]) + abs(y - self.cfg.base[1])
        return steps * self.fly + (self.arrive if steps else 0.0)

    def reserve(self, x, y):
        around = [(x, y)] + [(x + dx, y + dy) for dx, dy in MOVES.values() if self.on_grid(x + dx, y + dy)]
        return max(self.stay + self.flight(x, y), self.move + max(self.flight(*c) for c in around))

    def on_grid(self, x, y):
        return 0 <= x < self.L1 and 0 <= y < self.L2

    def utility(self, serving):
        """U of the serving UAVs ``(x, y, task, battery)``."""
        pu = sum(self.contributions[y * self.L1 + x][0] for x, y, task, _ in serving if task == 1)
        se = sum(self.contributions[y * self.L1 + x][1] for x, y, task, _ in serving if task == 0)
        relays = any(task == 1 for _, _, task, _ in serving)
        return 0.5 * math.log2(1 + pu) + (0.5 * math.log2(1 + se) if relays else 0.0)

    def actions(self, uav):
        x, y = uav[:2]
        return [a for a in range(6) if a >= SENSE or self.on_grid(x + MOVES[a][0], y + MOVES[a][1])]

    def step(self, serving, joint):
        """The serving UAVs after the joint action (one per serving UAV): those who left are dropped."""
        targets = [
            (x + MOVES[a][0], y + MOVES[a][1]) if a < SENSE else (x, y)
            for (x, y, _, _), a in zip(serving, joint, strict=True)
        ]
        clash = len(targets) == 2 and targets[0] == targets[1]
        after = []
        for (x, y, task, battery), a, target in zip(serving, joint, targets, strict=True):
            cell = (x, y) if clash else target
            moved = a < SENSE if self.by_action else cell != (x, y)
            left = battery - (self.move if moved else self.stay)
            if left > self.reserve(*cell):
                after.append((*cell, {SENSE: 0, RELAY: 1}.get(a, task), left))
        return tuple(after)

    def best(self, serving, steps_left):
        """The most ``sum_t U_t`` over the next ``steps_left`` steps from the serving UAVs: every joint action."""

        @functools.lru_cache(maxsize=None)
        def value(serving, left):
            if left == 0 or not serving:
                return 0.0, ()
            best = (-1.0, ())
            for joint in itertools.product(*(self.actions(u) for u in serving)):
                after = self.step(serving, joint)
                rest, plan = value(after, left - 1)
                best = max(best, (self.utility(after) + rest, (joint, *plan)))
            return best

        return value(serving, steps_left)


def brute_force_cases():
    yield rotary(grid=(2, 2), num_uavs=1, battery_wh=0.35), None
    yield rotary(grid=(2, 2), num_uavs=2, battery_wh=0.3, battery_init="uniform"), None
    yield rotary(grid=(3, 3), num_uavs=1, base=(1, -1), battery_wh=0.45), None
    yield rotary(grid=(3, 2), num_uavs=2, base=(3, 1), battery_wh=0.3, layout="random"), None
    yield make_config("paper", grid=(2, 2), num_uavs=2, energy="follow_up", base=(-1, 0)), [13.0, 15.5]
    yield make_config("paper", grid=(3, 2), num_uavs=2, energy="follow_up", base=(0, 2)), [14.0, 12.5]


@pytest.mark.parametrize("case", range(6))
def test_the_bound_is_never_below_brute_force_optimal_control(case):
    cfg, batteries = list(brute_force_cases())[case]
    world = World(cfg, 3, seed=case)
    world.reset()
    if batteries is not None:  # the follow-up's 5000 would take thousands of steps: a few steps' worth by hand
        world._s.battery = torch.tensor([batteries] * 3, dtype=torch.float64)
    horizon = 12 if batteries is not None else evaluation_horizon(cfg)
    u_by_count = optimum_by_count(world.cell_contributions, world.direct, cfg)
    bound = delivered_bound(service_steps_bound(world.energy, world.battery), u_by_count, horizon, cfg.slot_s)
    cells, tasks, start_battery = world._s.cell.tolist(), world._s.task.tolist(), world.battery.tolist()
    for w in range(3):
        mission = Mission(cfg, world.cell_contributions[w])
        serving = tuple(
            (c % cfg.grid[0], c // cfg.grid[0], t, b)
            for c, t, b in zip(cells[w], tasks[w], start_battery[w], strict=True)
        )
        optimum, plan = mission.best(serving, horizon)
        assert optimum * cfg.slot_s <= bound[w].item() + 1e-9, (w, optimum, bound[w].item())
        assert bound[w] <= u_by_count[w, -1] * horizon * cfg.slot_s + 1e-9
        # the plan played by the World delivers what the model written here says: the two agree
        again = World(cfg, 3, seed=case)
        again.reset()
        again._s.battery = torch.tensor(start_battery, dtype=torch.float64)
        delivered, still = 0.0, list(range(cfg.num_uavs))
        for joint in plan:
            action = torch.full((3, cfg.num_uavs), SENSE)
            action[w, still] = torch.tensor(joint)
            out, _, _ = again.step(action)
            delivered += out["utility"][w].item()
            still = [i for i in still if again._s.status[w, i].item() == 0]
        assert delivered == pytest.approx(optimum, rel=1e-5) and optimum > 0


def test_u_star_by_count_is_the_optimum_of_k_uavs_and_grows():
    cfg = rotary(grid=(3, 3), num_uavs=3)
    world = World(cfg, 2)
    world.reset()
    u = optimum_by_count(world.cell_contributions, world.direct, cfg)
    mission = Mission(cfg, world.cell_contributions[0])
    for k in range(0, 4):
        best = max(
            mission.utility([(c % 3, c // 3, t, 0.0) for c, t in zip(cells, tasks, strict=True)])
            for cells in itertools.combinations(range(9), k)
            for tasks in itertools.product((0, 1), repeat=k)
        )
        assert u[0, k].item() == pytest.approx(best, rel=1e-12)
    assert (u.diff(dim=-1) >= 0).all()


def test_the_mission_horizon_sees_every_uav_home():
    for cfg in (rotary(battery_wh=0.5), rotary(grid=(4, 3), base=(5, 1), battery_wh=0.8, battery_init="uniform")):
        horizon = mission_steps(cfg)
        assert evaluation_horizon(cfg) == horizon and evaluation_horizon(make_config("paper")) == 24
        world = World(cfg, 16, seed=2)
        out = world.reset()
        bound = service_steps_bound(world.energy, world.battery)
        gen = torch.Generator().manual_seed(0)
        serving_steps = torch.zeros(16, 2, dtype=torch.long)
        for _ in range(horizon):
            action = torch.multinomial(out["action_mask"].view(-1, 6).float(), 1, generator=gen).view(16, 2)
            out, _, _ = world.step(action)
            serving_steps += world._s.status == 0
        assert (world._s.status == 2).all()  # every UAV is home
        assert (serving_steps <= bound).all()


def independent_mission_metrics(cfg, policy, num_starts, seed):
    """The mission's metrics over a rollout stepped here: rates, service and batteries read after every step."""
    from torchrl.envs.utils import step_mdp

    from uavrl.envs import UAVSpectrumEnv

    horizon = mission_steps(cfg)
    env = UAVSpectrumEnv(batch_size=num_starts, config=cfg.replace(max_steps=horizon), seed=seed)
    td = env.reset()
    world = env.world
    start_battery = world._s.battery.clone()
    cheapest = min(cfg.step_energies.move, cfg.step_energies.stay)
    mission = Mission(cfg, world.cell_contributions[0])
    least_reserve = min(mission.reserve(x, y) for x in range(cfg.grid[0]) for y in range(cfg.grid[1]))
    u_by_count = []
    for k in range(cfg.num_uavs + 1):
        u_by_count.append(
            max(
                mission.utility(
                    [(c % cfg.grid[0], c // cfg.grid[0], t, 0.0) for c, t in zip(cells, tasks, strict=True)]
                )
                for cells in itertools.combinations(range(cfg.num_cells), k)
                for tasks in itertools.product((0, 1), repeat=k)
            )
        )
    delivered = [0.0] * num_starts
    first_leave, lost = [horizon] * num_starts, [horizon] * num_starts
    in_service = [[0] * cfg.num_uavs for _ in range(num_starts)]
    for t in range(1, horizon + 1):
        td = env.step(policy(td))
        rates = (td["next", "r_pu"] + td["next", "r_se"]).view(-1).tolist()
        status = world._s.status.tolist()
        for w in range(num_starts):
            delivered[w] += rates[w] * cfg.slot_s
            serving = [s == 0 for s in status[w]]
            if not all(serving):
                first_leave[w] = min(first_leave[w], t)
            if not any(serving):
                lost[w] = min(lost[w], t)
            for i, s in enumerate(serving):
                in_service[w][i] += s
        td = step_mdp(td, keep_other=True, exclude_action=False)
    spent = (start_battery - world._s.battery).sum().item()
    bounds = []
    for w in range(num_starts):
        can = [math.floor((b - least_reserve) / cheapest) for b in start_battery[w].tolist()]
        bounds.append(sum(u_by_count[sum(c >= t for c in can)] for t in range(1, horizon + 1)) * cfg.slot_s)
    return {
        "eval/horizon": horizon,
        "eval/delivered_bit_per_hz": sum(delivered) / num_starts,
        "eval/delivered_bound": sum(bounds) / num_starts,
        "eval/delivered_horizon_bound": u_by_count[-1] * horizon * cfg.slot_s,
        "eval/delivered_ratio": sum(delivered) / sum(bounds),
        "eval/first_leave_steps": sum(first_leave) / num_starts,
        "eval/service_lost_steps": sum(lost) / num_starts,
        "eval/service_steps_per_uav": sum(map(sum, in_service)) / (num_starts * cfg.num_uavs),
        "eval/energy_per_bit": spent / sum(delivered),
    }


def test_the_mission_metrics_against_a_rollout_computed_here():
    from uavrl.agents.baselines import RandomPolicy
    from uavrl.agents.evaluation import evaluate

    cfg = rotary(battery_wh=0.6, battery_init="uniform")
    metrics = evaluate(RandomPolicy(seed=4), cfg, num_starts=6, seed=9)
    expected = independent_mission_metrics(cfg, RandomPolicy(seed=4), 6, 9)
    for key, value in expected.items():
        assert metrics[key] == pytest.approx(value, rel=1e-6), key
    assert "eval/return" not in metrics and "eval/return_ratio" not in metrics
    assert metrics["eval/delivered_ratio"] <= 1


@pytest.mark.parametrize("agent", ["random", "oracle"])
def test_baselines_under_rotary_wing_report_every_mission_metric(agent):
    from uavrl.agents.baselines import OraclePolicy, RandomPolicy
    from uavrl.agents.evaluation import evaluate

    cfg = make_config(
        "a2g_urban", grid=(4, 4), num_uavs=2, energy="rotary_wing", base=(-1, 0), battery_wh=8.0, fading="rayleigh"
    )
    policy = RandomPolicy(seed=0) if agent == "random" else OraclePolicy(cfg)
    metrics = evaluate(policy, cfg, num_starts=8)
    for key in (*MISSION_KEYS, "eval/delivered_bits", "eval/optimality", "eval/reach_999"):
        assert math.isfinite(metrics[key]), key
    assert "eval/return" not in metrics and "eval/return_ratio" not in metrics
    assert 0 < metrics["eval/delivered_ratio"] <= 1
    assert metrics["eval/delivered_bound"] <= metrics["eval/delivered_horizon_bound"]
    assert metrics["eval/first_leave_steps"] <= metrics["eval/service_lost_steps"] <= metrics["eval/horizon"]
    assert metrics["eval/delivered_bits"] == pytest.approx(metrics["eval/delivered_bit_per_hz"] * cfg.bandwidth_hz)
    if agent == "oracle":  # the full team reaches U* before anyone leaves, and is measured there
        assert metrics["eval/optimality"] == 1.0 and metrics["eval/reach_optimum"] == 1.0


def test_without_energy_the_evaluation_has_no_mission_metric():
    from uavrl.agents.baselines import RandomPolicy
    from uavrl.agents.evaluation import evaluate

    metrics = evaluate(RandomPolicy(seed=0), make_config("paper", grid=(3, 3), num_uavs=2), num_starts=4)
    assert not set(MISSION_KEYS) & set(metrics) and "eval/return" in metrics and "eval/return_ratio" in metrics


def test_a_mission_horizon_over_the_memory_budget_is_refused_in_one_line():
    from uavrl.agents.baselines import RandomPolicy
    from uavrl.agents.evaluation import evaluate

    cfg = make_config("paper", grid=(6, 6), num_uavs=2, energy="follow_up", base=(-1, 0))  # 10,000 steps of 0.5
    with pytest.raises(ValueError) as error:
        evaluate(RandomPolicy(seed=0), cfg, num_starts=64, memory_budget=10**8)
    assert str(error.value).startswith(f"horizon={mission_steps(cfg)} is invalid") and "\n" not in str(error.value)


def test_the_joint_action_mask_of_uavs_out_of_service():
    cfg = rotary(battery_wh=0.4)
    world = World(cfg, 2)
    world.reset()
    valid = world.joint_action_mask()
    plain = World(make_config("paper", grid=(3, 3), num_uavs=2), 2)
    plain.start_at(world._s.cell * 2 + world._s.task)
    assert valid.equal(plain.joint_action_mask())  # all serving: the masks without energy
    # one UAV out: its only action is the no-op, and the other's actions are the single UAV's
    world.start_at(torch.tensor([[0, 2 * 4], [2 * 8 + 1, 2 * 4]]))
    world._s.battery = torch.tensor([[1.0, 1e9], [1e9, 1.0]], dtype=torch.float64)
    out, _, _ = world.step(torch.tensor([[SENSE, SENSE], [SENSE, SENSE]]))
    assert world._s.status.tolist() == [[1, 0], [0, 1]]
    valid = world.joint_action_mask().view(2, 6, 6)  # [world, action of UAV 1, action of UAV 0]
    assert valid.equal(world.joint_action_mask(out["positions"]).view(2, 6, 6))
    masks = out["action_mask"]
    for w, (away, serving) in enumerate([(0, 1), (1, 0)]):
        allowed = valid[w].transpose(0, 1) if away == 0 else valid[w]  # [action of the one away, of the other]
        assert allowed[SENSE].equal(masks[w, serving]) and not allowed[[0, 1, 2, 3, 5]].any()
    assert masks[0, 1].tolist() == [True] * 6  # (1, 1), the centre: UAV 0 away blocks none of its moves


def test_the_environments_joint_action_mask_once_every_uav_is_out():
    from tensordict import TensorDict

    from uavrl.envs import UAVSpectrumEnv

    env = UAVSpectrumEnv(batch_size=2, config=rotary(battery_wh=0.3))
    env.reset()
    for _ in range(8):
        env.step(TensorDict({("agents", "action"): torch.full((2, 2), SENSE)}, batch_size=[2]))
    assert (env.world._s.status != 0).all()
    valid = env.joint_action_mask()
    assert valid.shape == (2, 36) and valid.sum(-1).tolist() == [1, 1] and valid[:, SENSE + 6 * SENSE].all()


def test_the_delivered_reward_is_each_steps_data_over_the_best_step():
    """reward=delivered: ``(R_PU + R_SE) / U*`` of each step, U* by brute force over every configuration here."""
    from uavrl.envs import UAVSpectrumEnv

    cfg = make_config(
        "paper", grid=(3, 3), num_uavs=2, energy="rotary_wing", base=(-1, 0), battery_wh=0.5, reward="delivered"
    )
    env = UAVSpectrumEnv(batch_size=3, config=cfg.replace(max_steps=12), seed=5)
    td = env.rollout(12, break_when_any_done=False)
    cells = [(x, y) for y in range(3) for x in range(3)]
    pairs = [(a, b) for a, b in itertools.product(cells, cells) if a != b]
    tasks = list(itertools.product((0, 1), repeat=2))
    positions = torch.tensor([[p for p in pairs for _ in tasks]] * 3)
    all_tasks = torch.tensor([[t for _ in pairs for t in tasks]] * 3)
    u_star = env.world.utility(positions, all_tasks)[2].max(-1).values  # [3]
    delivered = (td["next", "r_pu"] + td["next", "r_se"]).squeeze(-1).double() / u_star[:, None]
    assert torch.allclose(td["next", "reward"].squeeze(-1).double(), delivered, rtol=1e-6)


@pytest.mark.parametrize(
    "energy", ["energy=follow_up", "energy=rotary_wing", "energy=rotary_wing recharge_steps=3 num_spares=1"]
)
def test_the_dqn_trains_on_the_delivered_reward_under_every_energy_model(energy, compose_cfg):
    from uavrl.agents import agent_class
    from uavrl.config import model_config

    cfg = compose_cfg(
        *("agent=dqn", "agent.iterations=2", "env.max_steps=20", "agent.worlds=4", "agent.hidden=16"),
        *("agent.batch_size=16", "agent.buffer_size=64", "agent.updates=2", "agent.learning_starts=8"),
        *("env.grid=[3,3]", "env.base=[-1,0]", "env.reward=delivered", "agent.objective=delta", "agent.gamma=0.99"),
        *(f"env.{option}" for option in energy.split()),
        *(["env.battery_wh=0.5"] if "rotary_wing" in energy else []),
    )
    agent = agent_class("dqn")(model_config(cfg), cfg, torch.device("cpu"), 0)
    metrics = [agent.train_iteration() for _ in range(agent.num_iterations)]
    assert all(math.isfinite(value) for m in metrics for value in m.values())
    assert metrics[-1]["train/sum_utility"] > 0
