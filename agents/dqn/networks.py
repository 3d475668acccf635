"""The DQN's networks: the Q network over the joint observation and the modules that turn its values into valid actions.

- :class:`TeamQNet`: action values, per UAV (``factored``) or per joint action (``joint``);
- :class:`ValidGreedy`: the factored head's greedy valid joint action, UAV by UAV;
- :class:`JointActionMask`, :class:`DecodeJointAction`: the joint head's mask and its per-UAV actions;
- :class:`LocalQNet`, :class:`LocalGreedy`: with local observations (``env.observation=local``) each UAV's values
  from its own observation alone, and its best allowed action.
"""

from __future__ import annotations

import math

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.modules import MultiAgentMLP

from uavrl.envs import (
    NODE_FEATURES,
    NUM_ACTIONS,
    UAVSpectrumEnv,
    decode_joint_actions,
    joint_action_valid,
    observation_with_nodes,
)
from uavrl.envs.config import CLIMB, RELAYING, SENSING
from uavrl.envs.physics.dynamics import SENSE
from uavrl.envs.physics.grid import MOVES, cells_or_away
from uavrl.envs.physics.sensing import local_slot_features

Q_INPUTS = (("agents", "observation"), "positions", "state")  # what TeamQNet reads (the nodes are in the state)
GIVE_WAY = 0.8  # a UAV's chance of staying after a clash (YieldToContenders), chosen on tuning starts (BENCHMARKS.md)
LEVELS = "levels"  # with altitude levels, each UAV's level: the networks and the greedy rules read it after the rest


def q_inputs(cfg) -> list:
    """The entries a Q network reads in environments of the model ``cfg``: :data:`Q_INPUTS`, then with altitude
    levels each UAV's level."""
    return [*Q_INPUTS, LEVELS] if cfg.num_levels > 1 else list(Q_INPUTS)


def position_numbers(world) -> torch.Tensor | None:
    """``[L, C]`` the position of each cell at each altitude level of ``world``'s model (-1 inside a building): what
    turns a UAV's ``(x, y)`` and level into its position (:class:`PositionIndex`); None with one level."""
    cfg = world.cfg
    if cfg.num_levels == 1:
        return None
    return world.dynamics.positions.number.view(cfg.num_levels, cfg.num_cells)


class PositionIndex(nn.Module):
    """Position indices ``[*, N]`` of UAVs at ``(x, y)`` ``[*, N, 2]`` (and with altitude levels at levels ``[*, N]``):
    cells ``y L1 + x`` (``L1 L2`` for a UAV off the grid, out of service) with one level, the model's positions
    (:func:`~uavrl.envs.physics.positions.model_positions`) with several (``P``, past them, out of service).

    Args:
        grid: ``(L1, L2)``.
        numbers: ``[L, C]`` of :func:`position_numbers`; None: one level.
    """

    def __init__(self, grid: tuple[int, int], numbers: torch.Tensor | None = None):
        super().__init__()
        self.grid = tuple(grid)
        if numbers is not None:  # a UAV out of service (cell L1 L2, any level) is at position P, past the model's
            numbers = torch.cat([numbers, numbers.new_full((len(numbers), 1), int(numbers.max()) + 1)], -1)
        self.register_buffer("numbers", numbers, persistent=False)

    def forward(self, positions: torch.Tensor, levels: torch.Tensor | None = None) -> torch.Tensor:
        cells = cells_or_away(positions, self.grid)
        return cells if self.numbers is None else self.numbers[levels, cells]


def _grid(neighbours: torch.Tensor, width: int, numbers: torch.Tensor | None) -> tuple[int, int]:
    """The grid of a move table ``[P, M]`` of positions (cells with one level) and ``numbers`` ``[L, C]``."""
    cells = len(neighbours) if numbers is None else numbers.shape[-1]
    return width, cells // width


class TeamQNet(nn.Module):
    """Action values from the joint observation ``[*, N, F]``, the positions ``[*, N, 2]`` and the state (and with
    altitude levels the levels ``[*, N]``: :func:`q_inputs`).

    Each UAV's input is its observation followed by the node positions (the
    last 12 entries of ``state``, :func:`~uavrl.envs.world.observation_with_nodes`).
    The torso (a centralised ``MultiAgentMLP``) embeds all N inputs at once.
    ``factored``: a shared per-UAV head (a ``MultiAgentMLP`` with one hidden
    layer) reads that embedding, the UAV's own observation, its one-hot id and
    which of the M positions its moves reach another UAV holds (4, 6 with altitude levels), and returns
    ``[*, N, A]`` (A = 6, 7 with recharging, 8 with altitude levels).  The embedding is the same for every UAV of a
    world, so the head's first layer is applied in two parts: to the embedding once per
    world, to the rest once per UAV: the same function and parameters as the
    layer on the whole input, and with 6 UAVs 43% fewer multiplications for
    the whole network.
    ``joint``: a linear head returns ``[*, A^N]`` (``A = cfg.joint_action_base``: 6, 8 with altitude levels).

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
        self.joint = head == "joint"
        moves = env.neighbours.shape[1]  # the positions a UAV's moves reach: 4, 6 with altitude levels
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
            self.head = nn.Linear(hidden, env.cfg.joint_action_base**N, device=dev)
        else:
            self.head = MultiAgentMLP(
                hidden + F + N + moves,
                env.num_actions,  # 6, "return" with recharging, climb and descend with altitude levels
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
        self.position = PositionIndex(env.cfg.grid, position_numbers(env.world))
        self._torso_layers = sorted(self.torso.params.keys(), key=int)  # "0", "2", ...: the Linear layers

    def forward(
        self,
        observation: torch.Tensor,
        positions: torch.Tensor,
        state: torch.Tensor,
        levels: torch.Tensor | None = None,
        params: TensorDictBase = None,
    ) -> torch.Tensor:
        """The values: ``[*, N, A]`` per UAV (factored head), or ``[*, A^N]`` per joint action (joint head).

        Args:
            observation: the UAVs' observations ``[*, N, F]``.
            positions: their cells ``[*, N, 2]`` (which of the positions their moves reach another UAV holds).
            state: the worlds' state ``[*, S]``; its last 12 entries, the node positions, join each observation.
            levels: with altitude levels, their levels ``[*, N]``; None with one level.
            params: the structure of ``TensorDict.from_module(self)`` (the target network's copy in the loss),
                replacing the module's own parameters, which keeps the factored head free of any parameter swap;
                None: the module's own.
        """
        observation = observation_with_nodes(observation, state)
        if self.joint:
            return self.head(self.torso(observation)[..., 0, :])
        if params is None:
            torso, head = self.torso.params, self.head.params
        else:
            torso, head = params["torso", "params"], params["head", "params"]
        # the centralised torso once per world on the flattened joint observation: MultiAgentMLP's function without
        # its per-call parameter plumbing; every layer is followed by a ReLU
        embedding = observation.flatten(-2).unsqueeze(-2)  # [*, 1, N F]
        for layer in self._torso_layers:
            embedding = torch.relu(nn.functional.linear(embedding, torso[layer, "weight"], torso[layer, "bias"]))
        C = len(self.neighbours)
        cells = self.position(positions, levels)
        # [*, N, M]: which of the positions its moves reach another UAV holds (none, for a UAV out of service)
        held = (self.neighbours[cells.clamp(max=C - 1)].unsqueeze(-1) == cells[..., None, None, :]).any(-1)
        held &= (cells < C).unsqueeze(-1)
        own = torch.cat([observation, self.ids.expand(*observation.shape[:-1], -1), held.to(observation.dtype)], -1)
        first, last = head["0"], head["2"]  # the head's layers (Linear, ReLU, Linear)
        split = embedding.shape[-1]
        hidden = nn.functional.linear(embedding, first["weight"][:, :split], first["bias"])
        hidden = torch.relu(hidden + nn.functional.linear(own, first["weight"][:, split:]))
        return nn.functional.linear(hidden, last["weight"], last["bias"])


def heard_entry(slots: torch.Tensor) -> torch.Tensor:
    """``[..., 1]`` whether each local observation slot ``[..., slot features]`` was heard (its fourth entry, a 1;
    physics.sensing)."""
    return slots[..., 3:4] > 0


class HeardMoves(nn.Module):
    """``[*, N, M]`` which of the positions its moves reach (up, down, left, right; climb and descend with altitude
    levels) each UAV hears another UAV hold, from its local observation ``[*, N, F]`` alone: the slots' relative
    positions (docs/model.md, Local observations and messages).

    Args:
        env: an environment of the model (``env.observation=local``).
    """

    def __init__(self, env: UAVSpectrumEnv):
        super().__init__()
        cfg, N, dev = env.cfg, env.num_uavs, env.device
        self.num_uavs, self.levels = N, cfg.num_levels > 1
        self.slot = local_slot_features(cfg.energy != "none", self.levels, cfg.message_size)
        self.own = env.observation_size - (N - 1) * self.slot
        self.level_entry = 4 + 2 * (cfg.energy != "none")  # a slot's relative level, with altitude levels
        L1, L2 = cfg.grid
        scale = [max(L1 - 1, 1), max(L2 - 1, 1), max(cfg.num_levels - 1, 1)]
        self.register_buffer("scale", torch.tensor(scale, device=dev))
        moves = [(dx, dy, 0) for dx, dy in MOVES] + ([(0, 0, 1), (0, 0, -1)] if self.levels else [])
        self.register_buffer("moves", torch.tensor(moves, dtype=torch.float32, device=dev))  # [M, 3]
        actions = [0, 1, 2, 3] + ([CLIMB, CLIMB + 1] if self.levels else [])
        self.register_buffer("move_actions", torch.tensor(actions, device=dev), persistent=False)  # each move's action
        # slot k of UAV i holds UAV (i + k + 1) mod N (physics.sensing): a lower id where i + k + 1 >= N
        lower = (torch.arange(N, device=dev)[:, None] + torch.arange(1, N, device=dev) >= N).unsqueeze(-1)
        self.register_buffer("lower", lower, persistent=False)  # [N, N - 1, 1]

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return self.reached(*self.offsets(observation))

    def reached(self, offset: torch.Tensor, heard: torch.Tensor) -> torch.Tensor:
        """:meth:`forward` from the slots' :meth:`offsets`, for a caller that reads them too."""
        return ((offset.unsqueeze(-2) == self.moves).all(-1) & heard).any(-2)

    def contenders(self, observation: torch.Tensor) -> torch.Tensor:
        """``[*, N, M]`` which of the positions its moves reach a heard UAV of a lower id could move into too (one
        move from it: one cell or one level away)."""
        offset, heard = self.offsets(observation)
        return (((offset.unsqueeze(-2) - self.moves).abs().sum(-1) == 1) & heard & self.lower).any(-2)

    def slots(self, observation: torch.Tensor) -> torch.Tensor:
        """``[*, N, N - 1, slot]``: each UAV's slots of the others, as it observes them (physics.sensing)."""
        return observation[..., self.own :].unflatten(-1, (self.num_uavs - 1, self.slot))

    def offsets(self, observation: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``([*, N, N - 1, 3], [*, N, N - 1, 1])``: each slot's offset in cells and levels, and whether it is heard."""
        slots = self.slots(observation)
        level = slots[..., self.level_entry : self.level_entry + 1] if self.levels else torch.zeros_like(slots[..., :1])
        offset = (torch.cat([slots[..., :2], level], -1) * self.scale).round()  # in cells, levels
        return offset, heard_entry(slots)


class LocalQNet(nn.Module):
    """Each UAV's action values ``[*, N, A]`` from its own observation ``[*, N, F]`` alone (``env.observation=local``):
    one MLP shared by the UAVs (``depth`` hidden layers of ``hidden`` units, ReLU) reading the observation, the UAV's
    one-hot id and which positions its moves reach it hears another UAV hold (:class:`HeardMoves`), so a UAV's
    values change only with what it observes (it acts on what lies within its
    ``comm_radius``); trained centrally through the mixer, which may read the world's state.

    With ``env.message_size=d`` a linear layer on the last hidden layer and a tanh give the ``d`` numbers the UAV sends
    (:meth:`message`), learned end to end: in the loss, the messages a UAV heard are those the network sends now from
    the senders' previous observations (:meth:`forward`'s ``previous``), so the receiver's TD error reaches the
    sender's weights through one step of communication (DIAL, Foerster et al., NeurIPS 2016, truncated to one step).

    Example:
        >>> env = UAVSpectrumEnv(batch_size=3, grid=(4, 4), num_uavs=2, observation="local", comm_radius=1.0)
        >>> LocalQNet(env, hidden=16, depth=1)(env.reset()["agents", "observation"]).shape
        torch.Size([3, 2, 6])
    """

    def __init__(self, env: UAVSpectrumEnv, hidden: int, depth: int):
        super().__init__()
        cfg, N, dev = env.cfg, env.num_uavs, env.device
        self.held = HeardMoves(env)
        sizes = [env.observation_size + N + len(self.held.moves), *[hidden] * (depth + 1), env.num_actions]
        self.layers = nn.ModuleList(nn.Linear(a, b, device=dev) for a, b in zip(sizes, sizes[1:], strict=False))
        self.register_buffer("ids", torch.eye(N, device=dev))
        self.message_size = d = cfg.message_size
        self.speaker = nn.Linear(hidden, d, device=dev) if d else None
        # a local observation: its own part, then N - 1 slots ending with the sender's message (physics.sensing)
        self.slot, self.own = self.held.slot, self.held.own
        self.register_buffer("others", (torch.arange(N, device=dev)[:, None] + torch.arange(1, N, device=dev)) % N)
        self.loss_keys = [("agents", "observation"), *([("agents", "previous"), "has_previous"] if d else [])]
        """What the loss reads: the observation, and with messages the previous observations they were sent from."""

    def forward(
        self,
        observation: torch.Tensor,
        previous: torch.Tensor | None = None,
        has_previous: torch.Tensor | None = None,
        params: TensorDictBase = None,
    ) -> torch.Tensor:
        """The values ``[*, N, A]``.

        Args:
            observation: the UAVs' observations ``[*, N, F]``.
            previous: with messages, the UAVs' observations a step before ``[*, N, F]``: the messages heard are
                sent again from them by this network (the loss); None: the messages as observed (acting).
            has_previous: ``[*]`` whether there was a step before (after a reset the messages heard are zeros).
            params: the structure of ``TensorDict.from_module(self)`` (the target copy in the loss) in place of the
                module's own parameters.
        """
        if previous is not None:
            observation = self._heard(observation, previous, has_previous, params)
        weight, bias = self._layer(len(self.layers) - 1, params)
        return nn.functional.linear(self._hidden(observation, params), weight, bias)

    def message(self, observation: torch.Tensor, params: TensorDictBase = None) -> torch.Tensor:
        """``[*, N, d]`` what each UAV sends, in (-1, 1), from its observation ``[*, N, F]``."""
        hidden = self._hidden(observation, params)
        own = params is None
        weight = self.speaker.weight if own else params["speaker", "weight"]
        bias = self.speaker.bias if own else params["speaker", "bias"]
        return torch.tanh(nn.functional.linear(hidden, weight, bias))

    def _hidden(self, observation: torch.Tensor, params) -> torch.Tensor:
        ids = self.ids.expand(*observation.shape[:-1], -1)
        x = torch.cat([observation, ids, self.held(observation).to(observation.dtype)], -1)
        for i in range(len(self.layers) - 1):
            x = torch.relu(nn.functional.linear(x, *self._layer(i, params)))
        return x

    def _layer(self, i: int, params) -> tuple[torch.Tensor, torch.Tensor]:
        if params is None:
            return self.layers[i].weight, self.layers[i].bias
        return params["layers", str(i), "weight"], params["layers", str(i), "bias"]

    def _heard(self, observation, previous, has_previous, params) -> torch.Tensor:
        """``observation`` with each slot's message (where the sender is heard, after a first step) replaced by what
        this network sends from the sender's ``previous`` observation."""
        d = self.message_size
        sent = self.message(previous, params)[..., self.others, :]  # [*, N, N - 1, d]: each UAV's senders, in order
        slots = self.held.slots(observation)
        heard = heard_entry(slots) & has_previous.view(*has_previous.shape, 1, 1, 1)
        slots = torch.cat([slots[..., : self.slot - d], torch.where(heard, sent, slots[..., self.slot - d :])], -1)
        return torch.cat([observation[..., : self.own], slots.flatten(-2)], -1)


class LocalGreedy(nn.Module):
    """Each UAV's best allowed action ``[*, N]`` from its own values, mask and observation ``[*, N, ...]``: no move
    into a position it hears another UAV hold (:class:`HeardMoves`; such a move would be cancelled, docs/model.md,
    and a UAV that keeps trying it never moves again), and no UAV reads another's values.

    Args:
        held: the model's slot reader (``HeardMoves(env)``, ``env.observation=local``).
    """

    def __init__(self, held: HeardMoves):
        super().__init__()
        self.held = held

    def forward(self, values: torch.Tensor, mask: torch.Tensor, observation: torch.Tensor) -> torch.Tensor:
        blocked = torch.zeros_like(mask).index_copy(-1, self.held.move_actions, self.held(observation))
        return values.masked_fill(blocked | ~mask, -math.inf).argmax(-1)


class YieldToContenders(nn.Module):
    """Each UAV's action ``[*, N]``, kept, or replaced by staying (keeping its cell and task) with probability
    ``give_way`` where it is a move into a position that a UAV of a lower id it hears could move into too (one move
    from it) and, with ``after_cancel``, its own move at the last step was cancelled.

    Two UAVs that move into one free cell are both cancelled (docs/model.md), and UAVs acting on their own
    observations with a deterministic policy would try again forever; a coin (from the module's own seeded
    generator, started again by :meth:`restart`) for the UAV of the higher id lets the other go first, and a UAV of
    the lowest id among those contending never waits.  A coin, not a rule, because the other UAV may not want the
    position at all.  With ``after_cancel`` (the greedy policy) a UAV gives way only once a clash has happened, which
    it knows without a message (``("agents", "cancelled")``; docs/model.md, Local observations and messages): a UAV
    beside another that never meant to move there does not wait.  Without it (the behaviour policy while training,
    whose data the saved runs were trained on) the coin of 1/2 comes before any clash.  Decentralised: it reads the
    UAV's own id, action, observation and cancelled move only.

    Args:
        env: an environment of the model (``env.observation=local``).
        seed: seeds the coins.
        after_cancel: give way only after the UAV's own move was cancelled, with probability :data:`GIVE_WAY`;
            ``False``: before any clash, with probability 1/2.
    """

    def __init__(self, env: UAVSpectrumEnv, seed: int = 0, after_cancel: bool = True):
        super().__init__()
        self.held = HeardMoves(env)
        moves = self.held.move_actions
        lookup = torch.full((env.num_actions,), -1, dtype=torch.long, device=env.device)
        lookup[moves] = torch.arange(len(moves), device=env.device)
        self.register_buffer("move_of_action", lookup)  # an action's move, -1 for the others
        self.after_cancel, self.give_way = after_cancel, GIVE_WAY if after_cancel else 0.5
        self.seed, self.generator = seed, torch.Generator(device=env.device)
        self.restart()

    def restart(self) -> None:
        """The coins from the first again (an evaluation binding the policy to its environment calls it)."""
        self.generator.manual_seed(self.seed)

    def forward(
        self, action: torch.Tensor, observation: torch.Tensor, cancelled: torch.Tensor | None = None
    ) -> torch.Tensor:
        """The actions after the coins; ``cancelled`` ``[*, N]``: whether each UAV's move at the last step was
        cancelled (None: none was, as after a reset)."""
        contended = self.held.contenders(observation)  # [*, N, M]
        move = self.move_of_action[action]
        at = contended.gather(-1, move.clamp(min=0).unsqueeze(-1)).squeeze(-1) & (move >= 0)
        if self.after_cancel:
            at = at & cancelled if cancelled is not None else torch.zeros_like(at)
        coin = torch.rand(action.shape, generator=self.generator, device=action.device) < self.give_way
        stay = SENSE + observation[..., 2].round().long()  # sense (4) or relay (5): the action that keeps its task
        return torch.where(at & coin, stay, action)


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

    With altitude levels the moves are also climb and descend (actions 6, 7), and the targets are positions.

    Args:
        neighbours: the model's move table ``[P, M]`` (``UAVSpectrumEnv.neighbours``): the position each move
            reaches (up, down, left, right, and climb, descend with altitude levels), -1 where none.
        width: the grid's ``L1``, to turn positions ``(x, y)`` into cells ``x + L1 y``.
        num_actions: the actions of a UAV (6; 7 with a ``return`` action, 8 with altitude levels).
        numbers: with altitude levels, the position of each cell at each level ``[L, C]``
            (:func:`position_numbers`); None with one level.

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

    def __init__(
        self,
        neighbours: torch.Tensor,
        width: int,
        num_actions: int = NUM_ACTIONS,
        numbers: torch.Tensor | None = None,
    ):
        super().__init__()
        self.width, self.num_actions = width, num_actions
        self.vertical = neighbours.shape[1] > 4  # climb and descend: actions 6, 7, the move table's columns 4, 5
        self.register_buffer("neighbours", neighbours.clone())
        self.register_buffer("task_ids", torch.tensor([SENSING, RELAYING], device=neighbours.device))  # actions 4, 5
        self.position = PositionIndex(_grid(neighbours, width, numbers), numbers)

    def _targets(self, cells: torch.Tensor) -> torch.Tensor:
        """``[*, N, A]`` the position each action leads to from ``cells`` ``[*, N]``: impossible moves lead to the
        extra position P (masked out), where a UAV out of service stays.  "return" keeps the cell for the step, as the
        environment's dynamics do (its flight home is the energy part's).  Read from the UAVs' own rows of
        ``neighbours``: no per-position table, so the cost does not grow with the grid."""
        C, M = self.neighbours.shape
        serving = cells < C
        moves = self.neighbours.index_select(0, cells.where(serving, 0).reshape(-1)).view(*cells.shape, M)
        moves = torch.where((moves < 0) | ~serving.unsqueeze(-1), C, moves)
        stays = cells.unsqueeze(-1).expand(*cells.shape, self.num_actions - M)  # sense, relay (and "return")
        if self.vertical:
            return torch.cat([moves[..., :4], stays, moves[..., 4:]], -1)
        return torch.cat([moves, stays], -1)

    def _moves(self, x: torch.Tensor) -> torch.Tensor:
        """The entries ``[*, A]`` of the moves (0-3, and climb, descend with altitude levels) of per-action ``x``."""
        return torch.cat([x[..., :4], x[..., CLIMB:]], -1) if self.vertical else x[..., :4]

    def forward(
        self,
        action_value: torch.Tensor,
        action_mask: torch.Tensor,
        positions: torch.Tensor,
        tasks: torch.Tensor,
        levels: torch.Tensor | None = None,
    ) -> torch.Tensor:
        C = len(self.neighbours)
        cells = self.position(positions, levels)
        # per-UAV rows, UAV first ([N, *, ...], contiguous): one row per step of the sequential choice
        targets = self._targets(cells).movedim(-2, 0).contiguous()
        values, allowed = action_value.movedim(-2, 0).contiguous(), action_mask.movedim(-2, 0).contiguous()
        switches = (tasks.unsqueeze(-1) != self.task_ids).movedim(-2, 0)  # [N, *, 2]: actions 4, 5 change the task
        # claimed[..., j]: the cell UAV j holds or has claimed.  A target is blocked when another UAV claims it; the
        # cell C off the grid blocks no one (only masked moves and the UAVs out of service, whose one action is to
        # stay there, lead to it).  Found by comparing each target with the N claims (no work per cell), or where
        # the grid has fewer cells than that costs, read from a per-row occupancy table (a UAV's own claim released
        # while it chooses).
        N = len(values)
        claimed = cells.clone()
        others = ~torch.eye(N, dtype=torch.bool, device=cells.device)  # [N, N]: row i leaves UAV i out
        occupied = None
        if C + 2 <= N * N * self.num_actions:
            occupied = torch.zeros(*cells.shape[:-1], C + 2, dtype=torch.bool, device=cells.device)
            occupied.scatter_(-1, cells, True)

        def taken(i: int, target: torch.Tensor) -> torch.Tensor:
            if occupied is not None:
                return occupied.gather(-1, target) & (target < C)
            return ((target.unsqueeze(-1) == claimed.unsqueeze(-2)) & others[i]).any(-1) & (target < C)

        def release(i: int) -> None:
            if occupied is not None:
                occupied.scatter_(-1, claimed[..., i : i + 1], False)

        def claim(i: int, cell: torch.Tensor) -> None:
            claimed[..., i : i + 1] = cell
            if occupied is not None:
                occupied.scatter_(-1, cell, True)

        switched_to = torch.zeros(*cells.shape[:-1], 2, dtype=torch.bool, device=cells.device)  # switched to this step
        actions = []
        for i in range(N):
            release(i)
            blocked = taken(i, targets[i]) | ~allowed[i]
            blocked[..., 4:6] |= switches[i] & switched_to
            action = values[i].masked_fill(blocked, -math.inf).argmax(-1, keepdim=True)
            claim(i, targets[i].gather(-1, action))
            switched_to |= switches[i] & (action == self.task_ids + 4)
            actions.append(action)
        # second pass: a UAV that kept its cell because a later UAV still held the cell it wanted takes that move
        # now if the holder has left it (UAVs following one another move together)
        for i in range(N):
            release(i)
            blocked = taken(i, self._moves(targets[i])) | ~self._moves(allowed[i])
            value, move = self._moves(values[i]).masked_fill(blocked, -math.inf).max(-1, keepdim=True)
            kept = (actions[i] >= 4) & (actions[i] < CLIMB) if self.vertical else actions[i] >= 4
            if self.vertical:  # the moves' entries 4, 5 are climb, descend
                move = torch.where(move >= 4, move + CLIMB - 4, move)
            better = kept & (value > values[i].gather(-1, actions[i]))
            actions[i] = torch.where(better, move, actions[i])
            claim(i, torch.where(better, targets[i].gather(-1, move), claimed[..., i : i + 1]))
        return torch.cat(actions, -1)


class JointActionMask(nn.Module):
    """``[*, A^N]`` valid joint actions at positions ``[*, N, 2]`` (and levels ``[*, N]`` with altitude levels: ``A``
    8, else 6), the environment's rule.

    Args:
        neighbours: the model's move table ``[P, M]`` (``UAVSpectrumEnv.neighbours``).
        width: the grid's ``L1``, to turn positions ``(x, y)`` into cells ``x + L1 y``.
        num_uavs: ``N``.
        numbers: with altitude levels, the position of each cell at each level ``[L, C]``
            (:func:`position_numbers`); None with one level.
    """

    def __init__(self, neighbours: torch.Tensor, width: int, num_uavs: int, numbers: torch.Tensor | None = None):
        super().__init__()
        self.num_uavs = num_uavs
        self.register_buffer("neighbours", neighbours.clone())
        self.position = PositionIndex(_grid(neighbours, width, numbers), numbers)

    def forward(self, positions: torch.Tensor, levels: torch.Tensor | None = None) -> torch.Tensor:
        return joint_action_valid(self.position(positions, levels), self.neighbours, self.num_uavs)


class DecodeJointAction(nn.Module):
    """Per-UAV actions ``[*, N]`` of joint actions ``[*]``, ``j = sum_i a_i A^i``.

    Args:
        num_uavs: ``N``.
        device: the torch device of its decoding table ``[A^N, N]``.
        num_actions: ``A``, the joint action base (``cfg.joint_action_base``: 6, 8 with altitude levels).
    """

    def __init__(self, num_uavs: int, device, num_actions: int = NUM_ACTIONS):
        super().__init__()
        self.register_buffer("table", decode_joint_actions(num_uavs, device, num_actions))

    def forward(self, joint_action: torch.Tensor) -> torch.Tensor:
        return self.table[joint_action]
