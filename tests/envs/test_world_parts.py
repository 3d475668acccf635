"""The World's parts (docs/architecture.md, The World's parts), each used alone, and Rician fading.

The Rician power gain is checked against a formula written here with complex numbers, against
``scipy.stats.rice`` and against its moments ``E[X] = 1`` and ``E[X^2] = (2 + 4K + K^2) / (K + 1)^2``; the World's
faded rates are checked by recovering ``X`` from them as tests/envs/test_env.py does for Rayleigh fading.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from scipy import stats

from uavrl.agents.tabular import TabularModel
from uavrl.agents.tabular.tables import exact_q_table
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.config import FADINGS, InvalidOption
from uavrl.envs.limits import FADING_PEAKS, fixed_node_positions
from uavrl.envs.physics import streams
from uavrl.envs.physics.dynamics import UAV_STATE, Dynamics
from uavrl.envs.physics.fading import FADING_PARTS, Fading, fading_part, rician_power, rician_shares
from uavrl.envs.physics.layouts import Layouts
from uavrl.envs.physics.rewards import TeamReward
from uavrl.envs.world import World


def second_moment(k: float) -> float:
    """``E[X^2]`` of a Rician power gain of mean 1 and K-factor ``k`` (linear)."""
    return (2 + 4 * k + k**2) / (k + 1) ** 2


def rician_draws(k_db: float, worlds: int = 4096, events: int = 2) -> torch.Tensor:
    """The Rician part's draws ``X`` on unit mean gains: ``worlds x events x 6 UAVs x 4 links`` of them."""
    part = fading_part(make_config("paper", grid=(4, 4), num_uavs=6, fading="rician", rician_k_db=k_db))
    keys = streams.world_keys(11, worlds)
    draws = [part.gains(torch.ones(worlds, 6, 4), keys, torch.full((worlds,), e)) for e in range(events)]
    return torch.cat([d.flatten() for d in draws]).double()


# ----------------------------------------------------------------- Rician fading, the part alone
@pytest.mark.parametrize("k_db", [-10.0, 0.0, 9.0, 20.0])
def test_rician_draw_is_the_complex_formula_of_its_uniforms(k_db):
    """X = |sqrt(K / (K + 1)) + sqrt(1 / (K + 1)) CN(0, 1)|^2, CN(0, 1) = (n1 + i n2) / sqrt(2) from Box-Muller,
    written here with numpy's complex numbers from the same uniforms (the part's stream purpose, two per link)."""
    worlds, k = 64, 10 ** (k_db / 10)
    keys, counters = streams.world_keys(3, worlds), torch.arange(worlds)
    part = fading_part(make_config("paper", grid=(3, 3), num_uavs=2, fading="rician", rician_k_db=k_db))
    got = part.gains(torch.ones(worlds, 2, 4), keys, counters).numpy()
    u = streams.uniform(keys, counters, streams.RICIAN, 2 * 2 * 4).view(worlds, 2, 4, 2).numpy()
    radius, angle = np.sqrt(-2 * np.log(1 - u[..., 0])), 2 * np.pi * u[..., 1]
    cn = (radius * np.cos(angle) + 1j * radius * np.sin(angle)) / np.sqrt(2)
    want = np.abs(np.sqrt(k / (k + 1)) + np.sqrt(1 / (k + 1)) * cn) ** 2
    np.testing.assert_allclose(got, want, rtol=1e-12)


@pytest.mark.parametrize("k_db", [0.0, 3.0, 9.0, 20.0])
def test_rician_draws_follow_the_rice_distribution(k_db):
    """Mean 1, E[X^2] = (2 + 4K + K^2) / (K + 1)^2, and sqrt(X) passes a KS test against scipy's Rice law.

    n = 196,608 draws: sd(mean) <= 0.0023 and sd(E[X^2]) <= 0.006, tolerances over 4 sd; the seeds are fixed.
    """
    k, x = 10 ** (k_db / 10), rician_draws(k_db)
    assert x.mean().item() == pytest.approx(1.0, abs=0.01)
    assert (x**2).mean().item() == pytest.approx(second_moment(k), abs=0.025)
    amplitude = stats.rice(b=math.sqrt(2 * k), scale=math.sqrt(1 / (2 * (k + 1))))
    assert stats.kstest(x.sqrt().numpy(), amplitude.cdf).pvalue > 1e-3
    wrong = stats.rice(b=math.sqrt(2 * k) * 1.1, scale=math.sqrt(1 / (2 * (k + 1))))  # the test can tell 10% off
    assert stats.kstest(x.sqrt().numpy(), wrong.cdf).pvalue < 1e-6


def test_a_tiny_k_factor_is_rayleigh_fading_and_a_huge_one_no_fading():
    """K -> 0 (-40 dB): X ~ Exp(1) (E[X^2] = 2, P(X > 1) = e^-1); K -> infinity (40 dB): X -> 1 (var ~ 2 / K)."""
    x = rician_draws(-40.0)
    assert x.mean().item() == pytest.approx(1.0, abs=0.01) and (x**2).mean().item() == pytest.approx(2.0, abs=0.03)
    assert (x > 1).double().mean().item() == pytest.approx(math.exp(-1), abs=0.005)
    assert stats.kstest(x.numpy(), stats.expon.cdf).pvalue > 1e-3
    x = rician_draws(40.0)
    assert x.mean().item() == pytest.approx(1.0, abs=1e-3) and x.var().item() == pytest.approx(2e-4, rel=0.05)


def test_rician_shares_and_the_largest_draw_stay_finite_and_within_the_limits_bound():
    """K / (K + 1) + 1 / (K + 1) = 1 for every finite K-factor (no overflow), and the largest draw a 32-bit uniform
    can give stays under the bound envs/limits.py checks the options with (1 + 32 ln 2)."""
    for k_db in (-1e6, -300.0, -40.0, 0.0, 9.0, 40.0, 300.0, 1e6):
        los, scattered = rician_shares(k_db)
        assert los + scattered == pytest.approx(1.0, abs=1e-15) and 0 <= los <= 1 and 0 <= scattered <= 1
    largest_u1 = 1 - 2**-32  # the largest uniform of the streams
    for k_db in (-40.0, -3.0, 0.0, 3.0, 9.0, 40.0):
        peak = rician_power(torch.tensor([largest_u1, 0.0], dtype=torch.float64), rician_shares(k_db)).item()
        assert peak <= FADING_PEAKS["rician"]


# ----------------------------------------------------------------- Rician fading in the World
def recovered_power_gains(k_db: float, measured: str) -> torch.Tensor:
    """X of the PU source or destination hop, recovered from the rates: with the other hop's power huge, the AF term is
    the measured hop's SNR k X (1 - O(1e-12)), so X = (2^(2 R_PU) - 1) / k (2x1 grid, UAV 0 relays, UAV 1 senses).
    ``[steps, worlds]``."""
    L1, h, cell, noise, small, huge = 2, 2.0, 10.0, 1e-9, 1e-7, 1e6
    powers = dict(p_pt=small, p_s=small, p_u=huge) if measured == "source" else dict(p_pt=huge, p_s=huge, p_u=small)
    cfg = make_config(
        "paper", grid=(L1, 1), num_uavs=2, fading="rician", rician_k_db=k_db, noise=noise, max_steps=10**6, **powers
    )
    world = World(cfg, batch_size=1024, seed=5)
    world.reset()
    node = (0.0, 0.5, 0.0) if measured == "source" else (float(L1), 0.5, 0.0)  # PT or PR (layout=line)
    xs = []
    for _ in range(40):
        out, _, _ = world.step(torch.tensor([[5, 4]]).expand(1024, 2))
        x = out["positions"][:, 0].double()
        d2 = ((x[:, 0] - node[0]) ** 2 + (x[:, 1] - node[1]) ** 2 + h**2) * cell**2
        xs.append((torch.exp2(2 * out["r_pu"].double()) - 1) / (small / d2 / noise))
    return torch.stack(xs)


@pytest.mark.parametrize("measured", ["source", "destination"])
def test_the_worlds_rician_rates_carry_one_fresh_draw_per_link_and_step(measured):
    k_db = 6.0
    k, xs = 10 ** (k_db / 10), recovered_power_gains(k_db, measured)
    x = xs.flatten()  # n = 40,960: sd(mean) = 0.004, sd(E[X^2]) ~ 0.01
    assert x.mean().item() == pytest.approx(1.0, abs=0.02)
    assert (x**2).mean().item() == pytest.approx(second_moment(k), abs=0.05)
    amplitude = stats.rice(b=math.sqrt(2 * k), scale=math.sqrt(1 / (2 * (k + 1))))
    assert stats.kstest(x.sqrt().numpy(), amplitude.cdf).pvalue > 1e-3
    lag = torch.corrcoef(torch.stack([xs[1:].flatten(), xs[:-1].flatten()]))[0, 1]
    assert abs(lag.item()) < 0.03  # drawn anew every step


def test_rician_fades_the_direct_links():
    """Every link is Rician, the direct ones too: with the UAVs silenced (P_U = 1e-30 W), 2^(2R) - 1 = k X of the
    direct link PT->PR (d = L1 cells) and S->E (2 L1 cells)."""
    L1, noise, p_pt, p_s, k_db = 2, 1e-9, 1e-7, 4e-7, 3.0
    options = dict(fading="rician", rician_k_db=k_db, direct_links=True, p_u=1e-30, noise=noise, max_steps=10**6)
    world = World(make_config("paper", grid=(L1, 1), num_uavs=2, p_pt=p_pt, p_s=p_s, **options), 1024, seed=9)
    world.reset()
    k_pu, k_se = p_pt / (L1 * 10.0) ** 2 / noise, p_s / (2 * L1 * 10.0) ** 2 / noise
    pu, se = [], []
    for _ in range(40):
        out, _, _ = world.step(torch.tensor([[5, 4]]).expand(1024, 2))
        pu.append((torch.exp2(2 * out["r_pu"].double()) - 1) / k_pu)
        se.append((torch.exp2(2 * out["r_se"].double()) - 1) / k_se)
    k = 10 ** (k_db / 10)
    for x in (torch.cat(pu), torch.cat(se)):
        assert x.mean().item() == pytest.approx(1.0, abs=0.02)
        assert (x**2).mean().item() == pytest.approx(second_moment(k), abs=0.06)
    assert abs(torch.corrcoef(torch.stack([torch.cat(pu), torch.cat(se)]))[0, 1].item()) < 0.04


def run_world(cfg, seed: int, actions: torch.Tensor) -> list:
    """The outputs of a World of ``len(actions[0])`` worlds seeded ``seed`` over ``actions`` ``[T, B, N]``, finished
    episodes reset."""
    world = World(cfg, actions.shape[1], seed=seed)
    seen = [world.reset()]
    for action in actions:
        out, reward, done = world.step(action)
        seen.append({**out, "reward": reward, "done": done})
        if done.any():
            seen.append(world.reset(done.nonzero().squeeze(-1)))
    return seen


@pytest.mark.parametrize("options", [{}, {"layout": "random", "direct_links": True}])
def test_rician_worlds_are_deterministic_per_seed(options):
    """The same seed gives the same draws; world i of a batch seeded s is the lone world seeded s + i."""
    cfg = make_config("paper", grid=(4, 3), num_uavs=3, fading="rician", max_steps=5, **options)
    actions = torch.randint(0, 6, (12, 4, 3), generator=torch.Generator().manual_seed(1))
    batch, again, other = (run_world(cfg, seed, actions) for seed in (21, 21, 22))
    assert all(a[key].equal(b[key]) for a, b in zip(batch, again, strict=True) for key in a)
    assert not all(a["r_pu"].equal(b["r_pu"]) for a, b in zip(batch, other, strict=True))
    for i in range(4):
        alone = run_world(cfg, 21 + i, actions[:, i : i + 1])
        for a, b in zip(batch, alone, strict=True):
            for key in a:
                assert a[key][i : i + 1].equal(b[key]), (i, key)


def test_rician_on_every_channel_keeps_the_mean_channel_for_u_star():
    """A Rician world's U* and per-cell tables are those of fading=none (X has mean 1), on a power law and on a
    physical channel."""
    for preset, options in (("paper", {}), ("a2g_urban", {"grid": (5, 5), "num_uavs": 3})):
        faded = World(make_config(preset, fading="rician", rician_k_db=3.0, **options), 2)
        mean = World(make_config(preset, **options), 2)
        assert faded.optimum()[0].equal(mean.optimum()[0])
        assert faded.cell_contributions.equal(mean.cell_contributions)


def test_the_tabular_agent_refuses_a_random_channel():
    for fading in ("rician", "rayleigh"):
        cfg = make_config("paper", grid=(3, 3), fading=fading)
        with pytest.raises(ValueError, match=f"fading='{fading}' is invalid for agent=tabular"):
            TabularModel(cfg)
        with pytest.raises(ValueError, match="deterministic channels"):
            exact_q_table(cfg, gamma=0.3)


def test_rician_k_db_is_checked_and_read_only_under_rician_fading():
    assert make_config("paper", fading="rician").rician_k_db == 9.0  # TR 38.901 Table 7.5-6, UMa LoS
    assert make_config("paper", fading="rician", rician_k_db=-3).rician_k_db == -3
    for value in (math.inf, math.nan, "9", True):
        with pytest.raises(InvalidOption, match="rician_k_db=.* is invalid: it must be a finite number"):
            make_config("paper", fading="rician", rician_k_db=value)
    with pytest.raises(InvalidOption) as refused:
        make_config("paper", fading="rayleigh", rician_k_db=6.0)
    assert str(refused.value) == "rician_k_db=6.0 is invalid: only fading='rician' reads it, not fading='rayleigh'"


def test_rician_on_the_command_line(compose_cfg, command_exit, tmp_path):
    """``env.fading=rician env.rician_k_db=6`` compose into the run's model; the K-factor alone is refused in one
    line naming it as typed, before anything runs."""
    from uavrl.config import model_config

    model = model_config(compose_cfg("agent=dqn", "env.fading=rician", "env.rician_k_db=6"))
    assert (model.fading, model.rician_k_db) == ("rician", 6)
    assert model_config(compose_cfg("agent=dqn", "env.fading=rician")).rician_k_db == 9.0
    error = command_exit("train agent=dqn env.rician_k_db=6", tmp_path)
    assert error == "error: env.rician_k_db=6 is invalid: only env.fading='rician' reads it, not env.fading='none'"
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------- each part alone
def test_every_fading_name_has_a_part_that_says_whether_it_is_random():
    assert tuple(FADING_PARTS) == FADINGS
    assert {name: part.random for name, part in FADING_PARTS.items()} == {
        "none": False,
        "rayleigh": True,
        "los_nlos": True,
        "rician": True,
    }
    with pytest.raises(NotImplementedError, match="fading='none' draws nothing"):
        Fading(make_config()).gains(torch.ones(1, 2, 4), streams.world_keys(0, 1), torch.zeros(1, dtype=torch.long))


def test_the_fading_parts_tables_and_draws_alone():
    """Per layout: nothing for none, the mean gains for rayleigh and rician, (P_LoS, LoS gain, NLoS gain) for
    los_nlos; a draw of unit gains is X itself, mean 1 for Rayleigh (Exp(1)), P_LoS-weighted for los_nlos."""
    cell_xyz, nodes = torch.rand(5, 3, dtype=torch.float64), torch.rand(2, 4, 3, dtype=torch.float64) + 10
    mean = torch.rand(2, 5, 4, dtype=torch.float64)
    assert fading_part(make_config()).table(cell_xyz, nodes, mean) is None
    for fading in ("rayleigh", "rician"):
        assert fading_part(make_config(fading=fading)).table(cell_xyz, nodes, mean) is mean
    los_nlos = fading_part(make_config("a2g_urban", fading="los_nlos"))
    assert los_nlos.table(cell_xyz * 50, nodes * 50, mean).shape == (2, 5, 4, 3)
    keys, counters = streams.world_keys(1, 8192), torch.ones(8192, dtype=torch.long)
    x = fading_part(make_config(fading="rayleigh")).gains(torch.ones(8192, 2, 4), keys, counters)
    assert x.mean().item() == pytest.approx(1.0, abs=0.02) and x.var().item() == pytest.approx(1.0, abs=0.06)
    rows = torch.tensor([0.25, 2.0, 1.0]).expand(8192, 2, 4, 3)  # P_LoS 1/4, LoS gain 2, NLoS gain 1
    assert los_nlos.gains(rows, keys, counters).eq(2.0).double().mean().item() == pytest.approx(0.25, abs=0.01)
    snr = torch.full((8192, 2), 3.0, dtype=torch.float64)
    assert los_nlos.direct(snr, keys, counters) is snr  # its channels have no direct links


def test_the_layout_part_alone():
    """Fixed layouts are docs/model.md's; layout=random draws each world's nodes from its own stream, apart as the
    rules say, and the World's nodes after a reset are that draw."""
    cfg = make_config("paper", grid=(5, 4))
    assert Layouts(cfg).fixed.tolist() == [list(p) for p in fixed_node_positions("line", (5, 4), cfg.height)]
    random_cfg = cfg.replace(layout="random")
    layouts, keys = Layouts(random_cfg), streams.world_keys(4, 256)
    assert layouts.fixed is None
    nodes = layouts.sample(keys, torch.ones(256, dtype=torch.long))
    L1, L2 = cfg.grid
    diagonal = math.hypot(L1, L2)
    for pt, pr, s, e in nodes.tolist():
        assert pt[2] == pr[2] == 0.0 and s[2] == e[2] == cfg.height
        assert math.dist(pt[:2], pr[:2]) >= 0.6 * diagonal and math.dist(s[:2], e[:2]) >= 0.6 * diagonal
        for x, y, _ in (pt, pr, s, e):
            assert -L1 / 2 <= x < 1.5 * L1 and -L2 / 2 <= y < 1.5 * L2
        for x, y, _ in (s, e):  # S and E at least half a cell from every cell centre
            assert min(math.dist((x, y), (cx, cy)) for cx in range(L1) for cy in range(L2)) >= 0.5
    assert layouts.sample(keys[3:5], torch.ones(2, dtype=torch.long)).equal(nodes[3:5])  # per world, its own stream
    world = World(random_cfg, 256, seed=4)
    world.reset()
    assert world.nodes.equal(nodes)


def test_the_dynamics_part_alone():
    """docs/model.md's moves on a 3x2 grid: off the grid stays, sense and relay set the task, clashing moves are
    cancelled (a stayer blocks a mover, two movers into one cell), swaps go through; a reset's cells are distinct."""
    cfg = make_config("paper", grid=(3, 2), num_uavs=3, init_tasks="relaying")
    dynamics = Dynamics(cfg)
    state = SimpleNamespace(cell=torch.tensor([[0, 1, 5]] * 4), task=torch.tensor([[0, 1, 0]] * 4))
    actions = torch.tensor(
        [
            [0, 4, 5],  # up off the grid stays; UAV 1 senses, UAV 2 relays
            [3, 4, 4],  # UAV 0 right into UAV 1's cell, which stays: cancelled
            [3, 2, 1],  # UAV 0 and UAV 1 swap; UAV 2 down off the grid stays
            [1, 1, 2],  # 0 -> 3, 1 -> 4 and 5 -> 4 clash: 1 and 2 stay
        ]
    )
    after = dynamics.step(state, actions)
    assert after["cell"].tolist() == [[0, 1, 5], [0, 1, 5], [1, 0, 5], [3, 1, 5]]
    assert after["task"].tolist() == [[0, 0, 1], [0, 0, 0], [0, 1, 0], [0, 1, 0]]
    assert set(after) == set(UAV_STATE) and dynamics.terminated(state) is None
    assert dynamics.masks(torch.tensor([[0, 5]])).tolist() == [
        [[False, True, False, True, True, True], [True, False, True, False, True, True]]
    ]
    start = dynamics.start(streams.world_keys(0, 64), torch.ones(64, dtype=torch.long))
    assert all(len(set(row)) == 3 for row in start["cell"].tolist()) and start["task"].eq(1).all()


def test_the_reward_part_alone():
    """delta weighs the rate changes, best_so_far keeps the episode's best, log_gap reads the mean-channel rates
    (mean_rates) exactly when the channel is random."""
    r, prev, best, u_star = torch.tensor([[2.0, 1.0]]), torch.tensor([[1.5, 1.5]]), torch.tensor([2.5]), torch.ones(1)

    def never():
        raise AssertionError("a deterministic channel's log_gap must not ask for the mean-channel rates")

    delta = TeamReward(make_config(beta1=2.0, beta2=0.5), random_channel=False)
    assert delta(r, prev, best, u_star, never)[0].tolist() == [2.0 * 0.5 + 0.5 * -0.5]
    reward, new_best = TeamReward(make_config(reward="best_so_far"), False)(r, prev, best, u_star, never)
    assert reward.tolist() == [10 * 0.5] and new_best.tolist() == [3.0]
    u_star = torch.tensor([4.0])
    log_gap = TeamReward(make_config(reward="log_gap"), random_channel=False)(r, prev, best, u_star, never)[0]
    mean = (torch.tensor([[1.0, 1.0]]), torch.tensor([[0.5, 0.5]]))
    faded = TeamReward(make_config(reward="log_gap", fading="rayleigh"), True)(r, prev, best, u_star, lambda: mean)[0]
    gap = lambda u: -math.log(1 - u / 4.0 + 1e-4)  # noqa: E731
    assert log_gap.item() == pytest.approx(gap(3.0) - gap(3.0)) and faded.item() == pytest.approx(gap(2.0) - gap(1.0))


def test_the_world_names_its_parts_and_its_per_uav_state():
    world = World(make_config("paper", grid=(4, 4), num_uavs=3, fading="rician"), 2)
    assert set(world.parts) == {"layouts", "fading", "dynamics", "reward"} and world.fading.name == "rician"
    world.reset()
    for name in UAV_STATE:
        assert getattr(world._s, name).shape == (2, 3)
    assert world.code.equal(2 * world._s.cell + world._s.task)


# ----------------------------------------------------------------- termination
@pytest.mark.parametrize(
    "preset,options",
    [("paper", {}), ("paper", {"fading": "rician", "layout": "random", "num_uavs": 3}), ("reference_code", {})],
)
def test_nothing_terminates_an_episode_today(preset, options):
    """World.terminated is all False after every step and reset; the env publishes it, so done is the truncation."""
    cfg = make_config(preset, max_steps=3, **options)
    world = World(cfg, 4, seed=2)
    world.reset()
    for _ in range(4):
        _, _, truncated = world.step(torch.randint(0, 6, (4, cfg.num_uavs)))
        assert world.terminated.dtype == torch.bool and not world.terminated.any()
    env = UAVSpectrumEnv(batch_size=4, max_steps=3, preset=preset, seed=2, **options)
    rollout = env.rollout(7, break_when_any_done=False)
    assert not rollout["next", "terminated"].any()
    assert rollout["next", "done"].equal(rollout["next", "truncated"]) and rollout["next", "done"].any()
