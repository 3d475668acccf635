"""The DQN iteration's cheaper parts give TorchRL's results bit for bit: epsilon's schedule, the soft target update."""

import copy

import pytest
import torch
from torchrl.data import Categorical
from torchrl.modules import EGreedyModule
from torchrl.objectives import SoftUpdate

from uavrl.agents.dqn import DQNAgent
from uavrl.agents.dqn.builders import EpsilonGreedy, TargetUpdate
from uavrl.config import model_config

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


@pytest.mark.parametrize("eps_init, eps_end, steps", [(1.0, 0.05, 1000), (0.9, 0.1, 333), (0.3, 0.3, 10)])
def test_epsilon_follows_torchrls_frame_by_frame_schedule(eps_init, eps_end, steps):
    ours, torchrls = (
        module(Categorical(6), eps_init=eps_init, eps_end=eps_end, annealing_num_steps=steps)
        for module in (EpsilonGreedy, EGreedyModule)
    )
    for frames in (1, 7, 250, 499, 1, 1920):  # past the end of the schedule
        ours.step(frames)
        torchrls.step(frames)
        assert ours.eps.dtype == torchrls.eps.dtype and torch.equal(ours.eps, torchrls.eps)


def test_target_update_moves_the_targets_as_torchrls_soft_update(compose_cfg):
    cfg = compose_cfg("agent=dqn", "env.grid=[3,3]", "agent.mixer=qmix", "agent.hidden=16", "agent.tau=0.3")
    agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    theirs = copy.deepcopy(agent.loss)
    reference = SoftUpdate(theirs, tau=0.3)
    for _ in range(3):
        for loss in (agent.loss, theirs):  # the online parameters move away from the targets
            with torch.no_grad():
                for p in loss.parameters():
                    p.add_(torch.randn_like(p, generator=torch.Generator().manual_seed(p.numel())))
        agent.network.target_update.step()
        reference.step()
    assert isinstance(agent.network.target_update, TargetUpdate)
    ours, expected = agent.loss.state_dict(), theirs.state_dict()
    assert ours.keys() == expected.keys()
    assert all(torch.equal(ours[k], expected[k]) for k in ours if torch.is_tensor(ours[k]))
    assert not torch.equal(
        agent.loss.target_local_value_network_params.flatten_keys()["module.0.module.torso.params.0.weight"],
        agent.loss.local_value_network_params.flatten_keys()["module.0.module.torso.params.0.weight"],
    )
