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


def test_the_docs_table_is_the_schemas():
    """docs/settings.md is generated from the schemas (``python -m uavrl.schema > docs/settings.md``)."""
    from pathlib import Path

    from uavrl.schema import settings_markdown

    docs = Path(__file__).resolve().parents[2] / "docs" / "settings.md"
    assert docs.read_text() == settings_markdown(), "regenerate: python -m uavrl.schema > docs/settings.md"


def test_env_schema_is_every_model_option():
    from dataclasses import fields

    from uavrl.envs.config import OPTION_NAMES
    from uavrl.schema import EnvSchema

    assert [f.name for f in fields(EnvSchema)] == ["name", "preset", *OPTION_NAMES]
    assert all(f.default is None for f in fields(EnvSchema) if f.name in OPTION_NAMES)


def test_each_preset_is_written_once():
    """``env=<preset>`` is registered from envs/config.py's presets, with no yaml of its own."""
    from pathlib import Path

    from hydra.core.config_store import ConfigStore

    from uavrl.config import config_dir

    assert not (Path(config_dir()) / "env").exists()
    assert sorted(ConfigStore.instance().list("env")) == sorted(f"{preset}.yaml" for preset in PRESETS)


def test_the_yaml_files_hold_no_defaults():
    """A default lives in its schema only: the yaml files choose groups and set what differs (an agent's training
    episode length, BenchMARL's experiment)."""
    from pathlib import Path

    from omegaconf import OmegaConf

    from uavrl.config import config_dir

    allowed = {"config": {"defaults", "hydra"}, "reproduce": {"defaults", "hydra"}}
    allowed["benchmarl"] = {"defaults", "hydra", "env", "experiment"}
    root = Path(config_dir())
    for name, keys in allowed.items():
        assert set(OmegaConf.load(root / f"{name}.yaml")) <= keys, name
    assert OmegaConf.load(root / "benchmarl.yaml").env.keys() == {"max_steps"}
    for agent in (root / "agent").glob("*.yaml"):
        saved = OmegaConf.load(agent)
        assert set(saved) <= {"defaults", "env"} and set(saved.get("env", {})) <= {"max_steps"}, agent.name


def test_an_agent_follows_its_own_rules_only():
    """``agent.alpha`` is the tabular agent's: another agent's setting of that name is not held to its rule."""
    from omegaconf import OmegaConf

    from uavrl.settings import AGENT_SETTINGS, check_run

    assert "agent.alpha" in AGENT_SETTINGS["tabular"] and "agent.alpha" not in AGENT_SETTINGS["dqn"]
    assert "agent.iterations" in AGENT_SETTINGS["dqn"] and "agent.iterations" not in AGENT_SETTINGS["tabular"]
    check_run(OmegaConf.create({"agent": {"name": "dqn", "alpha": 5}}))
    with pytest.raises(ValueError, match=r"^agent\.alpha=5 is invalid: it must lie in \(0\.0, 1\.0\]$"):
        check_run(OmegaConf.create({"agent": {"name": "tabular", "alpha": 5}}))
    with pytest.raises(ValueError, match=r"^agent\.name='sarsa' is invalid: allowed agents are 'tabular'"):
        check_run(OmegaConf.create({"agent": {"name": "sarsa", "alpha": 5}}))


def test_the_library_defaults_are_the_schemas():
    """``TeamQLearner(cfg)`` and ``evaluate(policy, cfg)`` without settings run as the command line's defaults."""
    import inspect

    from uavrl.agents.evaluation import evaluate
    from uavrl.agents.schema import TabularSchema
    from uavrl.agents.tabular import TeamQLearner
    from uavrl.schema import EvalSchema

    learner = inspect.signature(TeamQLearner).parameters
    for name in ("alpha", "gamma", "epsilon", "shared_table", "backend", "memory_budget"):
        assert learner[name].default == getattr(TabularSchema, name), name
    evaluation = inspect.signature(evaluate).parameters
    assert (evaluation["num_starts"].default, evaluation["seed"].default, evaluation["gamma"].default) == (
        EvalSchema.num_starts,
        EvalSchema.seed,
        EvalSchema.gamma,
    )
    with pytest.raises(ValueError, match=r"^alpha=0 is invalid: it must lie in \(0\.0, 1\.0\]$"):
        TeamQLearner(make_config("paper", grid=(2, 2)), alpha=0)
