"""The DQN's compact replay buffer: what it rebuilds is, bit for bit, what a buffer of full transitions holds."""

import io

import pytest
import torch
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from uavrl.agents import agent_class
from uavrl.config import model_config
from uavrl.envs.limits import stored_transition_bytes

TINY = [
    "agent=dqn",
    "env.max_steps=6",
    "agent.worlds=8",
    "agent.hidden=16",
    "agent.depth=1",
    "agent.batch_size=32",
    "agent.buffer_size=100",  # 3 iterations of 48 transitions wrap around
    "agent.updates=2",
    "agent.learning_starts=16",
]
ENERGY = ["env.energy=rotary_wing", "env.base=[-1,0]", "env.battery_wh=0.3", "env.battery_init=uniform"]
CASES = {
    "n2-fixed-vdn": ["env.grid=[3,3]"],
    "n6-fixed-qmix": ["env.grid=[4,4]", "env.num_uavs=6", "agent.mixer=qmix"],
    "n2-joint": ["env.grid=[3,3]", "agent.head=joint"],
    "n3-random-layouts": ["env.grid=[4,4]", "env.num_uavs=3", "env.layout=random", "agent.mixer=qmix"],
    "n2-rayleigh": ["env.grid=[3,3]", "env.fading=rayleigh"],
    "n3-energy-terminating": ["env.grid=[3,3]", "env.num_uavs=3", *ENERGY],
    "n3-energy-terminating-3-step": ["env.grid=[3,3]", "env.num_uavs=3", *ENERGY, "agent.n_step=3"],
    "n2-energy-recharge-spare-random": [
        *("env.grid=[3,3]", *ENERGY, "env.recharge_steps=2", "env.num_spares=1", "env.layout=random"),
    ],
}

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


def assert_identical(rebuilt, full):
    """The same keys, dtypes, shapes and values, bit for bit."""
    keys = set(full.keys(include_nested=True, leaves_only=True))
    assert set(rebuilt.keys(include_nested=True, leaves_only=True)) == keys
    for key in keys:
        a, b = rebuilt.get(key), full.get(key)
        assert a.dtype == b.dtype and a.shape == b.shape and torch.equal(a, b), key


SET = ["agent.network=set", "agent.mixer=mean", "agent.heads=2"]  # two groups: 16 of the 32 a sample each
SET_CASES = {
    "set-sizes": [*SET, "agent.sizes=[[2,3,3],[3,4,4]]"],
    "set-sizes-2-step": [*SET, "agent.sizes=[[2,3,3],[3,4,4]]", "agent.n_step=2"],
    "set-layouts-energy": [
        *SET,
        "agent.sizes=[[2,3,3]]",
        "agent.layouts=[line,random]",
        *ENERGY,
        "env.recharge_steps=2",
    ],
}


@pytest.mark.parametrize("case", [*CASES, *SET_CASES])
def test_sampled_transitions_are_the_full_ones_bit_for_bit(case, compose_cfg):
    """Every replay buffer: the per-size agent's, and each team and layout's of the size-free one."""
    cfg = compose_cfg(*TINY, *CASES.get(case, ["env.grid=[3,3]"]), *SET_CASES.get(case, []))
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=1)
    buffers = [group.buffer for group in agent.groups] if case in SET_CASES else [agent.buffer]
    # a buffer of the full transitions beside each of the agent's, extended with the same batches
    fulls = [TensorDictReplayBuffer(storage=LazyTensorStorage(100), batch_size=b.batch_size) for b in buffers]
    for buffer, full in zip(buffers, fulls, strict=True):

        def both(batch, full=full, extend=buffer.extend):
            full.extend(batch.clone())
            return extend(batch)

        buffer.extend = both
    for _ in range(3):
        agent.train_iteration()
    for buffer, full in zip(buffers, fulls, strict=True):
        assert full.write_count == buffer.write_count == 3 * 48
        # a full buffer also stores the slots' indices ("index", written by TorchRL's extend); a sample has them anew
        assert_identical(buffer[:], full[:].exclude("index"))
        rng = torch.get_rng_state()
        sample = buffer.sample()
        torch.set_rng_state(rng)
        assert_identical(sample, full.sample())
        if "energy" in case:  # the stored batteries are the episodes' own, not one value
            assert buffer.storage._storage.get("energy")[..., 0].unique().numel() > 1


def test_the_compact_buffer_is_a_tenth_of_the_full_one(compose_cfg):
    """Bytes per transition kept, N = 6 on 10x10: the full transitions' against the compact ones'."""
    cfg = compose_cfg(*TINY, "env.grid=[10,10]", "env.num_uavs=6", "agent.mixer=qmix", "agent.learning_starts=1000")
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    agent.train_iteration()
    stored, full = agent.buffer.storage._storage, agent.buffer[:]
    per_transition = lambda td: td.bytes() / len(td)  # noqa: E731
    assert per_transition(stored) * 10 <= per_transition(full)
    # the memory check's estimate (uavrl.costs): the stored bytes, and 2 for a joint head's action
    assert per_transition(stored) + 2 == stored_transition_bytes(agent.env_cfg)


def full_transitions_checkpoint(agent) -> dict:
    """The agent's state as the uavrl before the compact buffer saved it: every transition in full, and its index (a
    size-free agent: in each group's buffer)."""
    state = agent.state_dict()
    if isinstance(state["buffer"], list):  # one buffer per group
        buffers = [(g.buffer, g.transitions, saved) for g, saved in zip(agent.groups, state["buffer"], strict=True)]
        state["buffer"] = [full_buffer_state(*held) for held in buffers]
    else:
        state["buffer"] = full_buffer_state(agent.buffer, agent.transitions, state["buffer"])
    saved = io.BytesIO()  # a checkpoint on disk holds copies, not the live tensors
    torch.save(state, saved)
    saved.seek(0)
    return torch.load(saved, weights_only=False)


def full_buffer_state(buffer, transitions, saved: dict) -> dict:
    stored, filled = buffer.storage._storage, len(buffer)
    full = transitions(stored[:filled].exclude("index"))
    unfilled = full[:1].apply(
        lambda x: x.new_zeros(len(stored) - filled, *x.shape[1:]), batch_size=[len(stored) - filled]
    )
    full = torch.cat([full, unfilled]).set("index", stored.get("index"))
    return {**saved, "_storage": {**saved["_storage"], "_storage": full.state_dict()}}


@pytest.mark.parametrize(
    "case", ["n2-fixed-vdn", "n3-random-layouts", "n2-energy-recharge-spare-random", "set-layouts-energy"]
)
def test_a_checkpoint_of_full_transitions_is_compacted_and_resumes_exactly(case, compose_cfg):
    """Random layouts: the nodes of each stored transition are those its iteration's worlds were reset to."""
    cfg = compose_cfg(*TINY, *CASES.get(case, ["env.grid=[3,3]"]), *SET_CASES.get(case, []))
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=3)
    for _ in range(3):
        agent.train_iteration()
    state = full_transitions_checkpoint(agent)
    restored = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=3)
    restored.load_state_dict(state)
    for group, again in zip(getattr(agent, "groups", [agent]), getattr(restored, "groups", [restored]), strict=True):
        assert (again.buffer.storage._storage == group.buffer.storage._storage).all()
    torch.set_rng_state(state["rng"])
    metrics = agent.train_iteration()
    torch.set_rng_state(state["rng"])
    assert restored.train_iteration() == metrics


def test_full_transitions_of_unknown_layouts_are_refused_in_one_line(compose_cfg):
    cfg = compose_cfg(*TINY, *CASES["n3-random-layouts"])
    agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=3)
    agent.train_iteration()
    state = full_transitions_checkpoint(agent)
    state["buffer"]["_storage"]["_storage"]["agents.observation"][5, 0, 4] += 0.25  # no layout of its iteration's
    restored = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=3)
    with pytest.raises(ValueError, match="holds transitions of layouts that cannot be recovered") as refused:
        restored.load_state_dict(state)
    assert "\n" not in str(refused.value)


def test_two_runs_of_one_seed_save_the_same_bytes_before_the_buffer_fills(compose_cfg):
    """The slots not yet written are zeros, not the allocator's leftovers (``agents/dqn/builders.py``)."""
    cfg = compose_cfg(*TINY, "env.grid=[3,3]", "agent.buffer_size=1000")
    saved = []
    for _ in range(2):
        agent = agent_class("dqn", cfg.agent)(model_config(cfg), cfg, torch.device("cpu"), seed=3)
        agent.train_iteration()
        assert len(agent.buffer) < 1000
        file = io.BytesIO()
        torch.save(agent.state_dict(), file)
        saved.append(file.getvalue())
        del agent
        torch.full((1 << 16,), -1, dtype=torch.int64)  # leftovers for the second run's storage, were it not zeroed
    assert saved[0] == saved[1]


@pytest.mark.parametrize("n_step, dtype", [(3, torch.int8), (200, torch.int16)])
def test_n_step_counts_past_127_are_kept_whole(n_step, dtype):
    """A 200-step episode's n-step counts (MultiStep's ``steps_to_next_obs``) rebuild exactly: up to 200 steps to the
    next observation do not fit the int8 a short horizon is stored in (200 became -56, and the loss raised gamma to
    that power)."""
    from uavrl.agents.dqn.transitions import STEPS, CompactTransitions, n_step_returns
    from uavrl.envs import UAVSpectrumEnv

    env = UAVSpectrumEnv(batch_size=2, grid=(3, 3), num_uavs=2, max_steps=200, seed=0)
    episodes = env.rollout(200)
    full = n_step_returns(episodes, n_step, 0.9).reshape(-1)
    compact = CompactTransitions(env.world, [("agents", "action")], n_step)
    stored = compact.inv(full)
    assert stored.get(STEPS).dtype == dtype
    assert torch.equal(compact(stored).get(STEPS), full.get(STEPS).long())
    assert full.get(STEPS).max().item() == min(n_step, 200)
