"""Grid geometry and joint actions: the moves of docs/model.md, with no TorchRL import.

Cells are numbered ``c = y * L1 + x``; a UAV's move goes to a neighbouring cell
(``-1`` when it would leave the grid); a joint action ``j = sum_i a_i 6^i``
is valid when every UAV stays on the grid and all target cells differ.  The
environment, the exact solver, the bounds, the oracle and the agents all use
these functions.

Example:
    >>> neighbours = grid_neighbours((3, 2))
    >>> neighbours[0].tolist()  # cell (0, 0): up leaves the grid, down is cell 3, left leaves, right is cell 1
    [-1, 3, -1, 1]
    >>> joint_action_valid(torch.tensor([0, 1]), neighbours, 2).sum().item()  # of 36 joint actions
    16
"""

from __future__ import annotations

import torch

from ..config import NUM_ACTIONS

# (dx, dy) of the four moves: up, down, left, right
MOVES = ((0, -1), (0, 1), (-1, 0), (1, 0))
MAX_JOINT_ACTIONS = 6**7


def on_grid(positions: torch.Tensor, grid: tuple[int, int]) -> torch.Tensor:
    """``[...]`` whether each ``[..., 2]`` (x, y) position lies on the grid: under an energy model a UAV out of
    service is shown at its base, off the grid."""
    x, y = positions[..., 0], positions[..., 1]
    return (x >= 0) & (x < grid[0]) & (y >= 0) & (y < grid[1])


def cells_or_away(positions: torch.Tensor, grid: tuple[int, int]) -> torch.Tensor:
    """The cells ``y L1 + x`` of ``[..., 2]`` positions, and ``L1 L2`` (one past the grid's) for a UAV off the grid
    (out of service)."""
    return torch.where(on_grid(positions, grid), cells_of(positions, grid[0]), grid[0] * grid[1])


def grid_neighbours(grid: tuple[int, int], device=None) -> torch.Tensor:
    """``[C, 4]`` target cell of each move (up, down, left, right) from every cell, ``-1`` off the grid."""
    L1, L2 = grid
    c = torch.arange(L1 * L2, device=device)
    x, y = c % L1, c // L1
    targets = []
    for dx, dy in MOVES:
        nx, ny = x + dx, y + dy
        inside = (nx >= 0) & (nx < L1) & (ny >= 0) & (ny < L2)
        targets.append(torch.where(inside, ny * L1 + nx, -1))
    return torch.stack(targets, -1)


def cells_of(positions: torch.Tensor, width: int) -> torch.Tensor:
    """Cell indices ``y * L1 + x`` of ``[..., 2]`` (x, y) positions."""
    return positions[..., 1] * width + positions[..., 0]


def positions_of(cells: torch.Tensor, width: int) -> torch.Tensor:
    """``[..., 2]`` (x, y) positions of cell indices."""
    return torch.stack([cells % width, cells // width], -1)


def manhattan(cells: torch.Tensor, others: torch.Tensor, width: int) -> torch.Tensor:
    """Manhattan distances between cell indices, broadcast: the fewest moves between them on an empty grid.

    Computed from the cells given, never as a ``[C, C]`` table (8 TB on a 1000x1000 grid)."""
    delta = (positions_of(cells, width) - positions_of(others, width)).abs()
    return delta[..., 0] + delta[..., 1]


def decode_joint_actions(num_uavs: int, device=None, num_actions: int = NUM_ACTIONS) -> torch.Tensor:
    """``[A^N, N]`` per-UAV actions of every joint action ``j = sum_i a_i A^i`` of ``num_uavs`` UAVs of
    ``num_actions`` actions ``A`` each (6; 8 with altitude levels), on ``device``.

    A team's joint action indexes the rows: UAV ``i``'s action is digit ``i`` of ``j`` in base ``A``. More than
    ``MAX_JOINT_ACTIONS`` joint actions (6^7) is refused.

    >>> decode_joint_actions(2)[[0, 1, 6, 35]].tolist()
    [[0, 0], [1, 0], [0, 1], [5, 5]]
    """
    if num_actions**num_uavs > MAX_JOINT_ACTIONS:
        raise ValueError(
            f"num_uavs={num_uavs} has {num_actions}^{num_uavs} joint actions: joint-action tables allow at most "
            f"{MAX_JOINT_ACTIONS:,} (N <= 7 with 6 actions, N <= 6 with 8)"
        )
    j = torch.arange(num_actions**num_uavs, device=device)
    return torch.stack([(j // num_actions**i) % num_actions for i in range(num_uavs)], -1)


def joint_targets(cells: torch.Tensor, neighbours: torch.Tensor, num_uavs: int) -> torch.Tensor:
    """``[..., A^N, N]`` target position of every UAV under every joint action from ``[..., N]`` positions (-1: off
    the grid, the levels, or into a building).

    ``cells`` are position indices (cells ``y * L1 + x`` without altitude levels), ``neighbours`` the ``[P, M]`` table
    of the position each move reaches (up, down, left, right, and with levels climb, descend; -1 where none:
    :func:`grid_neighbours`, :func:`~.positions.model_positions`), ``num_uavs`` the team's size N; a UAV has
    ``A = M + 2`` actions (the moves, then sense and relay at 4 and 5, which keep it where it is).
    """
    moves = neighbours.shape[1]
    actions = decode_joint_actions(num_uavs, cells.device, moves + 2)  # [A, N]
    column = torch.where(actions >= NUM_ACTIONS, actions - 2, actions.clamp(max=3))  # climb 6, descend 7: columns 4, 5
    moving = (actions < 4) | (actions >= NUM_ACTIONS)
    options = neighbours[cells].unsqueeze(-3).expand(*cells.shape[:-1], actions.shape[0], num_uavs, moves)
    moved = torch.gather(options, -1, column.expand_as(options[..., 0]).unsqueeze(-1)).squeeze(-1)
    return torch.where(moving, moved, cells.unsqueeze(-2))


def joint_next_tasks(tasks: torch.Tensor, num_uavs: int, num_actions: int = NUM_ACTIONS) -> torch.Tensor:
    """``[..., A^N, N]`` task of every UAV after every joint action of ``num_actions`` actions each from ``[..., N]``
    tasks (4 senses, 5 relays)."""
    actions = decode_joint_actions(num_uavs, tasks.device, num_actions)  # [A, N]
    return torch.where(actions == 4, 0, torch.where(actions == 5, 1, tasks.unsqueeze(-2)))


def joint_action_valid(cells: torch.Tensor, neighbours: torch.Tensor, num_uavs: int) -> torch.Tensor:
    """``[..., A^N]`` validity of every joint action at position configurations ``[..., N]``: every move reaches a
    position, targets distinct.

    ``cells``, ``neighbours`` and ``num_uavs`` as in :func:`joint_targets`. Two UAVs side by side on a 2x2 grid:

    >>> valid = joint_action_valid(torch.tensor([0, 1]), grid_neighbours((2, 2)), 2)
    >>> int(valid.sum()), bool(valid[decode_joint_actions(2).tolist().index([4, 5])])  # UAV 0 senses, UAV 1 relays
    (12, True)
    """
    return targets_valid(joint_targets(cells, neighbours, num_uavs))


def targets_valid(target: torch.Tensor) -> torch.Tensor:
    """``[...]`` whether target cells ``[..., N]`` are all on the grid and pairwise distinct."""
    ordered = target.sort(-1).values
    return (target >= 0).all(-1) & (ordered[..., 1:] != ordered[..., :-1]).all(-1)
