"""Model options: presets hold docs/model.md's numbers, and every invalid value is a one-line ValueError naming it."""

from __future__ import annotations

import math

import pytest
import torch

from uavrl.envs import ModelConfig, UAVSpectrumEnv, make_config


def test_paper_preset_holds_the_spec_numbers():
    cfg = make_config("paper")
    assert cfg.grid == (6, 6) and cfg.num_uavs == 2 and cfg.layout == "line" and cfg.fading == "none"
    assert (cfg.p_pt, cfg.p_s, cfg.p_u, cfg.noise) == (0.01, 0.02, 0.02, 1e-9)
    assert (cfg.alpha, cfg.g0, cfg.cell_size) == (2.0, 1.0, 10.0)
    assert not cfg.direct_links and cfg.lease_rule and cfg.reward == "delta" and (cfg.beta1, cfg.beta2) == (1.0, 1.0)
    assert cfg.init_tasks == "random" and cfg.reset_positions == "random" and not cfg.state_includes_tasks
    assert cfg.height == 6.0 and make_config(grid=(4, 9)).height == 4.0
    assert cfg.num_cells == 36 and cfg.num_states == 36**2 == 1296 and cfg.num_joint_actions == 36


def test_reference_code_preset_holds_the_authors_choices():
    cfg = make_config("reference_code", grid=(3, 3))
    assert cfg.layout == "reference_code" and cfg.rate_model == "reference_code" and cfg.reward == "best_so_far"
    assert cfg.init_tasks == "sensing" and cfg.height == 10.0 and cfg.cell_size == 1.0
    assert (cfg.alpha, cfg.g0, cfg.reference_gain) == (4.0, 2.0, 200.0)
    assert cfg.preset == "reference_code" and make_config("reference_code", reward="delta").reward == "delta"


def test_state_space_sizes():
    assert make_config(grid=(6, 6), state_includes_tasks=True).num_states == 72**2
    big = make_config(grid=(20, 20), num_uavs=10)
    assert big.num_states == 400**10 and not big.has_state_index
    assert make_config(grid=(20, 20), num_uavs=7).has_state_index


BAD_VALUES = [
    ("grid", (0, 3)),
    ("grid", (3, 0)),
    ("grid", (-2, 2)),
    ("grid", (2.5, 3)),
    ("grid", (1, 2, 3)),
    ("grid", "6x6"),
    ("grid", 6),
    ("num_uavs", 0),
    ("num_uavs", -1),
    ("num_uavs", 10),
    ("num_uavs", 2.5),
    ("max_steps", 0),
    ("max_steps", -5),
    ("p_pt", -0.01),
    ("p_s", 0.0),
    ("p_u", -1.0),
    ("noise", -1e-9),
    ("noise", 0.0),
    ("p_pt", math.inf),
    ("noise", math.nan),
    ("cell_size", 0.0),
    ("g0", -1.0),
    ("alpha", -2.0),
    ("reference_gain", 0.0),
    ("altitude", 0.0),
    ("altitude", -3.0),
    ("altitude", math.inf),
    ("beta1", math.nan),
    ("beta2", math.inf),
    ("layout", "circle"),
    ("fading", "nakagami"),
    ("rician_k_db", math.nan),
    ("rician_k_db", "9"),
    ("reward", "sparse"),
    ("rate_model", "df"),
    ("init_tasks", "both"),
    ("reset_positions", "never"),
]


@pytest.mark.parametrize("name,value", BAD_VALUES, ids=[f"{n}={v!r}" for n, v in BAD_VALUES])
def test_invalid_option_is_a_one_line_value_error(name, value):
    options = {"grid": (3, 3), "num_uavs": 2, name: value}
    with pytest.raises(ValueError) as err:
        make_config("paper", **options)
    message = str(err.value)
    assert "\n" not in message and name in message and (repr(value) in message or str(value) in message), message
    with pytest.raises(ValueError):  # the same through the environment
        UAVSpectrumEnv(**options)


@pytest.mark.parametrize(
    "call,words",
    [
        (lambda: make_config("papers"), "preset='papers'"),
        (lambda: make_config("paper", grdi=(3, 3)), "'grdi'"),
        (lambda: UAVSpectrumEnv(batch_size=1, speed=3), "'speed'"),
        (lambda: UAVSpectrumEnv(batch_size=0), "batch_size=0"),
        (lambda: UAVSpectrumEnv(batch_size=[2, 3]), "batch_size=[2, 3]"),
        (lambda: UAVSpectrumEnv(batch_size=-4), "batch_size=-4"),
        (lambda: UAVSpectrumEnv(config=make_config(), layout="random"), "config="),
        (lambda: make_config("reference_code", direct_links=True), "direct_links=True"),
        (lambda: UAVSpectrumEnv(preset="reference_code", grid=(16, 6)), "grid=(16, 6)"),  # E sits on cell (15, 5)
    ],
)
def test_other_bad_input(call, words):
    with pytest.raises(ValueError) as err:
        call()
    assert "\n" not in str(err.value) and words in str(err.value), str(err.value)


def test_config_is_immutable_and_replace_validates():
    cfg = make_config(grid=(3, 3))
    with pytest.raises(AttributeError):
        cfg.num_uavs = 3
    assert cfg.replace(num_uavs=3).num_uavs == 3
    with pytest.raises(ValueError, match="num_uavs=10"):
        cfg.replace(num_uavs=10)
    assert isinstance(cfg, ModelConfig) and cfg == make_config(grid=[3, 3])


def test_env_from_config_uses_it():
    cfg = make_config("reference_code", grid=(3, 4), num_uavs=3, max_steps=7)
    env = UAVSpectrumEnv(batch_size=2, config=cfg)
    assert env.cfg is cfg and env.num_uavs == 3 and env.batch_size == torch.Size([2])
