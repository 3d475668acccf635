"""The channel models (docs/model.md, Channel models) against implementations written here from their sources."""

import json
import math
import subprocess
import sys
from types import SimpleNamespace

import pytest
import torch

from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.config import InvalidOption, ModelConfig
from uavrl.envs.physics.channel import cell_xyz, fixed_layout, link_gains
from uavrl.envs.physics.pathloss import al_hourani_los_probability, mean_path_loss_db, uma_av_los_probability

C = 299_792_458.0
# Al-Hourani, Kandeepan, Lardner, IEEE WCL 3(6), 2014, Table I at 2 GHz: (a, b, eta_LoS dB, eta_NLoS dB)
PAPER_TABLE = {
    "suburban": (4.88, 0.43, 0.1, 21.0),
    "urban": (9.61, 0.16, 1.0, 20.0),
    "dense_urban": (12.08, 0.11, 1.6, 23.0),
    "highrise": (27.23, 0.08, 2.3, 34.0),
}
HEIGHTS = (25.0, 50.0, 80.0, 100.0, 150.0, 300.0)  # metres, in TR 36.777's UMa-AV range (22.5, 300]
HORIZONTAL = (0.0, 5.0, 18.0, 60.0, 200.0, 700.0, 1500.0, 4000.0)  # metres


def fspl(d, f_ghz):
    return 20 * math.log10(4 * math.pi * f_ghz * 1e9 * d / C)


def al_hourani(r, h, f_ghz, environment):
    a, b, eta_los, eta_nlos = PAPER_TABLE[environment]
    theta = math.degrees(math.atan2(h, r))
    p = 1 / (1 + a * math.exp(-b * (theta - a)))
    return fspl(math.hypot(r, h), f_ghz) + p * eta_los + (1 - p) * eta_nlos


def uma_av_p_los(r, h):
    if h > 100:
        return 1.0
    d1 = max(460 * math.log10(h) - 700, 18)
    p1 = 4300 * math.log10(h) - 3800
    return 1.0 if r <= d1 else d1 / r + math.exp(-r / p1) * (1 - d1 / r)


def uma_av(r, h, f_ghz):
    d = math.hypot(r, h)
    los = 28 + 22 * math.log10(d) + 20 * math.log10(f_ghz)
    nlos = -17.5 + (46 - 7 * math.log10(h)) * math.log10(d) + 20 * math.log10(40 * math.pi * f_ghz / 3)
    p = uma_av_p_los(r, h)
    return p * los + (1 - p) * nlos


def tr36777_p_los(r, h, p1, d1, all_los_above):
    if h > all_los_above:
        return 1.0
    return 1.0 if r <= d1 else d1 / r + math.exp(-r / p1) * (1 - d1 / r)


def umi_av(r, h, f_ghz):
    """TR 36.777 Tables B-1 and B-2, UMi-AV, 22.5 m < h <= 300 m (free space as the standard writes it, c = 3e8)."""
    d = math.hypot(r, h)
    free = 20 * math.log10(40 * math.pi * d * f_ghz / 3)
    los = max(free, 30.9 + (22.25 - 0.5 * math.log10(h)) * math.log10(d) + 20 * math.log10(f_ghz))
    nlos = max(los, 32.4 + (43.2 - 7.6 * math.log10(h)) * math.log10(d) + 20 * math.log10(f_ghz))
    p1, d1 = 233.98 * math.log10(h) - 0.95, max(294.05 * math.log10(h) - 432.94, 18)
    p = tr36777_p_los(r, h, p1, d1, math.inf)
    return p * los + (1 - p) * nlos


def rma_av(r, h, f_ghz):
    """TR 36.777 Tables B-1 and B-2, RMa-AV, 10 m < h <= 300 m: all in line of sight above 40 m."""
    d = math.hypot(r, h)
    los = max(23.9 - 1.8 * math.log10(h), 20) * math.log10(d) + 20 * math.log10(40 * math.pi * f_ghz / 3)
    nlos = max(los, -12 + (35 - 5.3 * math.log10(h)) * math.log10(d) + 20 * math.log10(40 * math.pi * f_ghz / 3))
    p1, d1 = max(15021 * math.log10(h) - 16053, 1000), max(1350.8 * math.log10(h) - 1602, 18)
    p = tr36777_p_los(r, h, p1, d1, 40.0)
    return p * los + (1 - p) * nlos


def losses(channel, environment, f_ghz, h):
    """``mean_path_loss_db`` of a UAV at every horizontal distance from a ground node (PT) and an aerial one (S)."""
    cfg = SimpleNamespace(
        channel=channel, environment=environment, carrier_ghz=f_ghz, cell_size=1.0, geometric_los=False
    )
    uavs = torch.tensor([[r, 0.0, h] for r in HORIZONTAL], dtype=torch.float64)
    nodes = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, h], [0.0, 0.0, h]], dtype=torch.float64)
    return mean_path_loss_db(uavs, nodes, cfg)


@pytest.mark.parametrize("environment", PAPER_TABLE)
@pytest.mark.parametrize("f_ghz", [0.7, 2.0, 5.8])
def test_al_hourani_is_the_papers_formula(environment, f_ghz):
    for h in (10.0, *HEIGHTS, 1000.0):
        got = losses("al_hourani", environment, f_ghz, h)
        for i, r in enumerate(HORIZONTAL):
            assert got[i, 0].item() == pytest.approx(al_hourani(r, h, f_ghz, environment), abs=1e-9)
            assert got[i, 1].item() == got[i, 0].item()
            if r > 0:  # UAV-S and UAV-E: air to air, free space
                assert got[i, 2].item() == pytest.approx(fspl(r, f_ghz), abs=1e-9)


@pytest.mark.parametrize("f_ghz", [0.5, 2.0, 3.5, 6.0])
def test_uma_av_is_tr36777s_formula(f_ghz):
    for h in HEIGHTS:
        got = losses("tr36777_uma", "urban", f_ghz, h)
        for i, r in enumerate(HORIZONTAL):
            assert got[i, 0].item() == pytest.approx(uma_av(r, h, f_ghz), abs=1e-9)
            if r > 0:
                assert got[i, 3].item() == pytest.approx(fspl(r, f_ghz), abs=1e-9)


@pytest.mark.parametrize(
    ("channel", "formula", "heights"),
    [("tr36777_umi", umi_av, HEIGHTS), ("tr36777_rma", rma_av, (12.0, 20.0, 35.0, 40.0, 41.0, *HEIGHTS))],
)
@pytest.mark.parametrize("f_ghz", [0.5, 2.0, 6.0])
def test_umi_and_rma_av_are_tr36777s_formulas(channel, formula, heights, f_ghz):
    for h in heights:
        got = losses(channel, "urban", f_ghz, h)
        for i, r in enumerate(HORIZONTAL):
            assert got[i, 0].item() == pytest.approx(formula(r, h, f_ghz), abs=1e-9)
            assert got[i, 1].item() == got[i, 0].item()
            if r > 0:  # UAV-S and UAV-E: air to air, free space
                assert got[i, 2].item() == pytest.approx(fspl(r, f_ghz), abs=1e-9)


def test_uma_av_gives_the_standards_check_value():
    """TR 36.777 Table B-1 at h = 50 m, d_2D = 200 m: P_LoS = 0.967."""
    assert round(uma_av_p_los(200.0, 50.0), 3) == 0.967
    assert uma_av_los_probability(
        torch.tensor(200.0, dtype=torch.float64), torch.tensor(50.0, dtype=torch.float64)
    ).item() == pytest.approx(uma_av_p_los(200.0, 50.0), abs=1e-12)
    h = torch.tensor(HEIGHTS, dtype=torch.float64)[:, None]
    r = torch.tensor(HORIZONTAL, dtype=torch.float64)[None, :]
    p = uma_av_los_probability(r, h)
    assert torch.all((p > 0) & (p <= 1)) and torch.all(p[h[:, 0] > 100] == 1)
    assert torch.all(p.diff(dim=1) <= 1e-15)  # farther away, less often in line of sight


def test_al_hourani_los_probability_rises_with_elevation():
    theta = torch.linspace(0.0, 90.0, 181, dtype=torch.float64)
    at_45 = []
    for environment in PAPER_TABLE:
        p = al_hourani_los_probability(theta, environment)
        assert torch.all(p.diff() >= 0) and torch.all(p[:61].diff() > 0)  # rising, strictly below 30 degrees
        assert torch.all((p > 0) & (p <= 1)) and p[-1] - p[0] > 0.8  # mostly blocked at the horizon, clear overhead
        at_45.append(al_hourani_los_probability(torch.tensor(45.0), environment).item())
    assert at_45 == sorted(at_45, reverse=True)  # denser cities block more


def test_a_los_nlos_draw_puts_each_air_to_ground_link_in_line_of_sight_with_probability_p_los():
    """fading=los_nlos: one relaying UAV's R_PU takes the four values of (PT link, PR link) in or out of line of
    sight, as often as P_LoS says, over 4,000 worlds."""
    from uavrl.envs.world import World

    cfg = make_config("a2g_urban", grid=(6, 6), num_uavs=1, fading="los_nlos")
    world = World(cfg, batch_size=4000, seed=5)
    x, y = 2, 3  # 100 m from PT (45 degrees), 200 m from PR (27 degrees)
    rates = world.start_at(torch.full((4000, 1), 2 * (y * 6 + x) + 1))["r_pu"].double()
    noise = 10 ** ((-174 + 70 + 9 - 30) / 10)
    a, b, eta_los, eta_nlos = PAPER_TABLE["urban"]
    links = []
    for node_x, power_dbm in ((0.0, 46.0), (6.0, 23.0)):  # PT -> UAV at the PT's power, UAV -> PR at the UAV's
        r, h = abs(x - node_x) * 50.0, 100.0
        p = 1 / (1 + a * math.exp(-b * (math.degrees(math.atan2(h, r)) - a)))
        snr = [10 ** ((power_dbm - 30 - fspl(math.hypot(r, h), 2.0) - eta) / 10) / noise for eta in (eta_los, eta_nlos)]
        links.append([(p, snr[0]), (1 - p, snr[1])])
    for p1, g1 in links[0]:
        for p2, g2 in links[1]:
            value = 0.5 * math.log2(1 + g1 * g2 / (1 + g1 + g2))
            share = (torch.isclose(rates, torch.tensor(value, dtype=torch.float64), rtol=1e-6)).double().mean().item()
            assert share == pytest.approx(p1 * p2, abs=4 * math.sqrt(p1 * p2 * (1 - p1 * p2) / 4000) + 1e-3)
    assert 0.3 < links[1][0][0] < 0.9  # the PR link is often blocked: the test sees both states
    # the deterministic utility stays the mean channel's
    mean = World(cfg.replace(fading="none"), batch_size=1)
    position, task = torch.tensor([[[x, y]]]), torch.tensor([[1]])
    assert torch.equal(
        world.utility(position.expand(4000, 1, 2), task.expand(4000, 1))[2][0], mean.utility(position, task)[2][0]
    )


def test_the_power_laws_are_g0_d_to_the_minus_alpha_bit_for_bit():
    for preset, (g0, alpha) in (("paper", (1.0, 2.0)), ("reference_code", (2.0, 4.0))):
        cfg = make_config(preset)
        assert (cfg.g0, cfg.alpha, cfg.channel) == (g0, alpha, preset)
        cells, nodes = cell_xyz(cfg), fixed_layout(cfg)
        d = torch.linalg.vector_norm(cells.unsqueeze(-2) - nodes.unsqueeze(-3), dim=-1) * cfg.cell_size
        assert torch.equal(link_gains(cells, nodes, cfg), g0 * d.pow(-alpha))
        assert (cfg.powers_w, cfg.noise_w, cfg.bandwidth_hz) == ((cfg.p_pt, cfg.p_s, cfg.p_u), cfg.noise, None)
    assert make_config("paper") == ModelConfig() == make_config("paper", channel="paper", g0=1.0, alpha=2.0)
    assert make_config("paper", channel="reference_code") == make_config("paper", g0=2.0, alpha=4.0).replace(
        channel="reference_code"
    )


def test_physical_units():
    cfg = make_config("a2g_urban")
    assert (cfg.grid, cfg.num_uavs, cfg.channel, cfg.environment, cfg.cell_size) == (
        (10, 10),
        6,
        "al_hourani",
        "urban",
        50.0,
    )
    assert cfg.height * cfg.cell_size == 100.0 and cfg.bandwidth_hz == 1e7
    assert cfg.powers_w == pytest.approx((10**1.6, 10**-0.7, 10**-0.7), rel=1e-12)  # 46, 23, 23 dBm
    assert cfg.noise_w == pytest.approx(10 ** ((-174 + 70 + 9 - 30) / 10), rel=1e-12)  # -95 dBm in 10 MHz, NF 9 dB
    # a UAV's gain to a node: 10^(-PL / 10) of the mean path loss
    nodes, cells = fixed_layout(cfg), cell_xyz(cfg)
    gains = link_gains(cells, nodes, cfg)
    for c in (0, 37, 99):
        x, y, z = (cells[c] * cfg.cell_size).tolist()
        pt, s = (nodes[0] * cfg.cell_size).tolist(), (nodes[2] * cfg.cell_size).tolist()
        expected_pt = al_hourani(math.hypot(x - pt[0], y - pt[1]), z - pt[2], 2.0, "urban")
        assert -10 * math.log10(gains[c, 0].item()) == pytest.approx(expected_pt, abs=1e-9)
        expected_s = fspl(math.dist((x, y, z), s), 2.0)
        assert -10 * math.log10(gains[c, 2].item()) == pytest.approx(expected_s, abs=1e-9)


@pytest.mark.parametrize(
    "options",
    [
        dict(channel="al_hourani"),
        dict(channel="al_hourani", environment="highrise", fading="rayleigh"),
        dict(channel="tr36777_uma", altitude_m=60.0, cell_size=30.0),
        dict(channel="tr36777_uma", altitude_m=150.0, cell_size=30.0, layout="random"),
        dict(channel="al_hourani", reward="log_gap", init_tasks="sensing"),
        dict(channel="tr36777_uma", altitude_m=60.0, cell_size=30.0, fading="los_nlos", reward="log_gap"),
        dict(channel="al_hourani", fading="los_nlos", layout="random"),
        dict(channel="tr36777_umi", altitude_m=60.0, cell_size=30.0, fading="los_nlos"),
        dict(channel="tr36777_rma", altitude_m=30.0, cell_size=30.0, fading="los_nlos", reward="log_gap"),
        dict(channel="tr36777_rma", altitude_m=120.0, cell_size=200.0, layout="random"),
    ],
    ids=str,
)
def test_each_channel_runs_end_to_end(options):
    torch.manual_seed(0)
    env = UAVSpectrumEnv(batch_size=3, grid=(5, 5), num_uavs=2, max_steps=6, seed=1, **options)
    td = env.rollout(6)
    assert torch.isfinite(td["next", "utility"]).all() and torch.isfinite(td["next", "reward"]).all()
    u_star, positions, tasks = env.optimum()
    assert torch.all(u_star > 0)
    _, _, u = env.world.utility(positions, tasks)
    assert torch.allclose(u, u_star, rtol=1e-12)
    # U* is no worse than any configuration the rollout visited (mean channels)
    visited = env.world.utility(td["next", "positions"], td["next", "tasks"])[2]
    assert torch.all(visited <= u_star[:, None] * (1 + 1e-12))


@pytest.mark.parametrize(
    "options, words",
    [
        (dict(channel="rain"), "channel='rain' is invalid: allowed values are 'paper', 'reference_code', 'al_hourani'"),
        (dict(channel="al_hourani", environment="rural"), "environment='rural' is invalid: allowed values are"),
        (dict(channel="al_hourani", carrier_ghz=28.0), "carrier_ghz=28.0 is invalid: channel='al_hourani' holds for"),
        (dict(channel="tr36777_uma", carrier_ghz=0), "carrier_ghz=0 is invalid"),
        (dict(channel="al_hourani", bandwidth_mhz=-1.0), "bandwidth_mhz=-1.0 is invalid: give a bandwidth in MHz"),
        (dict(channel="al_hourani", noise_figure_db=float("nan")), "noise_figure_db=nan is invalid"),
        (dict(channel="al_hourani", p_u_dbm=500.0), "p_u_dbm=500.0 is invalid: give a transmit power in dBm"),
        (dict(channel="al_hourani", p_u=0.1), "p_u=0.1 is invalid: only the power-law channels"),
        (dict(channel="al_hourani", alpha=3.0), "alpha=3.0 is invalid: only the power-law channels"),
        (dict(channel="paper", environment="suburban"), "environment='suburban' is invalid: only the physical"),
        (dict(channel="paper", carrier_ghz=3.5), "carrier_ghz=3.5 is invalid: only the physical channels"),
        (dict(fading="los_nlos"), "fading='los_nlos' is invalid: channel='paper' has no line-of-sight state"),
        (dict(channel="al_hourani", direct_links=True), "direct_links=True is invalid: channel='al_hourani' has no"),
        (dict(channel="al_hourani", rate_model="reference_code"), "rate_model='reference_code' is invalid"),
        (dict(channel="tr36777_uma", altitude_m=10.0), "altitude_m=10.0 is invalid: the UAVs fly at 10 m"),
        (dict(channel="tr36777_uma", cell_size=1000.0, altitude_m=100.0), "cell_size=1000.0 is invalid: a UAV can"),
        (dict(channel="tr36777_rma", altitude_m=8.0), "RMa-AV model holds for heights in (10, 300] m"),
        (dict(channel="tr36777_umi", altitude_m=400.0), "UMi-AV model holds for heights in (22.5, 300] m"),
        (dict(channel="tr36777_rma", cell_size=3000.0, altitude_m=100.0), "RMa-AV model holds to 10000 m"),
        (dict(altitude=3.0, altitude_m=30.0), "altitude_m=30.0 is invalid: give the height once: altitude=3 (in"),
        (dict(channel="al_hourani", altitude_m=20000.0), "altitude_m=20000.0 is invalid: the UAVs fly at 20000 m"),
        (dict(channel="al_hourani", altitude=2000.0, cell_size=10.0), "altitude=2000.0 is invalid: the UAVs fly at"),
        (dict(altitude_m=-5.0), "altitude_m=-5.0 is invalid: give a finite positive height in metres"),
        (dict(preset="a2g_urban", cell_size=1e-200), "cell_size=1e-200 is invalid: the channel gain 10^(-PL / 10)"),
        (dict(preset="a2g_urban", p_s_dbm=-100.0, cell_size=1e5), "cell_size=100000.0 is invalid: a UAV in the best"),
    ],
    ids=str,
)
def test_bad_channel_options_are_one_line(options, words):
    preset = options.pop("preset", "paper")
    with pytest.raises(InvalidOption) as refused:
        make_config(preset, **options)
    message = str(refused.value)
    assert words in message and "\n" not in message, message


def test_a_power_in_dbm_is_refused_with_the_range_that_passes():
    """Too little power to tell a rate from 0 in float64: the refusal's bound, in dBm, passes; below it does not."""
    weak = dict(p_u_dbm=-100.0, carrier_ghz=5.8, grid=(100, 100))
    with pytest.raises(InvalidOption, match=r"^p_s_dbm=-100.0 is invalid: .* must be at least (-?[0-9.]+) dBm$") as e:
        make_config("a2g_urban", p_s_dbm=-100.0, **weak)
    bound = float(str(e.value).split()[-2])
    assert make_config("a2g_urban", p_s_dbm=bound, **weak).p_s_dbm == bound
    with pytest.raises(InvalidOption):
        make_config("a2g_urban", p_s_dbm=bound - 0.1, **weak)


def test_a_bad_channel_override_is_one_line_on_the_command_line(tmp_path, command_exit):
    error = command_exit("train agent=oracle env=a2g_urban env.carrier_ghz=60", tmp_path)
    assert error.startswith(
        "error: env.carrier_ghz=60 is invalid: env.channel='al_hourani' holds for carriers (GHz) in [0.7, 5.8]"
    )
    assert "\n" not in error and list(tmp_path.iterdir()) == []


def test_the_oracle_solves_a2g_urban_from_the_command_line(tmp_path):
    run = tmp_path / "run"
    argv = [sys.executable, "-m", "uavrl.train", "agent=oracle", "env=a2g_urban", "eval.num_starts=8"]
    result = subprocess.run([*argv, "progress=false", f"run_dir={run}"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["eval/optimality"] == pytest.approx(1.0, abs=1e-6), metrics
    # U* in bit/s: the mean-channel optimum in bit/s/Hz times 10 MHz
    u_star = UAVSpectrumEnv(config=make_config("a2g_urban")).optimum()[0].item()
    assert metrics["eval/u_star_bit_per_s"] == pytest.approx(u_star * 1e7, rel=1e-12)
    assert metrics["eval/utility_bit_per_s"] == pytest.approx(u_star * 1e7, rel=1e-6)
