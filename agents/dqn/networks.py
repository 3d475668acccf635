"""The DQN's networks: the Q network over the joint observation and the modules that turn its values into valid actions.

- :class:`TeamQNet`: action values, per UAV (``factored``) or per joint action (``joint``);
- :class:`ValidGreedy`: the factored head's greedy valid joint action, UAV by UAV;
- :class:`JointActionMask`, :class:`DecodeJointAction`: the joint head's mask and its per-UAV actions.
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
from uavrl.envs.config import RELAYING, SENSING
from uavrl.envs.physics.grid import cells_or_away

Q_INPUTS = (("agents", "observation"), "positions", "state")  # what TeamQNet reads (the nodes are in the state)


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
        self._torso_layers = sorted(self.torso.params.keys(), key=int)  # "0", "2", ...: the Linear layers

    def forward(
        self, observation: torch.Tensor, positions: torch.Tensor, state: torch.Tensor, params: TensorDictBase = None
    ) -> torch.Tensor:
        """The values: ``[*, N, A]`` per UAV (factored head), or ``[*, 6^N]`` per joint action (joint head).

        Args:
            observation: the UAVs' observations ``[*, N, F]``.
            positions: their cells ``[*, N, 2]`` (the greedy rule's neighbours and the masked moves read them).
            state: the worlds' state ``[*, S]``; its last 12 entries, the node positions, join each observation.
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
        cells = cells_or_away(positions, (self.width, C // self.width))
        # [*, N, 4]: which of its neighbouring cells another UAV holds (none, for a UAV out of service)
        held = (self.neighbours[cells.clamp(max=C - 1)].unsqueeze(-1) == cells[..., None, None, :]).any(-1)
        held &= (cells < C).unsqueeze(-1)
        own = torch.cat([observation, self.ids.expand(*observation.shape[:-1], -1), held.to(observation.dtype)], -1)
        first, last = head["0"], head["2"]  # the head's layers (Linear, ReLU, Linear)
        split = embedding.shape[-1]
        hidden = nn.functional.linear(embedding, first["weight"][:, :split], first["bias"])
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

    Args:
        neighbours: the grid's neighbour table ``[C, 4]`` (``UAVSpectrumEnv.neighbours``): the cell each move
            reaches, -1 off the grid.
        width: the grid's ``L1``, to turn positions ``(x, y)`` into cells ``x + L1 y``.
        num_actions: the actions of a UAV (6; 7 with a ``return`` action).

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

    def _targets(self, cells: torch.Tensor) -> torch.Tensor:
        """``[*, N, A]`` the cell each action leads to from ``cells`` ``[*, N]``: off-grid moves lead to the extra cell
        C (masked out), where a UAV out of service stays.  "return" keeps the cell for the step, as the environment's
        dynamics do (its flight home is the energy part's).  Read from the UAVs' own rows of ``neighbours``: no
        per-cell table, so the cost does not grow with the grid."""
        C = len(self.neighbours)
        serving = cells < C
        moves = self.neighbours.index_select(0, cells.where(serving, 0).reshape(-1)).view(*cells.shape, 4)
        moves = torch.where((moves < 0) | ~serving.unsqueeze(-1), C, moves)
        return torch.cat([moves, cells.unsqueeze(-1).expand(*cells.shape, self.num_actions - 4)], -1)

    def forward(
        self, action_value: torch.Tensor, action_mask: torch.Tensor, positions: torch.Tensor, tasks: torch.Tensor
    ) -> torch.Tensor:
        C = len(self.neighbours)
        cells = cells_or_away(positions, (self.width, C // self.width))
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
            blocked = taken(i, targets[i][..., :4]) | ~allowed[i][..., :4]
            value, move = values[i][..., :4].masked_fill(blocked, -math.inf).max(-1, keepdim=True)
            better = (actions[i] >= 4) & (value > values[i].gather(-1, actions[i]))
            actions[i] = torch.where(better, move, actions[i])
            claim(i, torch.where(better, targets[i].gather(-1, move), claimed[..., i : i + 1]))
        return torch.cat(actions, -1)


class JointActionMask(nn.Module):
    """``[*, 6^N]`` valid joint actions at positions ``[*, N, 2]`` (the environment's rule).

    Args:
        neighbours: the grid's neighbour table ``[C, 4]`` (``UAVSpectrumEnv.neighbours``).
        width: the grid's ``L1``, to turn positions ``(x, y)`` into cells ``x + L1 y``.
        num_uavs: ``N``.
    """

    def __init__(self, neighbours: torch.Tensor, width: int, num_uavs: int):
        super().__init__()
        self.width, self.num_uavs = width, num_uavs
        self.register_buffer("neighbours", neighbours.clone())

    def forward(self, positions: torch.Tensor) -> torch.Tensor:
        return joint_action_valid(_cells(positions, self.width), self.neighbours, self.num_uavs)


class DecodeJointAction(nn.Module):
    """Per-UAV actions ``[*, N]`` of joint actions ``[*]``, ``j = sum_i a_i 6^i``.

    Args:
        num_uavs: ``N``.
        device: the torch device of its decoding table ``[6^N, N]``.
    """

    def __init__(self, num_uavs: int, device):
        super().__init__()
        self.register_buffer("table", decode_joint_actions(num_uavs, device))

    def forward(self, joint_action: torch.Tensor) -> torch.Tensor:
        return self.table[joint_action]
