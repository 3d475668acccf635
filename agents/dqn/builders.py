"""The DQN's parts built from its settings: the Q network, the greedy and exploring policies, the mixer, the loss,
the replay buffer (its transitions kept compact, :mod:`.transitions`) and the collector (TorchRL modules around
:mod:`.networks` and :mod:`.loss`); :class:`QNetwork`, what ``agent.network`` decides for the agent, and
:class:`TeamNetwork`, the per-size network's."""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import Categorical, Composite, LazyTensorStorage, TensorDictReplayBuffer
from torchrl.modules import EGreedyModule, QValueModule
from torchrl.objectives import DQNLoss, LossModule, SoftUpdate

from uavrl.agents.env_check import CheckedPolicy
from uavrl.agents.schema import run_city
from uavrl.envs import ModelConfig, UAVSpectrumEnv
from uavrl.envs.compat import make_collector

from .common_knowledge import CommonKnowledgeGreedy
from .curriculum import Curriculum
from .loss import DoubleQMixerLoss, QMix, VDNMix
from .networks import (
    LEVELS,
    DecodeJointAction,
    HeardMoves,
    JointActionMask,
    LocalGreedy,
    LocalQNet,
    TeamQNet,
    ValidGreedy,
    YieldToContenders,
    position_numbers,
    q_inputs,
)
from .priorities import ProportionalSampler
from .transitions import CompactTransitions

if TYPE_CHECKING:
    from .agent import DQNAgent, _Group


@dataclass
class Policies:
    """The modules that act: ``greedy`` (the greedy valid joint action), ``explore`` (greedy, then
    ``exploration``'s epsilon-greedy), ``value_network`` (what the loss evaluates), ``action_spec`` and
    ``action_keys`` (the action entries a transition stores)."""

    greedy: TensorDictSequential
    explore: TensorDictSequential
    exploration: EGreedyModule
    value_network: TensorDictSequential
    action_spec: object
    action_keys: list


def build_q_network(env: UAVSpectrumEnv, a) -> TensorDictModule:
    """:class:`TeamQNet` as a module writing ``("agents", "action_value")`` (factored) or ``"joint_action_value"``.

    Args:
        env: the training environment (its observation keys and sizes).
        a: the agent's settings ``cfg.agent`` (``head``, ``hidden``, ``depth``).
    """
    if env.cfg.local:  # each UAV from its own observation (the factored head's values)
        net = LocalQNet(env, int(a.hidden), int(a.depth))
        return TensorDictModule(net, in_keys=[("agents", "observation")], out_keys=[_values_key(a)])
    net = TeamQNet(env, a.head, int(a.hidden), int(a.depth))
    return TensorDictModule(net, in_keys=q_inputs(env.cfg), out_keys=[_values_key(a)])


def _levels(env: UAVSpectrumEnv) -> list:
    """The levels entry the greedy rules read after the positions, with altitude levels."""
    return [LEVELS] if env.cfg.num_levels > 1 else []


def _values_key(a):
    return ("agents", "action_value") if a.head == "factored" else "joint_action_value"


def exploration_schedule(a, frames: int, device) -> dict:
    """``EGreedyModule`` keywords: epsilon from ``agent.eps_start`` to ``agent.eps_end`` over ``agent.eps_fraction``
    of the run's ``frames``.

    Args:
        a: the agent's settings ``cfg.agent``.
        frames: the team steps of the whole run (worlds times steps times iterations).
        device: the torch device of epsilon.
    """
    steps = max(1, int(float(a.eps_fraction) * frames))
    return dict(eps_init=float(a.eps_start), eps_end=float(a.eps_end), annealing_num_steps=steps, device=device)


class EpsilonGreedy(EGreedyModule):
    """TorchRL's ``EGreedyModule`` whose ``step(frames)`` takes its frame-by-frame float32 decrements of epsilon as
    float32 scalars rather than a tensor operation per frame (1920 frames an iteration at N = 6 on 10x10: 30 ms of
    ~700): the same epsilon, bit for bit.

    Example:
        >>> from torchrl.data import Categorical
        >>> ours, torchrls = (m(Categorical(6), eps_init=1.0, eps_end=0.05, annealing_num_steps=999)
        ...                   for m in (EpsilonGreedy, EGreedyModule))
        >>> ours.step(700), torchrls.step(700)
        (None, None)
        >>> torch.equal(ours.eps, torchrls.eps)
        True
    """

    def step(self, frames: int = 1) -> None:
        decrement = np.float32(((self.eps_init - self.eps_end) / self.annealing_num_steps).item())
        eps, end = np.float32(self.eps.item()), np.float32(self.eps_end.item())
        for _ in range(frames):
            if eps == end:  # where every later frame leaves it
                break
            eps = max(end, np.float32(eps - decrement))
        self.eps.data.fill_(float(eps))


class TargetUpdate(SoftUpdate):
    """TorchRL's ``SoftUpdate`` with its ``torch._foreach_lerp_`` over every target parameter called once, without
    building a ``TensorDict`` per network each step (about half its cost): the same parameters, bit for bit."""

    def step(self) -> None:
        targets, sources = [], []
        for name, source in self._sources.items():
            target = self._targets.get(f"target_{name}")
            for key in source.keys(include_nested=True, leaves_only=True):
                targets.append(target.get(key).data)
                sources.append(source.get(key).data)
        torch._foreach_lerp_(targets, sources, 1 - self.eps)


def build_policies(env: UAVSpectrumEnv, a, q: TensorDictModule, eps: dict) -> Policies:
    """The greedy and the exploring policy of ``agent.head`` around the Q network ``q``.

    Args:
        env: the training environment.
        a: the agent's settings ``cfg.agent`` (``head``: ``factored`` or ``joint``).
        q: the Q network (:func:`build_q_network`).
        eps: the exploration's keywords (:func:`exploration_schedule`).
    """
    return (_factored_policies if a.head == "factored" else _joint_policies)(env, q, eps)


def _factored_policies(env: UAVSpectrumEnv, q: TensorDictModule, eps: dict) -> Policies:
    # TorchRL's own Categorical: the exploration draws as they were before the env's cheaper MaskedCategorical
    spec = Composite(
        agents=Composite(
            action=Categorical(env.num_actions, (env.num_uavs,), dtype=torch.long, device=env.device),
            shape=(env.num_uavs,),
            device=env.device,
        ),
        device=env.device,
    )
    if env.cfg.local:  # each UAV by its own values, mask and observation
        greedy_action = TensorDictModule(
            LocalGreedy(HeardMoves(env)),
            in_keys=[("agents", "action_value"), ("agents", "action_mask"), ("agents", "observation")],
            out_keys=[("agents", "action")],
        )
    else:
        greedy_action = TensorDictModule(
            ValidGreedy(env.neighbours, env.cfg.grid[0], env.num_actions, position_numbers(env.world)),
            in_keys=[("agents", "action_value"), ("agents", "action_mask"), "positions", "tasks", *_levels(env)],
            out_keys=[("agents", "action")],
        )
    greedy = behaviour = TensorDictSequential(q, greedy_action)
    if env.cfg.local:  # then a coin for a move another UAV may contend, and what each UAV sends, from its observation
        speak = (
            []
            if not env.cfg.message_size
            else [
                TensorDictModule(
                    q.module.message, in_keys=[("agents", "observation")], out_keys=[("agents", "message")]
                )
            ]
        )
        # where every UAV knows the team's configuration (in the environment the policy is bound to), no clash
        agreed = [] if env.cfg.message_size else [_agreed(env, q)]
        greedy = TensorDictSequential(q, greedy_action, _give_way(env, after_cancel=True), *agreed, *speak)
        behaviour = TensorDictSequential(q, greedy_action, _give_way(env, after_cancel=False), *speak)
    exploration = EpsilonGreedy(spec, action_key=("agents", "action"), action_mask_key=("agents", "action_mask"), **eps)
    explore = TensorDictSequential(behaviour, exploration)
    # the loss evaluates the behaviour chain: its coins drawn as the saved runs drew them
    return Policies(greedy, explore, exploration, behaviour, spec, [("agents", "action")])


def _give_way(env: UAVSpectrumEnv, after_cancel: bool) -> TensorDictModule:
    """A local UAV's coin for a move another UAV may contend (:class:`YieldToContenders`): acting greedily only after a
    clash, while training (``after_cancel=False``) before one, as the saved runs were trained."""
    return TensorDictModule(
        YieldToContenders(env, after_cancel=after_cancel),
        in_keys=[("agents", "action"), ("agents", "observation"), *([("agents", "cancelled")] if after_cancel else [])],
        out_keys=[("agents", "action")],
    )


def _agreed(env: UAVSpectrumEnv, q: TensorDictModule) -> TensorDictModule:
    """A local UAV's part of the joint action every UAV computes alike where the team is common knowledge
    (:class:`CommonKnowledgeGreedy`), its coin's action elsewhere."""
    return TensorDictModule(
        CommonKnowledgeGreedy(q.module, env),
        in_keys=[("agents", "observation"), ("agents", "action")],
        out_keys=[("agents", "action")],
    )


def _joint_policies(env: UAVSpectrumEnv, q: TensorDictModule, eps: dict) -> Policies:
    N, values = env.num_uavs, "joint_action_value"
    spec = Categorical(env.cfg.num_joint_actions, device=env.device)
    mask = TensorDictModule(
        JointActionMask(env.neighbours, env.cfg.grid[0], N, position_numbers(env.world)),
        in_keys=["positions", *_levels(env)],
        out_keys=["joint_action_mask"],
    )
    argmax = QValueModule(
        spec=spec,
        action_value_key=values,
        action_mask_key="joint_action_mask",
        out_keys=["joint_action", values, "joint_chosen_action_value"],
    )
    decode = TensorDictModule(
        DecodeJointAction(N, env.device, env.cfg.joint_action_base),
        in_keys=["joint_action"],
        out_keys=[("agents", "action")],
    )
    exploration = EpsilonGreedy(spec, action_key="joint_action", action_mask_key="joint_action_mask", **eps)
    greedy = TensorDictSequential(mask, q, argmax, decode)
    explore = TensorDictSequential(mask, q, argmax, exploration, decode)
    value_network = TensorDictSequential(mask, q, argmax)
    return Policies(greedy, explore, exploration, value_network, spec, ["joint_action", ("agents", "action")])


def build_mixer(env: UAVSpectrumEnv, a) -> TensorDictModule:
    """The team value of the UAVs' chosen values: VDN (their sum) or QMIX (``agent.mixer``, :mod:`.loss`).

    Args:
        env: the training environment (``N`` and, for QMIX, the size of ``state``).
        a: the agent's settings ``cfg.agent`` (``mixer``, ``mixing_embed_dim``).
    """
    if a.mixer == "vdn":
        return TensorDictModule(VDNMix(), in_keys=[("agents", "chosen_action_value")], out_keys=["chosen_action_value"])
    return TensorDictModule(
        QMix(env.state_size, int(a.mixing_embed_dim), env.num_uavs, env.device),
        in_keys=[("agents", "chosen_action_value"), "state"],
        out_keys=["chosen_action_value"],
    )


def build_loss(env: UAVSpectrumEnv, a, policies: Policies) -> LossModule:
    """Double-DQN loss with target networks: mixed per-UAV values (factored) or the joint head's (joint).

    Args:
        env: the training environment.
        a: the agent's settings ``cfg.agent`` (``head``, ``mixer``, ``gamma``).
        policies: the policies of :func:`build_policies`, whose value network the loss trains.
    """
    if a.head == "factored":
        return DoubleQMixerLoss(policies.value_network, build_mixer(env, a), float(a.gamma))
    loss = DQNLoss(
        policies.value_network,
        double_dqn=True,
        delay_value=True,
        action_space=policies.action_spec,
        loss_function="smooth_l1",
    )
    loss.set_keys(action="joint_action", action_value=_values_key(a), value="joint_chosen_action_value")
    loss.make_value_estimator(gamma=float(a.gamma))
    return loss


class QNetwork(abc.ABC):
    """What ``agent.network`` decides for a :class:`~.agent.DQNAgent`: the teams it trains on, the parameters, the
    module that acts in each team's worlds, the loss and its targets, the greedy policy for other environments and the
    layout of the experience in a checkpoint.  Everything else (worlds, exploration, replay, the levers, the loop, the
    optimizer) is the agent's, shared.

    Built by the agent after every team's environment, before any collector (the collectors draw from torch's
    generator, so the networks' initial weights are the first draws after the seed).
    """

    name: str
    """The ``agent.network`` value it implements."""
    kind: str
    """What the error message calls it (``per-size``, ``size-free``)."""

    def __init__(self, agent: DQNAgent, env: UAVSpectrumEnv):
        self.agent, self.settings = agent, agent.settings

    @staticmethod
    @abc.abstractmethod
    def models(env_cfg: ModelConfig, a) -> list[ModelConfig]:
        """The teams (and layouts) a run trains on, one group of worlds each."""

    @abc.abstractmethod
    def values(self, env: UAVSpectrumEnv) -> TensorDictModule:
        """The module writing ``("agents", "action_value")`` (or the joint head's values) in ``env``'s worlds."""

    @abc.abstractmethod
    def build_loss(self, policies) -> nn.Module:
        """The double-DQN loss, given the first group's :class:`~.builders.Policies`."""

    @abc.abstractmethod
    def parameters(self) -> list[nn.Parameter]:
        """The online parameters the optimizer steps (in a fixed order: the optimizer's state and the clipping)."""

    @abc.abstractmethod
    def td_loss(self, batch: TensorDictBase, group: _Group) -> torch.Tensor:
        """The mean TD loss of ``batch``, transitions of ``group``."""

    @abc.abstractmethod
    def update_target(self) -> None:
        """Move the target parameters towards the online ones (after each gradient step)."""

    @abc.abstractmethod
    def policy_for(self, env_cfg: ModelConfig) -> CheckedPolicy:
        """The greedy policy in environments of ``env_cfg``."""

    @abc.abstractmethod
    def experience_state(self, per_group: list[dict], curriculum: Curriculum) -> dict:
        """The checkpoint's experience entries from each group's ``{"exploration", "buffer"}``."""

    @abc.abstractmethod
    def experience_of(self, state: dict, curriculum: Curriculum) -> list[dict]:
        """Each group's ``{"exploration", "buffer"}`` (and older keys) of a checkpoint's ``state``."""


class TeamNetwork(QNetwork):
    """``agent.network=team``: one :class:`TeamQNet` sized by the run's env (its one group), TorchRL's losses
    (:func:`build_loss`) with soft-updated targets (:class:`TargetUpdate`)."""

    name, kind = "team", "per-size"

    def __init__(self, agent: DQNAgent, env: UAVSpectrumEnv):
        super().__init__(agent, env)
        self.env, self.q = env, build_q_network(env, self.settings)

    @staticmethod
    def models(env_cfg: ModelConfig, a) -> list[ModelConfig]:
        return [env_cfg]

    def values(self, env: UAVSpectrumEnv) -> TensorDictModule:
        return self.q

    def build_loss(self, policies: Policies) -> LossModule:
        self.loss = build_loss(self.env, self.settings, policies)
        self.target_update = TargetUpdate(self.loss, tau=float(self.settings.tau))
        return self.loss

    def parameters(self) -> list[nn.Parameter]:
        return list(self.loss.parameters())

    def td_loss(self, batch: TensorDictBase, group: _Group) -> torch.Tensor:
        return self.loss(batch)["loss"]

    def update_target(self) -> None:
        self.target_update.step()

    def policy_for(self, env_cfg: ModelConfig) -> CheckedPolicy:
        """The run's greedy policy, in environments of the run's grid, number of UAVs and layout only; trained in a
        city, in another city of the run's model too (:func:`~uavrl.agents.schema.network_refusal`): the same
        weights on that city's positions, which the buildings number."""
        run = self.agent.env_cfg
        acting = env_cfg.replace(max_steps=run.max_steps)  # the episode length shapes training only
        if acting == run or acting.replace(**run_city(acting, run)) != run:
            return CheckedPolicy(self.agent.greedy, run)  # refuses any other environment in one line
        env = UAVSpectrumEnv(batch_size=1, config=env_cfg, device=self.agent.device)
        q = build_q_network(env, self.settings)
        with torch.no_grad():
            for mine, trained in zip(q.parameters(), self.q.parameters(), strict=True):
                mine.copy_(trained)
        frames = exploration_schedule(self.settings, 1, self.agent.device)
        return CheckedPolicy(build_policies(env, self.settings, q, frames).greedy, env_cfg)

    def experience_state(self, per_group: list[dict], curriculum: Curriculum) -> dict:
        return per_group[0]

    def experience_of(self, state: dict, curriculum: Curriculum) -> list[dict]:
        return [state]  # with the oldest checkpoints' "buffer_writes" (.migration)


class ZeroedStorage(LazyTensorStorage):
    """TorchRL's ``LazyTensorStorage`` with its slots zeroed when it is first written: its ``torch.empty`` leaves
    whatever bytes the allocator held in the slots not yet filled, which a checkpoint saves, so two runs of the same
    seed would write different files."""

    def _init(self, data) -> None:
        super()._init(data)
        self._storage.zero_()


def build_replay_buffer(a, transitions: CompactTransitions, batch_size: int | None = None) -> TensorDictReplayBuffer:
    """``agent.buffer_size`` transitions kept compact by ``transitions`` (:mod:`.transitions`), samples of
    ``batch_size`` (``agent.batch_size`` unless given), uniform or by priority (``agent.replay``, :mod:`.priorities`).

    Args:
        a: the agent's settings ``cfg.agent`` (``buffer_size``, ``batch_size``).
        transitions: the transform that compacts and rebuilds the transitions.
        batch_size: the transitions per sample; None: ``agent.batch_size``.
    """
    storage = ZeroedStorage(int(a.buffer_size), device=transitions.world.device)
    batch_size = int(a.batch_size) if batch_size is None else batch_size
    if a.get("replay", "uniform") == "prioritized":  # run configs saved before: no setting
        sampler = ProportionalSampler(int(a.buffer_size), float(a.priority_alpha), float(a.priority_beta))
        return TensorDictReplayBuffer(storage=storage, sampler=sampler, batch_size=batch_size, transform=transitions)
    return TensorDictReplayBuffer(storage=storage, batch_size=batch_size, transform=transitions)


def build_collector(env: UAVSpectrumEnv, policy: TensorDictSequential) -> Collector:
    """One episode of every world of ``env`` per batch.

    Args:
        env: the training environment; every batch is ``[worlds, max_steps]``.
        policy: the exploring policy that acts.
    """
    return make_collector(
        env, policy, frames_per_batch=env.num_worlds * env.cfg.max_steps, total_frames=-1, device=env.device
    )
