"""The size-free DQN's sample-efficiency levers: the oracle's demonstrations with DQfD's margin loss, the curriculum
over teams and layouts, and lookahead at evaluation time."""

from __future__ import annotations

import itertools

import pytest
import torch
from hydra import compose, initialize_config_dir

from uavrl.agents import agent_class
from uavrl.agents.dqn.curriculum import Curriculum
from uavrl.agents.dqn.demonstrations import margin_loss, oracle_transitions
from uavrl.agents.dqn.setnet import SetQCore, SetQNet
from uavrl.agents.evaluation import evaluate_agent, evaluate_with_lookahead
from uavrl.agents.lookahead import LookaheadPolicy, lookahead_policy
from uavrl.config import config_dir, model_config
from uavrl.envs import InvalidOption, UAVSpectrumEnv, make_config
from uavrl.envs.solvers import exact
from uavrl.experiment.runs import optimality_line

SMALL = [
    "agent=dqn",
    "agent.network=set",
    "agent.mixer=mean",
    "agent.sizes=[[2,4,4],[3,5,5]]",
    "agent.worlds=2",
    "agent.hidden=16",
    "agent.updates=2",
    "agent.learning_starts=10",
    "agent.buffer_size=500",
    "env.max_steps=10",
]


def compose_cfg(*overrides):
    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        return compose("config", overrides=[*SMALL, *overrides])


def test_margin_loss_matches_dqfd_formula_by_hand():
    generator = torch.Generator().manual_seed(0)
    values = torch.randn(5, 3, 6, generator=generator)
    expert = torch.randint(6, (5, 3), generator=generator)
    allowed = torch.rand(5, 3, 6, generator=generator) > 0.3
    allowed.scatter_(-1, expert.unsqueeze(-1), True)  # the expert's action is always allowed
    for mixer, mix in (("vdn", sum), ("mean", lambda terms: sum(terms) / len(terms))):
        expected = 0.0
        for b in range(5):
            terms = []
            for i in range(3):
                best = max(
                    float(values[b, i, a]) + (0.0 if a == int(expert[b, i]) else 0.8)
                    for a in range(6)
                    if allowed[b, i, a]
                )
                terms.append(best - float(values[b, i, expert[b, i]]))
            expected += mix(terms) / 5
        assert float(margin_loss(values, expert, allowed, 0.8, mixer)) == pytest.approx(expected, rel=1e-5)


def test_margin_loss_is_zero_once_the_expert_leads_by_the_margin():
    values = torch.tensor([[[0.0, 1.0, 0.1]]])
    allowed = torch.ones(1, 1, 3, dtype=torch.bool)
    assert float(margin_loss(values, torch.tensor([[1]]), allowed, 0.8, "vdn")) == 0.0
    assert float(margin_loss(values, torch.tensor([[2]]), allowed, 0.8, "vdn")) == pytest.approx(1.7)


@pytest.mark.parametrize("layout", ["line", "random"])
def test_demonstrations_reach_u_star_with_the_objectives_rewards(layout):
    cfg = make_config("paper", grid=(5, 5), num_uavs=3, layout=layout).replace(max_steps=16)
    demos = oracle_transitions(cfg, worlds=4, seed=3, objective="log_gap", gap_floor=1e-4).view(4, 16)
    env = UAVSpectrumEnv(batch_size=4, config=cfg, seed=3)
    env.reset()
    u_star = env.optimum()[0]
    last = demos["next"][:, -1]
    final = env.world.utility(last["positions"], last["tasks"])[2]  # the same seed: the same layouts
    assert bool((final >= 0.999 * u_star).all())
    first = demos[:, 0]
    start = env.world.utility(first["positions"], first["tasks"])[2]
    gained = demos["next", "reward"].squeeze(-1).double().sum(-1)  # a telescoping sum of -log(1 - U/U* + floor)
    expected = -torch.log(1 - final / u_star + 1e-4) + torch.log(1 - start / u_star + 1e-4)
    assert torch.allclose(gained, expected, atol=1e-4)


def test_agent_with_demonstrations_and_curriculum_trains_and_resumes():
    cfg = compose_cfg("agent.layouts=[line,random]", "agent.demonstrations=oracle", "agent.demo_transitions=80")
    cfg.agent.curriculum = "loss"
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    assert agent.demonstrations is None  # built at the first gradient step, never for an evaluation
    for _ in range(2):
        metrics = agent.train_iteration()
    assert [len(buffer) for buffer in agent.demonstrations.buffers] == [20] * 4
    assert "train/loss" in metrics
    shares = agent.curriculum.shares()
    assert float(shares.sum()) == pytest.approx(1.0) and bool((shares >= 0.5 / 4 - 1e-12).all())
    state = agent.state_dict()
    again = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    again.load_state_dict(state)
    assert torch.equal(again.curriculum.average, agent.curriculum.average)
    assert "train/loss" in again.train_iteration()
    for rebuilt, kept in zip(again.demonstrations.buffers, agent.demonstrations.buffers, strict=True):
        assert (rebuilt[:] == kept[:]).all()  # the demonstrations are rebuilt from the seed, not saved


def test_curriculum_shares_follow_the_recent_losses():
    curriculum = Curriculum("loss", groups=4, batch_size=400)
    assert curriculum.batch_sizes() == [100] * 4
    curriculum.record(torch.tensor([1.0, 1.0, 1.0, 5.0]))
    assert curriculum.batch_sizes() == [75, 75, 75, 175]
    for _ in range(2000):  # the moving average forgets: equal losses, equal shares
        curriculum.record(torch.ones(4))
    assert curriculum.batch_sizes() == [100] * 4
    losses = [torch.tensor(2.0)] * 4
    assert float(Curriculum("none", 4, 400).total(losses, [100] * 4)) == 8.0
    assert float(curriculum.total(losses, [50, 50, 100, 200])) == pytest.approx(2.0 * 400 / 100)


@pytest.mark.parametrize(
    ("overrides", "words"),
    [
        (["agent.network=team", "agent.mixer=vdn", "agent.sizes=[]", "agent.demonstrations=oracle"], "agent.network"),
        (["agent.network=team", "agent.mixer=vdn", "agent.sizes=[]", "agent.curriculum=loss"], "agent.network"),
        (["agent.demonstrations=expert"], "agent.demonstrations='expert' is invalid"),
        (["agent.demo_batch_share=1.5"], "agent.demo_batch_share=1.5 is invalid"),
        (["agent.curriculum=grow"], "agent.curriculum='grow' is invalid"),
        (
            ["agent.curriculum=loss", "agent.sizes=[]", "agent.layouts=[]"],
            "^agent.curriculum='loss' is invalid with one ",
        ),
        (["agent.demonstrations=oracle", "env.energy=rotary_wing", "env.base=[-1,0]"], "env.energy"),
    ],
)
def test_bad_lever_settings_are_refused_in_one_line(overrides, words):
    cfg = compose_cfg(*overrides)
    with pytest.raises(ValueError, match=words) as refused:
        agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    assert "\n" not in str(refused.value)


def test_lookahead_of_depth_one_with_the_true_values_is_the_bellman_optimum():
    cfg = make_config("paper", grid=(3, 3), num_uavs=2)
    space = exact.ConfigurationSpace(cfg.grid, 2, "cpu")
    contributions, direct = exact.fixed_layout_tables(cfg)
    potential = space.utility(cfg, contributions, direct)
    gamma, horizon = 0.9, 6
    shorter, full = (exact.optimal_values(space, potential, gamma, h)[0] for h in (horizon - 1, horizon))
    env = UAVSpectrumEnv(batch_size=8, config=cfg, seed=5)

    def true_value(code, worlds):
        return shorter[space.index(code >> 1, code & 1)]

    core = SetQCore(num_actions=6, energy=False, hidden=8, heads=2, depth=1)  # ranks candidates only: width=0
    policy = LookaheadPolicy(
        SetQNet(core, cfg.grid), "mean", cfg, depth=1, width=0, gamma=gamma, objective="delta", leaf_value=true_value
    )
    td = env.reset()
    code = 2 * env.cells_of(td["positions"]) + td["tasks"]
    tables = policy._tables(None)
    policy._nodes = None
    value, action = policy.search(code, torch.arange(8), 1, tables)
    assert torch.allclose(value, full[space.index(code >> 1, code & 1)], atol=1e-9)
    # the chosen joint action, played in the environment itself, earns that value
    after = env.step(td.set(("agents", "action"), action))["next"]
    earned = (
        env.world.utility(after["positions"], after["tasks"])[2]
        - env.world.utility(td["positions"], td["tasks"])[2]
        + gamma * true_value(2 * env.cells_of(after["positions"]) + after["tasks"], None)
    )
    assert torch.allclose(earned, value, atol=1e-9)


def test_lookahead_candidates_are_one_uav_changes_of_the_greedy_action_beyond_four_uavs():
    cfg = make_config("paper", grid=(6, 6), num_uavs=5)
    core = SetQCore(num_actions=6, energy=False, hidden=8, heads=2, depth=1)
    policy = LookaheadPolicy(SetQNet(core, cfg.grid), "vdn", cfg, depth=1, width=0, gamma=0.7)
    q = torch.randn(2, 5, 6)
    allowed = torch.ones(2, 5, 6, dtype=torch.bool)
    greedy = q.argmax(-1)
    actions, learned = policy.candidates(q, allowed, greedy)
    assert torch.equal(actions[:, 0], greedy)
    changed = (actions != greedy.unsqueeze(1)).sum(-1)
    assert bool((changed[learned > -float("inf")][1:] <= 1).all())
    for m, k in itertools.product(range(2), range(actions.shape[1])):
        if learned[m, k] > -float("inf"):
            assert float(learned[m, k]) == pytest.approx(float(q[m, torch.arange(5), actions[m, k]].sum()), rel=1e-5)


def test_lookahead_reads_the_mean_channel_model():
    cfg = make_config("paper", grid=(4, 4), num_uavs=3, fading="rayleigh")
    core = SetQCore(num_actions=6, energy=False, hidden=8, heads=2, depth=1)
    policy = LookaheadPolicy(SetQNet(core, cfg.grid), "mean", cfg, depth=2, width=3, gamma=0.7)
    env = UAVSpectrumEnv(batch_size=4, config=cfg, seed=1)
    td = env.reset()
    code = 2 * env.cells_of(td["positions"]) + td["tasks"]
    tables = policy._tables(None)
    mean = env.world.utility(td["positions"], td["tasks"])[2]  # the deterministic (mean) channels
    assert torch.allclose(policy.utility(code, torch.arange(4), tables), mean)
    assert not torch.allclose(td["r_pu"].squeeze(-1).double() + td["r_se"].squeeze(-1).double(), mean)
    rollout = env.rollout(3, policy, tensordict=td, auto_reset=False)
    assert rollout["agents", "action"].shape == (4, 3, 3) and policy.world_steps == 12


def test_eval_lookahead_on_a_size_free_agent_reports_its_cost():
    cfg = compose_cfg("agent.layouts=[random]")
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    env_cfg = make_config("paper", grid=(6, 6), num_uavs=4, layout="random")
    metrics = evaluate_with_lookahead(agent, env_cfg, 1, 4, num_starts=4)
    assert metrics["eval/lookahead"] == 1.0 and metrics["eval/lookahead_cpu_s_per_step"] > 0
    assert 0 < metrics["eval/optimality"] <= 1


def test_eval_lookahead_is_refused_for_an_agent_without_q_values():
    from uavrl.agents.baselines import RandomAgent

    cfg = make_config("paper", grid=(4, 4), num_uavs=2)
    with pytest.raises(ValueError, match="needs a Q-network agent"):
        lookahead_policy(RandomAgent(cfg, None, "cpu", 0), cfg, 2, 8)


@pytest.mark.parametrize(
    ("overrides", "words"),
    [
        (["agent=tabular"], "needs a Q-network agent"),
        (["agent=dqn", "agent.mixer=qmix"], "agent.mixer='qmix'"),
    ],
)
def test_eval_lookahead_is_refused_before_training(overrides, words):
    from uavrl.agents.lookahead_rules import lookahead_settings

    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        cfg = compose("config", overrides=[*overrides, "eval.lookahead=2"])
    with pytest.raises(ValueError, match=words):
        lookahead_settings(cfg)
    assert lookahead_settings(compose_cfg()) == {}


def test_eval_lookahead_on_a_per_size_dqn_in_its_own_model():
    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        overrides = ["agent=dqn", "agent.mixer=vdn", "agent.worlds=2", "agent.buffer_size=100", "env.grid=[4,4]"]
        cfg = compose("config", overrides=[*overrides, "env.num_uavs=2", "env.max_steps=5"])
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    metrics = evaluate_with_lookahead(agent, model_config(cfg), 2, 3, num_starts=3)
    assert metrics["eval/lookahead"] == 2.0 and 0 < metrics["eval/optimality"] <= 1
    assert "fixed starts, the greedy policy with a depth-2 lookahead ends at" in optimality_line(cfg, metrics, "dqn")
    with pytest.raises(ValueError, match="its run's model"):
        lookahead_policy(agent, make_config("paper", grid=(5, 5), num_uavs=2), 1, 3)


def test_evaluate_checks_the_lookahead_against_the_checkpoints_agent_not_its_own_default():
    """``python -m uavrl.evaluate checkpoint=<dqn run> eval.lookahead=1``: evaluate's own config holds the default
    agent (tabular); the saved run's agent is the one that must have a Q-network."""
    from uavrl.agents.lookahead_rules import lookahead_settings

    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        evaluate_cfg = compose("config", overrides=["agent=tabular", "eval.lookahead=1"])
    saved = compose_cfg()
    assert lookahead_settings(evaluate_cfg, saved.agent) == {"lookahead": 1, "lookahead_width": 8}
    with pytest.raises(ValueError, match="agent=tabular"):
        lookahead_settings(evaluate_cfg, evaluate_cfg.agent)


def test_the_python_lookahead_is_refused_before_its_deepest_level_outgrows_the_memory_budget():

    cfg = compose_cfg("agent.layouts=[random]")
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    env_cfg = make_config("paper", grid=(4, 4), num_uavs=2, layout="random")
    with pytest.raises(InvalidOption) as err:
        evaluate_agent(agent, env_cfg, lookahead=12, lookahead_width=0, num_starts=4)
    assert str(err.value).startswith(
        "lookahead=12 is invalid: the search's deepest level, 36^12 configurations for each of 4 starts, needs about "
    )
    assert str(err.value).endswith(
        "over memory_budget=4294967296: lower lookahead, give lookahead_width=<candidates per node>, or raise "
        "memory_budget=<bytes>"
    )
    # the same search within a budget runs; a smaller budget refuses it
    assert evaluate_agent(agent, env_cfg, lookahead=1, lookahead_width=0, num_starts=4)["eval/lookahead"] == 1.0
    with pytest.raises(InvalidOption, match="^lookahead=1 is invalid: .* over memory_budget=1000:"):
        evaluate_agent(agent, env_cfg, lookahead=1, lookahead_width=0, num_starts=4, memory_budget=1000)


def test_the_python_lookahead_width_is_refused_without_a_lookahead():
    from uavrl.agents.baselines import RandomAgent

    cfg = make_config("paper", grid=(4, 4), num_uavs=2)
    with pytest.raises(
        InvalidOption, match=r"^lookahead_width=3 is invalid: only lookahead >= 1 reads it, not lookahead=0$"
    ):
        evaluate_agent(RandomAgent(cfg, None, "cpu", 0), cfg, lookahead_width=3, num_starts=2)
