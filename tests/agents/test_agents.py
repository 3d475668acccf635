"""The agent contract (:class:`uavrl.agents.base.Agent`), checked for every agent of the registry
(:data:`uavrl.agents.AGENTS`): it trains briefly, saves, loads, evaluates, resumes exactly and refuses a bad setting
in one line, the command before any work and the agent built in Python alike, each rule run once per command."""

import dataclasses
import io

import pytest
import torch

import uavrl.agents.schema as agent_schema
from uavrl.agents import AGENTS, agent_class
from uavrl.agents.base import Agent
from uavrl.config import model_config
from uavrl.envs import UAVSpectrumEnv
from uavrl.train import train

COMMON = ["env.grid=[3,3]", "eval.num_starts=4", "train.checkpoint_every=2", "progress=false"]
TINY = {
    "tabular": ["agent.episodes=4", "env.max_steps=50", "agent.runs=2"],
    "dqn": [
        "agent.iterations=4",
        "env.max_steps=8",
        "agent.worlds=8",
        "agent.hidden=16",
        "agent.depth=1",
        "agent.batch_size=32",
        "agent.buffer_size=100",  # wraps around: 4 x 64 writes
        "agent.updates=2",
        "agent.learning_starts=16",
    ],
    "random": [],
    "oracle": [],
    "planner": [],
}
# one setting each agent refuses: (override, the one-line refusal)
BAD = {
    "tabular": ("agent.alpha=0", "agent.alpha=0 is invalid: it must lie in (0.0, 1.0]"),
    "dqn": ("agent.worlds=0", "agent.worlds=0 is invalid: it must be a whole number >= 1"),
    "random": ("agent.memory_budget=0", "agent.memory_budget=0 is invalid: it must be positive"),
    "oracle": ("agent.memory_budget=-1", "agent.memory_budget=-1 is invalid: it must be positive"),
    "planner": ("agent.memory_budget=0", "agent.memory_budget=0 is invalid: it must be positive"),
}


def test_every_agent_has_tiny_and_bad_settings():
    assert set(TINY) == set(AGENTS) == set(BAD)


@pytest.mark.parametrize("name", AGENTS)
def test_registry_names_a_schema_and_a_class(name):
    config = AGENTS[name]
    assert dataclasses.is_dataclass(config.schema) and config.schema().name == config.schema.name
    assert agent_class(name) is config.associated_class() and issubclass(agent_class(name), Agent)
    for setting, value, _ in config.variants:  # a variant's class is an Agent too
        assert issubclass(config.associated_class({setting: value}), agent_class(name))


def test_dqn_network_picks_the_class():
    from uavrl.agents.dqn import DQNAgent
    from uavrl.agents.dqn.multisize import SetDQNAgent

    assert agent_class("dqn", {"network": "set"}) is SetDQNAgent
    assert agent_class("dqn", {"network": "team"}) is DQNAgent and agent_class("dqn", {}) is DQNAgent
    assert agent_class("dqn") is DQNAgent
    with pytest.raises(ValueError, match=r"^agent='nope' is invalid: allowed agents are tabular, dqn, "):
        agent_class("nope")


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


@pytest.fixture
def agent_cfg(compose_cfg):
    return lambda name, *overrides: compose_cfg(f"agent={name}", *COMMON, *TINY[name], *overrides)


def make(cfg, seed=0):
    return agent_class(cfg.agent.name)(model_config(cfg), cfg, torch.device("cpu"), seed)


def same(a, b) -> bool:
    """Equal nested checkpoints: tensors by ``torch.equal``, tensordicts entry by entry, the rest by ``==``."""
    if hasattr(a, "to_dict") and not isinstance(a, dict):
        a, b = a.to_dict(), b.to_dict()
    if isinstance(a, torch.Tensor):
        return isinstance(b, torch.Tensor) and a.shape == b.shape and a.dtype == b.dtype and torch.equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


@pytest.mark.parametrize("name", AGENTS)
def test_agent_contract_train_checkpoint_and_policy(name, agent_cfg):
    cfg = agent_cfg(name)
    cls = agent_class(name)
    assert issubclass(cls, Agent)
    agent = make(cfg)
    # the iterations train runs: the learner's episodes or iterations, one sweep for value iteration, none for a
    # baseline (it does not train)
    a = cfg.agent
    expected = {
        "tabular": 1 if a.get("method") == "value_iteration" else a.get("episodes"),
        "dqn": a.get("iterations"),
    }.get(name, 0)
    assert isinstance(agent.num_iterations, int) and agent.num_iterations == expected
    for done in range(1, min(2, agent.num_iterations) + 1):
        metrics = agent.train_iteration()
        assert all(key.startswith("train/") and isinstance(value, float) for key, value in metrics.items())
        assert agent.env_steps > 0 or name == "tabular" and cfg.agent.method == "value_iteration", done
    # checkpoint round trip through bytes, as on disk
    saved = io.BytesIO()
    torch.save(agent.state_dict(), saved)
    saved.seek(0)
    restored = make(cfg)
    restored.load_state_dict(torch.load(saved, weights_only=False))
    assert restored.env_steps == agent.env_steps
    assert same(restored.state_dict(), agent.state_dict())
    # the restored agent evaluates: one result per independent run, the yardstick's keys
    results = restored.evaluate(model_config(cfg), num_starts=2, horizon=4)
    assert len(results) == len(restored.policies()) and all("eval/optimality" in r for r in results), results
    # the TorchRL policies roll out, every UAV taking an allowed action
    env_cfg = model_config(cfg)
    for policy in agent.policies():
        env = UAVSpectrumEnv(batch_size=4, config=env_cfg, seed=5)
        if hasattr(policy, "bind_env"):
            policy.bind_env(env)
        td = env.rollout(6, policy)
        actions = td["agents", "action"]
        assert actions.shape == (4, 6, env_cfg.num_uavs)
        assert td["agents", "action_mask"].gather(-1, actions.unsqueeze(-1)).all()  # each UAV's action allowed


@pytest.mark.parametrize("name", AGENTS)
def test_agent_resumes_after_a_kill_exactly(name, agent_cfg, interrupt_at, tmp_path):
    whole = train(agent_cfg(name, f"run_dir={tmp_path / 'whole'}"))
    killed = tmp_path / "killed"
    with interrupt_at(agent_class(name), 3):  # after the checkpoint of iteration 2
        try:
            train(agent_cfg(name, f"run_dir={killed}"))
        except KeyboardInterrupt:
            pass
    interrupted = not (killed / "metrics.json").exists()
    assert interrupted == (name in ("tabular", "dqn"))  # the baselines have no iteration to interrupt
    if interrupted:
        train(agent_cfg(name, f"resume={killed}"), overrides=[f"resume={killed}"])
    a, b = (torch.load(d / "checkpoint.pt", weights_only=False) for d in (whole, killed))
    assert a["iteration"] == b["iteration"] and same(a["agent"], b["agent"]) and a["final"] == b["final"]


@pytest.mark.parametrize("name", AGENTS)
def test_agent_refuses_a_bad_setting_in_one_line(name, agent_cfg, tmp_path):
    """The command refuses before any work (no run directory), and the agent built in Python with the same message."""
    override, message = BAD[name]
    cfg = agent_cfg(name, override, f"run_dir={tmp_path / 'run'}")
    with pytest.raises(ValueError) as by_command:
        train(cfg, overrides=[override])
    with pytest.raises(ValueError) as built:
        make(cfg)
    assert str(by_command.value) == str(built.value) == message
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("name", ["tabular", "dqn", "random"])
def test_each_agent_rule_runs_once_per_command(name, agent_cfg, monkeypatch, tmp_path):
    """python -m uavrl.train checks the settings before any work and builds the agent, whose constructor validates
    them too: each rule (each setting's own, then together) runs once."""
    calls = {"each": 0, "together": 0}
    check = agent_schema.check

    def each(settings, table, section=""):
        calls["each"] += section == "agent"
        return check(settings, table, section)

    config = AGENTS[name]

    def together(env_cfg, settings):
        calls["together"] += 1
        return config.together(env_cfg, settings) if config.together is not None else None

    monkeypatch.setattr(agent_schema, "_PASSED", {})
    monkeypatch.setattr(agent_schema, "check", each)
    monkeypatch.setitem(AGENTS, name, dataclasses.replace(config, together=together))
    train(agent_cfg(name, f"run_dir={tmp_path / 'run'}"))
    assert calls == {"each": 1, "together": 1}
    make(agent_cfg(name))  # built in Python with the settings the command checked: nothing runs again
    assert calls == {"each": 1, "together": 1}
    make(agent_cfg(name, "seed=3"))  # the seed is not an agent setting: the same settings
    assert calls == {"each": 1, "together": 1}
