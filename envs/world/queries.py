"""What the solvers and evaluations ask of a World about configurations other than its own now: their rates and
utility, the exact optimum of its layouts, the valid joint actions (:class:`SolverQueries`, a part of
:class:`~uavrl.envs.world.World`)."""

from __future__ import annotations

import torch

from ..config import RELAYING, SENSING
from ..errors import InvalidOption, InvalidType
from ..physics.channel import rates
from ..physics.grid import cells_of, decode_joint_actions, joint_action_valid, targets_valid
from ..solvers.optimum import optimum as exact_optimum


class SolverQueries:
    """Questions about any configurations of the World's layouts (a mixin of :class:`~uavrl.envs.world.World`)."""

    def cells_of(self, positions: torch.Tensor) -> torch.Tensor:
        """Position indices of ``[..., 2]`` (x, y) positions (cells ``y * L1 + x``), or with altitude levels of
        ``[..., 3]`` (x, y, level) ones (-1 inside a building)."""
        cells = cells_of(positions, self.cfg.grid[0])
        if self.cfg.num_levels == 1:
            return cells
        return self.dynamics.positions.number[cells + positions[..., 2] * self.cfg.num_cells]

    def utility(self, positions: torch.Tensor, tasks: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(R_PU, R_SE, U)`` of configurations of this env's worlds, deterministic channels.

        ``positions`` ``[B, ..., N, 2]`` (x, y), with altitude levels ``[B, ..., N, 3]`` (x, y, level), and ``tasks``
        ``[B, ..., N]``; results ``[B, ...]`` float64.
        """
        self._require_layout()
        positions, tasks = positions.to(self.device), tasks.to(self.device)
        D = 2 + (self.cfg.num_levels > 1)
        if (
            positions.shape[0] != self.num_worlds
            or positions.shape[-2:] != (self.num_uavs, D)
            or tasks.shape != positions.shape[:-1]
        ):
            raise InvalidOption(
                "positions",
                message=f"positions {tuple(positions.shape)} / tasks {tuple(tasks.shape)} do not fit: expected "
                f"[B={self.num_worlds}, ..., N={self.num_uavs}, {D}] and [B, ..., N]",
            )
        if any(t.dtype.is_floating_point or t.dtype.is_complex or t.dtype == torch.bool for t in (positions, tasks)):
            raise InvalidType(
                "positions", message=f"positions ({positions.dtype}) and tasks ({tasks.dtype}) must hold integers"
            )
        L1, L2 = self.cfg.grid
        x, y = positions[..., 0], positions[..., 1]
        off_grid = (x < 0) | (x >= L1) | (y < 0) | (y >= L2)
        if self.energy is not None:  # a UAV out of service is at the base: it adds nothing
            away = (x == self.cfg.base[0]) & (y == self.cfg.base[1])
            off_grid, tasks = off_grid & ~away, tasks.masked_fill(away, SENSING)
            positions = positions.masked_fill(away.unsqueeze(-1), 0)
        if D == 3:
            off_grid |= (positions[..., 2] < 0) | (positions[..., 2] >= self.cfg.num_levels)
        if off_grid.any():
            where = tuple(positions[off_grid][0].tolist())
            levels = f", level in 0..{self.cfg.num_levels - 1}" if D == 3 else ""
            raise InvalidOption(
                "positions",
                message=f"positions hold {where}, off the {L1}x{L2} grid: x lies in 0..{L1 - 1}, y in "
                f"0..{L2 - 1}{levels}",
            )
        bad_task = (tasks != SENSING) & (tasks != RELAYING)
        if bad_task.any():
            bad = tasks[bad_task][0].item()
            raise InvalidOption("tasks", message=f"tasks hold {bad}: a task is 0 (sensing) or 1 (relaying)")
        cells = self.cells_of(positions)
        if (cells < 0).any():
            inside = tuple(positions[cells < 0][0].tolist())
            raise InvalidOption("positions", message=f"positions hold {inside}, inside a building")
        contrib = self._per_cell(self._cell_contrib, cells)
        if self.energy is not None:
            contrib = contrib.masked_fill(away.unsqueeze(-1), 0.0)
        direct = self.direct.view(self.num_worlds, *([1] * (cells.dim() - 2)), 2)
        r_pu, r_se = rates(contrib, tasks, direct, self.cfg)
        return r_pu, r_se, r_pu + r_se

    def optimum(self, method: str = "auto") -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Exact ``U*`` ``[B]`` and one optimal configuration per world (positions ``[B, N, 2]`` (x, y), with altitude
        levels ``[B, N, 3]`` (x, y, level); tasks ``[B, N]``).

        Over all placements on distinct cells and all task vectors, for the
        deterministic (mean) channels.  See :func:`uavrl.envs.solvers.optimum.optimum` (``method`` as its).
        """
        self._require_layout()
        # a fixed layout has one row of tables: solved once per method, the same answer for every world
        optima = self._shared_tables.optima if self.layouts.fixed is not None else {}
        solved = optima.get(method)
        if solved is None:
            solved = optima[method] = exact_optimum(self._cell_contrib, self._direct, self.cfg, method=method)
        u, cells, tasks = solved
        B = self.num_worlds
        if len(u) != B:
            u, cells, tasks = u.expand(B), cells.expand(B, -1), tasks.expand(B, -1)
        return u.clone(), self.position_coordinates(cells), tasks.clone()

    def position_coordinates(self, cells: torch.Tensor) -> torch.Tensor:
        """``[..., 2]`` (x, y) of position indices ``[...]``, with altitude levels ``[..., 3]`` (x, y, level)."""
        L1, positions = self.cfg.grid[0], self.dynamics.positions
        grid_cell = cells if self.cfg.num_levels == 1 else positions.cell[cells]
        xy = [grid_cell % L1, grid_cell // L1]
        return torch.stack(xy if self.cfg.num_levels == 1 else [*xy, positions.level[cells]], -1)

    def joint_action_mask(self, positions: torch.Tensor | None = None) -> torch.Tensor:
        """``[B, A^N]`` valid joint actions (every move reaches a position, all distinct) at ``positions`` (default:
        now; ``A`` 6, 8 with altitude levels).

        Under an energy model a UAV out of service (at the base) has one valid action, the no-op, and blocks no one.
        """
        if positions is None:
            cells = self._s.cell
        else:
            positions = positions.to(self.device)
            cells = self.cells_of(positions)
            if self.energy is not None:
                away = (positions == torch.tensor(self.cfg.base, device=self.device)).all(-1)
                cells = cells.masked_fill(away, self.energy.away)
        if self.energy is None:
            return joint_action_valid(cells, self.dynamics.neighbours, self.num_uavs)
        N = self.num_uavs
        actions = decode_joint_actions(N, self.device)  # [A, N]
        row = cells.unsqueeze(-2) * self.dynamics.num_actions + actions  # [..., A, N]: each UAV's (cell, action) row
        allowed = self.dynamics.cell_mask.view(-1).index_select(0, row.view(-1)).view_as(row)
        target = self.dynamics.move_to.index_select(0, row.view(-1)).view_as(row)
        # the UAVs away all sit on one cell: give each its own, past the grid's, so they clash with no one
        target = torch.where(target == self.energy.away, self.energy.away + torch.arange(N, device=self.device), target)
        return allowed.all(-1) & targets_valid(target)

    def _require_layout(self):
        if self.cfg.layout == "random" and not bool(self._s.started.all()):
            raise RuntimeError("layout='random' draws each world's layout at reset: call env.reset() first")
