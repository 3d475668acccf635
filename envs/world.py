"""The physics of the UAV spectrum-sharing model for ``B`` worlds at once, with no TorchRL.

:class:`World` holds the layouts, the per-cell and per-code tables, the UAVs'
state and the per-world random streams; :meth:`World.reset` and
:meth:`World.step` move the worlds and return plain tensors (observations,
masks, rates, rewards).  :class:`~uavrl.envs.env.UAVSpectrumEnv` is the thin
TorchRL ``EnvBase`` on top (specs, keys, seeding); the tabular learner and the
tabular evaluation use a ``World`` directly, so they never import TorchRL.

A step is a fixed handful of tensor operations whatever ``B`` is, on CPU or
CUDA.  A UAV's cell and task are one code ``2 c + task``, so dynamics, rates
and observations are lookups in small per-code tables built once per layout
(see BENCHMARKS.md for timings).

Example:
    >>> from uavrl.envs import make_config
    >>> world = World(make_config("paper", grid=(6, 6), num_uavs=2, max_steps=10), batch_size=4)
    >>> first = world.reset()
    >>> out, reward, truncated = world.step(torch.full((4, 2), 5))
    >>> out["utility"].shape, reward.shape, first["observation"].shape
    (torch.Size([4]), torch.Size([4]), torch.Size([4, 2, 16]))
"""

from __future__ import annotations

import math
import numbers

import torch

from . import streams
from .channel import (
    direct_terms,
    fixed_layout,
    link_gains,
    link_state_gains,
    rates,
    rates_from_sums,
    relay_contributions,
)
from .config import NUM_ACTIONS, RELAYING, SENSING, InvalidOption, ModelConfig
from .grid import cells_of, grid_neighbours, joint_action_valid
from .limits import DEFAULT_MEMORY_BUDGET, gib, world_bytes
from .optimum import optimum as exact_optimum
from .rewards import best_so_far_reward, delta_reward, log_gap_reward

_POSITIONS, _TASKS, _FADING, _FADING_DIRECT, _LAYOUT = 1, 2, 3, 4, 16
SEED_LIMIT = 2**63  # world seeds are int64
NODE_FEATURES = 12  # PT, PR, S, E as (x / L1, y / L2, z / h): the last entries of the state
# outputs that describe a step rather than the configuration an agent acts from (World(diagnostics=False) skips them)
DIAGNOSTICS = ("r_pu", "r_se", "utility", "moves", "task_switches", "state_index")


def observation_with_nodes(observation: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
    """``[*, N, F + 12]``: each UAV's observation followed by its world's node positions (the last 12 of ``state``).

    The observation carried the nodes for every UAV and step until issue 17; a
    network that wants them builds this input (bit for bit the old observation).
    """
    nodes = state[..., None, -NODE_FEATURES:]
    return torch.cat([observation, nodes.expand(*observation.shape[:-1], NODE_FEATURES)], -1)


def resolve_device(device) -> torch.device:
    """``device`` as a ``torch.device``; a one-line ValueError when it is malformed, not a CPU or CUDA device, or not
    on this machine."""
    try:
        resolved = torch.device(device)
    except (RuntimeError, TypeError):
        resolved = None
    if resolved is None or resolved.type not in ("cpu", "cuda"):  # the worlds' kernels run on CPU and CUDA only
        raise InvalidOption("device", device, "use 'cpu', 'cuda' or 'cuda:<index>'")
    count = torch.cuda.device_count() if torch.cuda.is_available() else 0
    if resolved.type == "cuda" and (resolved.index or 0) >= count:
        raise ValueError(f"device={device!r} is not available: this torch sees {count} CUDA devices (README: GPU)")
    return resolved


def check_seed(seed) -> int:
    """``seed`` as an int; a one-line ValueError outside ``[0, 2^63)``."""
    if not isinstance(seed, numbers.Integral) or isinstance(seed, bool) or not 0 <= seed < SEED_LIMIT:
        raise ValueError(f"seed={seed!r} is invalid: give a whole number in [0, 2^63)")
    return int(seed)


def _check_batch_size(batch_size) -> int:
    """``B`` of ``batch_size`` (``B`` or ``[B]``); a one-line refusal for anything else (a bool, a float, a tensor)."""
    size = batch_size
    if isinstance(batch_size, (list, tuple, torch.Size)):
        size = batch_size[0] if len(batch_size) == 1 else None
    if not isinstance(size, numbers.Integral) or isinstance(size, bool) or size < 1:
        raise InvalidOption("batch_size", batch_size, "give the number of worlds B >= 1, a whole number or [B]")
    return int(size)


def check_memory(cfg: ModelConfig, batch_size: int, memory_budget) -> None:
    """A one-line refusal, before anything is allocated, when ``batch_size`` worlds of ``cfg`` would take more than
    ``memory_budget`` bytes (:func:`uavrl.envs.limits.world_bytes`)."""
    if not isinstance(memory_budget, numbers.Real) or isinstance(memory_budget, bool) or not memory_budget > 0:
        raise InvalidOption("memory_budget", memory_budget, "give the bytes the worlds may take, a positive number")
    need = world_bytes(cfg, batch_size)
    if need > memory_budget:
        L1, L2 = cfg.grid
        reason = (
            f"{batch_size:,} worlds of {cfg.num_uavs} UAVs on {L1}x{L2} need about {gib(need)}, over "
            f"memory_budget={int(memory_budget):,} bytes: use fewer worlds, or raise memory_budget"
        )
        raise InvalidOption("batch_size", batch_size, reason)


class _WorldsState:
    """The mutable per-world state, kept outside the ``nn.Module`` (whose ``__setattr__`` costs ~6 us a step per
    tensor).

    ``code`` ``[B, N]`` is ``2 * cell + task`` of every UAV; ``r`` ``[B, 2]`` the current
    (R_PU, R_SE); ``best`` the episode's best ``R_PU + R_SE`` (``best_so_far``);
    ``steps`` the episode clock; ``started`` whether a world has been reset;
    ``keys`` and ``counters`` the per-world random streams; ``was_reset``
    whether every world has been reset at least once (then every UAV has a cell).
    """

    __slots__ = ("code", "r", "best", "steps", "started", "counters", "keys", "was_reset")

    def __init__(self, **tensors):
        for name, value in tensors.items():
            setattr(self, name, value)


class World:
    """``B`` worlds of N UAVs of the model ``cfg``: layouts, tables, state and dynamics (no TorchRL).

    World ``i`` draws its randomness from its own stream seeded ``seed + i``, so
    it behaves exactly like world 0 of a batch of one seeded ``seed + i``.
    :meth:`reset` and :meth:`step` return the outputs of every world as a dict
    of tensors named as the environment's keys (``observation`` and
    ``action_mask`` ``[B, N, ...]``, the rest ``[B, ...]``); with
    ``diagnostics=False`` they leave out those of :data:`DIAGNOSTICS` (the
    step's rates, counts and the tabular state index), which nothing that
    acts or learns from the observation needs.
    """

    def __init__(
        self,
        cfg: ModelConfig,
        batch_size: int = 1,
        device="cpu",
        seed: int = 0,
        diagnostics: bool = True,
        memory_budget: int = DEFAULT_MEMORY_BUDGET,
    ):
        B = _check_batch_size(batch_size)
        check_memory(cfg, B, memory_budget)
        if not isinstance(diagnostics, bool):
            raise ValueError(f"diagnostics={diagnostics!r} is invalid: give True or False")
        self.diagnostics = diagnostics  # the outputs of DIAGNOSTICS too
        self.device = resolve_device(device)
        self.cfg: ModelConfig = cfg
        self.num_worlds, self.num_uavs = B, cfg.num_uavs
        L1, L2 = cfg.grid
        C, N, dev, f64 = cfg.num_cells, cfg.num_uavs, self.device, torch.float64
        # static geometry: the target cell of each move, -1 when it leaves the grid
        c = torch.arange(C, device=dev)
        x, y = c % L1, c // L1
        self._neighbours = grid_neighbours(cfg.grid, dev)  # [C, 4]
        self._cell_xyz = torch.stack([x.to(f64), y.to(f64), torch.full((C,), cfg.height, dtype=f64, device=dev)], -1)
        # digit base of the tabular state index s = sum_i d_i base^i, None when it overflows int64
        self._state_base = (2 * C if cfg.state_includes_tasks else C) if cfg.has_state_index else None
        self._grid_scale = torch.tensor([max(L1 - 1, 1), max(L2 - 1, 1)], dtype=f64, device=dev)
        self._node_scale = torch.tensor([L1, L2, cfg.height], dtype=f64, device=dev)
        layout = fixed_layout(cfg, f64, dev)  # ModelConfig refused one with a node on a UAV cell (envs/limits.py)
        self._cell_xy = torch.stack([x, y], -1)  # [C, 2]
        self._cell_mask = torch.cat(
            [self._neighbours >= 0, torch.ones(C, 2, dtype=torch.bool, device=dev)], -1
        )  # [C, 6]
        # A UAV's cell and task are one code 2 c + task, so a step is a few lookups in per-code tables.
        # _code_next[6 code + a]: the code after action a alone (a move off the grid stays)
        code = torch.arange(2 * C, device=dev)
        code_cell, code_task = code >> 1, code & 1
        nbr = self._neighbours[code_cell]
        moved = torch.where(nbr >= 0, 2 * nbr + code_task[:, None], code[:, None])
        self._code_next = torch.cat([moved, 2 * code_cell[:, None], 2 * code_cell[:, None] + 1], -1).flatten()
        self._code_xy = self._cell_xy[code_cell]  # [2C, 2]
        self._code_mask = self._cell_mask[code_cell]  # [2C, 6]
        self._code_cell, self._code_task = code_cell, code_task
        self._code_xyt = torch.cat(
            [self._code_xy / self._grid_scale, code_task[:, None]], -1
        ).float()  # [2C, 3] as observed
        self._cell_offset = torch.arange(B, device=dev).unsqueeze(-1) * C  # world w's cells as w C + c (clash counts)
        # per-code tables of the layout: one shared row for a fixed layout, one per world for random ones
        Bt = 1 if layout is not None else B
        self._code_offset = None if Bt == 1 else torch.arange(B, device=dev).unsqueeze(-1) * (2 * C)
        self._nodes = (
            (layout if layout is not None else torch.zeros(4, 3, dtype=f64, device=dev)).expand(Bt, 4, 3).clone()
        )
        # the gains fading draws from: the mean gain per link (rayleigh), or P_LoS and the LoS and NLoS gains (los_nlos)
        fading_shape = {"rayleigh": (Bt, C, 4), "los_nlos": (Bt, C, 4, 3)}.get(cfg.fading)
        self._cell_gains = None if fading_shape is None else torch.zeros(fading_shape, dtype=f64, device=dev)
        self._cell_contrib = torch.zeros(Bt, C, 2, dtype=f64, device=dev)
        self._code_obs = torch.zeros(
            Bt, 2 * C, 13, dtype=torch.float32, device=dev
        )  # own (x, y, task) and contributions
        self._code_rate = torch.zeros(
            Bt, 2 * C, 3, dtype=f64, device=dev
        )  # what a UAV adds to (sum PU, sum SE, relaying count)
        self._node_obs = torch.zeros(Bt, NODE_FEATURES, dtype=torch.float32, device=dev)
        self._direct = torch.zeros(Bt, 2, dtype=f64, device=dev)
        self._u_star = torch.zeros(Bt, dtype=f64, device=dev)  # reward="log_gap" only: each layout's exact U*
        self._world = torch.arange(B, device=dev).unsqueeze(-1)
        # two UAVs on a fixed layout: whole-pair tables (at most 2^16 rows: grids up to 128 cells)
        self._pairs = N == 2 and Bt == 1 and (2 * C) ** 2 <= 1 << 16
        self._pair_obs = self._pair_state = self._pair_rates = None
        self._s = _WorldsState(
            code=torch.zeros(B, N, dtype=torch.long, device=dev),
            r=torch.zeros(B, 2, dtype=f64, device=dev),
            best=torch.zeros(B, dtype=f64, device=dev),
            steps=torch.zeros(B, dtype=torch.long, device=dev),
            started=torch.zeros(B, dtype=torch.bool, device=dev),
            counters=torch.zeros(B, dtype=torch.long, device=dev),
            keys=streams.world_keys(0, B, dev),
            was_reset=False,  # a Python flag: stepping before every world was reset is an error, at no per-step cost
        )
        if layout is not None:
            self._set_layout(torch.zeros(1, dtype=torch.long, device=dev))
        self.set_seed(seed)

    def to(self, device) -> World:
        """Move every tensor the worlds own (tables, state, random streams) to ``device``; returns ``self``.

        Each stream is a pure function of its key and counter (:mod:`.streams`), so the worlds go on from where they
        were and a step gives the same outputs on any device.
        """
        device = resolve_device(device)
        for name, value in vars(self).items():
            if isinstance(value, torch.Tensor):
                setattr(self, name, value.to(device))
        for name in _WorldsState.__slots__:
            value = getattr(self._s, name)
            if isinstance(value, torch.Tensor):
                setattr(self._s, name, value.to(device))
        self.device = device
        return self

    # ---------------------------------------------------------- sizes
    @property
    def observation_size(self) -> int:
        """Per-UAV features: own (x, y, task), contributions at the own and 4 next cells, the others' (x, y, task).

        The 4 nodes' positions are the same for every UAV of a world: they are the last
        :data:`NODE_FEATURES` entries of the world's ``state`` (:func:`observation_with_nodes`)."""
        return 3 + 10 + 3 * (self.num_uavs - 1)

    @property
    def state_size(self) -> int:
        """Per UAV (x, y, task) and its contributions at its cell, then the 4 nodes' (x, y, z)."""
        return 5 * self.num_uavs + NODE_FEATURES

    def set_seed(self, seed: int | None):
        """World ``i`` draws from the stream of seed ``seed + i``; the episode counters restart."""
        seed = 0 if seed is None else check_seed(seed)
        self._s.keys = streams.world_keys(seed, self.num_worlds, self.device)
        self._s.counters.zero_()
        self._s.started.zero_()

    # ---------------------------------------------------------------- layout
    def _set_layout(self, worlds: torch.Tensor):
        """Recompute the per-cell and per-code tables of ``worlds`` (indices into the tables) from ``self._nodes``."""
        cfg, C, k = self.cfg, self.cfg.num_cells, len(worlds)
        nodes = self._nodes[worlds]
        gains = link_gains(self._cell_xyz, nodes, cfg)  # [k, C, 4]
        contrib = relay_contributions(gains, cfg)
        # observation of a UAV in cell c: its (x, y, task), then the contributions (scaled by the best cell's)
        # at c and at the cells its four moves reach, -1 where a move leaves the grid
        scaled = torch.cat([contrib / contrib.amax(1, keepdim=True), contrib.new_full((k, 1, 2), -1.0)], 1)
        around = torch.cat(
            [torch.arange(C, device=self.device)[:, None], self._neighbours.where(self._neighbours >= 0, C)], -1
        )  # [C, 5]
        cc, relay = self._code_cell, (self._code_task == RELAYING)[None, :]
        local = scaled.index_select(1, around[cc].flatten()).view(k, 2 * C, 10).float()
        code_obs = torch.cat([self._code_xyt.expand(k, -1, -1), local], -1)  # [k, 2C, 13]
        # per code: what the UAV adds to the sum inside the PU log, the SE log, and to the relaying count
        at_code, zero = contrib.index_select(1, cc), contrib.new_zeros(())
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
            "_node_obs": (nodes / self._node_scale).flatten(1).float(),  # [k, NODE_FEATURES]
            "_direct": direct_terms(nodes, cfg),
        }
        if cfg.fading == "rayleigh":
            tables["_cell_gains"] = gains
        elif cfg.fading == "los_nlos":
            tables["_cell_gains"] = link_state_gains(self._cell_xyz, nodes, cfg)
        if cfg.reward == "log_gap":
            tables["_u_star"] = exact_optimum(contrib, tables["_direct"], cfg)[0]
        for name, rows in tables.items():
            if k == len(getattr(self, name)):  # every world: a new table (no scatter)
                setattr(self, name, rows)
            else:
                getattr(self, name)[worlds] = rows
        if self._pairs:
            self._set_pair_tables()

    def _per_cell(self, table: torch.Tensor, cells: torch.Tensor, worlds: torch.Tensor | None = None) -> torch.Tensor:
        """Rows of a per-cell table ``[Bt, C, ...]`` at ``cells`` ``[W, ...]`` of all worlds (or of ``worlds``)."""
        if table.shape[0] == 1:
            return table[0][cells]
        worlds = self._world.squeeze(-1) if worlds is None else worlds
        return table[worlds.view(-1, *([1] * (cells.dim() - 1))), cells]

    def _sample_layout(self, worlds: torch.Tensor):
        """``layout=random``: nodes uniform in the grid widened by half a grid per side (docs/model.md, the nodes).

        PT-PR and S-E must be at least 0.6 grid diagonals apart.  Decision: S and E
        (at UAV altitude) must also be at least half a cell from every cell centre,
        so no UAV is ever at distance 0 from a node.  Rejection rounds run until
        every world in ``worlds`` is accepted; each world uses only its own stream.
        """
        L1, L2 = self.cfg.grid
        h = self.cfg.height
        lo = torch.tensor([-L1 / 2, -L2 / 2], dtype=torch.float64, device=self.device)
        span = torch.tensor([2.0 * L1, 2.0 * L2], dtype=torch.float64, device=self.device)
        min_sep = 0.6 * math.hypot(L1, L2)
        nodes = self._nodes[worlds]  # [k, 4, 3]
        keys, counters = self._s.keys[worlds], self._s.counters[worlds]
        for pair, z in ((0, 0.0), (1, h)):  # (PT, PR) on the ground, (S, E) at UAV altitude
            pending = torch.arange(len(worlds), device=self.device)  # round r draws only for the worlds still pending
            rnd = 0
            while len(pending):
                u = streams.uniform(keys[pending], counters[pending], _LAYOUT + 2 * rnd + pair, 4)
                xy = lo + span * u.view(-1, 2, 2)
                ok = torch.linalg.vector_norm(xy[:, 0] - xy[:, 1], dim=-1) >= min_sep
                if z > 0:
                    nearest = torch.stack(
                        [xy[..., 0].round().clamp(0, L1 - 1), xy[..., 1].round().clamp(0, L2 - 1)], -1
                    )
                    ok &= (torch.linalg.vector_norm(xy - nearest, dim=-1) >= 0.5).all(-1)
                nodes[pending[ok], 2 * pair : 2 * pair + 2] = torch.cat(
                    [xy[ok], xy.new_full((int(ok.sum()), 2, 1), z)], -1
                )
                pending = pending[~ok]
                rnd += 1
        self._nodes[worlds] = nodes
        self._set_layout(worlds)

    # -------------------------------------------------------------- dynamics
    @property
    def code(self) -> torch.Tensor:
        """``[B, N]`` ``2 * cell + task`` of every UAV now (:meth:`start_at` takes these)."""
        return self._s.code

    @property
    def _pos(self) -> torch.Tensor:
        """``[B, N]`` cell of every UAV."""
        return self._s.code >> 1

    @property
    def _tasks(self) -> torch.Tensor:
        """``[B, N]`` task of every UAV (0 sensing, 1 relaying)."""
        return self._s.code & 1

    def _code_rows(self, table: torch.Tensor, code: torch.Tensor, worlds: torch.Tensor | None = None) -> torch.Tensor:
        """Rows ``[W, N, F]`` of a per-code table ``[Bt, 2C, F]`` at the codes ``[W, N]`` of all worlds (or of
        ``worlds``)."""
        if self._code_offset is not None:
            code = code + (self._code_offset if worlds is None else worlds.unsqueeze(-1) * (2 * self.cfg.num_cells))
        return table.view(-1, table.shape[-1]).index_select(0, code.view(-1)).view(*code.shape, table.shape[-1])

    def _assemble(self, code: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(observation [W, N, F], state [W, S])`` of ``W`` configurations (one per world, or any ``W`` for a fixed
        layout)."""
        W, N = code.shape
        own = self._code_rows(self._code_obs, code)  # [W, N, 13]: x, y, task, 10 contributions
        parts = [own]
        if N == 2:  # the other UAV's (x, y, task)
            parts.append(self._code_xyt.index_select(0, code.flip(-1).view(-1)).view(W, N, 3))
        elif N > 2:
            # the others' (x, y, task), for UAV i in the order i+1, ..., i+N-1 (mod N): a window over the codes twice
            xyt = self._code_xyt.index_select(0, torch.cat([code, code], 1).view(-1))  # [2 W N, 3]
            parts.append(xyt.as_strided((W, N, 3 * (N - 1)), (6 * N, 3, 1), 3))
        observation = torch.cat(parts, -1) if len(parts) > 1 else own
        state = torch.cat([own[..., :5].reshape(W, 5 * N), self._node_obs.expand(W, NODE_FEATURES)], -1)
        return observation, state

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
        K = 2 * self.cfg.num_cells
        code = torch.arange(K, device=self.device)
        pairs = torch.stack([code.repeat_interleave(K), code.repeat(K)], -1)  # [K^2, 2]
        observation, state = self._assemble(pairs)
        self._pair_obs, self._pair_state, self._pair_rates = (
            observation[:, 0].contiguous(),
            state,
            self._sum_rates(pairs),
        )

    def _observe(self, code: torch.Tensor, cells: torch.Tensor, moves, switches) -> dict:
        """The outputs of configurations ``code`` ``[B, N]`` (``cells`` its cells) after a step; ``moves()`` and
        ``switches()`` count the step's moves and task switches ``[B]`` (called for the diagnostics only)."""
        B, N = self.num_worlds, self.num_uavs
        if self._pair_obs is not None:
            pair = torch.add(code.flip(-1), code, alpha=2 * self.cfg.num_cells)  # [B, 2]: rows (a, b) and (b, a)
            observation = self._pair_obs.index_select(0, pair.view(-1)).view(B, N, -1)
            state = self._pair_state.index_select(0, pair[:, 0])
        else:
            observation, state = self._assemble(code)
        flat = code.view(-1)
        out = {
            "observation": observation,
            "action_mask": self._code_mask.index_select(0, flat).view(B, N, NUM_ACTIONS),
            "state": state,
            "positions": self._code_xy.index_select(0, flat).view(B, N, 2),
            "tasks": code & 1,
        }
        if not self.diagnostics:
            return out
        r = self._s.r.float()
        out.update(r_pu=r[:, 0], r_se=r[:, 1], utility=r[:, 0] + r[:, 1], moves=moves(), task_switches=switches())
        if self._state_base is not None:
            digits = code if self.cfg.state_includes_tasks else cells
            index = digits[:, N - 1]
            for i in range(N - 2, -1, -1):  # Horner: d_0 + base (d_1 + base (...)); sums over tiny dims are slow
                index = torch.add(digits[:, i], index, alpha=self._state_base)
            out["state_index"] = index.clone() if N == 1 else index
        return out

    def _direct_of(self, worlds: torch.Tensor | None) -> torch.Tensor:
        """Direct-link SNRs ``[Bt or W, 2]`` broadcastable to all worlds (or to ``worlds``)."""
        return self._direct if worlds is None or len(self._direct) == 1 else self._direct[worlds]

    def _current_rates(self, code: torch.Tensor, worlds: torch.Tensor | None = None) -> torch.Tensor:
        """``[W, 2]`` (R_PU, R_SE) of the configurations ``code`` of all worlds (or of ``worlds``), with fresh fading
        if enabled."""
        cfg = self.cfg
        if cfg.fading == "none":
            if self._pair_rates is not None:
                return self._pair_rates.index_select(0, torch.add(code[:, 1], code[:, 0], alpha=2 * cfg.num_cells))
            return self._sum_rates(code, worlds)
        keys, counters = (
            (self._s.keys, self._s.counters) if worlds is None else (self._s.keys[worlds], self._s.counters[worlds])
        )
        gains = self._per_cell(self._cell_gains, code >> 1, worlds)
        u = streams.uniform(keys, counters, _FADING, 4 * self.num_uavs).view(gains.shape[:3])
        if cfg.fading == "los_nlos":  # each link in line of sight with probability P_LoS, drawn anew
            p_los, los, nlos = gains.unbind(-1)
            contrib = relay_contributions(torch.where(u < p_los, los, nlos), cfg)
        else:
            contrib = relay_contributions(gains * -torch.log1p(-u), cfg)  # Exp(1) power gain per link
        direct = self._direct_of(worlds).expand(len(code), 2)
        if cfg.direct_links:  # the direct links PT->PR and S->E fade too
            direct = direct * -torch.log1p(-streams.uniform(keys, counters, _FADING_DIRECT, 2))
        return torch.stack(rates(contrib, code & 1, direct, cfg), -1)

    def reset(self, worlds: torch.Tensor | None = None) -> dict:
        """Start a new episode in ``worlds`` (indices; default all); the outputs of every world, as after a step."""
        B, N, C, cfg, dev = self.num_worlds, self.num_uavs, self.cfg.num_cells, self.cfg, self.device
        worlds = torch.arange(B, device=dev) if worlds is None else worlds
        s = self._s
        # only the worlds being reset are touched (a partial reset of a few worlds costs little)
        s.counters[worlds] += 1
        if cfg.layout == "random":
            self._sample_layout(worlds)
        fresh = worlds[~s.started[worlds]] if cfg.reset_positions == "keep" else worlds
        # distinct cells: the N smallest of C random keys; tasks per init_tasks
        keys, counters = s.keys[fresh], s.counters[fresh]
        cells = streams.random_bits(keys, counters, _POSITIONS, C).topk(N, dim=-1, largest=False).indices
        if cfg.init_tasks == "random":
            tasks = streams.random_bits(keys, counters, _TASKS, N) & 1
        else:
            tasks = torch.full((len(fresh), N), RELAYING if cfg.init_tasks == "relaying" else SENSING, device=dev)
        s.code[fresh] = 2 * cells + tasks
        s.started[worlds] = True
        s.steps[worlds] = 0
        s.best[worlds] = 0.0
        s.r[worlds] = self._current_rates(s.code[worlds], worlds)
        # a partial first reset leaves worlds without cells: read the flags until every world has been reset
        s.was_reset = s.was_reset or len(worlds) == B or bool(s.started.all())
        return self._observe(self._s.code, self._s.code >> 1, self._no_counts, self._no_counts)

    def start_at(self, code: torch.Tensor) -> dict:
        """Start every world's episode at the configurations ``code`` ``[B, N]`` (``2 cell + task``) chosen elsewhere,
        e.g. another world's starts repeated; a fixed layout only.  The outputs of every world, as :meth:`reset`'s."""
        if self.cfg.layout == "random":
            raise ValueError("World.start_at needs a fixed layout: with layout='random' a reset draws the layout")
        s = self._s
        s.counters += 1
        s.code = code.to(self.device).clone()
        s.started.fill_(True)
        s.steps.zero_()
        s.best.zero_()
        s.r = self._current_rates(s.code)
        s.was_reset = True
        return self._observe(s.code, s.code >> 1, self._no_counts, self._no_counts)

    def _no_counts(self) -> torch.Tensor:
        """``[B]`` zero moves or switches (a reset)."""
        return torch.zeros(self.num_worlds, dtype=torch.long, device=self.device)

    def _resolve_moves(self, cells: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """Target cells made valid as docs/model.md decides (off-grid moves already stay).

        Until all targets differ, every UAV whose target another UAV also targets
        (a mover or a stayer) goes back to its cell; for a stayer that changes
        nothing.  Each round cancels at least one mover, and one cancelled in
        round k > 1 was blocked by one cancelled in round k - 1, which began with
        two UAVs (a stayer or a second mover): N - 1 rounds always suffice.
        """
        N = self.num_uavs
        if N == 1:
            return target
        if N == 2:  # one round, no sync
            return torch.where(target[:, :1] == target[:, 1:], cells, target)
        clash = self._clashes(target)
        target = torch.where(clash, cells, target)
        # later rounds: only worlds where a UAV went back can clash again (usually a few)
        active = clash.any(-1).nonzero().squeeze(-1)
        for _ in range(N - 2):
            if len(active) == 0:
                break
            sub_target, sub_cells = target[active], cells[active]
            clash = self._clashes(sub_target)
            target[active] = torch.where(clash, sub_cells, sub_target)
            active = active[clash.any(-1)]
        return target

    def _clashes(self, target: torch.Tensor) -> torch.Tensor:
        """``[W, N]``: does another UAV of the same world target the same cell?  By counting targets per cell."""
        C = self.cfg.num_cells
        flat = (target + self._cell_offset[: len(target)]).view(-1)
        return (torch.bincount(flat, minlength=len(target) * C).index_select(0, flat) > 1).view_as(target)

    def step(self, action: torch.Tensor) -> tuple[dict, torch.Tensor, torch.Tensor]:
        """Every world takes the UAVs' actions ``[B, N]`` (0..5, checked by the caller).

        Returns the outputs (as :meth:`reset`'s), the team reward ``[B]``
        (float64) and whether the episode is over ``[B]`` (truncation after
        ``max_steps``).
        """
        cfg, code = self.cfg, self._s.code
        proposed = self._code_next.take(
            torch.add(action.long(), code, alpha=NUM_ACTIONS)
        )  # [B, N] codes, moves unchecked
        cells = code >> 1
        target = self._resolve_moves(cells, proposed >> 1)
        tasks = proposed & 1
        new_code = torch.add(tasks, target, alpha=2)
        self._s.code = new_code
        self._s.counters += 1
        prev = self._s.r
        self._s.r = r = self._current_rates(new_code)
        if cfg.reward == "delta":
            reward = delta_reward(r[:, 0], r[:, 1], prev[:, 0], prev[:, 1], cfg.beta1, cfg.beta2)
        elif cfg.reward == "log_gap":  # of the mean-channel utility, as the yardstick measures it
            mean = (r, prev) if cfg.fading == "none" else (self._sum_rates(new_code), self._sum_rates(code))
            reward = log_gap_reward(mean[0].sum(-1), mean[1].sum(-1), self._u_star)
        else:
            total = r.sum(-1)
            reward = best_so_far_reward(total, self._s.best)
            self._s.best = torch.maximum(self._s.best, total)
        self._s.steps += 1
        out = self._observe(
            new_code, target, lambda: (target != cells).sum(-1), lambda: ((proposed ^ code) & 1).sum(-1)
        )
        return out, reward, self._s.steps >= cfg.max_steps

    # ------------------------------------------------------ shared helpers
    def cells_of(self, positions: torch.Tensor) -> torch.Tensor:
        """Cell indices ``y * L1 + x`` of ``[..., 2]`` (x, y) positions."""
        return cells_of(positions, self.cfg.grid[0])

    def utility(self, positions: torch.Tensor, tasks: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(R_PU, R_SE, U)`` of configurations of this env's worlds, deterministic channels.

        ``positions`` ``[B, ..., N, 2]`` (x, y) and ``tasks`` ``[B, ..., N]``; results ``[B, ...]`` float64.
        """
        self._require_layout()
        positions, tasks = positions.to(self.device), tasks.to(self.device)
        if (
            positions.shape[0] != self.num_worlds
            or positions.shape[-2:] != (self.num_uavs, 2)
            or tasks.shape != positions.shape[:-1]
        ):
            raise ValueError(
                f"positions {tuple(positions.shape)} / tasks {tuple(tasks.shape)} do not fit: expected "
                f"[B={self.num_worlds}, ..., N={self.num_uavs}, 2] and [B, ..., N]"
            )
        if any(t.dtype.is_floating_point or t.dtype.is_complex or t.dtype == torch.bool for t in (positions, tasks)):
            raise TypeError(f"positions ({positions.dtype}) and tasks ({tasks.dtype}) must hold integers")
        L1, L2 = self.cfg.grid
        x, y = positions[..., 0], positions[..., 1]
        off_grid = (x < 0) | (x >= L1) | (y < 0) | (y >= L2)
        if off_grid.any():
            where = tuple(positions[off_grid][0].tolist())
            raise ValueError(f"positions hold {where}, off the {L1}x{L2} grid: x lies in 0..{L1 - 1}, y in 0..{L2 - 1}")
        bad_task = (tasks != SENSING) & (tasks != RELAYING)
        if bad_task.any():
            raise ValueError(f"tasks hold {tasks[bad_task][0].item()}: a task is 0 (sensing) or 1 (relaying)")
        cells = self.cells_of(positions)
        contrib = self._per_cell(self._cell_contrib, cells)
        direct = self.direct.view(self.num_worlds, *([1] * (cells.dim() - 2)), 2)
        r_pu, r_se = rates(contrib, tasks, direct, self.cfg)
        return r_pu, r_se, r_pu + r_se

    def optimum(self, method: str = "auto") -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Exact ``U*`` ``[B]`` and one optimal configuration per world (positions ``[B, N, 2]``, tasks ``[B, N]``).

        Over all placements on distinct cells and all task vectors, for the
        deterministic (mean) channels.  See :func:`uavrl.envs.optimum.optimum`.
        """
        self._require_layout()
        # a fixed layout has one row of tables: solved once, the same answer for every world
        u, cells, tasks = exact_optimum(self._cell_contrib, self._direct, self.cfg, method=method)
        B, L1 = self.num_worlds, self.cfg.grid[0]
        if len(u) != B:
            u, cells, tasks = u.expand(B), cells.expand(B, -1), tasks.expand(B, -1)
        return u.clone(), torch.stack([cells % L1, cells // L1], -1), tasks.clone()

    def joint_action_mask(self, positions: torch.Tensor | None = None) -> torch.Tensor:
        """``[B, 6^N]`` valid joint actions (all cells on the grid and distinct) at ``positions`` (default: now)."""
        cells = self._pos if positions is None else self.cells_of(positions.to(self.device))
        return joint_action_valid(cells, self._neighbours, self.num_uavs)

    def _require_layout(self):
        if self.cfg.layout == "random" and not bool(self._s.started.all()):
            raise RuntimeError("layout='random' draws each world's layout at reset: call env.reset() first")

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
        return self._neighbours
