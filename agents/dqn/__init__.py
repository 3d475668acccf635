"""Factored deep Q-network: team Q-learning past the tabular state explosion.

The tabular agent keeps one Q row per joint location, ``(L1 L2)^N`` rows; this
agent replaces the table by a network over the joint observation, trained
with double-DQN targets from a replay buffer and a soft-updated target network.

Two heads (``agent.head``):

- ``factored`` (default): a torso reads every UAV's observation (the joint
  observation) and feeds one action head per UAV; the heads share parameters
  and see the UAV's own observation, its one-hot id and which neighbouring
  cells other UAVs hold.  The team value mixes the UAVs' chosen values by VDN
  (their sum) or QMIX (a monotonic state-conditioned mix), ``agent.mixer``.
  The greedy joint action is always valid: UAV by UAV in id order, each takes
  its best action whose target cell is neither held by a UAV still to choose
  nor claimed by one that chose, switching task only to a task no UAV before
  it switches to in that step (:class:`ValidGreedy`).
- ``joint``: the torso feeds one ``6^N``-way head over joint actions, masked to
  the valid ones: the exact deep counterpart of the team Q table, for N <= 4.

One iteration: each of ``agent.worlds`` worlds plays one episode of
``env.max_steps`` steps, the transitions join the replay buffer,
then ``agent.updates`` gradient steps.  Every iteration reseeds its worlds from
the seed and the iteration number (so a resumed run continues exactly as the
uninterrupted one, and episodes always start afresh, also with
``reset_positions=keep``); the seeds stay clear of the evaluation's.

Built from TorchRL parts: ``MultiAgentMLP`` (torso and per-UAV heads),
``QValueModule`` (joint argmax), ``EGreedyModule``, ``LossModule`` (the factored head's double-DQN loss with
the project's own VDN and QMIX mixers, :mod:`.loss`) and ``DQNLoss(double_dqn=True)``,
``TensorDictReplayBuffer``, ``SoftUpdate`` and ``Collector``.

The package, one job a module, each read top to bottom:

- :mod:`.networks`: :class:`TeamQNet` and the modules that turn its values into valid actions (:class:`ValidGreedy`);
- :mod:`.loss`: :class:`VDNMix`, :class:`QMix` and :class:`DoubleQMixerLoss`, the factored head's double-DQN loss;
- :mod:`.common_knowledge`: with local observations where every UAV hears every other, each UAV's part of one joint
  action every UAV computes alike (``CommonKnowledgeGreedy``);
- :mod:`.transitions`: :class:`CompactTransitions`, the replay buffer's transitions kept as configurations;
- :mod:`.builders`: the Q network, policies, mixer, loss, replay buffer and collector built from the settings;
- :mod:`.migration`: replay buffers of earlier checkpoints, loaded as the current agent would have saved them;
- :mod:`.agent`: :class:`DQNAgent`, the learner behind ``python -m uavrl.train agent=dqn``.

Example:
    >>> import torch
    >>> from hydra import compose, initialize_config_dir
    >>> from uavrl.config import config_dir, model_config
    >>> with initialize_config_dir(config_dir=config_dir(), version_base=None):
    ...     overrides = ["agent=dqn", "env.grid=[3,3]", "agent.worlds=4", "agent.buffer_size=1000"]
    ...     cfg = compose("config", overrides=[*overrides, "env.max_steps=5"])
    >>> agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), seed=0)
    >>> metrics = agent.train_iteration()  # 4 worlds x 5 steps, no gradient step before agent.learning_starts
    >>> agent.env_steps, metrics["train/epsilon"] < 1.0
    (20, True)
"""

from uavrl.agents.schema import MAX_JOINT_ACTIONS

from .agent import DQNAgent
from .builders import (
    Policies,
    build_collector,
    build_loss,
    build_mixer,
    build_policies,
    build_q_network,
    build_replay_buffer,
    exploration_schedule,
)
from .loss import DoubleQMixerLoss, QMix, VDNMix
from .networks import Q_INPUTS, DecodeJointAction, JointActionMask, TeamQNet, ValidGreedy
from .transitions import CompactTransitions, n_step_returns, transition_keys

__all__ = [
    "MAX_JOINT_ACTIONS",
    "Q_INPUTS",
    "CompactTransitions",
    "DQNAgent",
    "DecodeJointAction",
    "DoubleQMixerLoss",
    "JointActionMask",
    "Policies",
    "QMix",
    "TeamQNet",
    "VDNMix",
    "ValidGreedy",
    "build_collector",
    "build_loss",
    "build_mixer",
    "build_policies",
    "build_q_network",
    "build_replay_buffer",
    "exploration_schedule",
    "n_step_returns",
    "transition_keys",
]
