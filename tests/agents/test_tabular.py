"""Tabular team Q-learning: the update rule, both loops, learning, the TorchRL policy."""

import math

import pytest
import torch

from uavrl.agents.episodes import EPISODE_METRICS, episode_metrics
from uavrl.agents.evaluation import evaluate
from uavrl.agents.tabular import TabularModel, TabularPolicy, TeamQLearner
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.compat import make_collector
from uavrl.envs.physics import streams


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


def reference_episode(learner: TeamQLearner) -> dict[str, torch.Tensor]:
    """The learner's next episode written the direct way, in plain Python floats over the model's tables: updates
    its Q tables, episode and configuration as ``run_episode`` does, and returns each step's ``r_pu``, ``r_se``,
    ``task_switches``, ``moves`` ``[R, T]``.

    Same starts and random numbers as the learner (inputs here, not under test), same arithmetic in the same order:
    epsilon-greedy over the valid joint actions, ties broken by the uniform; the target's max over the next row as
    it was before the step's update; with ``shared_table`` every world reads the table, then each visited entry
    moves towards the mean of its worlds' targets, added in world order.
    """
    m, cfg = learner.model, learner.cfg
    R, T, T2, A = learner.runs, cfg.max_steps, m.num_task_codes, cfg.num_joint_actions
    alpha, gamma, eps = learner.alpha, learner.gamma, learner.epsilon
    q = learner.q.tolist()
    rates, row, valid = m.rates.tolist(), m.row.tolist(), m.valid.tolist()
    next_cells, next_tasks, moves, switches = (x.tolist() for x in (m.next_cells, m.next_tasks, m.moves, m.switches))
    k = learner._episode_starts().tolist()
    heads = learner._stream_heads()
    uniforms = (streams.lane_bits(heads[:, None], torch.arange(T)).double() * streams.UNIFORM_SCALE).tolist()
    table = [0] * R if learner.shared_table else list(range(R))
    prev, best = [rates[kw] for kw in k], [0.0] * R
    steps = {key: [[0.0] * T for _ in range(R)] for key in ("r_pu", "r_se", "task_switches", "moves")}
    for step in range(T):
        targets = {}
        for w in range(R):
            p, t, q_row = k[w] // T2, k[w] % T2, q[table[w]][row[k[w]]]
            actions = [a for a in range(A) if valid[p][a]]
            u = uniforms[w][step]
            if u < eps:
                j = actions[int(u / eps * len(actions))]
            else:
                ties = [a for a in actions if q_row[a] == max(q_row[b] for b in actions)]
                j = ties[int((u - eps) / (1 - eps) * len(ties))]
            k2 = next_cells[p][j] * T2 + next_tasks[t][j]
            r_pu, r_se = rates[k2]
            if cfg.reward == "best_so_far":  # 10 (S - M) above the episode's best M, S - M below
                gain = r_pu + r_se - best[w]
                reward = 10 * gain if gain > 0 else gain
                best[w] = max(best[w], r_pu + r_se)
            else:  # eq. 7
                reward = cfg.beta1 * (r_pu - prev[w][0]) + cfg.beta2 * (r_se - prev[w][1])
            next_row, next_actions = q[table[w]][row[k2]], [a for a in range(A) if valid[k2 // T2][a]]
            target = reward + gamma * max(next_row[a] for a in next_actions)
            targets.setdefault((table[w], row[k[w]], j), []).append(target)
            for key, value in zip(steps, (r_pu, r_se, switches[t][j], moves[p][j]), strict=True):
                steps[key][w][step] = float(value)
            prev[w], k[w] = (r_pu, r_se), k2
        for (n, s, j), visits in targets.items():
            total = 0.0
            for target in visits:
                total += target
            q[n][s][j] = (1 - alpha) * q[n][s][j] + alpha * (total / len(visits))
    learner.q.copy_(torch.tensor(q, dtype=torch.float64))
    learner.episode, learner._configuration = learner.episode + 1, torch.tensor(k)
    return {key: torch.tensor(v, dtype=torch.float64) for key, v in steps.items()}


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
def test_both_loops_learn_the_reference_episodes_bit_for_bit(shared, options):
    """After every episode, both backends' Q tables are those of the learner written the direct way, and their
    episode metrics are the steps' sums added in step order (bit for bit) and what episode_metrics, the DQN's and
    the evaluation's form, makes of the steps."""
    options = {"grid": (3, 3), "num_uavs": 2, **options}
    cfg = make_config(options.pop("preset"), max_steps=150, **options)
    learners = [TeamQLearner(cfg, runs=3, seed=4, shared_table=shared, backend=b) for b in ("numba", "torch")]
    reference = TeamQLearner(cfg, runs=3, seed=4, shared_table=shared)
    u_star = torch.full((3,), reference.model.u_star, dtype=torch.float64)
    for _ in range(3):
        steps = reference_episode(reference)
        expected = episode_metrics(steps["r_pu"], steps["r_se"], steps["task_switches"], steps["moves"], u_star)
        for learner in learners:
            metrics = learner.run_episode()
            assert torch.equal(learner.q, reference.q), learner.backend
            assert list(metrics) == list(expected) == list(EPISODE_METRICS)
            for key in EPISODE_METRICS:
                torch.testing.assert_close(metrics[key], expected[key], rtol=1e-12, atol=0)
            for key in ("task_switches", "moves", "steps_to_90"):
                assert torch.equal(metrics[key], expected[key]), key
            sums = {"sum_r_pu": steps["r_pu"], "sum_r_se": steps["r_se"], "sum_utility": steps["r_pu"] + steps["r_se"]}
            for key, values in sums.items():
                in_order = values[:, 0].clone()
                for t in range(1, cfg.max_steps):
                    in_order += values[:, t]
                assert torch.equal(metrics[key], in_order), key
    assert reference.q.abs().sum() > 0 and (expected["steps_to_90"] < cfg.max_steps).any()


def test_the_kernels_name_the_digest_of_the_functions_they_compile_from_other_modules():
    """numba's cache is keyed by kernels.py alone: a change of the reward, the metrics or the stream mixer must come
    with an edit of kernels.py (its digest), or the compiled loops would keep running the old code."""
    from uavrl.agents.tabular import kernels

    digest = kernels.sources_digest(kernels.COMPILED_ELSEWHERE)
    assert kernels.COMPILED_ELSEWHERE_DIGEST == digest, (
        f"a function the numba kernels compile changed: set COMPILED_ELSEWHERE_DIGEST = {digest!r} in "
        "agents/tabular/kernels.py (that edit makes numba recompile)"
    )


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


@pytest.mark.parametrize(
    "cfg",
    [
        make_config("paper", grid=(2, 2), num_uavs=3, max_steps=10),
        # altitude levels over the highrise city on 3x3: into a building, off the levels
        make_config(
            "a2g_urban",
            grid=(3, 3),
            num_uavs=2,
            city="highrise",
            environment="highrise",
            altitudes_m=[20, 100, 300],
            max_steps=40,
        ),  # fmt: skip
    ],
    ids=["grid", "levels-in-a-city"],
)
def test_greedy_actions_are_valid_joint_actions(cfg):
    # values that favour invalid joint actions: the policy must still pick valid ones
    q = torch.arange(cfg.num_joint_actions, dtype=torch.float64).expand(cfg.num_states, -1).clone()
    env = UAVSpectrumEnv(batch_size=16, config=cfg)
    td = env.reset()
    digits = cfg.joint_action_base ** torch.arange(cfg.num_uavs)
    for _ in range(10):
        mask = env.joint_action_mask()
        td = TabularPolicy(q, cfg)(td)
        joint = (td["agents", "action"] * digits).sum(-1)
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
