"""The DQN on local observations (``env.observation=local``): trained centrally, acting on what each UAV hears; its
greedy action does not change with anything beyond a UAV's range."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from tests.envs.test_local import perturbed_out_of_range
from uavrl.agents.dqn import DQNAgent
from uavrl.agents.evaluation import evaluate
from uavrl.config import model_config

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


def greedy_actions(agent: DQNAgent, code: torch.Tensor, messages=None) -> torch.Tensor:
    """``[W, N]`` the agent's greedy actions at the configurations ``code`` ``[W, N]`` of its training world."""
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
    return agent.groups[0].greedy(td)["agents", "action"]


@pytest.mark.parametrize("mixer", ["vdn", "qmix"])
def test_a_local_uav_acts_alike_whatever_lies_beyond_its_range(compose_cfg, mixer):
    """UAV 0's greedy action under the trained local DQN (VDN, or QMIX whose mixer alone reads the state) is the same
    when every UAV beyond its range moves elsewhere beyond it and switches task; the central DQN's changes (this test
    can fail)."""
    gen = torch.Generator().manual_seed(3)
    agents = {}
    for observation in ("local", "central"):
        overrides = [*LOCAL, f"agent.mixer={mixer}"]
        if observation == "central":
            overrides = [o for o in overrides if not o.startswith(("env.observation", "env.comm_radius"))]
        cfg = compose_cfg("agent=dqn", *overrides)
        agents[observation] = agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), 0)
        for _ in range(5):
            agent.train_iteration()
    codes, moved = [], []
    for _ in range(300):
        code = 2 * torch.randperm(36, generator=gen)[:4] + torch.randint(0, 2, (4,), generator=gen)
        far, _ = perturbed_out_of_range(code, torch.zeros(4, 0), (6, 6), 2.0, gen)
        codes.append(code)
        moved.append(far)
    codes, moved = torch.stack(codes), torch.stack(moved)
    local = [greedy_actions(agents["local"], c)[:, 0] for c in (codes, moved)]
    assert torch.equal(*local)
    central = [greedy_actions(agents["central"], c)[:, 0] for c in (codes, moved)]
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
