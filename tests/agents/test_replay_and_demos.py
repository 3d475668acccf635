"""What prioritized replay, the curriculum and the demonstrations do inside the DQN, checked so that a wrong
implementation fails: the sampling frequencies against ``p^alpha / sum p^alpha`` with a chi-square bound far below what
a wrong alpha or uniform sampling gives, the exact new priority after an update, each batch's demonstration share, the
margin term's exact part of the loss, and the curriculum's shares from the recorded TD losses."""

from __future__ import annotations

import copy

import pytest
import torch
from hydra import compose, initialize_config_dir
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from uavrl.agents import agent_class
from uavrl.agents.dqn import DQNAgent
from uavrl.agents.dqn.curriculum import DECAY
from uavrl.agents.dqn.demonstrations import margin_loss
from uavrl.agents.dqn.networks import Q_INPUTS
from uavrl.agents.dqn.priorities import PRIORITY_EPS, ProportionalSampler
from uavrl.agents.dqn.setnet import SetQNet
from uavrl.config import config_dir, model_config

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

DRAWS = 400_000


def chi_square(counts: torch.Tensor, probabilities: torch.Tensor) -> float:
    expected = probabilities * counts.sum()
    return float(((counts - expected) ** 2 / expected).sum())


def bound(slots: int) -> float:
    """A chi-square bound a correct sampler stays under (about 5 standard deviations above the mean, df = slots-1)."""
    df = slots - 1
    return df + 5 * (2 * df) ** 0.5


def proportional(errors: torch.Tensor, alpha: float) -> torch.Tensor:
    p = (errors.abs() + PRIORITY_EPS) ** alpha
    return p / p.sum()


# --------------------------------------------------------------------------------------------- prioritized replay
def test_sampling_frequencies_are_p_to_the_alpha_and_nothing_near():
    errors = torch.tensor([0.05, 0.1, 0.2, 0.4, 0.8, 1.6, 3.2, 6.4], dtype=torch.float64)
    buffer = TensorDictReplayBuffer(
        storage=LazyTensorStorage(8), sampler=ProportionalSampler(8, alpha=0.6, beta=0.4), batch_size=DRAWS
    )
    buffer.extend(TensorDict({"x": torch.arange(8)}, [8]))
    buffer.update_priority(torch.arange(8), errors)
    torch.manual_seed(0)
    counts = torch.bincount(buffer.sample()["x"], minlength=8).double()
    assert chi_square(counts, proportional(errors, 0.6)) < bound(8)
    # the bound tells alpha 0.6 from its neighbours and from uniform: each would be off by far more
    for wrong in (
        proportional(errors, 0.5),
        proportional(errors, 0.7),
        proportional(errors, 1.0),
        torch.full((8,), 1 / 8),
    ):
        assert chi_square(counts, wrong.double()) > 20 * bound(8)


def test_a_priority_update_writes_the_td_error_plus_eps_to_the_alpha():
    sampler = ProportionalSampler(6, alpha=0.7, beta=0.5)
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(6), sampler=sampler, batch_size=4)
    buffer.extend(TensorDict({"x": torch.arange(4)}, [4]))
    assert torch.equal(sampler.priorities, torch.tensor([1.0] * 4 + [0.0] * 2, dtype=torch.float64))  # max p = 1
    td_error = torch.tensor([-2.5, 0.0, 0.3], dtype=torch.float32)
    buffer.update_priority(torch.tensor([0, 1, 3]), td_error)
    expected = (td_error.double().abs() + PRIORITY_EPS) ** 0.7
    assert torch.equal(sampler.priorities[[0, 1, 3]], expected)
    assert sampler.priorities[2] == 1.0 and sampler.max_priority == 2.5 + PRIORITY_EPS
    # a new transition gets the largest priority seen, to the alpha
    buffer.extend(TensorDict({"x": torch.tensor([4])}, [1]))
    assert sampler.priorities[4] == (2.5 + PRIORITY_EPS) ** 0.7
    # and its importance weight is (p_i / min p)^-beta
    torch.manual_seed(1)
    sample = buffer.sample(256)
    p = sampler.priorities[:5]
    torch.testing.assert_close(sample["priority_weight"], ((p[sample["index"]] / p.min()) ** -0.5).float())


@pytest.fixture
def make_agent(compose_cfg):
    tiny = ["env.grid=[3,3]", "env.max_steps=8", "agent.worlds=32", "agent.hidden=32", "agent.depth=1"]
    replay = ["agent.batch_size=128", "agent.buffer_size=4000", "agent.updates=2", "agent.learning_starts=256"]

    def make(*overrides, seed=0):
        cfg = compose_cfg("agent=dqn", *tiny, *replay, *overrides)
        return DQNAgent(model_config(cfg), cfg, torch.device("cpu"), seed)

    return make


def test_the_agents_buffer_draws_by_its_configured_alpha(make_agent):
    agent = make_agent("agent.mixer=vdn", "agent.replay=prioritized", "agent.priority_alpha=0.35")
    agent.train_iteration()  # 256 transitions
    filled = len(agent.buffer)
    errors = torch.linspace(0.0, 4.0, filled, dtype=torch.float64)
    agent.buffer.update_priority(torch.arange(filled), errors)
    torch.manual_seed(0)
    counts = torch.bincount(agent.buffer.sample(DRAWS)["index"], minlength=filled).double()
    assert chi_square(counts, proportional(errors, 0.35)) < bound(filled)
    for wrong in (proportional(errors, 0.6), torch.full((filled,), 1 / filled, dtype=torch.float64)):
        assert chi_square(counts, wrong) > 5 * bound(filled)


def test_the_agents_gradient_step_sets_the_drawn_priorities_to_their_td_errors(make_agent):
    agent = make_agent("agent.mixer=vdn", "agent.replay=prioritized", "agent.priority_alpha=0.6")
    agent.train_iteration()
    sampler, updates = agent.buffer.sampler, []
    update = agent.buffer.update_priority

    def recorded(index, priority):
        updates.append((index.clone(), priority.detach().clone()))
        update(index, priority)

    agent.buffer.update_priority = recorded
    before, largest = sampler.priorities.clone(), sampler.max_priority
    agent._update()
    ((index, td_error),) = updates
    assert len(index) == 128 and td_error.shape == (128,)
    assert torch.equal(sampler.priorities[index], (td_error.double().abs() + PRIORITY_EPS) ** 0.6)
    untouched = torch.ones(len(before), dtype=torch.bool).index_fill(0, index, False)
    assert torch.equal(sampler.priorities[untouched], before[untouched])
    assert sampler.max_priority == max(largest, float(td_error.double().abs().max() + PRIORITY_EPS))


# -------------------------------------------------------------------------------- demonstrations and curriculum
SIZE_FREE = [
    "agent=dqn",
    "agent.network=set",
    "agent.mixer=mean",
    "agent.sizes=[[2,4,4],[3,5,5]]",
    "agent.layouts=[line,random]",
    "agent.worlds=2",
    "agent.hidden=16",
    "agent.updates=1",
    "agent.learning_starts=10",
    "agent.buffer_size=500",
    "agent.batch_size=64",
    "env.max_steps=10",
]


def size_free_agent(*overrides, curriculum="none"):
    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        cfg = compose("config", overrides=[*SIZE_FREE, *overrides])
    cfg.agent.curriculum = curriculum
    return agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=0)


def record_steps(agent):
    """Each gradient step's batches and TD losses per group (``agent.network.td_loss`` watched), and the
    demonstrations drawn (``agent.demonstrations.sample``, once they exist)."""
    seen = {"batches": [], "td": [], "demos": []}
    td_loss = agent.network.td_loss

    def watched(batch, group):
        loss = td_loss(batch, group)
        seen["batches"].append(batch.clone())
        seen["td"].append(loss.detach().clone())
        return loss

    agent.network.td_loss = watched
    return seen


def watch_demonstrations(agent, seen):
    sample = agent.demonstrations.sample

    def watched(g, size):
        demos = sample(g, size)
        seen["demos"].append(demos.clone())
        return demos

    agent.demonstrations.sample = watched


def margin_term(core, group, demos, margin: float, mixer: str) -> torch.Tensor:
    """DQfD's margin loss of ``demos`` under the values of ``core`` in the group's grid."""
    values = SetQNet(core, group.grid)(*(demos.get(k) for k in Q_INPUTS))
    return margin_loss(values, demos["agents", "action"], demos["agents", "action_mask"], margin, mixer)


def test_each_batch_holds_its_demonstration_share_and_the_margin_term_enters_the_loss():
    demo = [
        "agent.demonstrations=oracle",
        "agent.demo_transitions=80",
        "agent.demo_batch_share=0.25",
        "agent.margin=0.5",
    ]
    agent, without = size_free_agent(*demo), size_free_agent(*demo)
    for twin in (agent, without):
        torch.manual_seed(0)
        twin.train_iteration()  # builds the demonstrations, one gradient step: the twins stay identical
    assert all(torch.equal(a, b) for a, b in zip(agent.network.parameters(), without.network.parameters(), strict=True))
    seen = record_steps(agent)
    watch_demonstrations(agent, seen)
    without.demonstrations.loss = lambda net, demos: torch.zeros(())  # the twin with the margin term's weight 0
    core = copy.deepcopy(agent.network.core)  # the values the step's margin term is computed with
    torch.manual_seed(1)
    loss = agent._update()
    torch.manual_seed(1)
    loss_without = without._update()
    assert len(seen["batches"]) == len(seen["demos"]) == len(agent.groups) == 4
    margins = []
    for g, (group, batch, demos) in enumerate(zip(agent.groups, seen["batches"], seen["demos"], strict=True)):
        assert len(batch) == 64 // 4 and len(demos) == round(0.25 * 16) == 4  # equal shares, a quarter demonstrations
        assert (batch[-4:] == demos).all()  # the batch's last quarter: the demonstrations, after the agent's own
        kept = agent.demonstrations.buffers[g][:]
        for row in range(4):  # each one of the oracle's transitions kept for this team
            same = (kept["agents", "observation"] == demos["agents", "observation"][row]).flatten(1).all(-1)
            assert bool((kept["agents", "action"][same] == demos["agents", "action"][row]).all(-1).any())
        margins.append(float(margin_term(core, group, demos, 0.5, "mean")))
    assert all(m > 0 for m in margins)
    # the loss with the margin term is the loss without it plus exactly the margin terms, and the TD losses' sum
    assert float(loss - loss_without) == pytest.approx(sum(margins), rel=1e-5)
    assert float(loss) == pytest.approx(float(sum(seen["td"])) + sum(margins), rel=1e-5)


def test_the_curriculums_shares_follow_the_recorded_td_losses():
    agent = size_free_agent(curriculum="loss")
    seen = record_steps(agent)
    torch.manual_seed(0)
    agent.train_iteration()  # the first gradient step: equal shares, then its TD losses recorded
    assert [len(batch) for batch in seen["batches"]] == [16] * 4
    first = torch.stack(seen["td"]).double()
    assert torch.equal(agent.curriculum.average, first)
    shares = 1 / 8 + first / first.sum() / 2  # 1 / (2 G) + L_g / (2 sum L)
    sizes = [max(1, round(float(s) * 64)) for s in shares]
    assert sizes != [16] * 4  # the losses differ: so do the shares
    seen["batches"].clear(), seen["td"].clear()
    loss = agent._update()
    assert [len(batch) for batch in seen["batches"]] == sizes
    # each team's loss weighted by its batch over the equal one
    assert float(loss) == pytest.approx(
        sum(float(td) * n / 16 for td, n in zip(seen["td"], sizes, strict=True)), rel=1e-5
    )
    second = torch.stack(seen["td"]).double()
    torch.testing.assert_close(agent.curriculum.average, DECAY * first + (1 - DECAY) * second)


def test_without_a_curriculum_every_team_gets_an_equal_share():
    agent = size_free_agent(curriculum="none")
    seen = record_steps(agent)
    torch.manual_seed(0)
    for _ in range(2):
        agent.train_iteration()
    assert [len(batch) for batch in seen["batches"]] == [16] * 8
    assert len(set(float(td) for td in seen["td"][:4])) == 4  # the teams' losses differ, their shares do not
