"""The configs' schemas (uavrl/schema.py): unknown keys and wrong types fail while Hydra composes; presets are data."""

import pytest
from hydra.errors import ConfigCompositionException

from uavrl.cli import compose_config
from uavrl.config import model_config
from uavrl.envs.config import PRESETS, make_config


@pytest.mark.parametrize("preset", PRESETS)
def test_each_env_config_is_its_preset(preset, compose_cfg):
    cfg = compose_cfg(f"env={preset}")
    assert model_config(cfg) == make_config(preset, max_steps=cfg.env.max_steps)


@pytest.mark.parametrize(
    "overrides",
    [["agent.alhpa=0.2"], ["agent=dqn", "agent.episodes=3"], ["train.nope=1"], ["env.colour=red"]],
    ids=str,
)
def test_unknown_keys_fail_at_composition(overrides, compose_cfg):
    with pytest.raises(ConfigCompositionException):
        compose_cfg(*overrides)


@pytest.mark.parametrize(
    "override, message",
    [
        ("agent.episodes=2.5", "agent.episodes=2.5 is invalid: it must be a whole number"),
        ("progress=maybe", "progress='maybe' is invalid: it must be true or false"),
        ("env.num_uavs=two", "env.num_uavs='two' is invalid: it must be a whole number"),
        ("train.episodes=5", "train.episodes is now agent.episodes: write agent.episodes=5"),
    ],
)
def test_wrong_types_and_moved_settings_are_one_line(override, message):
    with pytest.raises(SystemExit) as refused:
        compose_config("config", [override])
    assert str(refused.value) == f"error: {message}"
