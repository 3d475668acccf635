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
``QValueModule`` (joint argmax), ``EGreedyModule``, ``VDNMixer``/``QMixer``,
``QMixerLoss`` (its double-DQN target here) and ``DQNLoss(double_dqn=True)``,
``TensorDictReplayBuffer``, ``SoftUpdate`` and ``Collector``.

Example:
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

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import Categorical, Composite, LazyTensorStorage, TensorDictReplayBuffer
from torchrl.modules import EGreedyModule, MultiAgentMLP, QMixer, QValueModule, VDNMixer
from torchrl.objectives import DQNLoss, LossModule, QMixerLoss, SoftUpdate

from uavrl.agents.base import Agent
from uavrl.agents.env_check import CheckedPolicy
from uavrl.agents.schema import agent_rules
from uavrl.compat import load_buffer_state, make_collector, written_into
from uavrl.envs import (
    NODE_FEATURES,
    NUM_ACTIONS,
    ModelConfig,
    UAVSpectrumEnv,
    decode_joint_actions,
    joint_action_valid,
    observation_with_nodes,
)
from uavrl.envs.channel import rates
from uavrl.envs.config import RELAYING, SENSING
from uavrl.envs.fading import fading_part
from uavrl.envs.grid import cells_or_away
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET
from uavrl.envs.optimum import MAX_EXCHANGE_UAVS
from uavrl.envs.rewards import log_gap_reward
from uavrl.evaluation import episode_metrics
from uavrl.rules import check

MAX_JOINT_ACTIONS = NUM_ACTIONS**4  # the joint head is for small teams: N <= 4
_ITERATION_STRIDE = 2**24  # world seeds of iteration k: seed * 2^44 + (k + 1) * 2^24 + world, clear of the eval seeds
_SEED_MODULUS = 2**63  # world seeds are int64: seeds past 2^19 wrap around
Q_INPUTS = (("agents", "observation"), "positions", "state")  # what TeamQNet reads (the nodes are in the state)


# ----------------------------------------------------------------------------- networks
def _cells(positions: torch.Tensor, width: int) -> torch.Tensor:
    return positions[..., 1] * width + positions[..., 0]


class TeamQNet(nn.Module):
    """Action values from the joint observation ``[*, N, F]``, the positions ``[*, N, 2]`` and the state.

    Each UAV's input is its observation followed by the node positions (the
    last 12 entries of ``state``, :func:`~uavrl.envs.world.observation_with_nodes`).
    The torso (a centralised ``MultiAgentMLP``) embeds all N inputs at once.
    ``factored``: a shared per-UAV head (a ``MultiAgentMLP`` with one hidden
    layer) reads that embedding, the UAV's own observation, its one-hot id and
    which of its 4 neighbouring cells another UAV holds, and returns
    ``[*, N, A]`` (A = 6, 7 with recharging).  The embedding is the same for every UAV of a world, so the
    head's first layer is applied in two parts: to the embedding once per
    world, to the rest once per UAV: the same function and parameters as the
    layer on the whole input, and with 6 UAVs 43% fewer multiplications for
    the whole network.
    ``joint``: a linear head returns ``[*, 6^N]``.

    Example:
        >>> env = UAVSpectrumEnv(batch_size=3, grid=(4, 4), num_uavs=2)
        >>> td = env.reset()
        >>> TeamQNet(env, "factored", hidden=16, depth=1)(*(td[k] for k in Q_INPUTS)).shape
        torch.Size([3, 2, 6])
        >>> TeamQNet(env, "joint", hidden=16, depth=1)(*(td[k] for k in Q_INPUTS)).shape
        torch.Size([3, 36])
    """

    def __init__(self, env: UAVSpectrumEnv, head: str, hidden: int, depth: int):
        super().__init__()
        N, F, dev = env.num_uavs, env.observation_size + NODE_FEATURES, env.device
        self.joint, self.width = head == "joint", env.cfg.grid[0]
        self.torso = MultiAgentMLP(
            F,
            hidden,
            N,
            centralized=True,
            share_params=True,
            depth=depth,
            num_cells=hidden,
            activation_class=nn.ReLU,
            activate_last_layer=True,
            device=dev,
        )
        if self.joint:
            self.head = nn.Linear(hidden, NUM_ACTIONS**N, device=dev)
        else:
            self.head = MultiAgentMLP(
                hidden + F + N + 4,
                env.num_actions,  # 6, and "return" with recharging
                N,
                centralized=False,
                share_params=True,
                depth=1,
                num_cells=hidden,
                activation_class=nn.ReLU,
                device=dev,
            )
        self.register_buffer("ids", torch.eye(N, device=dev))
        self.register_buffer("neighbours", env.neighbours.clone())

    def forward(self, observation: torch.Tensor, positions: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        observation = observation_with_nodes(observation, state)
        embedding = self.torso(observation)  # [*, N, hidden], the same row for every UAV
        if self.joint:
            return self.head(embedding[..., 0, :])
        C = len(self.neighbours)
        cells = cells_or_away(positions, (self.width, C // self.width))
        # [*, N, 4]: which of its neighbouring cells another UAV holds (none, for a UAV out of service)
        held = (self.neighbours[cells.clamp(max=C - 1)].unsqueeze(-1) == cells[..., None, None, :]).any(-1)
        held &= (cells < C).unsqueeze(-1)
        own = torch.cat([observation, self.ids.expand(*observation.shape[:-1], -1), held.to(observation.dtype)], -1)
        first, last = self.head.params["0"], self.head.params["2"]  # the head's layers (Linear, ReLU, Linear)
        split = embedding.shape[-1]
        hidden = nn.functional.linear(embedding[..., :1, :], first["weight"][:, :split], first["bias"])
        hidden = torch.relu(hidden + nn.functional.linear(own, first["weight"][:, split:]))
        return nn.functional.linear(hidden, last["weight"], last["bias"])


class ValidGreedy(nn.Module):
    """A valid joint action from per-UAV values ``[*, N, A]``, masks ``[*, N, A]``, positions and tasks.

    UAV by UAV in id order, each takes its best allowed action.  Allowed: a
    move whose target cell differs from the cells of the UAVs still to choose
    and from the targets of those that chose (staying always qualifies, so all
    targets differ: a valid joint action, docs/model.md), and a switch to a
    task that no UAV before it switches to in this step.  Then, in a second
    pass, a UAV that kept its cell takes its best move into a cell that no
    other UAV now targets, if it values that move more (a UAV held back by a
    later one that moved away follows it in the same step).  Per-UAV values rate
    each switch as if it were the only one; two UAVs that both switch (say, the
    two relays of N = 2 both turning to sensing) can land in a worse
    configuration than either alone, and flip back and forth forever.

    Example:
        >>> greedy = ValidGreedy(UAVSpectrumEnv(grid=(3, 1), num_uavs=2).neighbours, width=3)
        >>> allowed = torch.ones(1, 2, 6, dtype=torch.bool)
        >>> values = torch.tensor([[[0, 0, 0, 9.0, 0, 1], [0, 0, 9.0, 0, 0, 1]]])  # both want cell 1
        >>> greedy(values, allowed, torch.tensor([[[0, 0], [2, 0]]]), torch.tensor([[0, 0]]))
        tensor([[3, 5]])
        >>> values = torch.tensor([[[0, 0, 0, 9.0, 0, 1], [0, 0, 0, 9.0, 0, 1]]])  # a train: both move right together
        >>> greedy(values, allowed, torch.tensor([[[0, 0], [1, 0]]]), torch.tensor([[0, 0]]))
        tensor([[3, 3]])
        >>> values = torch.tensor([[[0, 0, 0, 0, 9.0, 1], [0, 0, 0, 0, 9.0, 1]]])  # both relays want to sense
        >>> greedy(values, allowed, torch.tensor([[[0, 0], [2, 0]]]), torch.tensor([[1, 1]]))
        tensor([[4, 5]])
    """

    def __init__(self, neighbours: torch.Tensor, width: int, num_actions: int = NUM_ACTIONS):
        super().__init__()
        self.width, self.num_actions = width, num_actions
        self.register_buffer("neighbours", neighbours.clone())
        self.register_buffer("task_ids", torch.tensor([SENSING, RELAYING], device=neighbours.device))  # actions 4, 5

    def _target_table(self) -> torch.Tensor:
        """``[C + 1, A]`` the cell each action leads to from each cell; off-grid moves lead to an extra cell C (masked
        out, but two UAVs given it would still collide there), where a UAV out of service stays.  "return" keeps the
        cell for the step, as the environment's dynamics do (its flight home is the energy part's)."""
        cells = len(self.neighbours)
        stay = torch.arange(cells, device=self.neighbours.device).unsqueeze(-1).expand(-1, self.num_actions - 4)
        moves = torch.cat([torch.where(self.neighbours < 0, cells, self.neighbours), stay], -1)
        return torch.cat([moves, moves.new_full((1, self.num_actions), cells)])

    def forward(
        self, action_value: torch.Tensor, action_mask: torch.Tensor, positions: torch.Tensor, tasks: torch.Tensor
    ) -> torch.Tensor:
        cells = cells_or_away(positions, (self.width, len(self.neighbours) // self.width))
        batch = cells.shape[:-1]
        # per-UAV rows, UAV first ([N, *, ...], contiguous): one row per step of the sequential choice
        table = self._target_table()
        targets = table.index_select(0, cells.reshape(-1)).view(*cells.shape, -1).movedim(-2, 0).contiguous()
        values, allowed = action_value.movedim(-2, 0).contiguous(), action_mask.movedim(-2, 0).contiguous()
        switches = (tasks.unsqueeze(-1) != self.task_ids).movedim(-2, 0)  # [N, *, 2]: actions 4, 5 change the task
        # occupied[..., c]: cell c is held or claimed by a UAV (while a UAV chooses, its own cell is left out)
        occupied = torch.zeros(*batch, len(table) + 1, dtype=torch.bool, device=cells.device)
        occupied.scatter_(-1, cells, True)
        switched_to = torch.zeros(*batch, 2, dtype=torch.bool, device=cells.device)  # a task switched to this step
        claimed = list(cells.movedim(-1, 0).unsqueeze(-1))  # [*, 1] per UAV
        actions = []
        for i in range(len(values)):
            occupied.scatter_(-1, claimed[i], False)
            blocked = occupied.gather(-1, targets[i]) | ~allowed[i]
            blocked[..., 4:6] |= switches[i] & switched_to
            action = values[i].masked_fill(blocked, -math.inf).argmax(-1, keepdim=True)
            claimed[i] = targets[i].gather(-1, action)
            occupied.scatter_(-1, claimed[i], True)
            switched_to |= switches[i] & (action == self.task_ids + 4)
            actions.append(action)
        # second pass: a UAV that kept its cell because a later UAV still held the cell it wanted takes that move
        # now if the holder has left it (UAVs following one another move together)
        for i in range(len(values)):
            occupied.scatter_(-1, claimed[i], False)
            blocked = occupied.gather(-1, targets[i][..., :4]) | ~allowed[i][..., :4]
            value, move = values[i][..., :4].masked_fill(blocked, -math.inf).max(-1, keepdim=True)
            better = (actions[i] >= 4) & (value > values[i].gather(-1, actions[i]))
            actions[i] = torch.where(better, move, actions[i])
            claimed[i] = torch.where(better, targets[i].gather(-1, move), claimed[i])
            occupied.scatter_(-1, claimed[i], True)
        return torch.cat(actions, -1)


class JointActionMask(nn.Module):
    """``[*, 6^N]`` valid joint actions at positions ``[*, N, 2]`` (the environment's rule)."""

    def __init__(self, neighbours: torch.Tensor, width: int, num_uavs: int):
        super().__init__()
        self.width, self.num_uavs = width, num_uavs
        self.register_buffer("neighbours", neighbours.clone())

    def forward(self, positions: torch.Tensor) -> torch.Tensor:
        return joint_action_valid(_cells(positions, self.width), self.neighbours, self.num_uavs)


class DecodeJointAction(nn.Module):
    """Per-UAV actions ``[*, N]`` of joint actions ``[*]``, ``j = sum_i a_i 6^i``."""

    def __init__(self, num_uavs: int, device):
        super().__init__()
        self.register_buffer("table", decode_joint_actions(num_uavs, device))

    def forward(self, joint_action: torch.Tensor) -> torch.Tensor:
        return self.table[joint_action]


# ----------------------------------------------------------------------------- loss
class DoubleQMixerLoss(QMixerLoss):
    """``QMixerLoss`` with double-DQN targets over valid joint actions.

    ``y = r + gamma (1 - terminated) Mix_target(Q_target(s', a'), s')`` where the
    online network's :class:`ValidGreedy` picks ``a'``; the loss is the Huber
    distance to ``Mix(Q(s, a), s)``.
    """

    def __init__(self, greedy: TensorDictSequential, mixer: TensorDictModule, action_spec, gamma: float):
        super().__init__(greedy, mixer, action_space=action_spec, loss_function="smooth_l1")
        self.gamma = gamma

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        # The online parameters are the modules' own (the optimizer steps them in place): called directly, without
        # the parameter swap of to_module.  The target parameters are swapped in.
        net, greedy = (m.module for m in self.local_value_network.module)
        mixer, k, nxt = self.mixer_network.module, self.tensor_keys, td.get("next")

        def team_value(td: TensorDictBase, action: torch.Tensor) -> torch.Tensor:
            chosen = net(*(td.get(key) for key in Q_INPUTS)).gather(-1, action.unsqueeze(-1))
            return mixer(chosen, td.get("state")) if mixer.needs_state else mixer(chosen)

        value = team_value(td, td.get(k.action))
        with torch.no_grad():
            next_values = net(*(nxt.get(key) for key in Q_INPUTS))
            next_action = greedy(
                next_values, nxt.get(("agents", "action_mask")), nxt.get("positions"), nxt.get("tasks")
            )
            with (
                written_into(self.target_local_value_network_params, self.local_value_network),
                written_into(self.target_mixer_network_params, self.mixer_network),
            ):
                next_value = team_value(nxt, next_action)  # the online greedy valid action, valued by the target
            target = nxt.get(k.reward) + self.gamma * (~nxt.get(k.terminated)) * next_value
        return TensorDict({"loss": nn.functional.smooth_l1_loss(value, target)})


# ----------------------------------------------------------------------------- settings
def check_settings(env_cfg: ModelConfig, a) -> None:
    """One-line errors for settings the agent cannot run: the rules of its schema (:mod:`uavrl.agents.schema`), then
    the head's size."""
    check(a, agent_rules("dqn"), section="agent")
    if a.head == "joint" and env_cfg.num_joint_actions > MAX_JOINT_ACTIONS:
        raise ValueError(
            f"agent.head='joint' with num_uavs={env_cfg.num_uavs} needs 6^{env_cfg.num_uavs} = "
            f"{env_cfg.num_joint_actions:,} outputs, over {MAX_JOINT_ACTIONS:,} (N <= 4): use agent.head=factored"
        )
    if a.head == "joint" and env_cfg.energy != "none":
        raise ValueError(
            f"agent.head='joint' is invalid with env.energy={env_cfg.energy!r}: its joint action mask knows no UAV out "
            "of service; use agent.head=factored"
        )


# ----------------------------------------------------------------------------- builders
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
    """:class:`TeamQNet` as a module writing ``("agents", "action_value")`` (factored) or ``"joint_action_value"``."""
    net = TeamQNet(env, a.head, int(a.hidden), int(a.depth))
    return TensorDictModule(net, in_keys=list(Q_INPUTS), out_keys=[_values_key(a)])


def _values_key(a):
    return ("agents", "action_value") if a.head == "factored" else "joint_action_value"


def exploration_schedule(a, frames: int, device) -> dict:
    """``EGreedyModule`` keywords: epsilon from ``agent.eps_start`` to ``agent.eps_end`` over ``agent.eps_fraction``
    of the run's ``frames``."""
    steps = max(1, int(float(a.eps_fraction) * frames))
    return dict(eps_init=float(a.eps_start), eps_end=float(a.eps_end), annealing_num_steps=steps, device=device)


def build_policies(env: UAVSpectrumEnv, a, q: TensorDictModule, eps: dict) -> Policies:
    """The greedy and the exploring policy of ``agent.head`` around the Q network ``q``."""
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
    greedy_action = TensorDictModule(
        ValidGreedy(env.neighbours, env.cfg.grid[0], env.num_actions),
        in_keys=[("agents", "action_value"), ("agents", "action_mask"), "positions", "tasks"],
        out_keys=[("agents", "action")],
    )
    greedy = TensorDictSequential(q, greedy_action)
    exploration = EGreedyModule(spec, action_key=("agents", "action"), action_mask_key=("agents", "action_mask"), **eps)
    explore = TensorDictSequential(greedy, exploration)
    return Policies(greedy, explore, exploration, greedy, spec, [("agents", "action")])


def _joint_policies(env: UAVSpectrumEnv, q: TensorDictModule, eps: dict) -> Policies:
    N, values = env.num_uavs, "joint_action_value"
    spec = Categorical(env.cfg.num_joint_actions, device=env.device)
    mask = TensorDictModule(
        JointActionMask(env.neighbours, env.cfg.grid[0], N),
        in_keys=["positions"],
        out_keys=["joint_action_mask"],
    )
    argmax = QValueModule(
        spec=spec,
        action_value_key=values,
        action_mask_key="joint_action_mask",
        out_keys=["joint_action", values, "joint_chosen_action_value"],
    )
    decode = TensorDictModule(
        DecodeJointAction(N, env.device), in_keys=["joint_action"], out_keys=[("agents", "action")]
    )
    exploration = EGreedyModule(spec, action_key="joint_action", action_mask_key="joint_action_mask", **eps)
    greedy = TensorDictSequential(mask, q, argmax, decode)
    explore = TensorDictSequential(mask, q, argmax, exploration, decode)
    value_network = TensorDictSequential(mask, q, argmax)
    return Policies(greedy, explore, exploration, value_network, spec, ["joint_action", ("agents", "action")])


def build_mixer(env: UAVSpectrumEnv, a) -> TensorDictModule:
    """The team value of the UAVs' chosen values: VDN (their sum) or QMIX (``agent.mixer``)."""
    if a.mixer == "vdn":
        return TensorDictModule(
            VDNMixer(env.num_uavs, env.device),
            in_keys=[("agents", "chosen_action_value")],
            out_keys=["chosen_action_value"],
        )
    return TensorDictModule(
        QMixer((env.state_size,), int(a.mixing_embed_dim), env.num_uavs, env.device),
        in_keys=[("agents", "chosen_action_value"), "state"],
        out_keys=["chosen_action_value"],
    )


def build_loss(env: UAVSpectrumEnv, a, policies: Policies) -> LossModule:
    """Double-DQN loss with target networks: mixed per-UAV values (factored) or the joint head's (joint)."""
    if a.head == "factored":
        return DoubleQMixerLoss(policies.value_network, build_mixer(env, a), policies.action_spec, float(a.gamma))
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


def build_replay_buffer(a, device) -> TensorDictReplayBuffer:
    """``agent.buffer_size`` transitions, uniform samples of ``agent.batch_size``."""
    storage = LazyTensorStorage(int(a.buffer_size), device=device)
    return TensorDictReplayBuffer(storage=storage, batch_size=int(a.batch_size))


def transition_keys(a, action_keys: list) -> list:
    """The entries of a transition the replay buffer keeps (the loss reads no others)."""
    inputs = [("agents", "observation"), ("agents", "action_mask"), "positions", "tasks", "state"]
    return inputs + action_keys + [("next", k) for k in inputs + ["reward", "done", "terminated"]]


def build_collector(env: UAVSpectrumEnv, policy: TensorDictSequential) -> Collector:
    """One episode of every world of ``env`` per batch."""
    return make_collector(
        env, policy, frames_per_batch=env.num_worlds * env.cfg.max_steps, total_frames=-1, device=env.device
    )


def _nodes_out_of_observation(transitions, observation_size: int) -> None:
    """A replay buffer of the earlier observation layout (the node positions in every UAV's observation, the state
    only with QMIX) becomes the current one in place, so a run saved in that layout resumes bit for bit.

    ``transitions``: the storage of a buffer's ``state_dict`` or the ``TensorDict`` of the oldest checkpoints.
    """
    for step in ((), ("next",)):
        holder, key = _stored_entry(transitions, (*step, "agents", "observation"))
        observation = holder[key]
        if observation.shape[-1] != observation_size + NODE_FEATURES:
            return
        holder[key] = observation[..., :observation_size].contiguous()
        holder, key = _stored_entry(transitions, (*step, "state"))
        if key not in holder.keys():  # per UAV its first 5 entries, then the nodes (World._assemble)
            own, nodes = observation[..., :5].flatten(-2), observation[..., 0, observation_size:]
            holder[key] = torch.cat([own, nodes], -1)


def _stored_entry(transitions, names: tuple):
    """``(mapping, key)`` of the entry ``names`` of a stored buffer: a ``TensorDict`` (tuple keys), torchrl 0.14's
    flat ``state_dict`` (keys joined by dots) or torchrl 0.11's nested dicts."""
    if not isinstance(transitions, dict):
        return transitions, names
    if ".".join(names) in transitions or names[0] not in transitions:
        return transitions, ".".join(names)
    holder = transitions
    for name in names[:-1]:
        holder = holder[name]
    return holder, names[-1]


# ----------------------------------------------------------------------------- the agent
class DQNAgent(Agent):
    """The deep agent behind ``python -m uavrl.train agent=dqn`` (contract: :class:`uavrl.agents.base.Agent`).

    ``cfg.agent`` holds the settings (``configs/agent/dqn.yaml``), ``agent.iterations`` the run length.
    """

    def __init__(self, env_cfg: ModelConfig, cfg, device, seed: int):
        a = cfg.agent
        check_settings(env_cfg, a)
        self.env_cfg, self.settings, self.seed = env_cfg, a, int(seed)
        self.device = torch.device(device)
        self.num_iterations = int(a.iterations)
        self.iteration = 0
        torch.manual_seed(self.seed)  # the networks' initial weights; build order matters
        self.env = UAVSpectrumEnv(
            batch_size=int(a.worlds),
            config=env_cfg,
            seed=self._world_seed(0),
            device=self.device,
            memory_budget=a.get("memory_budget", DEFAULT_MEMORY_BUDGET),  # run directories saved without it
        )
        q = build_q_network(self.env, a)
        frames = int(a.worlds) * env_cfg.max_steps * self.num_iterations
        policies = build_policies(self.env, a, q, exploration_schedule(a, frames, self.device))
        self.greedy, self.exploration = policies.greedy, policies.exploration
        self.loss = build_loss(self.env, a, policies)
        self.optimizer = torch.optim.Adam(self.loss.parameters(), lr=float(a.lr))
        self.target_update = SoftUpdate(self.loss, tau=float(a.tau))
        self.buffer = build_replay_buffer(a, self.device)
        self._keys = transition_keys(a, policies.action_keys)
        self.collector = build_collector(self.env, policies.explore)
        self._batches = iter(self.collector)

    def _world_seed(self, iteration: int) -> int:
        return (self.seed * 2**44 + (iteration + 1) * _ITERATION_STRIDE) % _SEED_MODULUS

    @property
    def env_steps(self) -> int:
        """Team steps collected so far (worlds times steps)."""
        return self.iteration * int(self.settings.worlds) * self.env_cfg.max_steps

    def train_iteration(self) -> dict[str, float]:
        """One episode in every world, then ``agent.updates`` gradient steps."""
        self.collector.set_seed(self._world_seed(self.iteration), static_seed=True)
        self.collector.reset()
        for group in self.optimizer.param_groups:  # annealed linearly from agent.lr to agent.lr_end over the run
            group["lr"] = float(self.settings.lr) + (float(self.settings.lr_end) - float(self.settings.lr)) * min(
                1.0, self.iteration / self.num_iterations
            )
        # this episode's layouts; the exchange method where it runs (its results recorded), the search beyond
        u_star = self.env.optimum(method="exchange" if self.env_cfg.num_uavs <= MAX_EXCHANGE_UAVS else "search")[0]
        # kept: the collector's closing reset draws new random layouts before the batch is read
        layout = (self.env.cell_contributions.clone(), self.env.direct.clone())
        batch = next(self._batches)  # [worlds, steps]

        def mean_utility(td: TensorDictBase) -> torch.Tensor:
            """``[W, T]`` mean-channel utility of the batch's configurations in the layouts they were played in."""
            C = self.env_cfg.num_cells
            cells = cells_or_away(td.get("positions"), self.env_cfg.grid)  # C: out of service, adds nothing
            on_grid = layout[0][torch.arange(len(cells), device=cells.device)[:, None, None], cells.clamp(max=C - 1)]
            contributions = on_grid.masked_fill((cells == C).unsqueeze(-1), 0.0)
            r_pu, r_se = rates(contributions, td.get("tasks"), layout[1][:, None], self.env_cfg)
            return r_pu + r_se

        if self.settings.objective == "log_gap":
            batch.set(("next", "reward"), self._log_gap_reward(batch, u_star, mean_utility))
        self.buffer.extend(batch.reshape(-1).select(*self._keys))
        losses = (
            [self._update() for _ in range(int(self.settings.updates))]
            if len(self.buffer) >= int(self.settings.learning_starts)
            else []
        )
        self.exploration.step(batch.numel())
        self.iteration += 1
        nxt = batch.get("next")
        # under fading, "reaches 90% of U*" is decided on the configurations' mean-channel utility
        reach_utility = mean_utility(nxt) if fading_part(self.env_cfg).random else None
        per_world = episode_metrics(
            *(nxt.get(key).squeeze(-1) for key in ("r_pu", "r_se", "task_switches", "moves")), u_star, reach_utility
        )
        out = {f"train/{k}": v.mean().item() for k, v in per_world.items()}
        out["train/epsilon"] = self.exploration.eps.item()
        if losses:
            out["train/loss"] = torch.stack(losses).mean().item()
        return out

    def _log_gap_reward(self, batch: TensorDictBase, u_star: torch.Tensor, mean_utility) -> torch.Tensor:
        """``[W, T, 1]`` the change of ``-log(1 - U / U* + agent.gap_floor)`` over each step, mean-channel ``U``.

        The delta reward's action gaps shrink with the distance to the optimum
        (the last 0.1% of U* is worth 0.01 bit/s/Hz), below what the network
        resolves: greedy policies then wander near U*.  On a log scale of the
        gap to U* each halving of the gap is worth the same, down to the floor.
        """
        change = log_gap_reward(
            mean_utility(batch.get("next")), mean_utility(batch), u_star.unsqueeze(-1), float(self.settings.gap_floor)
        )
        return change.unsqueeze(-1).to(batch.get(("next", "reward")).dtype)

    def _update(self) -> torch.Tensor:
        loss = self.loss(self.buffer.sample())["loss"]
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        nn.utils.clip_grad_norm_(self.loss.parameters(), float(self.settings.max_grad_norm))
        self.optimizer.step()
        self.target_update.step()
        return loss.detach()

    def policies(self) -> list[CheckedPolicy]:
        """The greedy policy: reads the env's keys, writes ``("agents", "action")``, in environments of the run's grid,
        number of UAVs and layout only."""
        return [CheckedPolicy(self.greedy, self.env_cfg)]

    def state_dict(self) -> dict:
        """Networks with their targets, optimizer, exploration, replay buffer, RNG and progress."""
        state = {
            "iteration": self.iteration,
            "loss": self.loss.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "exploration": self.exploration.state_dict(),
            "buffer": self.buffer.state_dict(),  # storage, write cursor and count, sampler
            "rng": torch.get_rng_state(),
        }
        if self.device.type == "cuda":
            state["cuda_rng"] = torch.cuda.get_rng_state(self.device)
        return state

    def load_state_dict(self, state: dict):
        self.loss.load_state_dict(state["loss"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.exploration.load_state_dict(state["exploration"])
        transitions = state["buffer"] if "buffer_writes" in state else state["buffer"]["_storage"]["_storage"]
        if transitions is not None:
            _nodes_out_of_observation(transitions, self.env.observation_size)
        if "buffer_writes" in state:  # a checkpoint of an earlier version: the filled slots, in slot order
            self._load_filled_slots(state["buffer"], state["buffer_writes"])
        else:
            load_buffer_state(self.buffer, state["buffer"])
        self.iteration = int(state["iteration"])
        torch.set_rng_state(state["rng"])
        if "cuda_rng" in state:
            torch.cuda.set_rng_state(state["cuda_rng"], self.device)

    def _load_filled_slots(self, data, writes: int) -> None:
        self.buffer.empty()
        if data is not None:
            data = data.to(self.device)
            self.buffer.extend(data)
            wrapped = writes % len(data) if writes > len(data) else 0
            if wrapped:  # rewrite the first slots with themselves so the next write lands where it would have
                self.buffer.extend(data[:wrapped])
