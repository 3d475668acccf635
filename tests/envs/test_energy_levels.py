"""Energy with altitude levels (docs/model.md, Energy and lifetime): a climb and a descent cost what Zeng, Wu and
Zhang's approximation for 3D flight says, written out here; a battery over a rollout in 3D against a per-step sum kept
here, with each position's reserve found here by trying every next step; and what is refused in one line."""

from __future__ import annotations

import itertools
import math

import pytest
import torch

from tests.envs.test_energy import BASE, fly_a_step_home, per_step, steps_home, train_a_small_dqn, zeng_power
from tests.envs.test_mission import Mission
from uavrl.envs import make_config
from uavrl.envs.errors import InvalidOption
from uavrl.envs.solvers.mission_exact import MissionTooLarge, mission_size, optimal_mission
from uavrl.envs.world import World

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

LEVELS_M = (10.0, 20.0, 80.0)  # a climb of 10 m (its descent floored at the profile power) and one of 60 m
WEIGHT_N = 20.0  # Zeng et al.'s W
PROFILE_POWER = 0.012 / 8 * 1.225 * 0.05 * 0.503 * 300.0**3 * 0.4**3  # their P0 = delta/8 rho s A Omega^3 R^3
MOVES = {0: (0, -1, 0), 1: (0, 1, 0), 2: (-1, 0, 0), 3: (1, 0, 0), 6: (0, 0, 1), 7: (0, 0, -1)}  # (dx, dy, dlevel)


def leveled(energy="rotary_wing", **options):
    options = {"grid": (3, 3), **options}
    return make_config("paper", num_uavs=2, energy=energy, base=BASE, cell_size=10.0, altitudes_m=LEVELS_M, **options)


def vertical(cfg) -> tuple[list[float], list[float]]:
    """The climb from each level and the descent to it, in J, of a serving UAV (radio included)."""
    radio = (cfg.p_u + cfg.circuit_power_w) * cfg.slot_s
    climbs, descents = [], []
    for low, high in itertools.pairwise(LEVELS_M):
        dh, slot = high - low, cfg.slot_s
        level_flight = zeng_power(dh / slot) * slot
        climbs.append(level_flight + WEIGHT_N * dh + radio)
        descents.append(max(level_flight - WEIGHT_N * dh, PROFILE_POWER * slot) + radio)
    return climbs, descents


def test_a_climb_and_a_descent_cost_zeng_wu_zhangs_3d_approximation():
    cfg = leveled(battery_wh=2.0)
    e, (climbs, descents) = cfg.step_energies, vertical(cfg)
    assert e.climb == pytest.approx(climbs, rel=1e-12) and e.descend == pytest.approx(descents, rel=1e-12)
    radio = cfg.p_u + cfg.circuit_power_w
    assert e.descend[0] == pytest.approx(PROFILE_POWER + radio, rel=1e-12)  # 10 m down: the floor holds
    assert e.descend[1] > PROFILE_POWER + radio  # 60 m down in a second: level flight at 60 m/s outweighs W dh
    assert e.dearest == max(e.climb) and e.cheapest == min(e.descend)
    follow_up = leveled("follow_up").step_energies  # no altitude in the follow-up: a climb is a move action
    assert follow_up.climb == follow_up.descend == (follow_up.move,) * 2


def test_a_battery_over_a_3d_rollout_is_the_sum_of_its_steps():
    """Two UAVs on 3 cells x 3 cells x 3 levels stepped here, independently of the World, under random valid
    actions until both have flown home."""
    cfg = leveled(battery_wh=3.0, battery_init="uniform", max_steps=400)
    stay, move, fly = per_step(cfg)
    climbs, descents = vertical(cfg)

    def cost(before, after):
        if before == after:
            return stay
        if after[2] != before[2]:
            return climbs[before[2]] if after[2] > before[2] else descents[after[2]]
        return move

    def inside(x, y, z):
        return 0 <= x < 3 and 0 <= y < 3 and 0 <= z < len(LEVELS_M)

    def reserve(x, y, z):  # every next step a serving UAV may take, then the flight home from where it ends
        ends = [(x + dx, y + dy, z + dz) for dx, dy, dz in MOVES.values() if inside(x + dx, y + dy, z + dz)]
        return max(cost((x, y, z), end) + steps_home(end[0], end[1]) * fly for end in [(x, y, z), *ends])

    B, gen = 8, torch.Generator().manual_seed(1)
    world = World(cfg, B, seed=5)
    out = world.reset()
    battery = world._s.battery.clone().tolist()
    where = [
        [(*xy, z) for xy, z in zip(p, lv, strict=True)]
        for p, lv in zip(out["positions"].tolist(), out["levels"].tolist(), strict=True)
    ]
    status = [[0, 0] for _ in range(B)]
    timer = [[0, 0] for _ in range(B)]
    climbed = descended = 0
    for _ in range(400):
        if all(s == [2, 2] for s in status):
            break
        action = torch.multinomial(out["action_mask"].view(-1, 8).float(), 1, generator=gen).view(B, 2)
        out, _, _ = world.step(action)
        for w in range(B):
            target = []
            for i in range(2):
                x, y, z = where[w][i]
                dx, dy, dz = MOVES.get(action[w, i].item(), (0, 0, 0)) if status[w][i] == 0 else (0, 0, 0)
                target.append((x + dx, y + dy, z + dz))
            clash = status[w] == [0, 0] and target[0] == target[1]
            for i in range(2):
                if status[w][i] == 0:
                    new = where[w][i] if clash else target[i]
                    battery[w][i] -= cost(where[w][i], new)
                    climbed += new[2] > where[w][i][2]
                    descended += new[2] < where[w][i][2]
                    where[w][i] = new
                    if battery[w][i] <= reserve(*new):
                        status[w][i], timer[w][i], where[w][i] = 1, steps_home(*new[:2]), (*BASE, 0)
                elif status[w][i] == 1:
                    fly_a_step_home(battery[w], status[w], timer[w], i, fly)
        assert world._s.battery.view(-1).tolist() == pytest.approx(sum(battery, []), rel=1e-12)
        assert world._s.status.tolist() == status
        shown = [
            [(*xy, z) for xy, z in zip(p, lv, strict=True)]
            for p, lv in zip(out["positions"].tolist(), out["levels"].tolist(), strict=True)
        ]
        assert shown == where
    assert all(s == [2, 2] for s in status) and min(climbed, descended) >= 10
    assert min(min(b) for b in battery) > 0  # every UAV flew home, none overdrew


def test_no_uav_leaves_service_within_the_steps_before_reserve():
    cfg = leveled(battery_wh=3.0, max_steps=400)
    world, gen = World(cfg, 16, seed=0), torch.Generator().manual_seed(0)
    out, first_leave = world.reset(), math.inf
    for t in range(1, 200):
        action = torch.multinomial(out["action_mask"].view(-1, 8).float(), 1, generator=gen).view(16, 2)
        out, _, _ = world.step(action)
        if (world._s.status != 0).any():
            first_leave = t
            break
    assert cfg.steps_before_reserve < first_leave < math.inf


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"recharge_steps": 3}, "recharge_steps=3 is invalid: recharging with altitude levels is not modelled"),
        (
            {"battery_wh": 0.05},
            "battery_wh=0.05 is invalid: a UAV may start with 0.05 Wh (full) at the cell farthest from the base "
            "[-1, 0], 5 steps away, where its dearest step (a climb of 60 m) and the flight",
        ),
    ],
)
def test_what_energy_with_levels_refuses_in_one_line(options, message):
    with pytest.raises(InvalidOption) as refused:
        leveled(**options)
    assert str(refused.value).startswith(message) and "\n" not in str(refused.value)


@pytest.mark.parametrize(
    "model",
    [
        pytest.param("env.energy=rotary_wing env.battery_wh=3 env.altitudes_m=[10,20,80]", id="rotary_wing"),
        pytest.param(
            "env=a2g_urban env.city=urban env.energy=rotary_wing env.battery_wh=20 env.altitudes_m=[30,60,100]",
            id="rotary_wing-city",
            marks=pytest.mark.slow,
        ),
        pytest.param("env.energy=follow_up env.altitudes_m=[10,20,80]", id="follow_up", marks=pytest.mark.slow),
    ],
)
def test_the_command_line_trains_and_evaluates_a_dqn_with_levels_under_an_energy_model(model, tmp_path):
    train_a_small_dqn(f"{model} env.base=[-1,0] env.grid=[3,3] env.cell_size=10", tmp_path)


def test_with_levels_the_planner_cycles_in_the_plane_and_delivers_more_than_the_oracle():
    """6x6 cells of 10 m at three levels, 2 UAVs: moving one cell costs less than hovering, so the planner's A-B cycle
    (moves in the plane at each UAV's level) serves longer than the oracle hovering on A, from the same starts."""
    from uavrl.agents.baselines import OraclePolicy
    from uavrl.agents.evaluation import evaluate
    from uavrl.agents.planner import PlannerPolicy

    cfg = leveled(grid=(6, 6), battery_wh=3.0)
    oracle = evaluate(OraclePolicy(cfg), cfg, num_starts=8)
    planner = evaluate(PlannerPolicy(cfg), cfg, num_starts=8)
    assert planner["eval/delivered_bit_per_hz"] > 1.1 * oracle["eval/delivered_bit_per_hz"]
    assert planner["eval/first_leave_steps"] > oracle["eval/first_leave_steps"] + 10


def test_a_world_with_levels_and_uavs_out_of_service_renders_each_row():
    from uavrl.envs.render import WorldRenderer

    world = World(leveled(battery_wh=3.0), 1, seed=0)
    world.reset()
    while world._s.status[0, 0] == 0:  # UAV 0 climbs and descends until it leaves; UAV 1 stays where it is
        level = int(world.dynamics.positions.level[world._s.cell[0, 0]])
        world.step(torch.tensor([[6 if level == 0 else 7, 4]]))
    renderer = WorldRenderer(world)
    frame = renderer.frame(0)
    rows = [row.get_text() for row in renderer._rows]
    assert frame.shape[-1] == 3 and frame.std() > 0
    assert rows[0].split()[1] in ("return", "out") and not rows[0].endswith("m")  # at the base: no height
    assert rows[1].endswith(f"{LEVELS_M[int(world.dynamics.positions.level[world._s.cell[0, 1]])]:g}m")


@pytest.mark.gym  # .ci/leg-gym runs it (-m gym), where a skip fails
def test_the_pettingzoo_state_and_the_gymnasium_observation_stay_in_their_spaces_to_the_missions_end():
    pytest.importorskip("gymnasium")
    pytest.importorskip("pettingzoo")
    import numpy as np

    from uavrl.envs.adapters.gym_env import UAVSpectrumGymEnv
    from uavrl.envs.adapters.pettingzoo_env import UAVSpectrumParallelEnv

    cfg = leveled(battery_wh=3.0, max_steps=200)
    zoo, single, rng = UAVSpectrumParallelEnv(config=cfg), UAVSpectrumGymEnv(config=cfg), np.random.default_rng(0)
    observations, _ = zoo.reset(seed=1)
    obs, info = single.reset(seed=1)
    for _ in range(200):
        assert zoo.state_space.contains(zoo.state()) and single.observation_space.contains(obs)
        actions = [rng.choice(np.flatnonzero(mask)) for mask in info["action_mask"]]
        observations, *_, truncations, _ = zoo.step(dict(zip(zoo.agents, actions, strict=True)))
        obs, _, terminated, truncated, info = single.step(np.array(actions))
        if terminated or truncated:
            break
    assert terminated and zoo.state_space.contains(zoo.state()) and len(zoo.state()) == 7 * 2 + 2 + 12


class Mission3D(Mission):
    """tests/envs/test_mission.py's brute force with altitude levels, written out here: a UAV ``(x, y, z, task,
    battery)`` also climbs (6) and descends (7), at the costs of :func:`vertical`; its reserve is its dearest next
    step (stay, a move, a climb, a descent), then the flight home from where that step ends."""

    def __init__(self, cfg, contributions):
        super().__init__(cfg, contributions)
        self.levels = cfg.num_levels
        self.climbs, self.descents = vertical(cfg) if cfg.energy == "rotary_wing" else ([self.move] * 2,) * 2

    def inside(self, x, y, z):
        return self.on_grid(x, y) and 0 <= z < self.levels

    def cost(self, before, after, action):
        if self.by_action:  # the follow-up: a move action, climbs and descents among them, costs a move
            return self.move if action in MOVES else self.stay
        if after == before:
            return self.stay
        if after[2] != before[2]:
            return self.climbs[before[2]] if after[2] > before[2] else self.descents[after[2]]
        return self.move

    def reserve(self, x, y, z):
        ends = [
            ((x + dx, y + dy, z + dz), a) for a, (dx, dy, dz) in MOVES.items() if self.inside(x + dx, y + dy, z + dz)
        ]
        return max(self.cost((x, y, z), end, a) + self.flight(*end[:2]) for end, a in [((x, y, z), 4), *ends])

    def utility(self, serving):
        C = self.L1 * self.L2
        position = [z * C + y * self.L1 + x for x, y, z, _, _ in serving]
        pu = sum(self.contributions[p][0] for p, (*_, task, _) in zip(position, serving, strict=True) if task == 1)
        se = sum(self.contributions[p][1] for p, (*_, task, _) in zip(position, serving, strict=True) if task == 0)
        relays = any(task == 1 for *_, task, _ in serving)
        return 0.5 * math.log2(1 + pu) + (0.5 * math.log2(1 + se) if relays else 0.0)

    def actions(self, uav):
        x, y, z = uav[:3]
        return [a for a in range(8) if a in (4, 5) or self.inside(x + MOVES[a][0], y + MOVES[a][1], z + MOVES[a][2])]

    def step(self, serving, joint):
        targets = [
            tuple(c + d for c, d in zip(uav[:3], MOVES[a], strict=True)) if a in MOVES else uav[:3]
            for uav, a in zip(serving, joint, strict=True)
        ]
        clash = len(targets) == 2 and targets[0] == targets[1]
        after = []
        for (x, y, z, task, battery), a, target in zip(serving, joint, targets, strict=True):
            position = (x, y, z) if clash else target
            left = battery - self.cost((x, y, z), position, a)
            if left > self.reserve(*position):
                after.append((*position, {4: 0, 5: 1}.get(a, task), left))
        return tuple(after)


MISSION_CASES = [  # (model, start batteries or None, horizon): a 2x2 grid at two or three levels
    (dict(grid=(2, 2), num_uavs=1, battery_wh=1.2), None, 10),
    (dict(grid=(2, 2), num_uavs=1, battery_wh=1.5, altitudes_m=(10.0, 20.0), battery_init="uniform"), None, 12),
    (dict(grid=(2, 1), num_uavs=2, battery_wh=1.2, altitudes_m=(10.0, 40.0)), None, 7),
    (dict(grid=(2, 1), num_uavs=2, energy="follow_up", altitudes_m=(10.0, 20.0)), [13.0, 15.5], 10),
]


@pytest.mark.parametrize("case", range(len(MISSION_CASES)))
def test_the_exact_mission_solver_with_levels_is_brute_force_optimal_control(case):
    options, batteries, horizon = MISSION_CASES[case]
    options = {"altitudes_m": LEVELS_M, "energy": "rotary_wing", **options}
    cfg = make_config("paper", base=BASE, cell_size=10.0, **options)
    world = World(cfg, 3, seed=case)
    world.reset()
    if batteries is not None:  # the follow-up's 5000 would take thousands of steps: a few steps' worth by hand
        world._s.battery = torch.tensor([batteries] * 3, dtype=torch.float64)
    best = optimal_mission(world, horizon)
    C, L1 = cfg.num_cells, cfg.grid[0]
    cells, tasks, start_battery = world._s.cell.tolist(), world._s.task.tolist(), world.battery.tolist()
    for w in range(3):
        serving = tuple(
            (p % C % L1, p % C // L1, p // C, t, b)
            for p, t, b in zip(cells[w], tasks[w], start_battery[w], strict=True)
        )
        brute, _ = Mission3D(cfg, world.cell_contributions[w]).best(serving, horizon)
        assert best.value[w].item() == pytest.approx(brute * cfg.slot_s, rel=1e-12, abs=1e-12), w
    assert 0 < best.states <= mission_size(world, horizon)[0]
    index, delivered = best.start_index, torch.zeros(3, dtype=torch.float64)
    for step in range(horizon):  # its policy played in the World delivers it
        action, index = best.actions(step, index, world._s.cell)
        out, _, _ = world.step(action)
        positions = torch.cat([out["positions"], out["levels"].unsqueeze(-1)], -1)
        delivered += world.utility(positions, out["tasks"])[2] * cfg.slot_s
    torch.testing.assert_close(delivered, best.value, rtol=1e-12, atol=1e-12)


def test_a_mission_past_int64_states_is_estimated_and_refused_before_any_work():
    """Two UAVs on 10x10 cells at three levels over 400 steps: more states than an int64 holds, counted without
    wrapping round, and refused in one line."""
    world = World(make_config("paper", grid=(10, 10), num_uavs=2, energy="rotary_wing", base=BASE, battery_wh=20.0,
                              altitudes_m=LEVELS_M), 2, seed=0)  # fmt: skip
    world.reset()
    states, transitions, need = mission_size(world, 400)
    assert states > 2**63 and transitions == 64 * states and need > transitions
    with pytest.raises(MissionTooLarge, match=r"^the exact mission solver for 2 UAVs on 10x10 over 400 steps needs"):
        optimal_mission(world, 400)
