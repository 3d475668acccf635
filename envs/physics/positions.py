"""Where a UAV can be: a model's positions, each a cell of the grid at one altitude level, and the moves between them
(docs/model.md, Altitude as a decision).

Without ``altitudes_m`` there is one level and a position is a cell (``y L1 + x``).  With levels, positions are
numbered level by level (the lowest first), cells in order within a level, leaving out those inside a building (in a
city); a UAV moves in the plane (up, down, left, right) within its level, or climbs or descends one level.  The
dynamics, the World's tables, the exact solvers and the agents all read one :class:`Positions` per model.

Example:
    >>> from uavrl.envs import make_config
    >>> positions = model_positions(make_config("a2g_urban", grid=(2, 2), num_uavs=2, altitudes_m=[50, 100]))
    >>> positions.cell.tolist(), positions.level.tolist()
    ([0, 1, 2, 3, 0, 1, 2, 3], [0, 0, 0, 0, 1, 1, 1, 1])
    >>> positions.neighbours[0].tolist()  # up, down, left, right, climb, descend from cell (0, 0) at 50 m
    [-1, 2, -1, 1, 4, -1]
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from .buildings import city_part
from .grid import grid_neighbours


@dataclass(frozen=True)
class Positions:
    """A model's ``P`` positions.

    Args:
        cell: ``[P]`` each position's cell ``y L1 + x``.
        level: ``[P]`` its level (0 the lowest).
        xyz: ``[P, 3]`` float64 its point in cells: the cell's centre at the level's height.
        neighbours: ``[P, M]`` the position each move reaches (up, down, left, right, then climb and descend with
            levels), ``-1`` where it would leave the grid or the levels or enter a building.
        number: ``[C L]`` the position of cell ``c`` at level ``l`` at ``l C + c``, ``-1`` inside a building.
    """

    cell: torch.Tensor
    level: torch.Tensor
    xyz: torch.Tensor
    neighbours: torch.Tensor
    number: torch.Tensor

    def __len__(self) -> int:
        return len(self.cell)


def model_positions(cfg, device=None) -> Positions:
    """The positions of the model ``cfg`` (its grid, ``altitudes_m`` and city) on ``device``."""
    L1, L2 = cfg.grid
    C, L = L1 * L2, cfg.num_levels
    cell = torch.arange(C, device=device).repeat(L)
    level = torch.arange(L, device=device).repeat_interleave(C)
    heights = torch.tensor(cfg.level_heights, dtype=torch.float64, device=device)
    xyz = torch.stack([(cell % L1).double(), (cell // L1).double(), heights[level]], -1)
    planar = grid_neighbours(cfg.grid, device)[cell]  # [C L, 4]
    targets = [torch.where(planar >= 0, planar + (level * C)[:, None], -1)]
    if L > 1:
        everywhere = torch.arange(C * L, device=device)
        targets.append(torch.stack([everywhere + C, everywhere - C], -1).where(
            torch.stack([level < L - 1, level > 0], -1), -1
        ))  # fmt: skip
    targets = torch.cat(targets, -1)
    city = city_part(cfg)
    if L == 1 or city is None:  # every position is free (a city at one level refuses a cell inside a building)
        return Positions(cell, level, xyz, targets, torch.arange(C * L, device=device))
    free = ~city.inside(xyz)
    number = torch.full((C * L,), -1, dtype=torch.long, device=device)
    number[free] = torch.arange(int(free.sum()), device=device)
    neighbours = torch.where(targets >= 0, number[targets.clamp(min=0)], -1)
    return Positions(cell[free], level[free], xyz[free], neighbours[free], number)
