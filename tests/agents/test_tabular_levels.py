"""The tabular agent at altitude levels and in a city: its tables over the model's positions, the learner, value
iteration, the greedy evaluation and the policy, and the command's train and evaluate round trip."""

import json

import pytest
import torch

from uavrl.agents.evaluation import evaluate
from uavrl.agents.tabular import TabularModel, TabularPolicy, TeamQLearner, exact_q_table
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.physics.positions import model_positions


def city_levels(**options):
    """Three levels over the highrise city on 3x3: 21 of the 27 (cell, level) positions lie outside its buildings."""
    options = dict(grid=(3, 3), num_uavs=2, city="highrise", environment="highrise", max_steps=40) | options
    return make_config("a2g_urban", altitudes_m=[20, 100, 300], **options)


@pytest.fixture(autouse=True)
def _one_thread(one_thread):
    """Small tensors: one torch thread."""


def test_the_tables_span_the_positions_and_eight_actions_a_uav():
    cfg = city_levels()
    positions = len(model_positions(cfg))
    assert positions == 21 and cfg.num_positions == 27  # a building holds 6 of them
    model = TabularModel(cfg)
    assert model.valid.shape == (positions**2, 8**2) and model.rates.shape == (positions**2 * 4, 2)
    learner = TeamQLearner(cfg, runs=2, seed=0)
    assert learner.q.shape == (2, cfg.num_states, 64) and cfg.num_states == 27**2  # rows: the upper bound
    assert exact_q_table(cfg, 0.9).shape == (27**2, 64)


def test_model_tables_agree_with_the_environment_at_levels_in_a_city():
    """A random walk that climbs and descends: every step's rates, next positions and Q row match the tables."""
    cfg = city_levels(state_includes_tasks=True)
    model = TabularModel(cfg)
    env = UAVSpectrumEnv(batch_size=8, config=cfg, seed=3)
    td = env.reset()
    policy = TabularPolicy(torch.rand(cfg.num_states, cfg.num_joint_actions, dtype=torch.float64), cfg)
    climbed = False
    for _ in range(40):
        td = policy(td)
        k_before = model.configuration_ids(td["positions"], td["tasks"], td["levels"])
        joint = (td["agents", "action"] * torch.tensor([1, 8])).sum(-1)
        td = env.step(td)
        nxt = td["next"]
        climbed |= bool((nxt["levels"] != td["levels"]).any())
        k_after = model.configuration_ids(nxt["positions"], nxt["tasks"], nxt["levels"])
        assert torch.equal(model.next_cells[k_before // 4, joint].long(), k_after // 4)
        assert torch.equal(model.next_tasks[k_before % 4, joint].long(), k_after % 4)
        assert torch.allclose(model.r_pu[k_after].float(), nxt["r_pu"][:, 0])
        assert torch.equal(model.row[k_after].long(), nxt["state_index"][:, 0])
        td = env.step_mdp(td)
    assert climbed


def test_a_table_without_levels_is_refused_the_levels():
    model = TabularModel(city_levels())
    with pytest.raises(ValueError, match=r"altitudes_m=\[20.0, 100.0, 300.0\] needs each UAV's level"):
        model.configuration_ids(torch.zeros(1, 2, 2, dtype=torch.long), torch.zeros(1, 2, dtype=torch.long))


@pytest.mark.parametrize("method", ["q_learning", "value_iteration"])
def test_evaluating_the_tables_gives_the_numbers_of_the_torchrl_policies_at_levels(method):
    """The tabular agent's batched evaluation equals TorchRL rollouts of its policies at levels in a city."""
    from omegaconf import OmegaConf

    from uavrl.agents.tabular import TabularAgent

    cfg = city_levels(max_steps=200)
    settings = dict(name="tabular", method=method, alpha=0.1, gamma=0.9, epsilon=0.1, shared_table=False)
    settings |= dict(backend="numba", memory_budget=2**30, episodes=3, runs=2)
    agent = TabularAgent(cfg, OmegaConf.create({"agent": settings}), "cpu", seed=1)
    for _ in range(agent.num_iterations):
        agent.train_iteration()
    kwargs = dict(num_starts=16, horizon=9, seed=5, gamma=0.9)
    from_tables = agent.evaluate(cfg, **kwargs)
    from_rollouts = [evaluate(policy, cfg, **kwargs) for policy in agent.policies()]
    assert from_tables == from_rollouts and 0 < from_tables[0]["eval/optimality"] <= 1


@pytest.mark.slow
@pytest.mark.parametrize("method", ["q_learning", "value_iteration"])
def test_train_and_evaluate_a_tabular_run_at_levels(tmp_path, compose_cfg, method):
    """``python -m uavrl.train agent=tabular`` at three levels over a city, then its checkpoint's policy evaluated
    again (as ``uavrl.evaluate`` does): the numbers of the run."""
    from uavrl import load_policy
    from uavrl.train import train

    model = ["env=a2g_urban", "env.altitudes_m=[20,100,300]", "env.grid=[3,3]", "env.num_uavs=2"]
    model += ["env.city=highrise", "env.environment=highrise"]
    settings = ["agent=tabular", f"agent.method={method}", "agent.episodes=3", "agent.runs=1", "env.max_steps=100"]
    run_dir = train(compose_cfg(*settings, *model, "eval.num_starts=8", "progress=false", f"run_dir={tmp_path}"))
    trained = json.loads((run_dir / "metrics.json").read_text())
    policy, env_cfg = load_policy(run_dir)
    assert env_cfg.altitudes_m == (20, 100, 300) and env_cfg.city == "highrise"
    evaluated = evaluate(policy, env_cfg, num_starts=8)
    assert 0 < evaluated["eval/optimality"] <= 1
    assert evaluated["eval/optimality"] == pytest.approx(trained["eval/optimality"])
