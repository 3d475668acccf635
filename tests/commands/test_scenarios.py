"""Named scenarios (configs/scenario/): each a setting of the model with a training budget per agent."""

from pathlib import Path

import pytest
from omegaconf import OmegaConf

from uavrl.agents import AGENTS
from uavrl.config import model_config
from uavrl.settings import check_scenario
from uavrl.train import check_settings

SCENARIOS = {  # name: (grid, UAVs, preset, option values, agents)
    "paper_6x6": ((6, 6), 2, "paper", {}, {"tabular", "dqn", "random", "oracle"}),
    "n6_10x10": ((10, 10), 6, "paper", {}, {"dqn", "random", "oracle"}),
    "random_layouts": ((10, 10), 6, "paper", {"layout": "random"}, {"dqn", "random", "oracle"}),
    "rayleigh": ((6, 6), 2, "paper", {"fading": "rayleigh"}, {"tabular", "dqn", "random", "oracle"}),
    "reference_code": ((6, 6), 2, "reference_code", {"reward": "best_so_far"}, {"tabular", "dqn", "random", "oracle"}),
    "large_20x20": ((20, 20), 10, "paper", {}, {"dqn", "random", "oracle"}),
    "size_free": ((10, 10), 6, "paper", {}, {"dqn", "random", "oracle"}),
    "a2g_urban": (
        (10, 10),
        6,
        "a2g_urban",
        {"channel": "al_hourani", "environment": "urban"},
        {"dqn", "random", "oracle"},
    ),
    "city_urban_10x10": (
        (10, 10),
        6,
        "a2g_urban",
        {"city": "urban", "environment": "urban", "altitudes_m": (30.0, 60.0, 100.0, 200.0, 300.0)},
        {"dqn", "random", "oracle"},
    ),
    "city_dense_20x20": (
        (20, 20),
        10,
        "a2g_urban",
        {"city": "dense_urban", "environment": "dense_urban", "altitudes_m": (30.0, 60.0, 100.0, 200.0)},
        {"dqn", "random", "oracle"},
    ),
    "energy_6x6": (
        (6, 6),
        2,
        "paper",
        {"energy": "rotary_wing", "base": (-1, 0), "battery_wh": 5.0, "recharge_steps": None, "num_spares": 0},
        {"dqn", "random", "oracle", "planner"},
    ),
    "energy_4x4": (
        (4, 4),
        2,
        "paper",
        {"energy": "rotary_wing", "base": (-1, 0), "battery_wh": 1.2, "recharge_steps": None, "num_spares": 0},
        {"dqn", "random", "oracle", "planner"},
    ),
    "persistent_10x10": (
        (10, 10),
        6,
        "paper",
        {"energy": "rotary_wing", "base": (-1, 0), "battery_wh": 6.0, "recharge_steps": 60, "num_spares": 2},
        {"dqn", "random", "oracle", "planner"},
    ),
}


def test_the_scenarios_are_the_configs_shipped():
    from uavrl.config import config_dir

    assert {p.stem for p in (Path(config_dir()) / "scenario").glob("*.yaml")} == set(SCENARIOS)


@pytest.mark.parametrize("name", SCENARIOS)
def test_each_scenario_sets_its_model_and_agents(name, compose_cfg):
    """Every agent of the registry composes with every scenario; those the scenario names pass the checks."""
    grid, uavs, preset, options, agents = SCENARIOS[name]
    for agent in sorted(AGENTS):
        cfg = compose_cfg(f"agent={agent}", f"scenario={name}")
        model = model_config(cfg)
        assert (model.grid, model.num_uavs, cfg.env.preset, cfg.env.name) == (grid, uavs, preset, name)
        assert all(getattr(model, key) == value for key, value in options.items())
        assert set(cfg.scenario.agents) == agents
        if agent in agents:
            check_settings(cfg)
        else:
            with pytest.raises(ValueError, match=f"^agent={agent} is invalid with scenario={name}: its agents are"):
                check_scenario(cfg)


@pytest.mark.parametrize(
    "overrides, budget",
    [
        (["agent=tabular", "scenario=paper_6x6"], {"agent.episodes": 200, "agent.runs": 10, "env.max_steps": 12000}),
        (["agent=dqn", "scenario=n6_10x10"], {"agent.iterations": 800, "agent.mixer": "qmix", "env.max_steps": 30}),
        (["agent=dqn", "scenario=large_20x20"], {"agent.iterations": 500, "env.max_steps": 40}),
        (["agent=dqn", "scenario=large_20x20", "agent.iterations=7", "env.max_steps=9"], {"agent.iterations": 7}),
        (["agent=oracle", "scenario=large_20x20"], {"env.max_steps": 100}),  # nothing to train: the env's default
        (
            ["agent=dqn", "scenario=energy_6x6"],
            {"env.reward": "delivered", "agent.objective": "delta", "agent.gamma": 0.99, "env.max_steps": 145},
        ),
        (["agent=planner", "scenario=energy_6x6"], {"env.reward": None, "env.max_steps": 100}),
        (["agent=dqn", "scenario=persistent_10x10"], {"env.reward": "delivered", "eval.horizon": 500}),
    ],
    ids=str,
)
def test_budgets_follow_the_agent_and_yield_to_overrides(overrides, budget, compose_cfg):
    cfg = compose_cfg(*overrides)
    assert {key: OmegaConf.select(cfg, key) for key in budget} == budget
    if "env.max_steps=9" in overrides:
        assert cfg.env.max_steps == 9


@pytest.mark.parametrize("agent", sorted(AGENTS))
def test_no_scenario_is_todays_config(agent, compose_cfg):
    """Without ``scenario`` the config is the one before scenarios existed; paper_6x6 is that setting by name."""
    plain = compose_cfg(f"agent={agent}")
    assert plain.scenario is None and plain.sweep_dir is None
    named = compose_cfg(f"agent={agent}", "scenario=paper_6x6")
    assert model_config(named) == model_config(plain)
    assert named.agent == plain.agent


def test_a_scenario_run_is_named_after_it(compose_cfg, tmp_path, monkeypatch):
    """``python -m uavrl.train agent=dqn scenario=rayleigh`` as every other override: a run in runs/dqn/rayleigh/."""
    import torch

    from uavrl.train import train

    torch.set_num_threads(1)
    monkeypatch.chdir(tmp_path)
    tiny = ["agent.iterations=2", "agent.worlds=4", "agent.hidden=8", "agent.depth=1", "agent.batch_size=8"]
    cfg = compose_cfg("agent=dqn", "scenario=rayleigh", *tiny, "agent.learning_starts=8", "eval.num_starts=2")
    cfg.progress = False
    run_dir = train(cfg)
    assert run_dir.parent == Path("runs/dqn/rayleigh")
    saved = OmegaConf.load(run_dir / "config.yaml")
    assert saved.scenario.name == "rayleigh" and saved.env.fading == "rayleigh"


def test_each_benchmarl_task_of_a_scenario_points_at_it(tmp_path):
    """``task=uavrl/<name>`` of ``python -m uavrl.benchmarl`` is the scenario ``<name>``, written once: its task file
    holds the task's name and the scenario it is; composed, it gives the scenario's model."""
    from hydra import compose, initialize_config_dir

    from uavrl.config import config_dir

    tasks = sorted((Path(config_dir()) / "task" / "uavrl").glob("*.yaml"))
    of_scenarios = [task.stem for task in tasks if task.stem in SCENARIOS]
    assert of_scenarios == ["city_urban_10x10", "n6_10x10", "paper_6x6"]
    for name in of_scenarios:
        saved = OmegaConf.to_container(OmegaConf.load(Path(config_dir()) / "task" / "uavrl" / f"{name}.yaml"))
        assert saved == {"defaults": [{"/scenario": name}], "task": {"name": name}}
    # configs/benchmarl.yaml without BenchMARL's groups (they need the extra)
    primary = {"defaults": ["benchmarl_schema", {"env": "paper"}, {"task": "uavrl/paper_6x6"}, "_self_"]}
    primary["hydra"] = {"searchpath": [f"file://{config_dir()}"]}
    OmegaConf.save(OmegaConf.create(primary), tmp_path / "primary.yaml")
    with initialize_config_dir(config_dir=str(tmp_path), version_base=None):
        for name in of_scenarios:
            cfg = compose("primary", overrides=[f"task=uavrl/{name}"])
            grid, uavs, preset, _, _ = SCENARIOS[name]
            model = model_config(cfg)
            assert (model.grid, model.num_uavs, cfg.env.preset, cfg.env.name, cfg.task.name) == (
                grid,
                uavs,
                preset,
                name,
                name,
            )


@pytest.mark.parametrize("name, mission", [("energy_6x6", 145), ("persistent_10x10", 500)])
def test_the_energy_scenarios_missions(name, mission, compose_cfg):
    """energy_6x6's mission ends with the batteries (the evaluation's default horizon: every UAV home from a full
    battery); persistent_10x10's is eval.horizon, over four lifetimes of a battery that hovers."""
    from uavrl.envs.limits import evaluation_horizon

    cfg = compose_cfg("agent=planner", f"scenario={name}")
    model = model_config(cfg)
    assert (cfg.eval.horizon or evaluation_horizon(model)) == mission
    energies = model.step_energies
    hover_lifetime = energies.capacity / energies.stay
    assert 100 <= mission <= 250 if name == "energy_6x6" else mission > 4 * hover_lifetime
