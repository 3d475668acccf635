"""Tabular team Q-learning: the update rule, both loops, learning, the TorchRL policy."""

import math

import pytest
import torch

from uavrl.agents.tabular import TabularModel, TabularPolicy, TeamQLearner
from uavrl.compat import make_collector
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.evaluation import EPISODE_METRICS, episode_metrics, evaluate


def test_q_update_matches_hand_worked_step():
    """One UAV on a 2x1 grid, greedy, Q preset so 'right' wins; the max is over valid actions only."""
    cfg = make_config("paper", grid=(2, 1), num_uavs=1, max_steps=1, init_tasks="relaying")
    learner = TeamQLearner(cfg, runs=1, seed=0, alpha=0.1, gamma=0.3, epsilon=0.0, backend="torch")
    model = learner.model
    # start in cell 0 relaying: configuration k = cell * 2 + task
    learner._episode_starts = lambda: torch.tensor([0 * 2 + 1])
    learner.q[0, 0] = torch.tensor([0.0, 0.0, 0.0, 5.0, 1.0, 2.0])  # row of cell 0
    learner.q[0, 1] = torch.tensor([9.0, 9.0, 4.0, 9.0, 0.5, 0.25])  # cell 1: up, down, right leave the grid
    steps = learner.run_episode()
    r_before = model.r_pu[1] + model.r_se[1]
    r_after = model.r_pu[3] + model.r_se[3]  # cell 1, relaying
    reward = r_after - r_before  # delta reward, beta = 1
    expected = 0.9 * 5.0 + 0.1 * (reward + 0.3 * 4.0)  # best valid action in cell 1 is 'left' (4.0)
    assert learner.q[0, 0, 3].item() == pytest.approx(expected.item(), rel=1e-12)
    assert steps["moves"].item() == 1 and steps["task_switches"].item() == 0  # one step: the episode's counts
    # untouched entries stay
    assert learner.q[0, 0, 5].item() == 2.0 and learner.q[0, 1, 0].item() == 9.0


@pytest.mark.parametrize("shared", [False, True])
@pytest.mark.parametrize(
    "options",
    [
        dict(preset="paper"),
        dict(preset="paper", state_includes_tasks=True),
        dict(preset="reference_code"),
        dict(preset="paper", reset_positions="keep", grid=(2, 3), num_uavs=3),
    ],
)
def test_numba_and_torch_loops_give_identical_tables(shared, options):
    options = {"grid": (3, 3), "num_uavs": 2, **options}
    cfg = make_config(options.pop("preset"), max_steps=150, **options)
    fast = TeamQLearner(cfg, runs=3, seed=4, shared_table=shared, backend="numba")
    plain = TeamQLearner(cfg, runs=3, seed=4, shared_table=shared, backend="torch")
    for episode in range(3):
        a, b = fast.run_episode(record_steps=episode == 1), plain.run_episode(record_steps=episode == 1)
        assert a.keys() == b.keys()
        for key in EPISODE_METRICS:
            assert torch.equal(a[key], b[key]), key
        for key in a.get("steps", {}):
            assert torch.equal(a["steps"][key], b["steps"][key]), key
    assert torch.equal(fast.q, plain.q)
    assert fast.q.abs().sum() > 0


@pytest.mark.parametrize("backend", ["numba", "torch"])
def test_episode_metrics_are_those_of_the_shared_definition(backend):
    """The learner sums its metrics while it steps; they are what uavrl.evaluation.episode_metrics makes of the
    episode's steps (the sums up to rounding: added in step order there, pairwise here)."""
    cfg = make_config("paper", grid=(3, 3), num_uavs=2, max_steps=40)
    learner = TeamQLearner(cfg, runs=4, seed=1, backend=backend)
    for _ in range(3):
        out = learner.run_episode(record_steps=True)
        u_star = torch.full((4,), learner.model.u_star, dtype=torch.float64)
        steps = out["steps"]
        expected = episode_metrics(steps["r_pu"], steps["r_se"], steps["task_switches"], steps["moves"], u_star)
        assert list(expected) == list(EPISODE_METRICS)
        for key, value in expected.items():
            torch.testing.assert_close(out[key], value, rtol=1e-12, atol=0)
        assert (out["steps_to_90"] < 40).any() and torch.equal(out["moves"], out["moves"].round())


def test_same_seed_same_tables_and_different_seed_differs():
    cfg = make_config("paper", grid=(3, 3), num_uavs=2, max_steps=200)
    tables = []
    for seed in (7, 7, 8):
        learner = TeamQLearner(cfg, runs=2, seed=seed)
        for _ in range(3):
            learner.run_episode()
        tables.append(learner.q.clone())
    assert torch.equal(tables[0], tables[1])
    assert not torch.equal(tables[0], tables[2])


def test_model_tables_agree_with_the_environment():
    """A random walk through the env: every step's rates and next cells match the tables."""
    cfg = make_config("paper", grid=(3, 2), num_uavs=2, max_steps=40, state_includes_tasks=True)
    model = TabularModel(cfg)
    env = UAVSpectrumEnv(batch_size=8, config=cfg, seed=3)
    td = env.reset()
    policy = TabularPolicy(torch.rand(cfg.num_states, cfg.num_joint_actions, dtype=torch.float64), cfg)
    for _ in range(40):
        td = policy(td)
        k_before = model.configuration_ids(td["positions"], td["tasks"])
        joint = (td["agents", "action"] * torch.tensor([1, 6])).sum(-1)
        td = env.step(td)
        nxt = td["next"]
        k_after = model.configuration_ids(nxt["positions"], nxt["tasks"])
        assert torch.equal(model.next_cells[k_before // 4, joint].long(), k_after // 4)
        assert torch.equal(model.next_tasks[k_before % 4, joint].long(), k_after % 4)
        assert torch.allclose(model.r_pu[k_after].float(), nxt["r_pu"][:, 0])
        assert torch.equal(model.row[k_after].long(), nxt["state_index"][:, 0])
        td = env.step_mdp(td)


def test_greedy_policy_reaches_the_optimum_from_every_start_on_3x3():
    cfg = make_config("paper", grid=(3, 3), num_uavs=2, max_steps=800, state_includes_tasks=True)
    learner = TeamQLearner(cfg, runs=2, seed=0)
    for _ in range(100):
        learner.run_episode()
    for q in learner.q:
        result = evaluate(TabularPolicy(q, cfg), cfg, num_starts=64, horizon=20)
        assert result["eval/optimality_min"] >= 0.99


def test_policy_runs_in_rollout_and_collector():
    cfg = make_config("paper", grid=(3, 3), num_uavs=2, max_steps=5)
    policy = TabularPolicy(torch.zeros(cfg.num_states, cfg.num_joint_actions, dtype=torch.float64), cfg)
    env = UAVSpectrumEnv(batch_size=4, config=cfg)
    rollout = env.rollout(5, policy)
    assert rollout["agents", "action"].shape == (4, 5, 2)
    collector = make_collector(UAVSpectrumEnv(batch_size=4, config=cfg), policy, frames_per_batch=40, total_frames=80)
    batches = [b for b in collector]
    collector.shutdown()
    assert len(batches) == 2 and batches[0]["next", "done"].any()


def test_greedy_actions_are_valid_joint_actions():
    cfg = make_config("paper", grid=(2, 2), num_uavs=3, max_steps=10)
    # values that favour invalid joint actions: the policy must still pick valid ones
    q = torch.arange(cfg.num_joint_actions, dtype=torch.float64).expand(cfg.num_states, -1).clone()
    env = UAVSpectrumEnv(batch_size=16, config=cfg)
    td = env.reset()
    for _ in range(10):
        mask = env.joint_action_mask()
        td = TabularPolicy(q, cfg)(td)
        joint = (td["agents", "action"] * torch.tensor([1, 6, 36])).sum(-1)
        assert mask.gather(1, joint[:, None]).all()
        td = env.step_mdp(env.step(td))


def test_too_large_table_and_bad_settings_are_refused():
    with pytest.raises(ValueError, match=r"would need [\d,]+ bytes.*agent=dqn"):
        TeamQLearner(make_config("paper", grid=(10, 10), num_uavs=4), memory_budget=2**30)
    with pytest.raises(ValueError, match="no int64 state index"):
        TeamQLearner(make_config("paper", grid=(20, 20), num_uavs=10))
    with pytest.raises(ValueError, match="layout='random' is invalid for agent=tabular"):
        TeamQLearner(make_config("paper", grid=(3, 3), layout="random"))
    with pytest.raises(ValueError, match="epsilon=1.5 is invalid"):
        TeamQLearner(make_config("paper", grid=(3, 3)), epsilon=1.5)
    with pytest.raises(ValueError, match="backend='jax' is invalid"):
        TeamQLearner(make_config("paper", grid=(3, 3)), backend="jax")
    with pytest.raises(ValueError, match="env.reward='log_gap' is invalid for agent=tabular"):
        TeamQLearner(make_config("paper", grid=(3, 3), reward="log_gap"))
    assert math.isfinite(TeamQLearner(make_config("paper", grid=(2, 2))).model.u_star)


@pytest.mark.parametrize(
    "options",
    [dict(grid=(4, 4), num_uavs=2), dict(grid=(3, 3), num_uavs=3, state_includes_tasks=True)],
)
def test_evaluating_the_tables_gives_the_numbers_of_the_torchrl_policies(options):
    """The tabular agent's evaluation reads its tables in one batched world: the same numbers as TorchRL rollouts of
    each table's TabularPolicy (same starts, same tie-breaking draws)."""
    from omegaconf import OmegaConf

    from uavrl.agents.tabular import TabularAgent

    cfg = make_config("paper", max_steps=200, **options)
    settings = dict(name="tabular", method="q_learning", alpha=0.1, gamma=0.3, epsilon=0.1, shared_table=False)
    settings |= dict(backend="numba", memory_budget=2**30, episodes=3, runs=3)
    agent = TabularAgent(cfg, OmegaConf.create({"agent": settings}), "cpu", seed=1)
    for _ in range(3):
        agent.train_iteration()
    kwargs = dict(num_starts=16, horizon=9, seed=5, gamma=0.9)
    from_tables = agent.evaluate(cfg, **kwargs)
    from_rollouts = [evaluate(policy, cfg, **kwargs) for policy in agent.policies()]
    assert len(from_tables) == 3 and from_tables == from_rollouts
    assert len({r["eval/sum_utility"] for r in from_tables}) > 1  # the tables differ, and so do their results
