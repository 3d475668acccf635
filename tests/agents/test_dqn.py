"""Factored deep Q-network: learning, double-DQN targets over valid actions, masks, checkpoints, errors."""

import copy
import io
import math

import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensordict import TensorDict

from uavrl.agents.baselines import RandomPolicy
from uavrl.agents.dqn import Q_INPUTS, DQNAgent, TeamQNet, ValidGreedy, n_step_returns
from uavrl.agents.dqn.migration import _stored_entry
from uavrl.agents.evaluation import evaluate
from uavrl.config import model_config
from uavrl.envs import UAVSpectrumEnv, joint_action_valid, observation_with_nodes
from uavrl.train import train

TINY = [
    "env.grid=[3,3]",
    "env.max_steps=8",
    "agent.iterations=30",
    "agent.worlds=32",
    "agent.hidden=32",
    "agent.depth=1",
    "agent.batch_size=128",
    "agent.buffer_size=4000",
    "agent.updates=16",
    "agent.learning_starts=256",
    "agent.lr=0.003",
    "agent.lr_end=0.0003",
    "agent.tau=0.05",
]


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


@pytest.fixture
def tiny_cfg(compose_cfg):
    """``tiny_cfg(*overrides)``: the tiny DQN config; later overrides win."""
    return lambda *overrides: compose_cfg("agent=dqn", *TINY, *overrides)


@pytest.fixture
def make_agent(tiny_cfg):
    """``make_agent(*overrides, seed=0)``: a DQN agent of the tiny config."""

    def make(*overrides, seed=0):
        cfg = tiny_cfg(*overrides)
        return DQNAgent(model_config(cfg), cfg, torch.device("cpu"), seed)

    return make


def transitions(agent, iterations=1):
    """Stored transitions of ``iterations`` training iterations, straight from the replay buffer."""
    for _ in range(iterations):
        agent.train_iteration()
    return agent.buffer[: len(agent.buffer)]


@pytest.mark.parametrize("overrides", [["agent.mixer=vdn"], ["agent.mixer=qmix"], ["agent.head=joint"]])
def test_short_training_beats_a_random_policy(overrides, make_agent):
    agent = make_agent(*overrides)
    for _ in range(agent.num_iterations):
        metrics = agent.train_iteration()
    assert math.isfinite(metrics["train/loss"]) and metrics["train/epsilon"] == pytest.approx(0.05)
    assert agent.env_steps == 30 * 32 * 8
    trained = evaluate(agent.policies()[0], agent.env_cfg, num_starts=64)
    random = evaluate(RandomPolicy(0), agent.env_cfg, num_starts=64)
    assert trained["eval/optimality"] > random["eval/optimality"] + 0.25  # random: 0.58


def test_valid_greedy_respects_masks_never_collides_and_switches_each_task_once():
    env = UAVSpectrumEnv(batch_size=256, grid=(4, 3), num_uavs=4, seed=3)
    td = env.reset()
    greedy = ValidGreedy(env.neighbours, width=4)
    values = torch.randn(256, 4, 6)
    actions = greedy(values, td["agents", "action_mask"], td["positions"], td["tasks"])
    assert td["agents", "action_mask"].gather(-1, actions.unsqueeze(-1)).all()
    joint = (actions * 6 ** torch.arange(4)).sum(-1)
    assert joint_action_valid(env.cells_of(td["positions"]), env.neighbours, 4).gather(-1, joint.unsqueeze(-1)).all()
    for task in (0, 1):  # at most one UAV switches to each task per step
        assert ((actions == 4 + task) & (td["tasks"] != task)).sum(-1).max() <= 1
    # one UAV has no one to coordinate with: the plain masked argmax
    lone = UAVSpectrumEnv(batch_size=256, grid=(4, 3), num_uavs=1, seed=3).reset()
    masked = values[:, :1].masked_fill(~lone["agents", "action_mask"], -math.inf).argmax(-1)
    assert torch.equal(greedy(values[:, :1], lone["agents", "action_mask"], lone["positions"], lone["tasks"]), masked)


def greedy_rule(values, mask, cells, tasks, neighbours):
    """ValidGreedy's rule for one world, written out plainly: ``values``/``mask`` [N][6], ``cells``/``tasks`` [N]."""
    targets = [[*neighbours[c], c, c] for c in cells]
    claimed, switched_to, actions = list(cells), set(), []

    def best(i, options):  # first of the highest values among the options not claimed by another UAV (or None)
        free = [a for a in options if mask[i][a] and targets[i][a] not in claimed[:i] + claimed[i + 1 :]]
        return max(free, key=lambda a: (values[i][a], -a), default=None)

    for i in range(len(cells)):
        options = [a for a in range(6) if not (a >= 4 and tasks[i] != a - 4 and a - 4 in switched_to)]
        actions.append(best(i, options))
        claimed[i] = targets[i][actions[i]]
        if actions[i] >= 4 and tasks[i] != actions[i] - 4:
            switched_to.add(actions[i] - 4)
    for i in range(len(cells)):  # second pass: a UAV that kept its cell takes its best move if it is worth more now
        move = best(i, range(4))
        if move is not None and actions[i] >= 4 and values[i][move] > values[i][actions[i]]:
            actions[i], claimed[i] = move, targets[i][move]
    return actions


@pytest.mark.parametrize("grid, num_uavs", [((3, 3), 2), ((4, 3), 4), ((3, 2), 5), ((10, 10), 6)])
def test_valid_greedy_follows_its_rule_world_by_world(grid, num_uavs):
    env = UAVSpectrumEnv(batch_size=64, grid=grid, num_uavs=num_uavs, seed=5)
    td = env.reset()
    greedy = ValidGreedy(env.neighbours, width=grid[0])
    values = torch.randint(0, 3, (64, num_uavs, 6), generator=torch.Generator().manual_seed(0)).float()  # many ties
    actions = greedy(values, td["agents", "action_mask"], td["positions"], td["tasks"])
    cells, neighbours = env.cells_of(td["positions"]).tolist(), env.neighbours.tolist()
    for w in range(64):
        mask, tasks = td["agents", "action_mask"][w].tolist(), td["tasks"][w].tolist()
        assert actions[w].tolist() == greedy_rule(values[w].tolist(), mask, cells[w], tasks, neighbours)


def online_and_target(make_agent, *overrides):
    """An agent, its first transitions, and Q values under its online and its (perturbed) target parameters."""
    agent = make_agent(*overrides, "agent.learning_starts=100000")  # no gradient step
    data, loss = transitions(agent)[:64], agent.loss
    factored = agent.settings.head == "factored"
    params, module = (
        (loss.target_local_value_network_params, loss.local_value_network)
        if factored
        else (loss.target_value_network_params, loss.value_network)
    )
    with torch.no_grad():  # make the target network differ from the online one
        for name, p in params.items(True, True):
            if name[-1] in ("weight", "bias"):
                p.add_(0.1 * torch.randn_like(p))
    net = agent.greedy[0 if factored else 1].module

    def online(td):
        return net(td["agents", "observation"], td["positions"], td["state"])

    def target(td):
        with params.to_module(module):
            return online(td)

    return agent, data, online, target


@torch.no_grad()
def test_factored_head_is_its_mlp_on_the_whole_input():
    """The head's first layer, applied to the embedding once per world and to the rest per UAV, is the head's
    MultiAgentMLP on the concatenated input."""
    env = UAVSpectrumEnv(batch_size=5, grid=(4, 4), num_uavs=3)
    torch.manual_seed(0)
    net = TeamQNet(env, "factored", hidden=16, depth=2)
    td = env.reset()
    observation = observation_with_nodes(td["agents", "observation"], td["state"])
    embedding = net.torso(observation)
    cells = td["positions"][..., 1] * 4 + td["positions"][..., 0]
    held = (net.neighbours[cells].unsqueeze(-1) == cells[..., None, None, :]).any(-1).float()
    whole = torch.cat([embedding, observation, net.ids.expand(5, -1, -1), held], -1)
    torch.testing.assert_close(net(*(td[k] for k in Q_INPUTS)), net.head(whole), rtol=1e-5, atol=1e-6)


def test_factored_target_is_double_dqn_over_valid_actions(make_agent):
    agent, data, online, target = online_and_target(make_agent, "agent.mixer=vdn", "agent.gamma=0.7")
    nxt = data["next"]
    best = ValidGreedy(agent.env.neighbours, 3)(
        online(nxt), nxt["agents", "action_mask"], nxt["positions"], nxt["tasks"]
    )
    assert nxt["agents", "action_mask"].gather(-1, best.unsqueeze(-1)).all()
    assert not torch.equal(best, online(nxt).argmax(-1))  # the unmasked argmax would pick invalid moves
    y = nxt["reward"] + 0.7 * target(nxt).gather(-1, best.unsqueeze(-1)).sum(-2)
    value = online(data).gather(-1, data["agents", "action"].unsqueeze(-1)).sum(-2)
    assert agent.loss(data)["loss"].item() == pytest.approx(
        torch.nn.functional.smooth_l1_loss(value, y).item(), rel=1e-5
    )
    # the plain DQN target (the target network's own max) is a different number
    assert not torch.allclose(y, nxt["reward"] + 0.7 * target(nxt).max(-1).values.sum(-1, keepdim=True))


def n_step_reference(rewards, terminated, n, gamma):
    """Per step of one episode: (the discounted sum of up to n rewards, stopping after a terminal step or the
    episode's end; the index of the step whose successor bootstraps; how many rewards were summed)."""
    T, out = len(rewards), []
    for t in range(T):
        total, k = 0.0, 0
        while k < n and t + k < T:
            total += gamma**k * rewards[t + k]
            k += 1
            if terminated[t + k - 1]:
                break
        out.append((total, t + k - 1, k))
    return out


@pytest.mark.parametrize("n", [1, 2, 5])
def test_n_step_returns_sum_rewards_within_the_episode_and_stop_at_termination(n):
    T, W = 7, 3
    torch.manual_seed(n)
    rewards = torch.randn(W, T, 1)
    terminated = torch.zeros(W, T, 1, dtype=torch.bool)
    terminated[1, 4] = True  # world 1's episode ends at its fifth step; the rest is a new episode
    done = terminated.clone()
    done[:, -1] = True
    episodes = TensorDict(
        {
            "x": torch.arange(T).expand(W, T).unsqueeze(-1),
            "next": {"x": torch.arange(1, T + 1).expand(W, T).unsqueeze(-1), "reward": rewards, "done": done},
        },
        batch_size=[W, T],
    ).set(("next", "terminated"), terminated)
    out = n_step_returns(episodes.clone(), n, 0.7)
    for w in range(W):
        # a termination ends the sum as the episode's end does (done), both in the reference
        expected = n_step_reference(rewards[w, :, 0].tolist(), done[w, :, 0].tolist(), n, 0.7)
        for t, (total, last, k) in enumerate(expected):
            assert out["next", "reward"][w, t, 0].item() == pytest.approx(total, abs=1e-6)
            assert out["next", "x"][w, t, 0].item() == last + 1
            assert out["next", "terminated"][w, t, 0].item() == terminated[w, last, 0].item()
            if n > 1:
                assert out["steps_to_next_obs"][w, t].item() == k


def test_n_step_target_discounts_by_the_steps_summed(make_agent):
    agent, data, online, target = online_and_target(make_agent, "agent.mixer=vdn", "agent.gamma=0.7", "agent.n_step=3")
    nxt, steps = data["next"], data["steps_to_next_obs"]
    assert set(steps.unique().tolist()) == {1, 2, 3}  # the episodes' last two steps sum fewer
    best = ValidGreedy(agent.env.neighbours, 3)(
        online(nxt), nxt["agents", "action_mask"], nxt["positions"], nxt["tasks"]
    )
    y = nxt["reward"] + 0.7 ** steps.unsqueeze(-1) * (~nxt["terminated"]) * target(nxt).gather(
        -1, best.unsqueeze(-1)
    ).sum(-2)
    value = online(data).gather(-1, data["agents", "action"].unsqueeze(-1)).sum(-2)
    assert agent.loss(data)["loss"].item() == pytest.approx(
        torch.nn.functional.smooth_l1_loss(value, y).item(), rel=1e-5
    )


def test_prioritized_replay_draws_by_td_error_and_weights_the_loss(make_agent):
    agent = make_agent("agent.mixer=vdn", "agent.replay=prioritized", "agent.priority_alpha=0.5")
    for _ in range(2):
        agent.train_iteration()
    sampler, filled = agent.buffer.sampler, len(agent.buffer)
    errors = torch.rand(filled, dtype=torch.float64) * (torch.arange(filled) % 4 == 0)  # 3 of 4 slots: error 0
    agent.buffer.update_priority(torch.arange(filled), errors)
    sampler.beta = 0.7
    torch.manual_seed(0)
    batch = agent.buffer.sample(20000)
    # drawn in proportion to (|error| + 1e-6)^alpha, each slot's weight (p_i / min p)^-beta: Schaul et al.'s
    # importance weight over its largest, computed here from the errors
    p = (errors + 1e-6) ** 0.5
    counts = torch.bincount(batch["index"], minlength=filled).double()
    assert counts[errors == 0].sum() < 0.01 * len(batch["index"])
    assert torch.allclose(counts / counts.sum(), p / p.sum(), atol=0.01)
    expected = ((p / p.min()) ** -0.7)[batch["index"]]
    torch.testing.assert_close(batch["priority_weight"], expected.float())
    # the loss is the weighted mean of the Huber terms, and writes each transition's |TD error| for the priorities
    small = batch[:64]
    weighted = agent.loss(small)["loss"]
    td_error = small["td_error"]
    unweighted = agent.loss(small.exclude("priority_weight"))["loss"]
    huber = torch.where(td_error < 1, 0.5 * td_error**2, td_error - 0.5)
    assert weighted.item() == pytest.approx((small["priority_weight"] * huber).mean().item(), rel=1e-5)
    assert unweighted.item() == pytest.approx(huber.mean().item(), rel=1e-5)
    # the agent's gradient step sets the priorities of the transitions it drew
    before = sampler.priorities.clone()
    agent._update()
    assert (sampler.priorities != before).sum() > 0


@torch.no_grad()
def test_joint_target_masks_invalid_joint_actions_in_the_max(make_agent):
    agent, data, online, target = online_and_target(make_agent, "agent.head=joint", "agent.gamma=0.5")
    nxt = data["next"]
    valid = joint_action_valid(agent.env.cells_of(nxt["positions"]), agent.env.neighbours, 2)
    best = online(nxt).masked_fill(~valid, -math.inf).argmax(-1, keepdim=True)
    assert not torch.equal(
        best, online(nxt).argmax(-1, keepdim=True)
    )  # the unmasked argmax would pick invalid joint actions
    y = nxt["reward"] + 0.5 * target(nxt).gather(-1, best)
    value = online(data).gather(-1, data["joint_action"].unsqueeze(-1))
    assert agent.loss(data)["loss"].item() == pytest.approx(
        torch.nn.functional.smooth_l1_loss(value, y).item(), rel=1e-5
    )


@pytest.mark.parametrize("head", ["factored", "joint"])
def test_policies_take_valid_actions(head, make_agent):
    agent = make_agent(f"agent.head={head}")
    data = transitions(agent)  # exploration actions (epsilon = 1 at first)
    assert data["agents", "action_mask"].gather(-1, data["agents", "action"].unsqueeze(-1)).all()
    env = UAVSpectrumEnv(batch_size=32, config=agent.env_cfg, seed=5)
    rollout = env.rollout(8, agent.policies()[0])
    actions, mask = rollout["agents", "action"], rollout["agents", "action_mask"]
    assert mask.gather(-1, actions.unsqueeze(-1)).all()
    joint = (actions * 6 ** torch.arange(2)).sum(-1)
    assert (
        joint_action_valid(env.cells_of(rollout["positions"]), env.neighbours, 2).gather(-1, joint.unsqueeze(-1)).all()
    )


@pytest.mark.parametrize(
    "overrides",
    [
        ["agent.mixer=vdn", "agent.buffer_size=300"],
        ["agent.mixer=qmix", "agent.n_step=3"],
        ["agent.head=joint", "agent.replay=prioritized"],
        ["agent.mixer=vdn", "agent.replay=prioritized", "agent.buffer_size=300"],
    ],
)
def test_checkpoint_round_trip_continues_identically(overrides, make_agent):
    """state_dict -> disk -> load_state_dict: same Q values, then the same training and the same greedy actions.

    The first case wraps the replay buffer around (768 writes into 300 slots).
    """
    agent = make_agent(*overrides, seed=4)
    for _ in range(3):
        agent.train_iteration()
    saved = io.BytesIO()
    torch.save(agent.state_dict(), saved)  # a checkpoint on disk holds copies, not the live tensors
    saved.seek(0)
    state = torch.load(saved, weights_only=False)
    restored = make_agent(*overrides, seed=4)
    restored.load_state_dict(state)
    probe = UAVSpectrumEnv(batch_size=8, config=agent.env_cfg, seed=9).reset()
    assert (
        agent.greedy(probe.clone()) == restored.greedy(probe.clone())
    ).all() and restored.env_steps == agent.env_steps
    torch.set_rng_state(state["rng"])  # the two agents share this process's global RNG; a resumed run has its own
    metrics = agent.train_iteration()
    torch.set_rng_state(state["rng"])
    assert restored.train_iteration() == metrics
    assert (agent.greedy(probe.clone()) == restored.greedy(probe.clone())).all()
    actions = [
        UAVSpectrumEnv(batch_size=8, config=agent.env_cfg, seed=9).rollout(8, a.policies()[0])["agents", "action"]
        for a in (agent, restored)
    ]
    assert torch.equal(*actions)


@pytest.mark.parametrize("overrides", [["agent.mixer=vdn"], ["agent.mixer=qmix", "env.num_uavs=3"]])
def test_checkpoint_with_nodes_in_the_observation_resumes_identically(overrides, make_agent):
    """A replay buffer of the earlier layout (nodes in every observation, state only for QMIX) loads as the current."""
    agent = make_agent(*overrides, "agent.buffer_size=300", seed=2)
    for _ in range(2):
        agent.train_iteration()
    state = agent.state_dict()
    stored = agent.buffer.storage._storage  # 512 writes: every slot filled
    full = agent.transitions(stored.exclude("index")).set("index", stored.get("index"))  # as saved before
    old = copy.deepcopy(full.state_dict())  # flat (torchrl 0.14) or nested dicts (0.11)
    for step in ((), ("next",)):
        holder, key = _stored_entry(old, (*step, "agents", "observation"))
        states, state_key = _stored_entry(old, (*step, "state"))
        holder[key] = observation_with_nodes(holder[key], states[state_key])
        if "qmix" not in overrides[0]:
            del states[state_key]
    saved = io.BytesIO()
    storage = {**state["buffer"]["_storage"], "_storage": old}
    torch.save({**state, "buffer": {**state["buffer"], "_storage": storage}}, saved)
    saved.seek(0)
    restored = make_agent(*overrides, "agent.buffer_size=300", seed=2)
    restored.load_state_dict(torch.load(saved, weights_only=False))
    assert (agent.buffer.storage._storage == restored.buffer.storage._storage).all()
    torch.set_rng_state(state["rng"])
    metrics = agent.train_iteration()
    torch.set_rng_state(state["rng"])
    assert restored.train_iteration() == metrics


def test_training_command_logs_the_shared_tags_and_resumes_exactly(tmp_path, tiny_cfg, interrupt_at, episode_tags):
    """Through ``uavrl.train``: the tabular agent's TensorBoard tags; a run killed after a checkpoint and resumed ends
    as the whole run."""
    run = ["agent.iterations=4", "train.checkpoint_every=2", "eval.num_starts=8", "progress=false"]
    whole = train(tiny_cfg(*run, f"run_dir={tmp_path / 'whole'}"))
    tags = set(EventAccumulator(str(whole)).Reload().Tags()["scalars"])
    assert episode_tags | {"train/loss", "train/epsilon", "eval/optimal_fraction"} <= tags
    with interrupt_at(DQNAgent, 4), pytest.raises(KeyboardInterrupt):
        train(tiny_cfg(*run, f"run_dir={tmp_path / 'killed'}"))
    train(tiny_cfg(*run, f"resume={tmp_path / 'killed'}"), overrides=[f"resume={tmp_path / 'killed'}"])
    a, b = (torch.load(d / "checkpoint.pt", weights_only=False)["agent"]["loss"] for d in (whole, tmp_path / "killed"))
    assert a.keys() == b.keys()
    # torchrl 0.11's loss also keeps non-tensor entries (shapes) in its state
    assert all(torch.equal(a[k], b[k]) if torch.is_tensor(a[k]) else a[k] == b[k] for k in a)


def test_same_seed_same_training(make_agent):
    runs = []
    for seed in (1, 1, 2):
        agent = make_agent(seed=seed)
        runs.append([agent.train_iteration() for _ in range(3)])
    assert runs[0] == runs[1] and runs[0] != runs[2]


@pytest.mark.parametrize(
    "overrides, message",
    [
        (["agent.mixer=sum"], "agent.mixer='sum' is invalid: allowed mixers are 'vdn', 'qmix'"),
        (["agent.head=tree"], "agent.head='tree' is invalid: allowed heads are 'factored', 'joint'"),
        (
            ["agent.head=joint", "env.num_uavs=5"],
            r"agent.head=.joint. is invalid with env.num_uavs=5: it needs 6\^5 outputs, .* use agent.head=factored",
        ),
        (["agent.worlds=0"], "agent.worlds=0 is invalid"),
        (["agent.gamma=1.5"], r"agent.gamma=1.5 is invalid: it must lie in \[0.0, 1.0\]"),
        (["agent.lr=0"], "agent.lr=0 is invalid: it must be positive"),
    ],
)
def test_bad_settings_fail_with_one_line_errors(overrides, message, make_agent):
    with pytest.raises(ValueError, match=message) as err:
        make_agent(*overrides)
    assert "\n" not in str(err.value)


@pytest.mark.slow
def test_paper_preset_two_uavs_reaches_target(compose_cfg):
    """N = 2 on 6x6 with the default settings: return ratio >= 0.99 against the exact optimum (BENCHMARKS.md)."""
    cfg = compose_cfg("agent=dqn")
    agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), 0)
    for _ in range(agent.num_iterations):
        agent.train_iteration()
    metrics = evaluate(agent.policies()[0], agent.env_cfg, num_starts=100)
    assert metrics["eval/return_ratio"] >= 0.99 and metrics["eval/reach_999"] >= 0.99


@pytest.mark.parametrize("objective", ["delta", "log_gap"])
def test_training_reward_of_each_objective(objective, make_agent):
    agent = make_agent(f"agent.objective={objective}", "agent.learning_starts=100000")
    agent.train_iteration()
    data = agent.buffer[: len(agent.buffer)]
    env, reward = agent.env, data.get(("next", "reward")).squeeze(-1).double()
    u_star = env.optimum()[0][0]  # a fixed layout: one U* for every world

    def utility(td):  # the transitions, spread over the env's worlds (one layout)
        B, N = env.num_worlds, env.num_uavs
        return env.utility(td.get("positions").reshape(B, -1, N, 2), td.get("tasks").reshape(B, -1, N))[2].flatten()

    u, u_next = utility(data), utility(data.get("next"))
    if objective == "delta":
        expected = u_next - u
    else:
        gap = lambda value: -torch.log((1 - value / u_star).clamp(min=0) + 1e-4)  # noqa: E731
        expected = gap(u_next) - gap(u)
    torch.testing.assert_close(reward, expected, rtol=1e-5, atol=1e-5)


def test_log_gap_reward_uses_the_layouts_the_batch_was_played_in(make_agent):
    # random layouts are redrawn by the collector's closing reset: the reward must not read the new ones
    agent = make_agent("env.layout=random", "agent.objective=log_gap", "agent.learning_starts=100000")
    seen = []
    original = agent._log_gap_reward

    def spy(batch, u_star, mean_utility):
        seen.append((mean_utility(batch), batch.get("utility")[..., 0].double(), u_star))
        return original(batch, u_star, mean_utility)

    agent._log_gap_reward = spy
    agent.train_iteration()
    mine, recorded, u_star = seen[0]
    torch.testing.assert_close(mine, recorded, rtol=1e-5, atol=1e-5)  # the env's own (float32) utility of each step
    assert (mine <= u_star[:, None] * (1 + 1e-9)).all()
