"""The DQN with a size-free network (``agent.network=set``), trained over several team sizes and grids at once.

``agent.sizes`` lists the teams ``[N, L1, L2]`` one run trains on (``[]``: the run's ``env.num_uavs`` and
``env.grid`` only), each in every layout of ``agent.layouts`` (``[]``: ``env.layout``) and in a city, every city of
``agent.cities`` (null: ``env.city_seed``); every other model option is the run's (channel, energy model, altitude
levels, ...).  Each team, layout and city is a group
with its own ``agent.worlds`` worlds, collector, exploration and replay buffer; one core
(:class:`~.setnet.SetQCore`) acts in all of them.  One iteration: an episode in every world of every group, then
``agent.updates`` gradient steps, each the sum of one batch's loss per group (``agent.batch_size`` split evenly).
The checkpoint holds one core: :meth:`SetDQNAgent.policy_for` acts with it in an environment of any size, so
``python -m uavrl.evaluate checkpoint=<run> env.grid=[30,30] env.num_uavs=20`` evaluates it zero-shot.

Example:
    >>> from hydra import compose, initialize_config_dir
    >>> from uavrl.config import config_dir, model_config
    >>> with initialize_config_dir(config_dir=config_dir(), version_base=None):
    ...     sizes = "agent.sizes=[[2,4,4],[3,5,5]]"
    ...     cfg = compose("config", overrides=["agent=dqn", "agent.network=set", sizes, "agent.worlds=2"])
    >>> agent = SetDQNAgent(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    >>> agent.train_iteration()["train/epsilon"] < 1.0, agent.env_steps  # 2 sizes x 2 worlds x 30 steps
    (True, 120)
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torch import nn

from uavrl.agents.env_check import CheckedPolicy
from uavrl.agents.schema import AGENTS, network_refusal, training_models  # noqa: F401 (uavrl.load_policy's)
from uavrl.envs import ModelConfig, UAVSpectrumEnv
from uavrl.envs.rules import shown

from .agent import DQNAgent, _Group
from .builders import QNetwork, build_policies, exploration_schedule
from .curriculum import Curriculum
from .setnet import LocalSetQCore, LocalSetQNet, SetDoubleQLoss, SetQCore, SetQNet


class SetNetwork(QNetwork):
    """``agent.network=set``: one :class:`~.setnet.SetQCore` acting in every team and layout of ``agent.sizes`` x
    ``agent.layouts`` (one group of worlds each, :func:`~uavrl.agents.schema.training_models`) through a
    :class:`~.setnet.SetQNet` per grid, its loss :class:`~.setnet.SetDoubleQLoss`; a checkpoint's exploration and
    replay are lists over the groups, with the curriculum's state."""

    name, kind = "set", "size-free"
    models = staticmethod(training_models)

    def __init__(self, agent: DQNAgent, env: UAVSpectrumEnv):
        super().__init__(agent, env)
        a, env_cfg = self.settings, agent.env_cfg
        energy, levels = env_cfg.energy != "none", env_cfg.num_levels > 1
        kind = LocalSetQCore if env_cfg.local else SetQCore  # each UAV from what it hears, or from the team
        core = kind(env_cfg.num_actions, energy, int(a.hidden), int(a.heads), int(a.depth), levels)
        self.core = core.to(agent.device)

    def values(self, env: UAVSpectrumEnv) -> TensorDictModule:
        if env.cfg.local:
            net = LocalSetQNet.of(self.core, env)
        else:
            positions = env.world.dynamics.positions if env.cfg.num_levels > 1 else None  # its moves, its buildings
            net = SetQNet(self.core, env.cfg.grid, positions)
        return TensorDictModule(net, in_keys=net.in_keys, out_keys=[("agents", "action_value")])

    def build_loss(self, policies) -> SetDoubleQLoss:
        a = self.settings
        self.loss = SetDoubleQLoss(self.core, a.mixer, float(a.gamma), self.agent.env_cfg.num_actions)
        return self.loss

    def parameters(self) -> list[nn.Parameter]:
        return list(self.core.parameters())

    def td_loss(self, batch: TensorDictBase, group: _Group) -> torch.Tensor:
        return self.loss(batch, group.values.module)["loss"]

    def update_target(self) -> None:
        self.loss.update_target(float(self.settings.tau))

    def policy_for(self, env_cfg: ModelConfig) -> CheckedPolicy:
        """The greedy policy in environments of ``env_cfg``: any grid, number of UAVs and city of the run's model (a
        one-line ValueError for another model: other observations, or actions)."""
        agent = self.agent
        if (env_cfg.num_levels > 1) != self.core.levels:
            raise ValueError(
                f"env.altitudes_m={shown(env_cfg.altitudes_m)} is invalid for this network, trained with "
                f"env.altitudes_m={shown(agent.env_cfg.altitudes_m)}: its inputs and actions differ"
            )
        if (env_cfg.energy != "none") != self.core.energy or env_cfg.num_actions != agent.env_cfg.num_actions:
            raise ValueError(
                f"env.energy={env_cfg.energy!r} is invalid for this network, trained with "
                f"env.energy={agent.env_cfg.energy!r}: its inputs and actions differ"
            )
        env = UAVSpectrumEnv(batch_size=1, config=env_cfg, device=agent.device)
        frames = exploration_schedule(self.settings, 1, agent.device)
        return CheckedPolicy(build_policies(env, self.settings, self.values(env), frames).greedy, env_cfg)

    def experience_state(self, per_group: list[dict], curriculum: Curriculum) -> dict:
        """Every group's ``"exploration"`` and ``"buffer"``, in the order of the groups, and the curriculum's."""
        return {
            "exploration": [saved["exploration"] for saved in per_group],
            "buffer": [saved["buffer"] for saved in per_group],
            "curriculum": curriculum.state_dict(),
        }

    def experience_of(self, state: dict, curriculum: Curriculum) -> list[dict]:
        groups = len(self.agent.groups)
        if len(state["buffer"]) != groups:
            raise ValueError(f"the state holds {len(state['buffer'])} team sizes, the agent {groups}")
        if "curriculum" in state:  # checkpoints saved before the curriculum: none
            curriculum.load_state_dict(state["curriculum"])
        return [
            {"exploration": exploration, "buffer": buffer}
            for exploration, buffer in zip(state["exploration"], state["buffer"], strict=True)
        ]


class SetDQNAgent(DQNAgent):
    """:class:`DQNAgent` with the size-free network (``agent.network=set``, module doc), the class
    :func:`uavrl.agents.agent_class` gives for those settings.  The greedy rule (:class:`~.networks.ValidGreedy`),
    the double-DQN targets, the objective and the ``train/...`` tags are the factored DQN's; the tags are means over
    the sizes' worlds.  :meth:`~DQNAgent.policy_for` acts at any size."""

    Network = SetNetwork

    @property
    def core(self) -> SetQCore:
        """The size-free parameters (what :meth:`~DQNAgent.policy_for` acts with at any size)."""
        return self.network.core
