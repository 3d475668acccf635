"""The World's tables: the grid's (every cell's and code's position), each layout's (per-cell contributions,
per-code observations and rate terms, direct links, the fading part's rows, ``U*``), two UAVs' whole-pair tables, and
the cache that lets the Worlds of one model and device share the grid's and a fixed layout's
(:class:`LayoutTables`, a part of :class:`~uavrl.envs.world.World`).

A UAV's cell and task index the per-code tables as one code ``2 cell + task``, so rates and observations are lookups
in small tables built once per layout.
"""

from __future__ import annotations

import dataclasses
import weakref

import torch

from ..config import RELAYING, ModelConfig
from ..physics.channel import direct_terms, link_gains, rates_from_sums, relay_contributions
from ..physics.dynamics import Dynamics
from ..physics.rewards import U_STAR_REWARDS
from ..solvers.optimum import optimum as exact_optimum


class SharedTables(dict):
    """What every World of one model and device shares, read-only: the grid's tables and a fixed layout's by attribute
    name, ``dynamics`` (the dynamics part, whose tables are per cell) and ``optima`` (a fixed layout's exact optimum by
    method, once solved)."""

    def __init__(self):
        super().__init__()
        self.dynamics: Dynamics | None = None
        self.optima: dict[str, tuple] = {}


# what World._build_geometry computes for the grid
GRID_TABLES = (
    "_cell_xyz",
    "_code_level",
    "_slot_level",
    "_state_base",
    "_grid_scale",
    "_node_scale",
    "_cell_xy",
    "_code_cell",
    "_code_task",
    "_code_xyt",
    "_slot_xyz",
    "_heard_slot",
    "_send_key",
    "_hear_key",
)

# what World._set_layout computes for a layout (and the two-UAV pair tables from them)
LAYOUT_TABLES = (
    "_cell_contrib",
    "_code_obs",
    "_code_vertical",
    "_code_rate",
    "_node_obs",
    "_direct",
    "_fading_table",
    "_u_star",
    "_pair_obs",
    "_pair_state",
    "_pair_rates",
)
# the shared tables by (model, device), kept while a World holds them: the environments of one command (training,
# evaluation) build the per-cell tables of a grid and of a fixed layout once
_SHARED_TABLES: weakref.WeakValueDictionary = weakref.WeakValueDictionary()


def shared_tables(cfg: ModelConfig, device: torch.device) -> SharedTables:
    """The tables the Worlds of the model ``cfg`` on ``device`` share: another World's, or a new set holding the
    dynamics part (its tables are per cell), kept here while a World holds it."""
    key = (dataclasses.replace(cfg, max_steps=1), str(device))  # no table depends on the episode's length
    shared = _SHARED_TABLES.get(key)
    if shared is None:
        shared = _SHARED_TABLES[key] = SharedTables()
        shared.dynamics = Dynamics(cfg, device)
    return shared


class LayoutTables:
    """The World's tables (a mixin of :class:`~uavrl.envs.world.World`): built, shared and read by code or cell."""

    def _share(self, names: tuple[str, ...], build) -> None:
        """Set the attributes ``names`` from another World of the same model and device, or ``build()`` them here
        and share them."""
        shared = self._shared_tables
        if names[0] not in shared:
            build()
            shared.update({name: getattr(self, name) for name in names})
        for name in names:
            setattr(self, name, shared[name])

    def _build_geometry(self):
        """The static tables of the grid the observation reads: every cell's and every code's position."""
        cfg, dev, f64 = self.cfg, self.device, torch.float64
        L1, L2 = cfg.grid
        positions = self.dynamics.positions  # a UAV's "cell" is one of these: a cell at a level
        C = len(positions)
        x, y = positions.cell % L1, positions.cell // L1
        self._cell_xyz = positions.xyz
        # a UAV's point in cells by its code's cell, a UAV out of service (cell C) at the origin: it hears no one
        self._slot_xyz = torch.cat([positions.xyz, positions.xyz.new_zeros(self._slots - C, 3)])
        # digit base of the tabular state index s = sum_i d_i base^i, None when it overflows int64
        tabular = cfg.has_state_index and self.energy is None  # the tabular state has no battery
        self._state_base = (2 * C if cfg.state_includes_tasks else C) if tabular else None
        self._grid_scale = torch.tensor([max(L1 - 1, 1), max(L2 - 1, 1)], dtype=f64, device=dev)
        self._node_scale = torch.tensor([L1, L2, cfg.height], dtype=f64, device=dev)
        self._cell_xy = torch.stack([x, y], -1)  # [C, 2]
        if self.energy is not None:  # a UAV out of service is shown at the base
            self._cell_xy = torch.cat([self._cell_xy, torch.tensor([cfg.base], device=dev)])
        # the per-code tables are indexed by a UAV's code 2 cell + task
        code = torch.arange(2 * self._slots, device=dev)
        self._code_cell, self._code_task = code >> 1, code & 1
        self._code_xyt = torch.cat(
            [self._cell_xy[self._code_cell] / self._grid_scale, self._code_task[:, None]], -1
        ).float()  # [2C, 3] as observed
        self._heard_slot = self._send_key = self._hear_key = None  # with local observations: the others' slots
        if cfg.local:
            self._build_heard_slots(positions)
        # with altitude levels, each slot's level (0 off the grid, at the base) and each code's as observed, 0 to 1
        self._slot_level = self._code_level = None
        if cfg.num_levels > 1:
            self._slot_level = torch.cat([positions.level, positions.level.new_zeros(self._slots - C)])
            self._code_level = (self._slot_level[self._code_cell] / (cfg.num_levels - 1)).float()

    def _build_heard_slots(self, positions):
        """What a UAV hears of another (:mod:`uavrl.envs.physics.sensing`), by their displacement: ``_heard_slot``
        ``[R, 4]`` float32 holds ``(dx / (L1 - 1), dy / (L2 - 1), task, 1)`` for every displacement in cells, pair of
        levels (the hearer's, the sender's) and sender's task within ``comm_radius`` (their points in float64), zeros
        otherwise; the UAV at position ``p`` hears the one of code ``c`` in row ``_send_key[c] - _hear_key[p]``.  A
        UAV out of service (position C) hears and is heard in rows of zeros.  Its size follows the grid and the
        levels, not the positions or the team: ``2 (2 L1 - 1) (2 L2 - 1) L^2`` rows."""
        cfg, dev, f64 = self.cfg, self.device, torch.float64
        (L1, L2), L, C = cfg.grid, cfg.num_levels, self.num_positions
        X, Y = 2 * L1 - 1, 2 * L2 - 1
        # every row: (the hearer's level, the sender's level, dy, dx, the sender's task), row-major
        hear, send, dy, dx, task = torch.meshgrid(
            *(torch.arange(n, device=dev) for n in (L, L, Y, X, 2)), indexing="ij"
        )
        heights = torch.tensor(cfg.level_heights, dtype=f64, device=dev)
        apart = torch.stack([(dx - (L1 - 1)).to(f64), (dy - (L2 - 1)).to(f64), heights[send] - heights[hear]], -1)
        heard = apart.square().sum(-1) <= cfg.comm_radius_cells**2
        slot = torch.cat([apart[..., :2] / self._grid_scale, task.unsqueeze(-1), torch.ones_like(apart[..., :1])], -1)
        slot = slot.where(heard.unsqueeze(-1), 0.0).float().view(-1, 4)
        # the row of (p, c): send(c) - hear(p), a displacement in mixed radix (X, Y, L L) then the task
        x, y, level = positions.cell % L1, positions.cell // L1, positions.level
        send_key = 2 * (x + X * (y + Y * level))
        hear_key = 2 * (x - (L1 - 1) + X * (y - (L2 - 1) - Y * L * level))
        if self._slots > C:  # out of service: the hearer's rows after the table, the sender's after those
            span = int(send_key.max() - send_key.min())
            hear_key = torch.cat([hear_key, (send_key.min() - len(slot)).view(1)])
            send_key = torch.cat([send_key, (hear_key[:C].max() + len(slot) + span + 1).view(1)])
            slot = torch.cat([slot, slot.new_zeros(int(send_key.max() - hear_key.min()) + 1 - len(slot), 4)])
        self._heard_slot, self._hear_key = slot, hear_key
        self._send_key = torch.add(self._code_task, send_key[self._code_cell])  # by code: its cell's key, its task

    def _set_layout(self, worlds: torch.Tensor):
        """Recompute the per-cell and per-code tables of ``worlds`` (indices into the tables) from ``self._nodes``."""
        cfg, C, k = self.cfg, self.num_positions, len(worlds)
        nodes = self._nodes[worlds]
        gains = link_gains(self._cell_xyz, nodes, cfg)  # [k, C, 4]: the channel model's mean gains
        contrib = relay_contributions(gains, cfg)  # the rate model's per-cell terms
        code_obs, node_obs, code_vertical = self._observation_tables(contrib, nodes)
        cc = self._code_cell
        relay = ((self._code_task == RELAYING) & (cc < C))[None, :]
        on_grid = torch.cat([contrib, contrib.new_zeros(k, 1, 2)], 1) if self._slots > C else contrib
        # per code: what the UAV adds to the sum inside the PU log, the SE log, and to the relaying count
        at_code, zero = on_grid.index_select(1, cc), contrib.new_zeros(())
        code_rate = torch.stack(
            [
                torch.where(relay, at_code[..., 0], zero),
                torch.where(relay, zero, at_code[..., 1]),
                relay.to(contrib.dtype).expand(k, -1),
            ],
            -1,
        )
        tables = {
            "_cell_contrib": contrib,
            "_code_obs": code_obs,
            "_code_rate": code_rate,
            "_node_obs": node_obs,
            "_direct": direct_terms(nodes, cfg),
        }
        if code_vertical is not None:
            tables["_code_vertical"] = code_vertical
        fading_table = self.fading.table(self._cell_xyz, nodes, gains)
        if fading_table is not None:
            if self._slots > C:  # zero gains at the cell of a UAV out of service: it adds nothing
                fading_table = torch.cat([fading_table, fading_table.new_zeros(k, 1, *fading_table.shape[2:])], 1)
            tables["_fading_table"] = fading_table
        if cfg.reward in U_STAR_REWARDS:
            tables["_u_star"] = exact_optimum(contrib, tables["_direct"], cfg)[0]
        for name, rows in tables.items():
            if k == len(self._nodes):  # every world: a new table (no scatter)
                setattr(self, name, rows)
                continue
            if getattr(self, name) is None:  # some worlds' first layouts: the others' rows wait for their reset
                setattr(self, name, rows.new_zeros(len(self._nodes), *rows.shape[1:]))
            getattr(self, name)[worlds] = rows
        if self._pairs:
            self._set_pair_tables()

    def _observation_tables(self, contrib: torch.Tensor, nodes: torch.Tensor):
        """``(code_obs [k, 2C, 13], node_obs [k, 12], code_vertical [k, 2C, 5] or None)`` of ``k`` layouts: what a UAV
        at each code observes of its layout (with local observations then the nodes it hears: ``[k, 2C, 29]``), the
        nodes as the state shows them, and with altitude levels its level and the contributions a climb and a descent
        reach, from the per-position contributions ``[k, C, 2]`` and the nodes."""
        C, k, K = self.num_positions, len(contrib), 2 * self._slots
        # observation of a UAV in cell c: its (x, y, task), then the contributions (scaled by the best cell's)
        # at c and at the cells its moves reach, -1 where a move leaves the grid (the levels, or enters a building)
        scaled = torch.cat([contrib / contrib.amax(1, keepdim=True), contrib.new_full((k, 1, 2), -1.0)], 1)
        neighbours = self.dynamics.neighbours
        around = torch.cat([torch.arange(C, device=self.device)[:, None], neighbours.where(neighbours >= 0, C)], -1)
        if self._slots > C:  # a UAV out of service (cell C) sees -1 everywhere, adds nothing and relays for no one
            around = torch.cat([around, around.new_full((1, around.shape[1]), C)])
        seen = scaled.index_select(1, around[self._code_cell].flatten()).view(k, K, -1).float()
        code_obs = torch.cat([self._code_xyt.expand(k, -1, -1), seen[..., :10]], -1)
        if self.cfg.local:  # then the nodes as a UAV at the code's position hears them
            heard = self._node_slots(self._cell_xyz.unsqueeze(0), nodes.unsqueeze(1))  # [k, C, 16]
            if self._slots > C:  # a UAV out of service hears no node
                heard = torch.cat([heard, heard.new_zeros(k, 1, heard.shape[-1])], 1)
            code_obs = torch.cat([code_obs, heard.index_select(1, self._code_cell)], -1)
        vertical = None
        if self.cfg.num_levels > 1:  # the level, then the contributions at the positions a climb and a descent reach
            vertical = torch.cat([self._code_level[None, :, None].expand(k, -1, -1), seen[..., 10:]], -1)
        return code_obs, (nodes / self._node_scale).flatten(1).float(), vertical

    def _per_cell(self, table: torch.Tensor, cells: torch.Tensor, worlds: torch.Tensor | None = None) -> torch.Tensor:
        """Rows of a per-cell table ``[Bt, C, ...]`` at ``cells`` ``[W, ...]`` of all worlds (or of ``worlds``)."""
        if table.shape[0] == 1:
            return table[0][cells]
        worlds = self._world.squeeze(-1) if worlds is None else worlds
        return table[worlds.view(-1, *([1] * (cells.dim() - 1))), cells]

    def _code_rows(self, table: torch.Tensor, code: torch.Tensor, worlds: torch.Tensor | None = None) -> torch.Tensor:
        """Rows ``[W, N, F]`` of a per-code table ``[Bt, 2C, F]`` at the codes ``[W, N]`` of all worlds (or of
        ``worlds``; a table of ``W`` rows other than the World's: row ``w`` for configuration ``w``)."""
        if len(table) > 1:
            if worlds is not None:
                code = code + worlds.unsqueeze(-1) * (2 * self._slots)
            elif self._code_offset is not None and len(code) == len(self._code_offset):
                code = code + self._code_offset
            else:
                code = code + torch.arange(len(code), device=code.device).unsqueeze(-1) * (2 * self._slots)
        return table.view(-1, table.shape[-1]).index_select(0, code.view(-1)).view(*code.shape, table.shape[-1])

    def _sum_rates(self, code: torch.Tensor, worlds: torch.Tensor | None = None) -> torch.Tensor:
        """``[W, 2]`` deterministic (R_PU, R_SE) of ``W`` configurations (of ``worlds``), from the per-code rate
        terms."""
        rows = self._code_rows(self._code_rate, code, worlds)  # [W, N, 3]: terms of sum PU, sum SE, relaying count
        terms = rows[:, 0]
        for i in range(1, code.shape[1]):  # N - 1 adds: a reduction over a tiny dim costs ~10x more
            terms = terms + rows[:, i]
        sums = terms[:, :2] + self._direct_of(worlds) if self.cfg.direct_links else terms[:, :2]
        return rates_from_sums(sums, terms[:, 2], code.shape[1], self.cfg)

    def _set_pair_tables(self):
        """Two UAVs and a fixed layout: cache the observation, state and rates of every pair of codes.

        Row ``a * 2C + b`` holds what :meth:`_assemble` and :meth:`_sum_rates` give for
        UAV 0 at code ``a`` and UAV 1 at code ``b`` (UAV 1's observation is row
        ``b * 2C + a``), so a step needs one gather per output instead of ~15 ops.
        """
        K = 2 * self.num_positions
        code = torch.arange(K, device=self.device)
        pairs = torch.stack([code.repeat_interleave(K), code.repeat(K)], -1)  # [K^2, 2]
        observation, state = self._assemble(pairs)
        self._pair_obs, self._pair_state, self._pair_rates = (
            observation[:, 0].contiguous(),
            state,
            self._sum_rates(pairs),
        )

    def _direct_of(self, worlds: torch.Tensor | None) -> torch.Tensor:
        """Direct-link SNRs ``[Bt or W, 2]`` broadcastable to all worlds (or to ``worlds``)."""
        return self._direct if worlds is None or len(self._direct) == 1 else self._direct[worlds]

    @property
    def cell_contributions(self) -> torch.Tensor:
        """``[B, C, 2]`` per-cell relay (PU) and sensing (SE) contributions, deterministic channels."""
        return self._cell_contrib.clone().expand(self.num_worlds, -1, -1)

    @property
    def direct(self) -> torch.Tensor:
        """``[B, 2]`` direct-link SNRs (PT->PR, S->E)."""
        return self._direct.clone().expand(self.num_worlds, -1)

    @property
    def nodes(self) -> torch.Tensor:
        """``[B, 4, 3]`` float64 (x, y, z) of PT, PR, S, E in cell units: what every layout table is computed from."""
        return self._nodes.clone().expand(self.num_worlds, -1, -1)

    @property
    def neighbours(self) -> torch.Tensor:
        """``[C, 4]`` target cell of each move, -1 off the grid."""
        return self.dynamics.neighbours
