"""The dynamics part: the UAVs' state, and how a reset and a joint action change it (docs/model.md, What a UAV can
do in one step).

The state is one ``[B, N]`` tensor per name of :data:`UAV_STATE`: ``cell``, the UAV's position (its cell ``y L1 + x``
at one level; with altitude levels a (cell, level) position of :mod:`.positions`) and ``task`` (0 sensing,
1 relaying).  :class:`Dynamics` gives

- ``start(keys, counters)``: the first values of ``k`` worlds at a reset, by name, from their random streams;
- ``step(state, action)``: the values after the joint actions ``[B, N]`` (0..5; 6, ``return``, with recharging),
  by name: a move off the grid stays, and clashing moves are cancelled (:meth:`Dynamics.resolve_moves`); under local
  observations also ``cancelled``, whether each UAV's move was (what a UAV knows of itself without a message);
- ``masks(cell)``: ``[B, N, A]`` the actions that keep each UAV on the grid (``A = cfg.num_actions``);
- ``terminated(state)``: ``[B]`` whether a world's episode ends, or ``None`` when none can (the model's episodes
  are truncated after ``max_steps``).

A new per-UAV variable (a battery, say) is one more name in :data:`UAV_STATE`, its first value in ``start``, its
next in ``step`` and, if it can end an episode, its condition in ``terminated``; the
:class:`~uavrl.envs.world.World` keeps, resets and moves every variable named there.

Example:
    >>> import torch
    >>> from types import SimpleNamespace
    >>> from uavrl.envs import make_config
    >>> dynamics = Dynamics(make_config("paper", grid=(3, 2), num_uavs=2))
    >>> now = SimpleNamespace(cell=torch.tensor([[0, 2]]), task=torch.tensor([[0, 0]]))
    >>> after = dynamics.step(now, torch.tensor([[3, 2]]))  # both move right/left into cell 1: both cancelled
    >>> after["cell"].tolist(), dynamics.step(now, torch.tensor([[3, 5]]))["cell"].tolist()
    ([[0, 2]], [[1, 2]])
    >>> dynamics.masks(now.cell)[0, 0].tolist()  # cell (0, 0): up and left leave the grid
    [False, True, False, True, True, True]
"""

from __future__ import annotations

import torch

from ..config import NUM_ACTIONS, RELAYING, SENSING, ModelConfig
from ..limits import KEYED_PLACEMENT_CELLS
from . import streams
from .positions import model_positions

UAV_STATE = ("cell", "task")  # the per-UAV variables, each a [B, N] tensor of the World's state
SENSE, RELAY = 4, 5  # the task actions
NO_OP = SENSE  # the one action of a UAV out of service under an energy model (uavrl.envs.physics.energy)


def _lookup(table: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``table[index]`` of a 1-D table (``index_select`` costs ~2.5x less than ``take`` or indexing on CPU)."""
    return table.index_select(0, index.view(-1)).view(index.shape)


class Dynamics:
    """The UAVs' dynamics of the model ``cfg``, for any number of worlds (the module's docstring)."""

    def __init__(self, cfg: ModelConfig, device="cpu"):
        self.cfg = cfg
        A = cfg.num_actions
        self.num_actions = A
        self.positions = model_positions(cfg, device)
        C = len(self.positions)  # the positions a UAV may take: the cells, at every altitude level
        self.num_positions = C
        cell = torch.arange(C, device=device)
        # [C, M] target position of each move (4 in the plane, climb and descend with levels), -1 where none
        self.neighbours = self.positions.neighbours
        # each action's move: its column of neighbours, or none (sensing, relaying and "return", whose flight home is
        # the energy part's, stay)
        column = [0, 1, 2, 3, None, None] + ([4, 5] if cfg.num_levels > 1 else []) + [None] * (A - NUM_ACTIONS)
        column = column[:A]
        targets = torch.stack([cell if m is None else self.neighbours[:, m] for m in column], -1)  # [C, A], -1: none
        # move_to[A c + a]: the position after action a alone from position c (a move nowhere stays)
        self.move_to = targets.where(targets >= 0, cell[:, None]).flatten()
        # task_after[2 a + task]: the task after action a (4 senses, 5 relays, every other keeps it)
        after = {SENSE: [SENSING] * 2, RELAY: [RELAYING] * 2}
        self.task_after = torch.tensor([t for a in range(A) for t in after.get(a, [0, 1])], device=device)
        self.cell_mask = targets >= 0
        # under an energy model a UAV out of service sits on one more cell, C, off the grid: it stays there, and
        # "sense" is its only action (uavrl.envs.physics.energy)
        self.slots = C + (cfg.energy != "none")
        if self.slots > C:
            self.move_to = torch.cat([self.move_to, self.move_to.new_full((A,), C)])
            away_mask = torch.arange(A, device=device) == NO_OP
            self.cell_mask = torch.cat([self.cell_mask, away_mask[None]])

    def start(self, keys: torch.Tensor, counters: torch.Tensor) -> dict[str, torch.Tensor]:
        """The state of ``k`` worlds at a reset (``keys``, ``counters`` ``[k]``: their streams): distinct random
        cells and tasks per ``init_tasks``; spares (``num_spares``) at the base.

        The cells: on up to :data:`~uavrl.envs.limits.KEYED_PLACEMENT_CELLS` cells the N smallest of C random keys,
        beyond it :func:`~.streams.distinct_cells` (both uniform over the ordered N-tuples of distinct cells)."""
        cfg, N, C = self.cfg, self.cfg.num_uavs, self.num_positions
        if C <= KEYED_PLACEMENT_CELLS:
            keyed = streams.random_bits(keys, counters, streams.POSITIONS, C)
            cell = keyed.topk(N, dim=-1, largest=False).indices
        else:
            cell = streams.distinct_cells(keys, counters, streams.POSITIONS, C, N)
        if cfg.init_tasks == "random":
            task = streams.random_bits(keys, counters, streams.TASKS, N) & 1
        else:
            task = torch.full((len(keys), N), RELAYING if cfg.init_tasks == "relaying" else SENSING, device=keys.device)
        if cfg.num_spares:  # the spares wait at the base, sensing nothing, on the cell off the grid
            cell = torch.cat([cell, cell.new_full((len(keys), cfg.num_spares), C)], -1)
            task = torch.cat([task, task.new_full((len(keys), cfg.num_spares), SENSING)], -1)
        return {"cell": cell, "task": task}

    def step(self, state, action: torch.Tensor) -> dict[str, torch.Tensor]:
        """The state after every world's joint action ``[B, N]`` (0..5, checked by the caller) from ``state`` (its
        ``[B, N]`` variables as attributes)."""
        action = action.long()
        target = _lookup(self.move_to, torch.add(action, state.cell, alpha=self.num_actions))  # [B, N], unchecked
        asked = target != state.cell if self.cfg.local else None  # before resolve_moves rewrites target
        cell = self.resolve_moves(state.cell, target)
        out = {"cell": cell, "task": _lookup(self.task_after, torch.add(state.task, action, alpha=2))}
        if asked is not None:
            out["cancelled"] = asked & (cell == state.cell)
        return out

    def masks(self, cell: torch.Tensor) -> torch.Tensor:
        """``[..., N, A]`` the actions that keep each UAV of ``cell`` ``[..., N]`` on the grid; on the cell off the grid
        only :data:`NO_OP`."""
        return self.cell_mask.index_select(0, cell.view(-1)).view(*cell.shape, self.num_actions)

    def terminated(self, state) -> torch.Tensor | None:
        """``[B]`` whether each world's episode ended with its last step, ``None`` when none can end (no tensor a
        step): without a battery no episode ends before ``max_steps``."""
        return None

    def resolve_moves(self, cells: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """Target cells made valid as docs/model.md decides (off-grid moves already stay).

        Until all targets differ, every UAV whose target another UAV also targets
        (a mover or a stayer) goes back to its cell; for a stayer that changes
        nothing.  Each round cancels at least one mover, and one cancelled in
        round k > 1 was blocked by one cancelled in round k - 1, which began with
        two UAVs (a stayer or a second mover): N - 1 rounds always suffice.
        """
        N = self.cfg.fleet_size
        if N == 1:
            return target
        if N == 2:  # one round, no sync
            return torch.where(target[:, :1] == target[:, 1:], cells, target)
        clash = self.clashes(target)
        target = torch.where(clash, cells, target)
        # later rounds: only worlds where a UAV went back can clash again (usually a few)
        active = clash.any(-1).nonzero().squeeze(-1)
        for _ in range(N - 2):
            if len(active) == 0:
                break
            sub_target, sub_cells = target[active], cells[active]
            clash = self.clashes(sub_target)
            target[active] = torch.where(clash, sub_cells, sub_target)
            active = active[clash.any(-1)]
        return target

    @staticmethod
    def clashes(target: torch.Tensor) -> torch.Tensor:
        """``[W, N]``: does another UAV of the same world target the same cell?  By sorting each world's N targets
        (no work per cell)."""
        ordered, order = target.sort(-1)
        same = ordered[:, 1:] == ordered[:, :-1]
        edge = same.new_zeros(len(target), 1)
        return torch.zeros_like(target, dtype=torch.bool).scatter_(
            -1, order, torch.cat([same, edge], -1) | torch.cat([edge, same], -1)
        )
