"""Energy and lifetime (docs/model.md, Energy and lifetime): the propulsion power against the formula written out
here, the follow-up's accounting on hand-worked steps, a battery over a rollout against a per-step sum kept here,
leaving service, the flight to the base and termination on a hand-built 3x3 case, and the refusals."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
import torch

from uavrl.envs import make_config
from uavrl.envs.world import World

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

BASE = (-1, 0)
ENERGY_CLI = ("env.energy=rotary_wing", "env.base=[-1,0]")
UP, DOWN, LEFT, RIGHT, SENSE, RELAY = range(6)


def zeng_power(v: float) -> float:
    """Zeng, Xu, Zhang (IEEE TWC 2019) eq. (12) with their Table I, written out independently of
    envs/physics/power.py."""
    W, rho, R, A, Omega, U_tip, s, d0, k, delta = 20.0, 1.225, 0.4, 0.503, 300.0, 120.0, 0.05, 0.6, 0.1, 0.012
    P0 = delta / 8 * rho * s * A * Omega**3 * R**3
    Pi = (1 + k) * W**1.5 / math.sqrt(2 * rho * A)
    v0 = math.sqrt(W / (2 * rho * A))
    induced = Pi * (math.sqrt(1 + v**4 / (4 * v0**4)) - v**2 / (2 * v0**2)) ** 0.5
    return P0 * (1 + 3 * v**2 / U_tip**2) + induced + 0.5 * d0 * rho * s * A * v**3


def rotary(**options):
    return make_config("paper", grid=(3, 3), num_uavs=2, energy="rotary_wing", base=BASE, **options)


def per_step(cfg):
    """(stay, move, fly) energies in J of a step of ``cfg`` from the formula above: hover or fly one cell in a slot,
    plus the UAV's transmit power and the circuit power while serving."""
    radio = cfg.p_u + cfg.circuit_power_w
    flying = zeng_power(cfg.cell_size / cfg.slot_s)
    return (zeng_power(0.0) + radio) * cfg.slot_s, (flying + radio) * cfg.slot_s, flying * cfg.slot_s


def steps_home(x: int, y: int) -> int:
    return abs(x - BASE[0]) + abs(y - BASE[1])


def test_propulsion_power_is_zengs():
    from uavrl.envs.physics import power

    assert power.BLADE_PROFILE_POWER == pytest.approx(79.86, abs=0.05)  # P0 ~ 79.9 W
    assert power.INDUCED_POWER == pytest.approx(88.63, abs=0.05)  # Pi ~ 88.6 W
    assert power.propulsion_power(0.0) == pytest.approx(168.5, abs=0.05)  # hover
    assert power.propulsion_power(10.0) == pytest.approx(126.0, abs=0.1)
    for v in (0.0, 1.0, 5.0, 10.0, 18.0, 30.0, 60.0):
        assert power.propulsion_power(v) == pytest.approx(zeng_power(v), rel=1e-12)
    assert min(range(0, 40), key=power.propulsion_power) == 10  # least power near 10.2 m/s (Zeng et al.'s V_me)


def test_rotary_wing_step_energies_and_capacity():
    cfg = rotary(battery_wh=2.0, slot_s=2.0, circuit_power_w=3.0, cell_size=12.0)
    e = cfg.step_energies
    stay, move, fly = per_step(cfg)
    assert (e.stay, e.move, e.fly, e.arrive) == pytest.approx((stay, move, fly, 0.0), rel=1e-12)
    assert e.capacity == 2.0 * 3600
    physical = make_config(
        "a2g_urban", grid=(3, 3), num_uavs=2, energy="rotary_wing", base=BASE, altitude_m=100.0, p_u_dbm=20.0
    )
    assert physical.step_energies.stay - zeng_power(0.0) == pytest.approx(6.8 + 0.1, rel=1e-3)  # 20 dBm = 0.1 W


def step(world, *actions):
    out, _, _ = world.step(torch.tensor([actions]))
    return out


def test_follow_up_accounting_on_hand_worked_steps():
    cfg = make_config("paper", grid=(3, 3), num_uavs=2, energy="follow_up", base=BASE)
    world = World(cfg, 1)
    world.start_at(torch.tensor([[0, 16]]))  # UAV 0 at (0, 0), UAV 1 at (2, 2), both sensing
    assert world._s.battery.tolist() == [[5000.0, 5000.0]]
    step(world, RIGHT, UP)  # both move: 1.0 + 0.5 transmission
    assert world._s.battery.tolist() == [[4998.5, 4998.5]]
    step(world, SENSE, RELAY)  # no move (a task switch too): transmission only
    assert world._s.battery.tolist() == [[4998.0, 4998.0]]
    out = step(world, DOWN, LEFT)  # both into (1, 1): cancelled, charged as moves (the follow-up's code)
    assert out["positions"].tolist() == [[[1, 0], [2, 1]]]
    assert world._s.battery.tolist() == [[4996.5, 4996.5]]
    # reserve 1.5 (a move) + 10 (one region of inter-region flight): at 11.5 a UAV leaves
    world._s.battery = torch.tensor([[12.0, 13.0]], dtype=torch.float64)
    out = step(world, SENSE, SENSE)
    assert world._s.status.tolist() == [[1, 0]] and world._s.timer.tolist() == [[2, 0]]  # (1, 0): 2 steps home
    assert out["positions"][0, 0].tolist() == list(BASE)
    step(world, SENSE, SENSE)
    assert world._s.battery.tolist() == [[11.5, 12.0]] and world._s.status.tolist() == [[1, 0]]
    step(world, SENSE, SENSE)  # UAV 0 reaches the base and pays the region's flight; UAV 1 leaves at 11.5
    assert world._s.battery.tolist() == [[1.5, 11.5]] and world._s.status.tolist() == [[2, 1]]


def test_leaving_service_flight_to_base_and_termination_by_hand(hand_built):
    cfg = rotary()
    stay, move, fly = per_step(cfg)
    cap = cfg.battery_wh * 3600
    # UAV 0 relaying at (1, 2), UAV 1 sensing at (2, 2): 4 and 5 steps from the base (-1, 0)
    reserve_22 = max(stay + 5 * fly, move + 5 * fly)  # its worst next step, then the flight home
    b0 = reserve_22 + 2.5 * stay + move  # after steps of stay, move, stay, stay: half a hover below the reserve
    world = hand_built(cfg, [2 * 7 + 1, 2 * 8], [b0, reserve_22 + 0.5 * stay])
    alone = World(make_config("paper", grid=(3, 3), num_uavs=1), 1)
    relaying_alone = alone.start_at(torch.tensor([[2 * 7 + 1]]))
    together = World(make_config("paper", grid=(3, 3), num_uavs=2), 1).start_at(torch.tensor([[15, 16]]))

    out = step(world, RIGHT, SENSE)  # UAV 0 is blocked by UAV 1; UAV 1 reaches its reserve and leaves
    assert world._s.battery[0].tolist() == pytest.approx([b0 - stay, reserve_22 - 0.5 * stay], rel=1e-12)
    assert world._s.status.tolist() == [[0, 1]] and world._s.timer.tolist() == [[0, 5]]
    assert out["positions"].tolist() == [[[1, 2], list(BASE)]]
    assert out["action_mask"][0, 1].tolist() == [False] * 4 + [True, False]  # only the no-op
    # the rates exclude UAV 1: those of UAV 0 relaying alone, not those of the two
    assert out["utility"].item() == relaying_alone["utility"].item() != together["utility"].item()
    assert out["r_se"].item() == 0.0 and not world.terminated.item()
    # after the observation of energy=none (13 + 3 features), each UAV's own battery and flag, then the other's
    observation, state = out["observation"][0], out["state"][0]
    assert observation[1, 16:18].tolist() == pytest.approx([(reserve_22 - 0.5 * stay) / cap, 0.0], rel=1e-6)
    assert observation[0, 16:18].tolist() == pytest.approx([(b0 - stay) / cap, 1.0], rel=1e-6)
    assert observation[0, 18:].tolist() == observation[1, 16:18].tolist()  # UAV 0 sees UAV 1's battery and flag
    assert observation[1, 18:].tolist() == observation[0, 16:18].tolist()
    assert state[10:14].tolist() == observation[0, 16:20].tolist()  # after the per-UAV (x, y, task, contributions)

    out = step(world, RIGHT, SENSE)  # the freed cell (2, 2) can be entered
    assert out["positions"][0, 0].tolist() == [2, 2]
    battery0 = [b0 - stay - move]
    for t in range(3, 10):
        step(world, RELAY, SENSE)
        battery0.append(battery0[-1] - (stay if t <= 4 else fly))
        if t <= 6:  # UAV 1's flight: 5 steps from step 2
            assert world._s.status[0, 1].item() == (1 if t < 6 else 2)
        assert world._s.battery[0, 0].item() == pytest.approx(battery0[-1], rel=1e-12)
        assert world.terminated.item() == (t >= 4)  # UAV 0 leaves after step 4: no one serves
    assert world._s.battery[0, 1].item() == pytest.approx(0.5 * stay, rel=1e-9)  # the reserve is never overdrawn
    assert world._s.status.tolist() == [[2, 2]] and world._s.battery.min() > 0


def test_battery_over_a_rollout_is_the_sum_of_its_steps():
    """N = 2 (a clash cancels both moves), stepped here independently of the World; uniform starting levels."""
    cfg = rotary(battery_wh=0.6, battery_init="uniform")
    stay, move, fly = per_step(cfg)
    deltas = {UP: (0, -1), DOWN: (0, 1), LEFT: (-1, 0), RIGHT: (1, 0)}

    def reserve(x, y):
        around = [(x, y)] + [(x + dx, y + dy) for dx, dy in deltas.values() if 0 <= x + dx < 3 and 0 <= y + dy < 3]
        return max(stay + steps_home(x, y) * fly, move + max(steps_home(*c) for c in around) * fly)

    B, gen = 4, torch.Generator().manual_seed(0)
    world = World(cfg, B, seed=3)
    out = world.reset()
    battery = world._s.battery.clone().tolist()
    where = [[tuple(p) for p in world_positions] for world_positions in out["positions"].tolist()]
    status = [[0, 0] for _ in range(B)]
    timer = [[0, 0] for _ in range(B)]
    left = 0
    for _ in range(40):
        action = torch.multinomial(out["action_mask"].view(-1, 6).float(), 1, generator=gen).view(B, 2)
        out, _, _ = world.step(action)
        for w in range(B):
            target = []
            for i in range(2):
                a, (x, y) = action[w, i].item(), where[w][i]
                dx, dy = deltas.get(a, (0, 0)) if status[w][i] == 0 else (0, 0)
                target.append((x + dx, y + dy))
            clash = status[w] == [0, 0] and target[0] == target[1]
            for i in range(2):
                if status[w][i] == 0:
                    new = where[w][i] if clash else target[i]
                    battery[w][i] -= move if new != where[w][i] else stay
                    where[w][i] = new
                    if battery[w][i] <= reserve(*new):
                        status[w][i], timer[w][i], where[w][i] = 1, steps_home(*new), BASE
                        left += 1
                elif status[w][i] == 1:
                    fly_a_step_home(battery[w], status[w], timer[w], i, fly)
        assert world._s.battery.view(-1).tolist() == pytest.approx(sum(battery, []), rel=1e-12)
        assert world._s.status.tolist() == status
        assert out["positions"].tolist() == [[list(p) for p in ws] for ws in where]
        assert world.terminated.tolist() == [0 not in s for s in status]
    assert left == 2 * B and min(min(b) for b in battery) > 0  # every UAV left, none overdrew


def fly_a_step_home(battery: list, status: list, timer: list, i: int, fly: float) -> None:
    """UAV ``i`` of one world flies one step of its flight home: it pays ``fly``, and is out once the timer ends."""
    battery[i] -= fly
    timer[i] -= 1
    status[i] = 2 if timer[i] == 0 else 1


def test_batteries_are_drawn_per_seed():
    cfg = rotary(battery_init="uniform")
    cap = cfg.battery_wh * 3600
    world = World(cfg, 3, seed=5)
    world.reset()
    first = world._s.battery.clone()
    world.set_seed(5)
    world.reset()
    assert world._s.battery.equal(first)
    one = World(cfg, 1, seed=6)
    one.reset()
    assert one._s.battery[0].equal(first[1])  # world i is a world of its own seeded seed + i
    assert (first >= 0.8 * cap).all() and (first <= cap).all() and len(first.unique()) == 6
    assert (
        World(make_config("paper", grid=(3, 3), num_uavs=2), 3, seed=5)
        .reset()["positions"]
        .equal(World(cfg, 3, seed=5).reset()["positions"])
    )  # the batteries' draw moves no other
    full = World(rotary(), 2)
    full.reset()
    assert full._s.battery.eq(cap).all()
    follow_up = World(make_config("paper", energy="follow_up", base=BASE, battery_init="uniform"), 64)
    follow_up.reset()
    assert follow_up._s.battery.min() >= 4000 and follow_up._s.battery.max() <= 5000


def test_the_observation_and_specs_follow_the_energy_model(tiny_env):
    from torchrl.envs.utils import check_env_specs

    for N in (1, 2, 3):
        plain = World(make_config("paper", grid=(3, 3), num_uavs=N), 2)
        powered = World(make_config("paper", **_energy(N), battery_init="uniform"), 2)
        assert plain.observation_size == 13 + 3 * (N - 1) and plain.state_size == 5 * N + 12
        assert powered.observation_size == 15 + 5 * (N - 1) and powered.state_size == 7 * N + 12
        first = powered.reset()
        assert first["observation"].shape == (2, N, powered.observation_size)
        assert first["observation"][..., : plain.observation_size].equal(plain.reset()["observation"])
        # the others' batteries and flags in the order of their (x, y, task): UAV i sees i + 1, ..., i + N - 1
        others = torch.tensor([[(i + k) % N for k in range(1, N)] for i in range(N)], dtype=torch.long)
        features = first["observation"][:, :, 13 + 3 * (N - 1) :].view(2, N, N, 2)
        assert features[:, :, 1:].equal(features[:, :, 0][:, others])
        assert first["state"][:, 5 * N : 7 * N].equal(features[:, :, 0].reshape(2, 2 * N))
        assert "energy" not in plain.parts and plain._s.battery is None
    env = tiny_env(energy="rotary_wing", base=BASE)
    check_env_specs(env)
    assert env.rollout(3)["agents", "observation"].shape == (2, 3, 2, 20)


def _energy(N):
    return dict(grid=(3, 3), num_uavs=N, energy="rotary_wing", base=BASE)


@pytest.mark.parametrize(
    "options, message",
    [
        (dict(energy="rotary_wing"), "energy='rotary_wing' is invalid: a UAV leaves service for its base"),
        (dict(energy="solar"), "energy='solar' is invalid: allowed values are 'none', 'follow_up', 'rotary_wing'"),
        (dict(base=(-1, 0)), "base=(-1, 0) is invalid: only an energy model"),
        (dict(battery_wh=50.0), "battery_wh=50.0 is invalid: only energy='rotary_wing' reads it"),
        (dict(battery_init="uniform"), "battery_init='uniform' is invalid: only an energy model"),
        (dict(energy="follow_up", base=BASE, slot_s=2.0), "slot_s=2.0 is invalid: only energy='rotary_wing'"),
        (_energy(2) | dict(base=(1, 1)), "base=[1, 1] is invalid: a UAV out of service is shown at the base"),
        (_energy(2) | dict(base=(1, 0.5)), "base=(1, 0.5) is invalid: give two integers"),
        (_energy(2) | dict(battery_wh=-1.0), "battery_wh=-1.0 is invalid: it must be a finite positive number"),
        (_energy(2) | dict(battery_wh=math.inf), "battery_wh=inf is invalid"),
        (_energy(2) | dict(slot_s=0.0), "slot_s=0.0 is invalid: it must be a finite positive number"),
        (_energy(2) | dict(circuit_power_w=math.nan), "circuit_power_w=nan is invalid: it must be a finite number"),
        (_energy(2) | dict(circuit_power_w=-0.1), "circuit_power_w=-0.1 is invalid"),
        (_energy(2) | dict(battery_wh=0.05), "battery_wh=0.05 is invalid: a UAV may start with 0.05 Wh (full)"),
        (_energy(2) | dict(base=(-3000, 0)), "base=[-3000, 0] is invalid: a UAV may start with 89.2 Wh (full) at"),
        (_energy(2) | dict(reset_positions="keep"), "energy='rotary_wing' is invalid: a UAV that left service"),
        (dict(energy="follow_up", base=BASE, p_u=-1.0), "p_u=-1.0 is invalid: it must be a finite positive number"),
    ],
)
def test_bad_energy_settings_are_refused_in_one_line(options, message):
    with pytest.raises(ValueError) as error:
        make_config("paper", **options)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_a_battery_just_above_the_largest_reserve_is_accepted():
    stay, move, fly = per_step(rotary())
    farthest = steps_home(2, 2)  # (2, 2) of the 3x3 grid
    need_wh = (max(stay, move) + farthest * fly) / 3600
    rotary(battery_wh=need_wh * 1.001)
    with pytest.raises(ValueError, match="battery_wh"):
        rotary(battery_wh=need_wh * 0.999)
    with pytest.raises(ValueError, match="battery_wh"):
        rotary(battery_wh=need_wh * 1.1, battery_init="uniform")  # U[0.8, 1] of it may start too low


def test_steps_before_reserve_is_the_last_step_a_battery_cannot_reach_its_reserve_on(hand_built):
    cfg = rotary(battery_wh=0.6)
    stay, move, fly = per_step(cfg)
    cap = cfg.battery_wh * 3600
    reserve_22 = max(stay, move) + steps_home(2, 2) * fly  # the farthest cell: no neighbour lies farther
    limit = 0
    while cap - (limit + 1) * max(stay, move) > reserve_22:
        limit += 1
    assert cfg.steps_before_reserve == limit and stay > move  # hovering is the dearer step
    world = hand_built(cfg, [2 * 8, 2 * 5], [cap, cap])  # at (2, 2) and (2, 1), hovering all along
    for _ in range(limit):
        step(world, SENSE, SENSE)
    assert world._s.status.tolist() == [[0, 0]]
    step(world, SENSE, SENSE)
    assert world._s.status[0, 0].item() == 1  # one step more, and the UAV at (2, 2) leaves for the base
    assert make_config("paper", energy="none").steps_before_reserve is None


def test_the_tabular_table_refuses_a_battery_that_may_reach_its_reserve():
    from uavrl.agents.tabular.tables import TabularModel

    limit = rotary().steps_before_reserve
    TabularModel(rotary(max_steps=limit))  # no battery reaches its reserve: the table without batteries is exact
    too_long = rf"energy='rotary_wing' is invalid for agent=tabular with max_steps={limit + 1}: .* 81 x .* rows"
    with pytest.raises(ValueError, match=too_long + rf".* max_steps <= {limit} "):
        TabularModel(rotary(max_steps=limit + 1))
    with pytest.raises(ValueError, match="with max_steps=100 and recharge_steps: "):
        TabularModel(rotary(recharge_steps=5))


def test_the_tabular_learner_under_follow_up_learns_as_without_energy_while_no_battery_can_leave():
    from uavrl.agents.tabular import TeamQLearner

    plain = make_config("paper", grid=(3, 3), num_uavs=2, max_steps=60, reward="best_so_far")
    follow_up = plain.replace(energy="follow_up", base=BASE, battery_init="uniform")
    learners = [TeamQLearner(cfg, runs=2, seed=3) for cfg in (plain, follow_up)]
    for _ in range(3):
        without, under = (learner.run_episode() for learner in learners)
        assert all(torch.equal(without[name], under[name]) for name in without)
    assert torch.equal(learners[0].q, learners[1].q) and learners[0].q.abs().sum() > 0


def test_the_tabular_agent_refuses_an_energy_model():
    from omegaconf import OmegaConf

    from uavrl.agents.tabular import TabularAgent

    cfg = make_config("paper", grid=(3, 3), num_uavs=2, max_steps=20, energy="follow_up", base=BASE)
    with pytest.raises(ValueError, match="env.energy='follow_up' is invalid for agent=tabular: its evaluation"):
        TabularAgent(cfg, OmegaConf.create({"agent": {"method": "q_learning"}}), "cpu", 0)


@pytest.mark.parametrize(
    "energy",
    [
        pytest.param("env.energy=rotary_wing env.battery_wh=0.5", id="rotary_wing"),
        pytest.param("env.energy=follow_up", id="follow_up", marks=pytest.mark.slow),
        pytest.param(
            "env.energy=rotary_wing env.battery_wh=0.5 env.recharge_steps=3 env.num_spares=1 env.reward=delivered "
            "agent.objective=delta agent.mixer=qmix",
            id="rotary_wing-recharge-spare-delivered",
            marks=pytest.mark.slow,
        ),
    ],
)
def test_the_command_line_trains_and_evaluates_a_dqn_under_every_energy_model(energy, tmp_path):
    train_a_small_dqn(f"{energy} env.base=[-1,0] env.grid=[3,3]", tmp_path)


def train_a_small_dqn(model: str, run_dir) -> None:
    """``python -m uavrl.train agent=dqn`` of a few steps on the model settings ``model``: it trains, evaluates and
    writes its metrics."""
    settings = (
        f"agent=dqn {model} agent.iterations=3 env.max_steps=8 agent.worlds=8 agent.hidden=16 agent.depth=1 "
        "agent.batch_size=32 agent.buffer_size=100 agent.updates=2 agent.learning_starts=16 eval.num_starts=4"
    )
    result = subprocess.run(
        [sys.executable, "-m", "uavrl.train", *settings.split(), "progress=false", f"run_dir={run_dir}"],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert "optimality" in result.stdout and list(run_dir.rglob("metrics.json"))


def test_an_energy_setting_without_base_is_one_line_on_the_command_line(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "uavrl.train", "env.energy=follow_up", "progress=false", f"run_dir={tmp_path}"],
        capture_output=True,
        text=True,
    )
    assert result.returncode != 0 and result.stderr.strip().count("\n") == 0, result.stderr
    assert "env.energy='follow_up' is invalid: a UAV leaves service for its base: give env.base=" in result.stderr


def test_the_dqns_joint_head_is_refused_under_an_energy_model(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "uavrl.train", "agent=dqn", "agent.head=joint", *ENERGY_CLI]
        + ["progress=false", f"run_dir={tmp_path}"],
        capture_output=True,
        text=True,
    )
    assert result.returncode != 0 and result.stderr.strip().count("\n") == 0, result.stderr
    assert "agent.head='joint' is invalid with env.energy='rotary_wing'" in result.stderr


@pytest.mark.gym  # .ci/leg-gym runs it (-m gym), where a skip fails
def test_the_gymnasium_and_pettingzoo_adapters_terminate_and_autoreset_apart():
    pytest.importorskip("gymnasium")
    pytest.importorskip("pettingzoo")
    import numpy as np

    from uavrl.envs.adapters.gym_env import UAVSpectrumGymEnv, UAVSpectrumVectorEnv
    from uavrl.envs.adapters.pettingzoo_env import UAVSpectrumParallelEnv

    options = _energy(3) | dict(battery_wh=0.6, battery_init="uniform", max_steps=30)
    rng = np.random.default_rng(0)

    def allowed(mask):  # one allowed action per UAV of masks [..., N, 6]
        return np.apply_along_axis(lambda m: rng.choice(np.flatnonzero(m)), -1, mask)

    single = UAVSpectrumGymEnv(**options)
    obs, info = single.reset(seed=1)
    for _ in range(30):
        obs, _, terminated, truncated, info = single.step(allowed(info["action_mask"]))
        assert single.observation_space.contains(obs)
        if terminated or truncated:
            break
    assert terminated and not truncated and single.world._s.status.ne(0).all()

    vector = UAVSpectrumVectorEnv(num_envs=5, **options)
    obs, infos = vector.reset(seed=3)
    first_ends = None
    for _ in range(30):
        ended = vector._autoreset.copy()
        obs, reward, terminated, truncated, infos = vector.step(allowed(infos["action_mask"]))
        assert vector.observation_space.contains(obs)
        if ended.any() and not ended.all():  # those restart (reward 0, first observation), the others step on
            assert (reward[ended] == 0).all() and (vector.world._s.steps.numpy()[ended] == 0).all()
            assert (vector.world._s.steps.numpy()[~ended] > 0).all() and (obs[ended, :, 20] == 1).all()
            first_ends = ended
    assert first_ends is not None

    parallel = UAVSpectrumParallelEnv(**options)
    observations, _ = parallel.reset(seed=1)
    for _ in range(30):
        actions = {agent: int(allowed(seen["action_mask"])) for agent, seen in observations.items()}
        observations, _, terminations, truncations, _ = parallel.step(actions)
        if not parallel.agents:
            break
    assert all(terminations.values()) and not any(truncations.values())


def test_a_world_with_uavs_out_of_service_renders():
    from uavrl.envs.render import render

    world = World(rotary(battery_wh=0.4), 1)
    world.reset()
    for _ in range(6):
        world.step(torch.full((1, 2), SENSE))
    assert world._s.status.ne(0).all()
    frame = render(world, "rgb_array", 0)
    assert frame.shape[-1] == 3 and frame.std() > 0
