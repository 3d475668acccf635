"""Recharging, the ``return`` action and spares (docs/model.md, Energy and lifetime): a hand-built 3x3 case of two
UAVs and a spare through leave, fly home, charge, wait and re-enter, the entry rule, the action count and masks, the
refusals, the persistent mission, and the agents and adapters over a fleet with spares."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import torch

from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.world import World

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

BASE = (-1, 0)  # left of cell (0, 0): the entry cell is 0
UP, DOWN, LEFT, RIGHT, SENSE, RELAY, RETURN = range(7)
SERVING, RETURNING, OUT, CHARGING, WAITING = range(5)
# the follow-up's accounting (docs/model.md, Energy and lifetime), written out here: 0.5 a serving step for
# transmission, 1.0 more for a move, nothing on the way home and 10 on reaching the base
STAY, MOVE, ARRIVE = 0.5, 1.5, 10.0
RESERVE = max(STAY, MOVE) + ARRIVE  # every cell of the grid: its worst next step, then the flight home
AWAY = 2 * 9  # the code of a UAV at the base on 3x3 (cell C = 9, sensing)


def fleet(**options):
    return make_config(
        "paper", **{"grid": (3, 3), "num_uavs": 2, "energy": "follow_up", "base": BASE, "recharge_steps": 2, **options}
    )


def step(world, *actions):
    out, _, truncated = world.step(torch.tensor([actions]))
    assert not truncated.item() and not world.terminated.item()  # with recharging a mission never terminates
    return out


def state(world):
    s = world._s
    return s.status[0].tolist(), s.timer[0].tolist(), s.cell[0].tolist()


def test_leave_fly_home_charge_wait_and_reenter_while_a_spare_serves(hand_built):
    cfg = fleet(num_spares=1)
    # UAV 0 sensing at (1, 0), 2 steps from the base, one stay above its reserve; UAV 1 relaying at (1, 1); the spare
    world = hand_built(cfg, [2 * 1, 2 * 4 + 1, AWAY], [RESERVE + STAY, 5000.0, 5000.0])
    assert state(world) == ([SERVING, SERVING, WAITING], [0, 0, 0], [1, 4, 9])

    out = step(world, SENSE, RELAY, SENSE)  # UAV 0 reaches its reserve and leaves; the spare enters at once
    assert state(world) == ([RETURNING, SERVING, SERVING], [2, 0, 0], [9, 4, 0])
    assert out["positions"][0].tolist() == [list(BASE), [1, 1], [0, 0]] and out["tasks"][0].tolist() == [0, 1, 0]
    assert out["action_mask"][0, 0].tolist() == [False] * 4 + [True, False, False]  # away: only the no-op
    assert out["action_mask"][0, 2].tolist() == [False, True, False, True, True, True, True]  # (0, 0), return too
    # the rates are those of UAV 1 relaying at (1, 1) and the spare sensing at (0, 0), as without UAV 0
    two = World(make_config("paper", grid=(3, 3), num_uavs=2), 1).start_at(torch.tensor([[2 * 4 + 1, 0]]))
    assert out["utility"].item() == two["utility"].item()

    step(world, SENSE, RELAY, SENSE)
    assert state(world) == ([RETURNING, SERVING, SERVING], [1, 0, 0], [9, 4, 0])
    step(world, SENSE, RELAY, SENSE)  # home: 10 paid on arrival, then 2 steps of charging
    assert state(world) == ([CHARGING, SERVING, SERVING], [2, 0, 0], [9, 4, 0])
    assert world._s.battery[0, 0].item() == RESERVE - ARRIVE
    step(world, SENSE, RELAY, SENSE)
    assert state(world) == ([CHARGING, SERVING, SERVING], [1, 0, 0], [9, 4, 0])
    step(world, SENSE, RELAY, SENSE)  # charged; two serve, so it waits
    assert state(world) == ([WAITING, SERVING, SERVING], [0, 0, 0], [9, 4, 0])
    assert world._s.battery[0].tolist() == [5000.0, 5000.0 - 5 * STAY, 5000.0 - 4 * STAY]
    out = step(world, SENSE, RELAY, RETURN)  # the controller sends the spare home: UAV 0 takes its place
    assert state(world) == ([SERVING, SERVING, RETURNING], [0, 0, 1], [0, 4, 9])
    assert out["positions"][0].tolist() == [[0, 0], [1, 1], list(BASE)]
    assert world._s.battery[0, 2].item() == 5000.0 - 5 * STAY  # "return" costs a serving step
    step(world, SENSE, RELAY, SENSE)
    assert state(world) == ([SERVING, SERVING, CHARGING], [0, 0, 2], [0, 4, 9])
    assert world._s.battery[0, 2].item() == 5000.0 - 5 * STAY - ARRIVE


def test_a_held_entry_cell_makes_the_charged_uav_wait_a_step(hand_built):
    cfg = fleet(num_spares=1)
    world = hand_built(cfg, [2 * 4, 0, AWAY], [5000.0, 5000.0, 5000.0])  # UAV 1 holds the entry cell (0, 0)
    step(world, RETURN, SENSE, SENSE)
    assert state(world) == ([RETURNING, SERVING, WAITING], [3, 0, 0], [9, 0, 9])  # (1, 1) is 3 steps home
    step(world, SENSE, RIGHT, SENSE)  # the entry cell is free after the step's moves: the spare enters
    assert state(world) == ([RETURNING, SERVING, SERVING], [2, 0, 0], [9, 1, 0])


def test_without_spares_a_charged_uav_reenters_and_no_more_than_n_serve(hand_built):
    cfg = fleet(recharge_steps=1)
    world = hand_built(cfg, [0, 2 * 8], [5000.0, 5000.0])
    step(world, RETURN, SENSE)
    step(world, SENSE, SENSE)
    assert state(world) == ([CHARGING, SERVING], [1, 0], [9, 8])
    step(world, SENSE, SENSE)  # charged and straight back in at the free entry cell, sensing
    assert state(world) == ([SERVING, SERVING], [0, 0], [0, 8]) and world._s.task[0].tolist() == [0, 0]


def test_a_fleet_with_spares_keeps_at_most_n_in_service_and_never_terminates():
    from uavrl.agents.baselines import RandomPolicy

    env = UAVSpectrumEnv(
        batch_size=4,
        grid=(3, 3),
        num_uavs=2,
        max_steps=60,
        energy="rotary_wing",
        base=BASE,
        battery_wh=0.3,
        recharge_steps=3,
        num_spares=2,
        seed=2,
    )
    assert env.n_agents == 4 and env.action_spec["agents", "action"].n == 7
    rollout = env.rollout(60, RandomPolicy(seed=1), break_when_any_done=False)
    positions = rollout["next", "positions"]
    on_grid = (positions >= 0).all(-1) & (positions[..., 0] < 3) & (positions[..., 1] < 3)
    serving = on_grid.sum(-1)  # [B, T]: UAVs on the grid after each step
    assert serving.max() == 2 and (serving[:, 0] == 2).all()  # N in service at most, all N at first
    assert (on_grid.any(1).sum(-1) > 2).any()  # a spare served: more UAVs than N were on the grid in a world
    assert not rollout["next", "terminated"].any() and rollout["next", "truncated"][:, -1].all()
    assert (on_grid[:, 0] != on_grid[:, -1]).any()  # UAVs left service and others took their places
    masks = rollout["next", "agents", "action_mask"]
    assert torch.equal(masks[..., 6], on_grid) and torch.equal(masks[..., 4], torch.ones_like(on_grid))


def test_the_same_seed_gives_the_same_mission():
    from uavrl.agents.baselines import RandomPolicy

    def mission(seed: int):
        env = UAVSpectrumEnv(
            batch_size=3,
            **dict(grid=(3, 3), num_uavs=2, max_steps=40, energy="rotary_wing", base=BASE, battery_wh=0.3),
            **dict(battery_init="uniform", recharge_steps=2, num_spares=1, seed=seed),
        )
        return env.rollout(40, RandomPolicy(seed=seed), break_when_any_done=False)

    first, again, other = mission(5), mission(5), mission(6)
    assert (first == again).all()
    assert not torch.equal(first["next", "positions"], other["next", "positions"])


def test_the_action_count_follows_the_model(tiny_env):
    assert make_config("paper").num_actions == 6 and fleet().num_actions == 7
    plain = tiny_env(energy="follow_up", base=BASE)
    assert plain.action_spec["agents", "action"].n == 6 and plain.reset()["agents", "action_mask"].shape[-1] == 6
    env = tiny_env(energy="follow_up", base=BASE, recharge_steps=2, num_spares=1)
    td = env.reset()
    assert td["agents", "action_mask"].shape == (2, 3, 7) and td["agents", "observation"].shape[-2] == 3
    assert td["agents", "action_mask"][:, :2, 6].all() and not td["agents", "action_mask"][:, 2, 6].any()
    assert td["state"].shape[-1] == 7 * 3 + 12


@pytest.mark.parametrize(
    ("options", "action", "message"),
    [
        (dict(energy="follow_up", base=BASE), 6, "holds 6: actions are 0..5 (up, down, left, right, sense, relay)"),
        (dict(recharge_steps=2), 7, "holds 7: actions are 0..6 (up, down, left, right, sense, relay, return)"),
        (dict(recharge_steps=2, num_spares=1), 6, "sends UAV 2 of world 0 home (6, return), but it does not serve"),
    ],
)
def test_return_where_it_is_not_valid_is_refused_in_one_line(tiny_env, options, action, message):
    env = tiny_env(**({"energy": "follow_up", "base": BASE} | options))
    td = env.reset()
    sent = torch.full((2, env.n_agents), SENSE)
    sent[0, -1] = action
    with pytest.raises(ValueError) as error:
        env.step(td.set(("agents", "action"), sent))
    assert message in str(error.value) and "\n" not in str(error.value)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (dict(recharge_steps=2, energy="none", base=None), "recharge_steps=2 is invalid: only an energy model"),
        (dict(num_spares=1, recharge_steps=None, energy="none", base=None), "num_spares=1 is invalid: only an"),
        (dict(recharge_steps=0), "recharge_steps=0 is invalid: give the whole number of steps >= 1"),
        (dict(recharge_steps=1.5), "recharge_steps=1.5 is invalid"),
        (dict(num_spares=-1), "num_spares=-1 is invalid: give the whole number >= 0"),
        (dict(recharge_steps=None, num_spares=1), "num_spares=1 is invalid: a spare enters when a UAV leaves"),
    ],
)
def test_bad_recharge_settings_are_refused_in_one_line(options, message):
    with pytest.raises(ValueError) as error:
        fleet(**options)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_the_dqn_acts_validly_over_a_fleet_with_spares(compose_cfg):
    from uavrl.agents import agent_class
    from uavrl.config import model_config

    cfg = compose_cfg(
        *("agent=dqn", "agent.iterations=2", "env.max_steps=12", "agent.worlds=4", "agent.hidden=16"),
        *("agent.batch_size=16", "agent.buffer_size=64", "agent.updates=2", "agent.learning_starts=8"),
        *("env.grid=[3,3]", "env.energy=rotary_wing", "env.base=[-1,0]", "env.battery_wh=0.3"),
        *("env.recharge_steps=2", "env.num_spares=1"),
    )
    env_cfg = model_config(cfg)
    agent = agent_class("dqn")(env_cfg, cfg, torch.device("cpu"), 0)
    metrics = [agent.train_iteration() for _ in range(agent.num_iterations)]
    assert all(torch.isfinite(torch.tensor(list(m.values()), dtype=torch.float64)).all() for m in metrics)
    env = UAVSpectrumEnv(config=env_cfg, batch_size=4, seed=1)
    policy = agent.policies()[0].bind_env(env)
    rollout = env.rollout(12, policy, break_when_any_done=False)  # env.step refuses an invalid "return"
    values = policy.policy[0](rollout[:, 0].clone())["agents", "action_value"]  # Q, then ValidGreedy
    assert values.shape == (4, 3, 7)
    actions, masks = rollout["agents", "action"], rollout["agents", "action_mask"]
    assert masks.gather(-1, actions.unsqueeze(-1)).all()


@pytest.mark.parametrize("spares", [0, 1])
@pytest.mark.parametrize("agent", ["dqn", "random", "oracle"])
def test_the_command_line_trains_and_evaluates_with_recharging(tmp_path, agent, spares):
    settings = (
        "env.energy=rotary_wing env.base=[-1,0] env.grid=[3,3] env.battery_wh=0.3 env.recharge_steps=2 "
        f"env.num_spares={spares} env.max_steps=20 eval.num_starts=4"
    )
    if agent == "dqn":
        settings += (
            " agent.iterations=3 agent.worlds=8 agent.hidden=16 agent.depth=1 agent.batch_size=32 "
            "agent.buffer_size=100 agent.updates=2 agent.learning_starts=16"
        )
    result = subprocess.run(
        [sys.executable, "-m", "uavrl.train", f"agent={agent}", *settings.split(), "progress=false"]
        + [f"run_dir={tmp_path}"],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert "optimality" in result.stdout
    metrics = json.loads(next(tmp_path.rglob("metrics.json")).read_text())
    # the spares wait at the base from the start: a UAV leaving service is one that served
    assert 1 < metrics["eval/first_leave_steps"] <= metrics["eval/horizon"]
    assert 0 < metrics["eval/delivered_ratio"] <= 1


def test_the_oracle_plans_for_the_uavs_in_service_and_never_returns():
    from uavrl.agents.baselines import OraclePolicy

    env = UAVSpectrumEnv(
        batch_size=3,
        **dict(grid=(3, 3), num_uavs=2, max_steps=40, energy="rotary_wing", base=BASE, battery_wh=1.0),
        **dict(recharge_steps=2, num_spares=1, seed=4),
    )
    oracle = OraclePolicy(env.cfg, env)
    rollout = env.rollout(40, oracle, break_when_any_done=False)
    actions, masks = rollout["agents", "action"], rollout["agents", "action_mask"]
    assert masks.gather(-1, actions.unsqueeze(-1)).all() and not (actions == RETURN).any()
    utility, u_star = rollout["next", "utility"], env.world.optimum()[0].float()
    assert (utility.squeeze(-1).amax(-1) >= 0.999 * u_star).all()  # two in service reach U* between departures
    at_base = (rollout["next", "positions"] == torch.tensor(BASE)).all(-1)
    assert at_base[..., :2].any() and not at_base[..., 2].all()  # UAVs left, and the spare served


@pytest.mark.gym  # .ci/leg-gym runs it (-m gym), where a skip fails
def test_the_adapters_have_the_fleet_and_seven_actions():
    pytest.importorskip("gymnasium")
    pytest.importorskip("pettingzoo")
    from uavrl.envs.adapters.gym_env import UAVSpectrumGymEnv, UAVSpectrumVectorEnv
    from uavrl.envs.adapters.pettingzoo_env import UAVSpectrumParallelEnv

    options = dict(grid=(3, 3), num_uavs=2, energy="follow_up", base=BASE, recharge_steps=2, num_spares=1)
    gym_env = UAVSpectrumGymEnv(**options)
    assert gym_env.action_space.nvec.tolist() == [7, 7, 7]
    observation, info = gym_env.reset(seed=0)
    assert observation.shape[0] == 3 and info["action_mask"].shape == (3, 7)
    gym_env.step([RETURN, SENSE, SENSE])
    with pytest.raises(ValueError, match=r"holds 7: actions are 0\.\.6 \(up, .*, return\)"):
        gym_env.step([7, SENSE, SENSE])
    vector = UAVSpectrumVectorEnv(num_envs=2, **options)
    assert vector.single_action_space.nvec.tolist() == [7, 7, 7]
    parallel = UAVSpectrumParallelEnv(**options)
    parallel.reset(seed=0)
    assert parallel.possible_agents == ["uav_0", "uav_1", "uav_2"] and parallel.action_space("uav_2").n == 7
    assert parallel.observation_space("uav_0")["action_mask"].shape == (7,)


def test_waiting_and_charging_uavs_render_at_the_base(hand_built):
    from uavrl.envs.render import WorldRenderer

    world = hand_built(fleet(num_spares=1), [2 * 1, 2 * 4 + 1, AWAY], [RESERVE + STAY, 5000.0, 5000.0])
    renderer = WorldRenderer(world)
    waiting = renderer.frame(0)
    for _ in range(3):
        step(world, SENSE, RELAY, SENSE)
    assert world._s.status[0, 0].item() == CHARGING
    charging = renderer.frame(0)
    assert waiting.shape == charging.shape and waiting.dtype == charging.dtype and (waiting != charging).any()
    assert renderer._uavs.get_offsets().tolist()[0] == list(BASE)


def test_the_greedy_rule_keeps_a_returning_uavs_cell_for_the_step():
    from uavrl.agents.dqn import ValidGreedy

    greedy = ValidGreedy(UAVSpectrumEnv(grid=(3, 1), num_uavs=2).neighbours, width=3, num_actions=7)
    allowed = torch.ones(1, 2, 7, dtype=torch.bool)
    allowed[0, 0, :3] = allowed[0, 1, 3] = False  # the moves that leave the 3x1 grid, and UAV 0's down
    values = torch.tensor([[[0, 0, 0, 1.0, 0, 0, 9.0], [0, 0, 9.0, 0, 0, 1.0, 0]]])  # 0 returns, 1 wants its cell
    assert greedy(values, allowed, torch.tensor([[[0, 0], [1, 0]]]), torch.tensor([[0, 0]])).tolist() == [[6, 5]]
    allowed[0, :, 6] = False  # without return, UAV 0 moves right only if UAV 1 leaves first: it does not
    assert greedy(values, allowed, torch.tensor([[[0, 0], [1, 0]]]), torch.tensor([[0, 0]])).tolist() == [[4, 5]]


def test_a_policy_without_an_environment_acts_for_uavs_at_the_base_and_refuses_other_off_grid_positions():
    from uavrl.agents.baselines import OraclePolicy, RandomPolicy
    from uavrl.agents.env_check import CheckedPolicy

    options = dict(grid=(6, 6), num_uavs=2, energy="rotary_wing", base=(-1, 0), recharge_steps=5, num_spares=1)
    env = UAVSpectrumEnv(batch_size=2, battery_wh=1, **options)
    td = env.rollout(80, OraclePolicy(env.cfg))  # no env bound: every tensordict checked in full, spares at the base
    assert bool((td["positions"] == torch.tensor([-1, 0])).all(-1).any())
    policy = CheckedPolicy(RandomPolicy(0), env.cfg)
    first = env.reset()
    first["positions"][0, 0] = torch.tensor([-1, 1])  # off the grid, and not the base
    with pytest.raises(ValueError, match="positions leave that grid and base"):
        policy(first)
