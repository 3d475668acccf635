"""The environment against docs/model.md: hand-worked rates, dynamics properties, batching, TorchRL integration.

The reference values here are computed with plain Python ``math`` from docs/model.md's
formulas, never with :mod:`uavrl.envs.physics.channel`, so a wrong formula in the
package cannot hide behind the same wrong formula in the test.
"""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tensordict import TensorDict
from torchrl.envs import ActionMask, Compose, RewardSum, StepCounter, TransformedEnv
from torchrl.envs.utils import check_env_specs, step_mdp

from uavrl.agents.baselines import RandomPolicy
from uavrl.envs import DIAGNOSTICS, UAVSpectrumEnv, observation_with_nodes
from uavrl.envs.env import MaskedCategorical

MOVES = {0: (0, -1), 1: (0, 1), 2: (-1, 0), 3: (1, 0)}
OUTPUT_KEYS = [
    "positions",
    "tasks",
    "r_pu",
    "r_se",
    "utility",
    "moves",
    "task_switches",
    "state",
    ("agents", "observation"),
    ("agents", "action_mask"),
]
PROPERTY_SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# ----------------------------------------------------------------- plain-Python reference of docs/model.md
def line_nodes(L1, L2, h):
    """Where the four nodes are, layout=line, in cell units: PT, PR, S, E."""
    return (0.0, L2 / 2, 0.0), (float(L1), L2 / 2, 0.0), (-L1 / 2, L2 / 2, h), (1.5 * L1, L2 / 2, h)


def paper_rates(
    cells_xy, tasks, nodes, h, *, cell=10.0, p_pt=0.01, p_s=0.02, p_u=0.02, noise=1e-9, direct=False, lease=True
):
    """How good a configuration is: |h|^2 = d^-2 (d in metres), normalised AF, 1/2 log2, lease rule."""
    PT, PR, S, E = nodes

    def gain(a, b):
        return (math.dist(a, b) * cell) ** -2

    sum_pu = p_pt * gain(PT, PR) / noise if direct else 0.0
    sum_se = p_s * gain(S, E) / noise if direct else 0.0
    for (x, y), task in zip(cells_xy, tasks, strict=True):
        uav = (x, y, h)
        if task == 1:
            g1, g2 = p_pt * gain(PT, uav) / noise, p_u * gain(uav, PR) / noise
            sum_pu += g1 * g2 / (1 + g1 + g2)
        else:
            g1, g2 = p_s * gain(S, uav) / noise, p_u * gain(uav, E) / noise
            sum_se += g1 * g2 / (1 + g1 + g2)
    r_pu, r_se = 0.5 * math.log2(1 + sum_pu), 0.5 * math.log2(1 + sum_se)
    if lease and 1 not in tasks:
        r_se = 0.0
    return r_pu, r_se


def reference_code_rates(cells_xy, tasks):
    """The authors' code: absolute layout, |h|^2 = 2 d^-4 in cells, A = 200 |h|^2 |h|^2, A/(1+A), log2, 0 unless
    both tasks staffed."""
    PT, PR, S, E = (0, 5, 0), (10, 5, 0), (-5, 5, 10), (15, 5, 10)

    def h2(a, b):
        return 2 * math.dist(a, b) ** -4

    sum_pu = sum_se = 0.0
    for (x, y), task in zip(cells_xy, tasks, strict=True):
        uav = (x, y, 10)
        src, dst = (PT, PR) if task == 1 else (S, E)
        a = 200 * h2(src, uav) * h2(uav, dst)
        if task == 1:
            sum_pu += a / (1 + a)
        else:
            sum_se += a / (1 + a)
    if len(set(tasks)) < 2:
        return 0.0, 0.0
    return math.log2(1 + sum_pu), math.log2(1 + sum_se)


def resolve(cells_xy, actions, L1, L2):
    """One step in plain Python: off-grid moves stay, then clashing movers are cancelled (all at once) until cells
    differ."""
    targets = []
    for (x, y), a in zip(cells_xy, actions, strict=True):
        if a < 4:
            nx, ny = x + MOVES[a][0], y + MOVES[a][1]
            targets.append((nx, ny) if 0 <= nx < L1 and 0 <= ny < L2 else (x, y))
        else:
            targets.append((x, y))
    while True:
        clash = [
            i
            for i, t in enumerate(targets)
            if t != cells_xy[i] and any(t == u for j, u in enumerate(targets) if j != i)
        ]
        if not clash:
            return targets
        for i in clash:
            targets[i] = cells_xy[i]


def new_tasks(tasks, actions):
    return [0 if a == 4 else 1 if a == 5 else t for t, a in zip(tasks, actions, strict=True)]


def xy_list(td, world):
    return [tuple(p) for p in td["positions"][world].tolist()]


def step_with(env, td, actions):
    td = td.clone(False)
    td.set(("agents", "action"), torch.as_tensor(actions, dtype=torch.long).view(env.num_worlds, env.num_uavs))
    return env.step(td)


def masked_random_actions(td, generator):
    mask = td.get(("agents", "action_mask"))
    return torch.rand(mask.shape, generator=generator).masked_fill(~mask, -1.0).argmax(-1)


# ----------------------------------------------------------------- rates worked by hand
def test_one_cell_by_hand():
    """1x1 grid, one UAV at (0, 0, h=1) cells, paper preset: every number written out."""
    # distances^2 in m^2 (cell 10 m): PT (0,.5,0): 100*(0+.25+1) = 125; PR (1,.5,0): 100*(1+.25+1) = 225
    # S (-.5,.5,1): 100*(.25+.25+0) = 50; E (1.5,.5,1): 100*(2.25+.25+0) = 250
    g1_pu, g2_pu = 0.01 / 125 / 1e-9, 0.02 / 225 / 1e-9
    c_pu = g1_pu * g2_pu / (1 + g1_pu + g2_pu)
    g1_se, g2_se = 0.02 / 50 / 1e-9, 0.02 / 250 / 1e-9
    c_se = g1_se * g2_se / (1 + g1_se + g2_se)
    env = UAVSpectrumEnv(batch_size=1, grid=(1, 1), num_uavs=1)
    env.reset()
    pos = torch.zeros(1, 1, 2, dtype=torch.long)
    r_pu, r_se, u = env.utility(pos, torch.ones(1, 1, dtype=torch.long))
    assert r_pu.item() == pytest.approx(0.5 * math.log2(1 + c_pu), rel=1e-12)
    assert r_se.item() == 0.0 and u.item() == pytest.approx(r_pu.item(), rel=1e-12)
    # sensing alone: the lease rule pays nothing; without it, R_SE = 1/2 log2(1 + c_se)
    assert env.utility(pos, torch.zeros(1, 1, dtype=torch.long))[2].item() == 0.0
    free = UAVSpectrumEnv(batch_size=1, grid=(1, 1), num_uavs=1, lease_rule=False)
    assert free.utility(pos, torch.zeros(1, 1, dtype=torch.long))[1].item() == pytest.approx(
        0.5 * math.log2(1 + c_se), rel=1e-12
    )
    # the same through reset and step: relay (action 5), then sense (action 4)
    td = step_with(env, env.reset(), [5])
    assert td["next", "r_pu"].item() == pytest.approx(0.5 * math.log2(1 + c_pu), rel=1e-6)
    td = step_with(env, step_mdp(td), [4])
    assert td["next", "r_pu"].item() == 0.0 and td["next", "r_se"].item() == 0.0


def test_two_by_one_by_hand():
    """2x1 grid (h = 2 cells), two UAVs, every configuration, through utility() and through steps."""
    L1, L2, h = 2, 1, 2.0
    nodes = line_nodes(L1, L2, h)
    env = UAVSpectrumEnv(batch_size=1, grid=(L1, L2), num_uavs=2)
    env.reset()
    for cells in ([(0, 0), (1, 0)], [(1, 0), (0, 0)]):
        for tasks in ([0, 0], [0, 1], [1, 0], [1, 1]):
            want = paper_rates(cells, tasks, nodes, h)
            got = env.utility(torch.tensor([cells]), torch.tensor([tasks]))
            assert got[0].item() == pytest.approx(want[0], rel=1e-12, abs=1e-15)
            assert got[1].item() == pytest.approx(want[1], rel=1e-12, abs=1e-15)
            assert got[2].item() == pytest.approx(sum(want), rel=1e-12)
    # one explicit value: UAV0 relaying at (0,0,2), UAV1 sensing at (1,0,2)
    # PT (0,.5,0)->(0,0,2): 100*(0+.25+4) = 425 m^2; (0,0,2)->PR (2,.5,0): 100*(4+.25+4) = 825
    # S (-1,.5,2)->(1,0,2): 100*(4+.25+0) = 425; (1,0,2)->E (3,.5,2): 100*(4+.25+0) = 425
    a1, a2 = 0.01 / 425e-9, 0.02 / 825e-9
    b1, b2 = 0.02 / 425e-9, 0.02 / 425e-9
    r_pu = 0.5 * math.log2(1 + a1 * a2 / (1 + a1 + a2))
    r_se = 0.5 * math.log2(1 + b1 * b2 / (1 + b1 + b2))
    got = env.utility(torch.tensor([[[0, 0], [1, 0]]]), torch.tensor([[1, 0]]))
    assert (got[0].item(), got[1].item()) == (pytest.approx(r_pu, rel=1e-12), pytest.approx(r_se, rel=1e-12))


@pytest.mark.parametrize(
    "preset,grid,num_uavs,options",
    [
        ("paper", (2, 1), 2, {}),
        ("paper", (3, 2), 3, {"direct_links": True}),
        ("paper", (1, 4), 2, {"lease_rule": False, "cell_size": 3.0}),
        ("paper", (4, 3), 3, {"altitude": 2.5, "p_pt": 0.05, "noise": 1e-8}),
        ("reference_code", (2, 2), 2, {}),
        ("reference_code", (3, 3), 3, {"init_tasks": "random"}),
    ],
)
def test_env_outputs_match_hand_rates(preset, grid, num_uavs, options):
    """r_pu, r_se, utility after reset and after every step equal the plain-Python formulas of docs/model.md."""
    L1, L2 = grid
    B = 3
    env = UAVSpectrumEnv(batch_size=B, grid=grid, num_uavs=num_uavs, preset=preset, seed=11, max_steps=50, **options)
    h = options.get("altitude", float(L1))
    kwargs = {k: options[k] for k in ("p_pt", "noise") if k in options}
    kwargs.update(
        direct=options.get("direct_links", False),
        lease=options.get("lease_rule", True),
        cell=options.get("cell_size", 10.0),
    )

    def check(out):
        for w in range(B):
            cells, tasks = xy_list(out, w), out["tasks"][w].tolist()
            if preset == "paper":
                want = paper_rates(cells, tasks, line_nodes(L1, L2, h), h, **kwargs)
            else:
                want = reference_code_rates(cells, tasks)
            assert out["r_pu"][w].item() == pytest.approx(want[0], rel=1e-6, abs=1e-7)
            assert out["r_se"][w].item() == pytest.approx(want[1], rel=1e-6, abs=1e-7)
            assert out["utility"][w].item() == pytest.approx(sum(want), rel=1e-6, abs=1e-7)
            r_pu, r_se, u = env.utility(
                out["positions"][w : w + 1].expand(B, -1, -1), out["tasks"][w : w + 1].expand(B, -1)
            )
            assert (r_pu[0].item(), r_se[0].item()) == (
                pytest.approx(want[0], rel=1e-12, abs=1e-15),
                pytest.approx(want[1], rel=1e-12, abs=1e-15),
            )

    gen = torch.Generator().manual_seed(0)
    td = env.reset()
    check(td)
    for _ in range(12):
        td.set(("agents", "action"), torch.randint(0, 6, (B, num_uavs), generator=gen))
        td = env.step(td)
        check(td["next"])
        td = step_mdp(td)


def test_direct_links_by_hand():
    """direct_links adds P |h_PT,PR|^2 / sigma^2 (d = L1 cells) and P_S |h_S,E|^2 / sigma^2 (d = 2 L1 cells)."""
    env = UAVSpectrumEnv(batch_size=1, grid=(3, 3), num_uavs=1, direct_links=True)
    env.reset()
    d_pt_pr, d_s_e = 3 * 10.0, 6 * 10.0
    assert env.direct[0, 0].item() == pytest.approx(0.01 / d_pt_pr**2 / 1e-9, rel=1e-12)
    assert env.direct[0, 1].item() == pytest.approx(0.02 / d_s_e**2 / 1e-9, rel=1e-12)
    # with one sensing UAV the lease rule still zeroes R_SE; R_PU is the direct link alone
    r_pu, r_se, _ = env.utility(torch.tensor([[[1, 1]]]), torch.tensor([[0]]))
    assert r_pu.item() == pytest.approx(0.5 * math.log2(1 + 0.01 / 900e-9), rel=1e-12) and r_se.item() == 0.0
    assert UAVSpectrumEnv(batch_size=1, grid=(3, 3), num_uavs=1).direct.abs().sum().item() == 0.0


def test_lease_rule_zeroes_r_se_without_relays():
    env = UAVSpectrumEnv(batch_size=1, grid=(3, 3), num_uavs=3)
    env.reset()
    pos = torch.tensor([[[0, 0], [1, 1], [2, 2]]])
    assert env.utility(pos, torch.tensor([[0, 0, 0]]))[1].item() == 0.0
    assert env.utility(pos, torch.tensor([[0, 0, 1]]))[1].item() > 0.0
    free = UAVSpectrumEnv(batch_size=1, grid=(3, 3), num_uavs=3, lease_rule=False)
    assert free.utility(pos, torch.tensor([[0, 0, 0]]))[1].item() > 0.0


def test_reference_code_preset():
    """The authors' code as a preset: their formula, both rates 0 when all UAVs share a task, sensing start,
    best_so_far reward."""
    env = UAVSpectrumEnv(batch_size=2, grid=(4, 4), num_uavs=2, preset="reference_code", seed=3, max_steps=30)
    assert env.cfg.reward == "best_so_far" and env.cfg.init_tasks == "sensing"
    td = env.reset()
    assert td["tasks"].eq(0).all() and td["utility"].eq(0).all()
    for tasks in ([0, 0], [1, 1], [0, 1], [1, 0]):
        cells = [(1, 2), (3, 0)]
        r_pu, r_se, _ = env.utility(torch.tensor([cells, cells]), torch.tensor([tasks, tasks]))
        want = reference_code_rates(cells, tasks)
        assert r_pu[0].item() == pytest.approx(want[0], rel=1e-12, abs=0) and r_se[1].item() == pytest.approx(
            want[1], rel=1e-12, abs=0
        )
    # one value by hand: UAV at (0,5) relaying? no: UAV (2,2) relaying, (1,1) sensing
    # PT (0,5,0)->(2,2,10): d^2 = 4+9+100 = 113; (2,2,10)->PR (10,5,0): 64+9+100 = 173
    # S (-5,5,10)->(1,1,10): 36+16 = 52; (1,1,10)->E (15,5,10): 196+16 = 212
    a_pu = 200 * (2 / 113**2) * (2 / 173**2)
    a_se = 200 * (2 / 52**2) * (2 / 212**2)
    r_pu, r_se, _ = env.utility(torch.tensor([[[2, 2], [1, 1]]] * 2), torch.tensor([[1, 0]] * 2))
    assert r_pu[0].item() == pytest.approx(math.log2(1 + a_pu / (1 + a_pu)), rel=1e-12)
    assert r_se[0].item() == pytest.approx(math.log2(1 + a_se / (1 + a_se)), rel=1e-12)


def test_state_index_and_observation_layout():
    """The tabular state s = sum c_i C^i (or base 2C with tasks); observation and state blocks as documented."""
    L1, L2, N = 4, 3, 3
    for with_tasks in (False, True):
        env = UAVSpectrumEnv(batch_size=4, grid=(L1, L2), num_uavs=N, seed=5, state_includes_tasks=with_tasks)
        td = env.reset()
        C = L1 * L2
        for w in range(4):
            cells = [y * L1 + x for x, y in xy_list(td, w)]
            tasks = td["tasks"][w].tolist()
            digits = [2 * c + t for c, t in zip(cells, tasks, strict=True)] if with_tasks else cells
            base = 2 * C if with_tasks else C
            assert td["state_index"][w].item() == sum(d * base**i for i, d in enumerate(digits))
            obs, state = td["agents", "observation"][w], td["state"][w]
            assert obs.shape == (N, 3 + 10 + 3 * (N - 1)) and state.shape == (5 * N + 12,)
            with_nodes = observation_with_nodes(obs, state)  # the earlier layout: nodes after the observation
            assert torch.equal(with_nodes[:, : obs.shape[-1]], obs) and with_nodes.shape == (N, obs.shape[-1] + 12)
            xyt = [(x / (L1 - 1), y / (L2 - 1), float(t)) for (x, y), t in zip(xy_list(td, w), tasks, strict=True)]
            for i in range(N):
                assert obs[i, :3].tolist() == pytest.approx(xyt[i])
                others = [v for j in list(range(i + 1, N)) + list(range(i)) for v in xyt[j]]
                assert obs[i, 13 : 13 + 3 * (N - 1)].tolist() == pytest.approx(others)
                assert with_nodes[i, -12:].tolist() == state[-12:].tolist()
                assert state[5 * i : 5 * i + 3].tolist() == pytest.approx(xyt[i])
                assert state[5 * i + 3 : 5 * i + 5].tolist() == obs[i, 3:5].tolist()
                x, y = xy_list(td, w)[i]
                assert td["agents", "action_mask"][w, i].tolist() == [y > 0, y < L2 - 1, x > 0, x < L1 - 1, True, True]
    nodes = line_nodes(L1, L2, float(L1))
    assert td["state"][0, -12:].tolist() == pytest.approx(
        [v / s for node in nodes for v, s in zip(node, (L1, L2, L1), strict=True)]
    )


# ----------------------------------------------------------------- dynamics properties
@st.composite
def scenarios(draw):
    L1, L2 = draw(st.integers(1, 4)), draw(st.integers(1, 4))
    N = draw(st.integers(1, min(4, L1 * L2)))
    B = draw(st.integers(1, 3))
    steps = draw(st.integers(1, 10))
    actions = draw(
        st.lists(st.lists(st.integers(0, 5), min_size=B * N, max_size=B * N), min_size=steps, max_size=steps)
    )
    options = dict(
        layout=draw(st.sampled_from(["line", "random"])),
        reward=draw(st.sampled_from(["delta", "best_so_far"])),
        beta1=draw(st.sampled_from([1.0, 0.5, 2.0])),
        beta2=draw(st.sampled_from([1.0, 0.25])),
        init_tasks=draw(st.sampled_from(["random", "sensing", "relaying"])),
    )
    return (L1, L2), N, B, draw(st.integers(0, 2**40)), actions, options


@PROPERTY_SETTINGS
@given(scenarios())
def test_dynamics_follow_spec(scenario):
    """Any action sequence (invalid joint actions included): docs/model.md's move resolution, counts, grid, rewards."""
    (L1, L2), N, B, seed, actions, options = scenario
    env = UAVSpectrumEnv(batch_size=B, grid=(L1, L2), num_uavs=N, seed=seed, max_steps=100, **options)
    td = env.reset()
    start = td.clone()
    rewards = torch.zeros(B, dtype=torch.float64)
    best = [0.0] * B
    for joint in actions:
        out = step_with(env, td, joint)["next"]
        utility = env.utility(out["positions"], out["tasks"])[
            2
        ]  # float64: the reward is computed before the float32 cast
        for w in range(B):
            a = joint[w * N : (w + 1) * N]
            before, tasks_before = xy_list(td, w), td["tasks"][w].tolist()
            after = xy_list(out, w)
            assert after == resolve(before, a, L1, L2)
            assert all(0 <= x < L1 and 0 <= y < L2 for x, y in after) and len(set(after)) == N
            assert out["tasks"][w].tolist() == new_tasks(tasks_before, a)
            assert out["moves"][w].item() == sum(p != q for p, q in zip(before, after, strict=True))
            assert out["task_switches"][w].item() == sum(
                p != q for p, q in zip(tasks_before, out["tasks"][w].tolist(), strict=True)
            )
            total = utility[w].item()
            assert out["utility"][w].item() == pytest.approx(total, rel=1e-6, abs=1e-6)
            if options["reward"] == "best_so_far":
                diff = total - best[w]
                want = 10 * diff if diff > 0 else diff
                assert out["reward"][w, 0].item() == pytest.approx(want, rel=1e-6, abs=1e-9)
                best[w] = max(best[w], total)
        rewards += out["reward"][:, 0].double()
        td = out
    if options["reward"] == "delta":
        weighted = [
            options["beta1"] * s["r_pu"][:, 0].double() + options["beta2"] * s["r_se"][:, 0].double()
            for s in (start, td)
        ]
        torch.testing.assert_close(rewards, weighted[1] - weighted[0], rtol=0, atol=1e-4)


@pytest.mark.parametrize(
    "grid,start,actions,end,switches",
    [
        ((3, 1), [(0, 0), (1, 0)], [3, 2], [(1, 0), (0, 0)], 0),  # swap
        ((3, 1), [(0, 0), (1, 0)], [3, 5], [(0, 0), (1, 0)], 1),  # into a UAV that stays (task action): cancelled
        ((3, 1), [(0, 0), (1, 0)], [3, 3], [(1, 0), (2, 0)], 0),  # a train: UAV0 follows UAV1 into the freed cell
        ((3, 1), [(0, 0), (1, 0)], [2, 0], [(0, 0), (1, 0)], 0),  # both off the grid: both stay
        ((3, 1), [(0, 0), (2, 0)], [3, 2], [(0, 0), (2, 0)], 0),  # both into the middle: both cancelled
        ((3, 1), [(1, 0), (2, 0)], [3, 3], [(1, 0), (2, 0)], 0),  # UAV1 off the grid stays, so UAV0 is cancelled
        (
            (4, 1),
            [(1, 0), (2, 0), (3, 0)],
            [3, 3, 3],
            [(1, 0), (2, 0), (3, 0)],
            0,
        ),  # a chain: cancelled over two rounds
        ((4, 1), [(0, 0), (1, 0), (3, 0)], [3, 3, 2], [(0, 0), (1, 0), (3, 0)], 0),  # two into cell 2, then UAV0 behind
        ((2, 2), [(0, 0), (1, 0), (1, 1)], [3, 1, 2], [(1, 0), (1, 1), (0, 1)], 0),  # a rotation with a free cell
        ((2, 2), [(0, 0), (1, 0), (1, 1), (0, 1)], [3, 1, 2, 0], [(1, 0), (1, 1), (0, 1), (0, 0)], 0),  # a full cycle
        (
            (2, 2),
            [(0, 0), (1, 0), (1, 1), (0, 1)],
            [3, 1, 2, 4],
            [(0, 0), (1, 0), (1, 1), (0, 1)],
            0,
        ),  # a blocked cycle
    ],
)
def test_swaps_and_cancelled_moves(grid, start, actions, end, switches):
    """Moves: swaps and cycles are allowed, clashing moves are cancelled (in chains) and count as no move."""
    env = UAVSpectrumEnv(batch_size=1, grid=grid, num_uavs=len(start), init_tasks="sensing")
    for seed in range(3000):
        env.set_seed(seed)
        td = env.reset()
        if xy_list(td, 0) == start:
            break
    else:
        raise AssertionError(f"no seed starts at {start}")
    out = step_with(env, td, actions)["next"]
    assert xy_list(out, 0) == end == resolve(start, actions, *grid)
    assert (
        out["moves"].item() == sum(p != q for p, q in zip(start, end, strict=True))
        and out["task_switches"].item() == switches
    )


def test_truncation_and_keep_positions():
    env = UAVSpectrumEnv(batch_size=2, grid=(3, 3), num_uavs=2, max_steps=3, reset_positions="keep", seed=1)
    gen = torch.Generator().manual_seed(1)
    td = env.reset()
    for t in range(1, 4):
        td.set(("agents", "action"), masked_random_actions(td, gen))
        td = env.step(td)
        assert td["next", "truncated"].all() == (t == 3) and not td["next", "terminated"].any()
        assert td["next", "done"].equal(td["next", "truncated"])
        last = td["next"]
        td = step_mdp(td)
    again = env.reset()
    assert again["positions"].equal(last["positions"]) and again["tasks"].equal(last["tasks"])
    assert not again["done"].any()


def test_best_so_far_reward_values():
    """r = 10 (S - M) above the best M of earlier steps (0 at the first step), 0 level, S - M below."""
    env = UAVSpectrumEnv(batch_size=4, grid=(3, 3), num_uavs=3, reward="best_so_far", seed=4, max_steps=6)
    gen = torch.Generator().manual_seed(2)
    for _ in range(2):  # two episodes: M restarts at 0
        td = env.reset()
        best = torch.zeros(4, dtype=torch.float64)
        for _ in range(6):
            td.set(("agents", "action"), torch.randint(0, 6, (4, 3), generator=gen))
            td = env.step(td)
            s = env.utility(td["next", "positions"], td["next", "tasks"])[2]  # float64
            diff = s - best
            want = torch.where(diff > 0, 10 * diff, diff)
            torch.testing.assert_close(td["next", "reward"][:, 0].double(), want, rtol=1e-6, atol=1e-9)
            best = torch.maximum(best, s)
            td = step_mdp(td)
    # staying put after reaching a best gives exactly 0
    td = env.reset()
    td = step_with(env, td, [[4, 4, 4]] * 4)
    td = step_with(env, step_mdp(td), [[4, 4, 4]] * 4)
    assert td["next", "reward"].eq(0).all()


# ----------------------------------------------------------------- batching, seeding, partial resets
def trajectory(env, actions_fn, steps):
    """Outputs of ``steps`` steps with auto partial resets, as a list of TensorDicts."""
    td = env.reset()
    out = [td.select(*OUTPUT_KEYS).clone()]
    for t in range(steps):
        td.set(("agents", "action"), actions_fn(t))
        td, td_next = env.step_and_maybe_reset(td)
        out.append(td.get("next").select(*OUTPUT_KEYS, "reward", "done").clone())
        out.append(td_next.select(*OUTPUT_KEYS).clone())
        td = td_next
    return out


@pytest.mark.parametrize(
    "options",
    [
        {"layout": "line"},
        {"layout": "random"},
        {"fading": "rayleigh"},
        {"layout": "random", "fading": "rayleigh", "direct_links": True},
    ],
)
def test_world_i_equals_single_world_seeded_s_plus_i(options):
    B, N, seed, steps = 5, 3, 123, 14
    acts = torch.randint(0, 6, (steps, B, N), generator=torch.Generator().manual_seed(9))
    big = UAVSpectrumEnv(batch_size=B, grid=(4, 3), num_uavs=N, seed=seed, max_steps=4, **options)
    full = trajectory(big, lambda t: acts[t], steps)
    for i in range(B):
        one = UAVSpectrumEnv(batch_size=1, grid=(4, 3), num_uavs=N, seed=seed + i, max_steps=4, **options)
        single = trajectory(one, lambda t, i=i: acts[t, i : i + 1], steps)
        for a, b in zip(full, single, strict=True):
            assert (a[i : i + 1] == b).all(), f"world {i} differs"
        torch.testing.assert_close(big.cell_contributions[i], one.cell_contributions[0], rtol=0, atol=0)


def test_same_seed_same_trajectory_and_reseeding():
    acts = torch.randint(0, 6, (10, 4, 2), generator=torch.Generator().manual_seed(0))
    runs = []
    for _ in range(2):
        env = UAVSpectrumEnv(
            batch_size=4, grid=(5, 5), num_uavs=2, seed=7, max_steps=3, layout="random", fading="rayleigh"
        )
        runs.append(trajectory(env, lambda t: acts[t], 10))
    env.set_seed(7)
    runs.append(trajectory(env, lambda t: acts[t], 10))
    env.set_seed(8)
    other = trajectory(env, lambda t: acts[t], 10)
    for a, b, c in zip(*runs, strict=True):
        assert (a == b).all() and (a == c).all()
    assert not all((a == o).all() for a, o in zip(runs[0], other, strict=True))


@pytest.mark.parametrize("layout", ["line", "random"])
def test_partial_reset_touches_only_masked_worlds(layout):
    """ "_reset" re-initialises the masked worlds (exactly as a lone world would) and leaves the others alone."""
    B, N, seed = 6, 3, 2
    acts = torch.randint(0, 6, (3, B, N), generator=torch.Generator().manual_seed(3))
    env = UAVSpectrumEnv(batch_size=B, grid=(5, 4), num_uavs=N, seed=seed, max_steps=5, layout=layout)
    td = env.reset()
    for t in range(3):
        td.set(("agents", "action"), acts[t])
        td = step_mdp(env.step(td))
    contrib = env.cell_contributions  # a copy: later resets must not change it
    saved = contrib.clone()
    mask = torch.tensor([True, False, True, False, False, True])
    td.set("_reset", mask.unsqueeze(-1))
    out = env.reset(td)
    keep = ~mask
    for key in OUTPUT_KEYS:
        assert out[key][keep].equal(td[key][keep]), key
    assert env.cell_contributions[keep].equal(contrib[keep]) and contrib.equal(saved)
    for w in mask.nonzero()[:, 0].tolist():  # a lone world seeded seed + w, same actions, then reset
        one = UAVSpectrumEnv(batch_size=1, grid=(5, 4), num_uavs=N, seed=seed + w, max_steps=5, layout=layout)
        alone = one.reset()
        for t in range(3):
            alone.set(("agents", "action"), acts[t, w : w + 1])
            alone = step_mdp(one.step(alone))
        alone = one.reset()
        assert (out[w : w + 1].select(*OUTPUT_KEYS) == alone.select(*OUTPUT_KEYS)).all()
        assert one.cell_contributions[0].equal(env.cell_contributions[w])
    # episode clocks: the others truncate after 2 more steps, the reset worlds do not
    for _ in range(2):
        out.set(("agents", "action"), torch.full((B, N), 4))
        stepped = env.step(out)
        out = step_mdp(stepped)
    assert stepped["next", "truncated"][:, 0].equal(keep)


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"preset": "reference_code"},
        {"direct_links": True, "lease_rule": False},
        {"state_includes_tasks": True, "reward": "best_so_far"},
        {"fading": "rayleigh"},
    ],
)
def test_two_uav_pair_tables_agree_with_the_generic_path(options):
    """Two UAVs on a fixed layout read observation, state and rates from cached pair tables; the generic path must
    agree."""
    acts = torch.randint(0, 6, (12, 6, 2), generator=torch.Generator().manual_seed(4))
    fast = UAVSpectrumEnv(batch_size=6, grid=(4, 3), num_uavs=2, seed=8, max_steps=5, **options)
    generic = UAVSpectrumEnv(batch_size=6, grid=(4, 3), num_uavs=2, seed=8, max_steps=5, **options)
    assert fast.world._pair_obs is not None
    generic.world._pair_obs = generic.world._pair_state = generic.world._pair_rates = (
        None  # white box: force the generic assembly
    )
    for a, b in zip(trajectory(fast, lambda t: acts[t], 12), trajectory(generic, lambda t: acts[t], 12), strict=True):
        assert (a == b).all()


# ----------------------------------------------------------------- Rayleigh fading
@pytest.mark.parametrize("measured", ["source", "destination"])
def test_rayleigh_power_gain_is_exp1(measured):
    """X ~ Exp(1) per link and step: recovered exactly from the rates when the other hop is made ~noise-free.

    With one hop's power huge, c = g1 g2 / (1 + g1 + g2) = g_measured (1 - O(1e-12)), so
    2^(2R) - 1 = k X with k = P |h|^2 / sigma^2 computed by hand; 2x1 grid, UAV0 relays, UAV1 senses.
    """
    L1, L2, h, cell, noise, small, huge = 2, 1, 2.0, 10.0, 1e-9, 1e-7, 1e6
    if measured == "source":
        powers = dict(p_pt=small, p_s=small, p_u=huge)
    else:
        powers = dict(p_pt=huge, p_s=huge, p_u=small)
    env = UAVSpectrumEnv(
        batch_size=1024, grid=(L1, L2), num_uavs=2, fading="rayleigh", seed=2024, noise=noise, max_steps=10**6, **powers
    )
    PT, PR, S, E = line_nodes(L1, L2, h)
    td = env.reset()
    xs = {"pu": [], "se": []}
    for _ in range(60):
        td = step_with(env, td, [[5, 4]] * 1024)
        out = td["next"]
        for w_key, r_key, node in (
            ("pu", "r_pu", PT if measured == "source" else PR),
            ("se", "r_se", S if measured == "source" else E),
        ):
            uav = 0 if w_key == "pu" else 1
            xy = out["positions"][:, uav].double()
            d2 = ((xy[:, 0] - node[0]) ** 2 + (xy[:, 1] - node[1]) ** 2 + (h - node[2]) ** 2) * cell**2
            k = small / d2 / noise
            xs[w_key].append((torch.exp2(2 * out[r_key][:, 0].double()) - 1) / k)
        td = step_mdp(td)
    for key in xs:
        x = torch.cat(xs[key])
        assert x.min() >= 0
        # n = 61,440 draws: sd(mean) = 0.004, sd(var) ~ 0.02; tolerances at > 7 sd, and the seeds are fixed
        assert x.mean().item() == pytest.approx(1.0, abs=0.03)
        assert x.var().item() == pytest.approx(1.0, abs=0.15)
        assert (x > 1).double().mean().item() == pytest.approx(math.exp(-1), abs=0.015)
        assert (x > 3).double().mean().item() == pytest.approx(math.exp(-3), abs=0.006)
    both = torch.stack([torch.cat(xs["pu"]), torch.cat(xs["se"])])
    assert abs(torch.corrcoef(both)[0, 1].item()) < 0.03  # independent links
    # fresh draws every step: consecutive steps of one world are uncorrelated
    per_step = torch.stack(xs["pu"])  # [steps, worlds]
    lag = torch.corrcoef(torch.stack([per_step[1:].flatten(), per_step[:-1].flatten()]))[0, 1]
    assert abs(lag.item()) < 0.03


def test_rayleigh_fades_direct_links():
    """The channel's "every link": with direct links on, PT->PR and S->E get their own Exp(1) draws.

    The UAV hops are silenced (P_U = 1e-30 W makes their contributions < 1e-20), so
    2^(2R) - 1 = k X with k = P |h|^2 / sigma^2 of the direct link (d = L1 and 2 L1 cells).
    """
    L1, noise = 2, 1e-9
    p_pt, p_s = 1e-7, 4e-7  # k = 1e-7 / 20^2 / 1e-9 = 0.25 and 4e-7 / 40^2 / 1e-9 = 0.25
    env = UAVSpectrumEnv(
        batch_size=1024,
        grid=(L1, 1),
        num_uavs=2,
        fading="rayleigh",
        direct_links=True,
        seed=77,
        p_pt=p_pt,
        p_s=p_s,
        p_u=1e-30,
        noise=noise,
        max_steps=10**6,
    )
    k_pu, k_se = p_pt / (L1 * 10.0) ** 2 / noise, p_s / (2 * L1 * 10.0) ** 2 / noise
    td = env.reset()
    xs = {"r_pu": [], "r_se": []}
    for _ in range(40):
        td = step_with(env, td, [[5, 4]] * 1024)
        for key, k in (("r_pu", k_pu), ("r_se", k_se)):
            xs[key].append((torch.exp2(2 * td["next", key][:, 0].double()) - 1) / k)
        td = step_mdp(td)
    pu, se = torch.cat(xs["r_pu"]), torch.cat(xs["r_se"])
    for x in (pu, se):  # n = 40,960: sd(mean) = 0.005
        assert x.mean().item() == pytest.approx(1.0, abs=0.04) and x.var().item() == pytest.approx(1.0, abs=0.2)
        assert (x > 1).double().mean().item() == pytest.approx(math.exp(-1), abs=0.02)
    assert abs(torch.corrcoef(torch.stack([pu, se]))[0, 1].item()) < 0.04
    assert env.direct[0].tolist() == pytest.approx([k_pu, k_se], rel=1e-12)  # the deterministic (mean) values


def test_fading_none_is_deterministic_and_utility_ignores_fading():
    env = UAVSpectrumEnv(batch_size=8, grid=(4, 4), num_uavs=2, fading="rayleigh", seed=1)
    td = env.reset()
    det = UAVSpectrumEnv(batch_size=8, grid=(4, 4), num_uavs=2, seed=1)
    det_td = det.reset()
    assert td["positions"].equal(det_td["positions"]) and td["tasks"].equal(det_td["tasks"])
    u_env = env.utility(td["positions"], td["tasks"])[2]
    torch.testing.assert_close(u_env.float(), det_td["utility"][:, 0], rtol=1e-6, atol=1e-6)
    assert not torch.allclose(td["utility"], det_td["utility"])


# ----------------------------------------------------------------- TorchRL integration
@pytest.mark.parametrize(
    "B,grid,N,preset,options",
    [
        (1, (1, 1), 1, "paper", {}),
        (1, (1, 3), 2, "paper", {}),
        (3, (2, 2), 4, "paper", {"layout": "random"}),
        (4, (6, 6), 2, "paper", {"fading": "rayleigh", "state_includes_tasks": True}),
        (2, (3, 3), 2, "reference_code", {}),
        (2, (20, 20), 10, "paper", {}),  # no state_index: 400^10 does not fit int64
    ],
)
def test_check_env_specs(B, grid, N, preset, options):
    env = UAVSpectrumEnv(batch_size=B, grid=grid, num_uavs=N, preset=preset, max_steps=5, **options)
    check_env_specs(env, seed=0)
    assert ("state_index" in env.observation_spec.keys()) == env.cfg.has_state_index
    assert ("nodes" in env.observation_spec.keys()) == (env.cfg.layout == "random")


@pytest.mark.parametrize("preset,options", [("paper", {}), ("a2g_urban", {"fading": "los_nlos"})])
def test_random_layouts_publish_the_nodes_every_table_is_computed_from(preset, options):
    """``nodes`` after a reset and a step, and after an auto-reset's new layouts, give the env's own tables through
    the channel functions, bit for bit (what the oracle plans on)."""
    from uavrl.envs.physics.channel import cell_xyz, direct_terms, link_gains, relay_contributions

    env = UAVSpectrumEnv(batch_size=3, grid=(4, 4), num_uavs=2, preset=preset, max_steps=2, layout="random", **options)
    td = env.rollout(3, break_when_any_done=False)  # the third step starts from new layouts
    assert td["next", "nodes"].dtype == torch.float64 and td["next", "nodes"].shape == (3, 3, 4, 3)
    assert not torch.equal(td["nodes"][:, 0], td["nodes"][:, 2])
    nodes = env.reset()["nodes"]
    assert torch.equal(nodes, env.world.nodes)
    contributions = relay_contributions(link_gains(cell_xyz(env.cfg), nodes, env.cfg), env.cfg)
    assert torch.equal(contributions, env.cell_contributions) and torch.equal(direct_terms(nodes, env.cfg), env.direct)


def test_rollout_shapes_and_transforms():
    B, N, T = 3, 2, 7
    env = TransformedEnv(
        UAVSpectrumEnv(batch_size=B, grid=(3, 3), num_uavs=N, max_steps=5),
        Compose(
            ActionMask(action_key=("agents", "action"), mask_key=("agents", "action_mask")), StepCounter(), RewardSum()
        ),
    )
    check_env_specs(env, seed=0)
    td = env.rollout(T, break_when_any_done=False)
    assert td.batch_size == (B, T) and td["agents", "observation"].shape == (B, T, N, 16)
    # ActionMask: every sampled action is allowed by the mask
    chosen = td["agents", "action_mask"].gather(-1, td["agents", "action"].unsqueeze(-1))
    assert chosen.all()
    # StepCounter and RewardSum restart after the truncation at step 5
    assert td["next", "step_count"][:, :, 0].tolist() == [[1, 2, 3, 4, 5, 1, 2]] * B
    assert td["next", "truncated"][:, :, 0].tolist() == [[False] * 4 + [True, False, False]] * B
    rewards = td["next", "reward"][..., 0]
    torch.testing.assert_close(td["next", "episode_reward"][:, 4, 0], rewards[:, :5].sum(1))
    torch.testing.assert_close(td["next", "episode_reward"][:, 6, 0], rewards[:, 5:].sum(1))


def test_collector_with_partial_resets():
    """torchrl Collector: worlds end episodes at different times and are reset alone."""
    from uavrl.envs.compat import make_collector

    B, T = 3, 4
    base = UAVSpectrumEnv(batch_size=B, grid=(3, 3), num_uavs=2, max_steps=T, seed=5)
    env = TransformedEnv(base, RewardSum())
    gen = torch.Generator().manual_seed(0)

    def policy(td):
        td.set(("agents", "action"), masked_random_actions(td, gen))
        return td

    collector = make_collector(env, policy, frames_per_batch=B * 10, total_frames=B * 20)
    base.world._s.steps += torch.tensor([0, 1, 2])  # desynchronise the episode clocks (white box)
    batches = [b.clone() for b in collector]
    collector.shutdown()
    data = torch.cat(batches, 1)
    assert data.batch_size == (B, 20)
    done = data["next", "done"][..., 0]
    for w, offset in enumerate([0, 1, 2]):
        ends = [t for t in range(20) if done[w, t]]
        assert ends == [t for t in range(20) if (t + 1 + offset) % T == 0], (w, ends)
        for t in range(19):
            if done[w, t]:  # the next root observation is a fresh start: utility of the reset configuration
                assert data["episode_reward"][w, t + 1, 0].item() == 0.0
            else:  # continuing worlds carry their configuration over
                assert data["positions"][w, t + 1].equal(data["next", "positions"][w, t])
                assert data["tasks"][w, t + 1].equal(data["next", "tasks"][w, t])
        # per-episode reward sums: RewardSum resets with each world's own episodes
        for t in ends:
            start = max([e + 1 for e in ends if e < t], default=None)
            if start is not None:
                torch.testing.assert_close(
                    data["next", "episode_reward"][w, t, 0], data["next", "reward"][w, start : t + 1, 0].sum()
                )


# ----------------------------------------------------------------- bad input and numerical hygiene
def test_bad_actions_raise_clear_errors():
    env = UAVSpectrumEnv(batch_size=2, grid=(3, 3), num_uavs=2)
    env.reset()
    cases = [
        (torch.zeros(2, 3, dtype=torch.long), ValueError, "shape"),
        (torch.zeros(2, dtype=torch.long), ValueError, "shape"),
        (torch.zeros(2, 2), TypeError, "dtype"),
        (torch.zeros(2, 2, dtype=torch.bool), TypeError, "dtype"),
        (torch.full((2, 2), 6), ValueError, "6"),
        (torch.tensor([[0, -1], [0, 0]]), ValueError, "-1"),
    ]
    for action, error, words in cases:
        td = TensorDict({("agents", "action"): action}, batch_size=[2])
        with pytest.raises(error, match=words):
            env.step(td)


def test_step_before_reset_is_a_clear_error():
    env = UAVSpectrumEnv(batch_size=2, grid=(3, 3), num_uavs=2)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(TensorDict({("agents", "action"): torch.zeros(2, 2, dtype=torch.long)}, batch_size=[2]))
    env.reset()
    env.step(TensorDict({("agents", "action"): torch.zeros(2, 2, dtype=torch.long)}, batch_size=[2]))


@pytest.mark.parametrize(
    "grid,N,options",
    [
        ((1, 1), 1, {}),
        ((1, 7), 3, {}),
        ((7, 1), 7, {}),
        ((1, 5), 2, {"layout": "random"}),
        ((3, 3), 9, {"layout": "random", "fading": "rayleigh", "direct_links": True}),
        ((2, 9), 4, {"layout": "random"}),
        ((1, 1), 1, {"preset": "reference_code"}),
        ((1, 4), 2, {"preset": "reference_code", "fading": "rayleigh"}),
    ],
)
def test_outputs_are_finite(grid, N, options):
    env = UAVSpectrumEnv(batch_size=16, grid=grid, num_uavs=N, max_steps=4, seed=17, **options)
    gen = torch.Generator().manual_seed(0)

    def policy(td):
        return td.set(("agents", "action"), torch.randint(0, 6, (16, N), generator=gen))

    td = env.rollout(10, policy, break_when_any_done=False)
    for key, value in td.items(True, True):
        if value.dtype.is_floating_point:
            assert torch.isfinite(value).all(), key
    assert torch.isfinite(env.cell_contributions).all() and torch.isfinite(env.optimum()[0]).all()


def test_q_value_modules_accept_the_action_spec():
    """TorchRL finds action spaces by exact type: the env's MaskedCategorical must be known as categorical."""
    from torchrl.modules import QValueModule

    spec = UAVSpectrumEnv(batch_size=2, grid=(3, 3), num_uavs=2).full_action_spec_unbatched["agents", "action"]
    module = QValueModule(spec=spec, action_value_key="values", action_mask_key="mask")
    assert module.action_space == "categorical"


def test_masked_random_actions_are_uniform_over_the_allowed_ones():
    """MaskedCategorical.rand (what ActionMask's random actions call): only allowed actions, each equally likely."""
    torch.manual_seed(0)
    patterns = torch.tensor([[1, 1, 1, 1, 1, 1], [0, 1, 0, 1, 1, 1], [1, 0, 0, 0, 0, 1], [0, 0, 0, 0, 1, 0]]).bool()
    spec = MaskedCategorical(6, (4, 20_000), dtype=torch.long)
    spec.update_mask(patterns[:, None].expand(4, 20_000, 6))
    draws = spec.rand()
    assert draws.shape == (4, 20_000) and draws.dtype == torch.long
    for pattern, drawn in zip(patterns, draws, strict=True):
        counts = torch.bincount(drawn, minlength=6).double()
        assert (counts[~pattern] == 0).all()
        k = int(pattern.sum())
        expected, sd = 20_000 / k, math.sqrt(20_000 * (1 / k) * (1 - 1 / k))
        assert ((counts[pattern] - expected).abs() <= 5 * sd).all()
    spec.update_mask(None)
    assert spec.rand().unique().tolist() == list(range(6))
    mask = ActionMask(action_key=("agents", "action"), mask_key=("agents", "action_mask"))
    env = TransformedEnv(UAVSpectrumEnv(batch_size=64, grid=(3, 3), num_uavs=2), mask)
    td = env.rollout(20)
    assert td["agents", "action_mask"].gather(-1, td["agents", "action"].unsqueeze(-1)).all()


@pytest.mark.parametrize("options", [dict(num_uavs=2), dict(num_uavs=3, layout="random", fading="rayleigh")])
def test_without_diagnostics_the_env_returns_the_same_steps_without_those_keys(options):
    """diagnostics=False: the specs hold, the diagnostic keys are gone, and every other key is what the full env
    returns for the same seed and actions."""
    lean = UAVSpectrumEnv(batch_size=16, grid=(4, 4), seed=3, diagnostics=False, **options)
    check_env_specs(lean, seed=0)
    full = UAVSpectrumEnv(batch_size=16, grid=(4, 4), seed=3, **options)
    lean.set_seed(3), full.set_seed(3)
    policy = RandomPolicy(seed=0)
    lean_steps = lean.rollout(12, policy, break_when_any_done=False)
    full_steps = full.rollout(12, RandomPolicy(seed=0), break_when_any_done=False)
    diagnostics = {*DIAGNOSTICS} - {"state_index"} if not lean.world.state_index_fits else {*DIAGNOSTICS}
    assert {*full_steps["next"].keys()} - {*lean_steps["next"].keys()} == diagnostics
    for key in lean_steps.keys(include_nested=True, leaves_only=True):
        assert torch.equal(lean_steps[key], full_steps[key]), key
    with pytest.raises(ValueError, match="diagnostics='no' is invalid: give True or False"):
        UAVSpectrumEnv(diagnostics="no")


@pytest.mark.parametrize("options", [dict(num_uavs=2), dict(num_uavs=3, layout="random", fading="rayleigh")])
def test_log_gap_reward_is_the_change_of_the_potential_of_the_mean_channel_utility(options):
    """reward='log_gap': each step's reward is the change of -log(1 - U/U* + floor), U the mean-channel utility of
    the configuration and U* the exact optimum of the world's layout, whatever the fading draws."""
    from uavrl.envs.physics.rewards import log_gap_potential

    env = UAVSpectrumEnv(batch_size=8, grid=(4, 4), reward="log_gap", seed=1, **options)
    td = env.rollout(10, RandomPolicy(seed=2), break_when_any_done=False)
    u_star = env.optimum()[0]
    positions = torch.cat([td["positions"][:, :1], td["next", "positions"]], 1)
    tasks = torch.cat([td["tasks"][:, :1], td["next", "tasks"]], 1)
    potential = log_gap_potential(env.utility(positions, tasks)[2], u_star[:, None])
    torch.testing.assert_close(td["next", "reward"][..., 0], potential.diff(dim=1).float())


def test_the_env_checks_each_action_once_in_its_step_hook(monkeypatch):
    """The action is checked once per step, in ``_step`` (TorchRL's hook), whether through ``step`` or ``rollout``;
    ``step``, ``reset`` and ``rollout`` refuse only what ``EnvBase`` reads before any hook."""
    env = UAVSpectrumEnv(batch_size=3, grid=(4, 4), max_steps=10)
    checked = []
    check = env._check_action_tensor
    monkeypatch.setattr(env, "_check_action_tensor", lambda action: checked.append(1) or check(action))
    env.rollout(4, break_when_any_done=False)
    assert len(checked) == 4
    env.step(env.rand_action(env.reset()))
    assert len(checked) == 5


def test_the_world_shows_its_state_through_public_properties():
    """``was_reset``, ``state`` and ``state_index_fits``: what the env, the renderer and the mission solver read."""
    env = UAVSpectrumEnv(batch_size=2, grid=(3, 3), max_steps=5)
    world = env.world
    assert not world.was_reset and world.state_index_fits
    td = env.reset()
    assert world.was_reset and torch.equal(world.state.cell, world.code >> 1)
    assert torch.equal(world.state.task, td["tasks"])
    energy = UAVSpectrumEnv(batch_size=2, grid=(3, 3), energy="rotary_wing", base=(-1, 0))
    assert not energy.world.state_index_fits and "state_index" not in energy.reset().keys()
