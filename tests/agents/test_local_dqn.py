"""The DQN on local observations (``env.observation=local``): trained centrally, acting on what each UAV hears; its
greedy action does not change with anything beyond a UAV's range."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from tests.envs.test_local import perturbed_out_of_range
from uavrl.agents.dqn import DQNAgent
from uavrl.agents.dqn.networks import GIVE_WAY, YieldToContenders
from uavrl.agents.evaluation import evaluate
from uavrl.config import model_config
from uavrl.envs import UAVSpectrumEnv
from uavrl.envs.physics.grid import MOVES

LOCAL = [
    "env.grid=[6,6]",
    "env.num_uavs=4",
    "env.max_steps=10",
    "env.observation=local",
    "env.comm_radius=2.0",
    "agent.iterations=15",
    "agent.worlds=32",
    "agent.hidden=32",
    "agent.batch_size=128",
    "agent.buffer_size=4000",
    "agent.updates=8",
    "agent.learning_starts=256",
]

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


def greedy_actions(agent: DQNAgent, code: torch.Tensor, messages=None) -> tuple:
    """The agent's greedy actions ``[W, N]`` (and with messages what the UAVs send ``[W, N, d]``) at the
    configurations ``code`` ``[W, N]`` of its training world, the messages heard ``[W, N, d]``."""
    world = agent.groups[0].env.world
    out = world.configurations(code) if messages is None else world.configurations(code, messages=messages)
    td = TensorDict(
        {
            "agents": TensorDict(
                {"observation": out.pop("observation"), "action_mask": out.pop("action_mask")}, [len(code), 4]
            ),
            **out,
        },
        [len(code)],
    )
    for module in agent.groups[0].greedy.modules():  # the same coins for every call
        if hasattr(module, "restart"):
            module.restart()
    out = agent.groups[0].greedy(td)["agents"]
    return (out["action"], out["message"]) if messages is not None else (out["action"],)


@pytest.mark.parametrize("mixer, message_size", [("vdn", 0), ("qmix", 0), ("vdn", 2)])
def test_a_local_uav_acts_alike_whatever_lies_beyond_its_range(compose_cfg, mixer, message_size):
    """UAV 0's greedy action (and message) under the trained local DQN (VDN, or QMIX whose mixer alone reads the
    state; with learned messages) is the same when every UAV beyond its range moves elsewhere beyond it, switches task
    and sent another message; the central DQN's changes (this test can fail)."""
    gen = torch.Generator().manual_seed(3)
    agents = {}
    for observation in ("local", "central"):
        overrides = [*LOCAL, f"agent.mixer={mixer}", f"env.message_size={message_size}"]
        if observation == "central":
            overrides = [o for o in overrides if not o.startswith(("env.observation", "env.comm_radius", "env.mess"))]
        cfg = compose_cfg("agent=dqn", *overrides)
        agents[observation] = agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), 0)
        for _ in range(5):
            agent.train_iteration()
    codes, moved, sent, heard = [], [], [], []
    for _ in range(300):
        code = 2 * torch.randperm(36, generator=gen)[:4] + torch.randint(0, 2, (4,), generator=gen)
        messages = 2 * torch.rand(4, message_size, generator=gen) - 1
        far, far_messages = perturbed_out_of_range(code, messages, (6, 6), 2.0, gen)
        codes.append(code)
        moved.append(far)
        sent.append(messages)
        heard.append(far_messages)
    codes, moved = torch.stack(codes), torch.stack(moved)
    sent, heard = (torch.stack(m) if message_size else None for m in (sent, heard))
    local = [greedy_actions(agents["local"], c, m) for c, m in ((codes, sent), (moved, heard))]
    assert all(torch.equal(a[:, 0], b[:, 0]) for a, b in zip(*local, strict=True))
    central = [greedy_actions(agents["central"], c)[0][:, 0] for c in (codes, moved)]
    assert (central[0] != central[1]).sum() > 0


def test_the_local_dqn_trains_saves_loads_and_evaluates(compose_cfg, tmp_path):
    cfg = compose_cfg("agent=dqn", *LOCAL)
    agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), 0)
    for _ in range(int(cfg.agent.iterations)):
        agent.train_iteration()
    again = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), 1)
    again.load_state_dict(agent.state_dict())
    starts = dict(num_starts=16, horizon=12, seed=7)
    first, second = (
        evaluate(agent.policies()[0], agent.env_cfg, **starts),
        evaluate(again.policies()[0], again.env_cfg, **starts),
    )
    assert first == second
    assert 0.0 < first["eval/optimality"] <= 1.0 + 1e-9


def test_messages_are_learned_through_the_receivers_loss(compose_cfg):
    """With env.message_size=2 the loss sends the heard messages again from the senders' previous observations: the
    sending layer gets a gradient from the receivers' TD errors, and training moves it."""
    cfg = compose_cfg("agent=dqn", *LOCAL, "env.message_size=2")
    agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), 0)
    speaker = agent.groups[0].values.module.speaker
    before = speaker.weight.detach().clone()
    while len(agent.groups[0].buffer) < int(cfg.agent.learning_starts):
        agent.train_iteration()
    batch = agent.groups[0].buffer.sample()
    assert batch["has_previous"].any() and not batch["has_previous"].all()
    agent.optimizer.zero_grad()
    agent.network.td_loss(batch, agent.groups[0]).backward()
    assert speaker.weight.grad.abs().sum() > 0
    agent.train_iteration()
    assert not torch.equal(speaker.weight.detach(), before)


def test_kept_transitions_with_messages_rebuild_what_was_collected(compose_cfg):
    """The replay buffer keeps configurations and the messages sent: the observations rebuilt from them are those
    collected bit for bit, and each step's previous observation is the one a step before."""
    cfg = compose_cfg("agent=dqn", *LOCAL, "env.message_size=2", "env.energy=follow_up", "env.base=[-1,0]")
    agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), 0)
    group = agent.groups[0]
    batch = group.transitions.with_previous(group.env.rollout(10, group.policies.explore))  # [W, T]
    full = batch.reshape(-1).select(*group.keys)
    rebuilt = group.transitions(group.transitions.inv(full))
    for key in [("agents", "observation"), ("next", "agents", "observation"), "state"]:
        assert torch.equal(rebuilt[key], full[key]), key
    previous = rebuilt["agents", "previous"].view(*batch.shape, *rebuilt["agents", "previous"].shape[1:])
    assert torch.equal(previous[:, 1:], batch["agents", "observation"][:, :-1])
    assert torch.equal(rebuilt["next", "agents", "previous"], full["agents", "observation"])


def test_a_local_policy_acts_at_any_radius_and_never_on_central_observations(compose_cfg):
    """A policy trained on local observations acts at another communication radius when a user binds it there (the
    same features), is scored by the benchmark and the evaluation command only at its own (a per-size policy acts in
    its run's model), and is refused, in one line, on central observations or another message size."""
    from uavrl.agents.schema import network_refusal
    from uavrl.envs import UAVSpectrumEnv

    cfg = compose_cfg("agent=dqn", *LOCAL)
    agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), 0)
    run = agent.env_cfg
    assert network_refusal(cfg, run, run) is None
    refusal = network_refusal(cfg, run.replace(comm_radius=4.0), run)
    assert "acts only in its run's model" in refusal and "local observations (env.comm_radius=2" in refusal
    assert "acts only in its run's model" in network_refusal(
        cfg, run.replace(observation="central", comm_radius=None), run
    )
    assert network_refusal(cfg, run.replace(message_size=2), run) is not None
    policy = agent.policies()[0]
    policy.bind_env(UAVSpectrumEnv(batch_size=2, config=run.replace(comm_radius=1.0)))
    with pytest.raises(ValueError, match="local observations\\); the environment has central observations"):
        policy.bind_env(UAVSpectrumEnv(batch_size=2, config=run.replace(observation="central", comm_radius=None)))


@pytest.mark.parametrize(
    "after_cancel, cancelled, chance", [(True, True, GIVE_WAY), (True, False, 0.0), (False, False, 0.5)]
)
def test_of_two_uavs_moving_into_one_cell_the_higher_id_gives_way(after_cancel, cancelled, chance):
    """UAVs 0 and 1 both move into the cell between them: UAV 0 (the lower id) always goes; UAV 1 stays (keeps its
    cell and task) in a share ``chance`` of the worlds: acting greedily (``after_cancel``) only once its own move was
    cancelled, with probability GIVE_WAY; in the behaviour policy before any clash, with probability 1/2.  UAV 2,
    whom no one contends, always goes (an independent count)."""
    worlds, width = 4000, 5
    env = UAVSpectrumEnv(batch_size=worlds, grid=(width, width), num_uavs=3, observation="local")
    cells = torch.tensor([1 + width * 1, 3 + width * 1, 0 + width * 4])  # (1, 1), (3, 1), (0, 4)
    tasks = torch.tensor([0, 1, 0])
    observation = env.world.configurations((2 * cells + tasks).repeat(worlds, 1))["observation"]
    right, left, up = MOVES.index((1, 0)), MOVES.index((-1, 0)), MOVES.index((0, -1))
    action = torch.tensor([right, left, up]).repeat(worlds, 1)
    out = YieldToContenders(env, seed=5, after_cancel=after_cancel)(
        action, observation, torch.full((worlds, 3), cancelled)
    )
    assert (out[:, 0] == right).all() and (out[:, 2] == up).all()
    stay_relaying = 5  # UAV 1 relays (task 1): its staying action keeps that task
    stayed = (out[:, 1] == stay_relaying).float().mean().item()
    assert ((out[:, 1] == left) | (out[:, 1] == stay_relaying)).all()
    assert chance - 0.05 <= stayed <= chance + 0.05, stayed


def test_the_size_free_network_acts_on_what_each_uav_hears_at_any_size(compose_cfg):
    """``agent.network=set`` on local observations (``LocalSetQCore``): it trains over two teams and grids, a UAV's
    greedy action is the same whatever lies beyond its range (the per-size network's test, on the 4-UAV group), it
    acts zero-shot in a team and grid it never saw, and with messages it is refused in one line."""
    from uavrl.agents import agent_class
    from uavrl.agents.dqn.setnet import LocalSetQNet

    sizes = ["agent.network=set", "agent.mixer=vdn", "agent.heads=2", "agent.sizes=[[4,6,6],[3,5,5]]"]
    cfg = compose_cfg("agent=dqn", *LOCAL, *sizes)
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), 0)
    assert all(isinstance(group.values.module, LocalSetQNet) for group in agent.groups)
    for _ in range(5):
        agent.train_iteration()
    gen = torch.Generator().manual_seed(5)
    codes, moved = [], []
    for _ in range(300):
        code = 2 * torch.randperm(36, generator=gen)[:4] + torch.randint(0, 2, (4,), generator=gen)
        codes.append(code)
        moved.append(perturbed_out_of_range(code, torch.zeros(4, 0), (6, 6), 2.0, gen)[0])
    before, after = (greedy_actions(agent, torch.stack(c))[0][:, 0] for c in (codes, moved))
    assert torch.equal(before, after)
    unseen = agent.env_cfg.replace(num_uavs=7, grid=(9, 9))
    metrics = evaluate(agent.policy_for(unseen), unseen, num_starts=4, horizon=8)
    assert 0.0 < metrics["eval/optimality"] <= 1.0 + 1e-9
    with pytest.raises(ValueError, match="agent.network='set' is invalid with env.message_size=2: the size-free"):
        agent_class("dqn", cfg.agent)(
            model_config(compose_cfg(*[], "agent=dqn", *LOCAL, *sizes, "env.message_size=2")),
            cfg,
            torch.device("cpu"),
            0,
        )


def test_with_every_uav_heard_each_uav_plays_its_part_of_one_joint_action(compose_cfg):
    """With every UAV heard and no messages, UAV i's greedy action is its entry of the joint action the central greedy
    rule picks from the team's local values (ValidGreedy over every UAV's actual observation, computed here); it
    depends on UAV i's own observation alone (every other row replaced by another configuration's changes no UAV's
    action but theirs), and no move is ever cancelled in greedy rollouts.  Bound to an environment at a radius that
    does not reach across the grid, the policy tosses its coins again."""
    from uavrl.agents.dqn.common_knowledge import CommonKnowledgeGreedy
    from uavrl.agents.dqn.networks import ValidGreedy

    cfg = compose_cfg("agent=dqn", *[o for o in LOCAL if not o.startswith("env.comm_radius")])
    agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), 0)
    for _ in range(3):
        agent.train_iteration()
    group = agent.groups[0]
    (agreed,) = [m for m in group.greedy.modules() if isinstance(m, CommonKnowledgeGreedy)]
    gen = torch.Generator().manual_seed(11)
    codes = [2 * torch.randperm(36, generator=gen)[:4] + torch.randint(0, 2, (4,), generator=gen) for _ in range(300)]
    out = group.env.world.configurations(torch.stack(codes))
    observation, coins = out["observation"], torch.full((300, 4), 4)
    actions = agreed(observation, coins)
    values = group.values.module(observation)
    central = ValidGreedy(group.env.neighbours, 6)(values, out["action_mask"], out["positions"], out["tasks"])
    assert torch.equal(actions, central)
    others = group.env.world.configurations(torch.stack(codes)[torch.randperm(300, generator=gen)])["observation"]
    for i in range(4):
        mixed = others.clone()
        mixed[:, i] = observation[:, i]
        assert torch.equal(agreed(mixed, coins)[:, i], actions[:, i])
    policy = agent.policies()[0]
    env = UAVSpectrumEnv(batch_size=64, config=agent.env_cfg.replace(max_steps=12), seed=3)
    rollout = env.rollout(12, policy.bind_env(env), break_when_any_done=False)
    assert not rollout["next", "agents", "cancelled"].any()
    near = UAVSpectrumEnv(batch_size=64, config=agent.env_cfg.replace(max_steps=12, comm_radius=2.0), seed=3)
    policy.bind_env(near)
    assert agreed.world is None and torch.equal(agreed(observation, coins), coins)
    assert near.rollout(12, policy, break_when_any_done=False)["next", "agents", "cancelled"].any()


@pytest.mark.parametrize(
    "options, agreed",
    [
        (dict(), True),
        (dict(comm_radius=7.1), True),  # the 6x6 grid's diagonal: 7.07 cells
        (dict(comm_radius=7.0), False),
        (dict(message_size=2), False),
        (dict(layout="random"), False),
        (dict(energy="follow_up", base=(-1, 0)), False),
        (dict(altitudes_m=[10.0, 20.0]), False),
        (dict(observation="central"), False),
    ],
)
def test_common_knowledge_only_where_every_uav_rebuilds_the_same_team(options, agreed):
    from uavrl.envs import make_config
    from uavrl.envs.physics.sensing import common_knowledge

    local = dict(observation="local") if options.get("observation") != "central" else {}
    cfg = make_config("paper", grid=(6, 6), num_uavs=3, **{**local, **options})
    assert common_knowledge(cfg) is agreed
