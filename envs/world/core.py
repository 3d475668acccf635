"""The World itself: its parts, its per-world state, and the pipeline of a reset and a step (the package's
docstring, :mod:`uavrl.envs.world`, tells the whole)."""

from __future__ import annotations

import copy

import torch

from ..config import ModelConfig
from ..limits import DEFAULT_MEMORY_BUDGET, VERTICAL_FEATURES
from ..physics import streams
from ..physics.channel import rates, relay_contributions
from ..physics.dynamics import UAV_STATE
from ..physics.energy import ENERGY_STATE, energy_part
from ..physics.fading import fading_part
from ..physics.layouts import Layouts
from ..physics.rewards import TeamReward
from .checks import check_batch_size, check_memory, check_seed, resolve_device
from .observations import NODE_FEATURES, Observations
from .queries import SolverQueries
from .tables import GRID_TABLES, LAYOUT_TABLES, LayoutTables, SharedTables, shared_tables


class WorldsState:
    """The mutable per-world state, kept outside the ``nn.Module`` (whose ``__setattr__`` costs ~6 us a step per
    tensor).

    Per UAV, one ``[B, N]`` tensor for each name of :data:`~uavrl.envs.physics.dynamics.UAV_STATE` (``cell``, ``task``)
    and, under an energy model, of :data:`~uavrl.envs.physics.energy.ENERGY_STATE` (``battery``, ``status``, ``timer``;
    ``None`` without one); per world: ``r`` ``[B, 2]`` the current (R_PU, R_SE); ``best`` the episode's best
    ``R_PU + R_SE`` (the reward part's memory for ``best_so_far``); ``steps`` the episode clock; ``terminated``
    whether the last step ended the episode (``None``: no world's); ``started`` whether a world has been reset;
    ``keys`` and ``counters`` the per-world random streams; ``was_reset`` whether every world has been reset at least
    once (then every UAV has a cell); ``messages`` ``[B, N, message_size]`` what each UAV sent at the last step (zeros
    after a reset; ``None`` without messages); ``cancelled`` ``[B, N]`` whether each UAV's move at the last step was
    cancelled (``False`` after a reset; ``None`` without local observations).
    """

    __slots__ = (
        *UAV_STATE,
        *ENERGY_STATE,
        "r",
        "best",
        "steps",
        "terminated",
        "started",
        "counters",
        "keys",
        "was_reset",
        "messages",
        "cancelled",
    )

    def __init__(self, **tensors):
        for name, value in tensors.items():
            setattr(self, name, value)


class World(LayoutTables, Observations, SolverQueries):
    """``B`` worlds of N UAVs of the model ``cfg``: its parts, the layouts' tables and the state (no TorchRL).

    World ``i`` draws its randomness from its own stream seeded ``seed + i``, so
    it behaves exactly like world 0 of a batch of one seeded ``seed + i``.
    :meth:`reset` and :meth:`step` return the outputs of every world as a dict
    of tensors named as the environment's keys (``observation`` and
    ``action_mask`` ``[B, N, ...]``, the rest ``[B, ...]``); with
    ``diagnostics=False`` they leave out those of :data:`DIAGNOSTICS` (the
    step's rates, counts and the tabular state index), which nothing that
    acts or learns from the observation needs.

    Args:
        cfg: the model (:func:`~uavrl.envs.make_config`).
        batch_size: the number of independent worlds ``B``.
        device: the torch device of every tensor.
        seed: seed of world 0.
        diagnostics: also return the outputs of :data:`DIAGNOSTICS`.
        memory_budget: the bytes the worlds may take; more is refused with one line before anything is allocated.

    Example:
        >>> from uavrl.envs import make_config
        >>> world = World(make_config("paper", grid=(4, 4), num_uavs=2), batch_size=3, seed=0)
        >>> world.reset()["observation"].shape
        torch.Size([3, 2, 16])
        >>> outputs, reward, done = world.step(torch.full((3, 2), 4))  # every UAV switches to sensing
        >>> reward.shape
        torch.Size([3])
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
        B = check_batch_size(batch_size)
        check_memory(cfg, B, memory_budget)
        if not isinstance(diagnostics, bool):
            raise ValueError(f"diagnostics={diagnostics!r} is invalid: give True or False")
        self.diagnostics = diagnostics  # the outputs of DIAGNOSTICS too
        self.device = dev = resolve_device(device)
        self.cfg: ModelConfig = cfg
        self.num_worlds, self.num_uavs = B, cfg.fleet_size  # every UAV of the fleet (spares too) is an agent
        # the parts (docs/architecture.md, The World's parts)
        self.layouts = Layouts(cfg, dev)
        self.fading = fading_part(cfg)
        self._shared_tables = shared = shared_tables(cfg, dev)  # the grid's and a fixed layout's, of every such World
        self.dynamics = copy.copy(shared.dynamics)  # its own part (World.to moves it), the same tables
        self.dynamics.cfg = cfg
        self.reward = TeamReward(cfg, self.fading.random)
        self.energy = energy_part(cfg, dev)
        self._slots = self.dynamics.slots  # the cells a UAV's code can name: C, and one off the grid with energy
        self.num_positions = self.dynamics.num_positions  # the (cell, level) positions: the cells without levels
        self._share(GRID_TABLES, self._build_geometry)
        # per-layout tables: one shared row for a fixed layout, one per world for random ones (zeros until a reset)
        C, f64 = self.num_positions, torch.float64
        fixed = self.layouts.fixed
        Bt = 1 if fixed is not None else B
        self._code_offset = None if Bt == 1 else torch.arange(B, device=dev).unsqueeze(-1) * (2 * self._slots)
        nodes = fixed if fixed is not None else torch.zeros(4, 3, dtype=f64, device=dev)
        self._nodes = nodes.expand(Bt, 4, 3).clone()
        self._cell_contrib = torch.zeros(Bt, C, 2, dtype=f64, device=dev)
        K = 2 * self._slots  # the codes
        self._code_obs = torch.zeros(Bt, K, 13, dtype=torch.float32, device=dev)  # own (x, y, task), contributions
        self._code_rate = torch.zeros(Bt, K, 3, dtype=f64, device=dev)  # adds to (sum PU, sum SE, relaying count)
        self._node_obs = torch.zeros(Bt, NODE_FEATURES, dtype=torch.float32, device=dev)
        self._code_vertical = None if cfg.num_levels == 1 else torch.zeros(Bt, K, VERTICAL_FEATURES, device=dev)
        self._direct = torch.zeros(Bt, 2, dtype=f64, device=dev)
        self._u_star = torch.zeros(Bt, dtype=f64, device=dev)  # U_STAR_REWARDS only: each layout's exact U*
        self._fading_table = None  # the fading part's table, its shape the part's: made by the first layout
        self._world = torch.arange(B, device=dev).unsqueeze(-1)
        # two UAVs on a fixed layout: whole-pair tables (at most 2^16 rows: grids up to 128 cells)
        self._pairs = (
            self.num_uavs == 2 and Bt == 1 and (2 * C) ** 2 <= 1 << 16 and self.energy is None and not cfg.local
        )
        self._pair_obs = self._pair_state = self._pair_rates = None
        N, long = self.num_uavs, torch.long
        energy_state = dict.fromkeys(ENERGY_STATE)  # None without an energy model
        if self.energy is not None:
            energy_state.update(
                battery=torch.zeros(B, N, dtype=f64, device=dev),
                status=torch.zeros(B, N, dtype=long, device=dev),
                timer=torch.zeros(B, N, dtype=long, device=dev),
            )
        self._s = WorldsState(
            **{name: torch.zeros(B, N, dtype=long, device=dev) for name in UAV_STATE},
            **energy_state,
            r=torch.zeros(B, 2, dtype=f64, device=dev),
            best=torch.zeros(B, dtype=f64, device=dev),
            steps=torch.zeros(B, dtype=long, device=dev),
            terminated=None,  # no world's episode has ended (the dynamics part's terminated)
            started=torch.zeros(B, dtype=torch.bool, device=dev),
            counters=torch.zeros(B, dtype=long, device=dev),
            keys=streams.world_keys(0, B, dev),
            was_reset=False,  # a Python flag: stepping before every world was reset is an error, at no per-step cost
            messages=torch.zeros(B, N, cfg.message_size, device=dev) if cfg.message_size else None,
            cancelled=torch.zeros(B, N, dtype=torch.bool, device=dev) if cfg.local else None,
        )
        if fixed is not None:
            self._share(LAYOUT_TABLES, lambda: self._set_layout(torch.zeros(1, dtype=long, device=dev)))
        self.set_seed(seed)

    def to(self, device) -> World:
        """Move every tensor the worlds own (parts, tables, state, random streams) to ``device``; returns ``self``.

        Each stream is a pure function of its key and counter (:mod:`uavrl.envs.physics.streams`), so the worlds go on
        from where they were and a step gives the same outputs on any device.
        """
        device = resolve_device(device)
        if device != self.device:  # the moved tables are this World's own from now on
            self._shared_tables = SharedTables()
        for owner in (self, *self.parts.values()):
            for name, value in vars(owner).items():
                if isinstance(value, torch.Tensor):
                    setattr(owner, name, value.to(device))
        for name in WorldsState.__slots__:
            value = getattr(self._s, name)
            if isinstance(value, torch.Tensor):
                setattr(self._s, name, value.to(device))
        self.device = device
        return self

    @property
    def parts(self) -> dict:
        """The model's parts by name (docs/architecture.md, The World's parts); ``city`` in a city, ``energy`` under an
        energy model."""
        parts = {"layouts": self.layouts, "fading": self.fading, "dynamics": self.dynamics, "reward": self.reward}
        if self.layouts.city is not None:
            parts["city"] = self.layouts.city
        return parts if self.energy is None else {**parts, "energy": self.energy}

    def set_seed(self, seed: int | None):
        """World ``i`` draws from the stream of seed ``seed + i``; the episode counters restart."""
        seed = 0 if seed is None else check_seed(seed)
        self._s.keys = streams.world_keys(seed, self.num_worlds, self.device)
        self._s.counters.zero_()
        self._s.started.zero_()

    # -------------------------------------------------------------- state
    @property
    def state(self) -> WorldsState:
        """The worlds' state now (:class:`WorldsState`: ``cell``, ``task``, the batteries, the clocks, ...), the
        World's own tensors: read them, never write them."""
        return self._s

    @property
    def was_reset(self) -> bool:
        """Whether every world has been reset at least once (then every UAV has a cell, and a step may follow)."""
        return self._s.was_reset

    @property
    def state_index_fits(self) -> bool:
        """Whether the tabular state index (the output ``state_index``) fits in int64 and is computed: a model
        with one (:attr:`~uavrl.envs.config.ModelConfig.has_state_index`) and no energy model."""
        return self._state_base is not None

    @property
    def code(self) -> torch.Tensor:
        """``[B, N]`` ``2 * cell + task`` of every UAV now (:meth:`start_at` takes these)."""
        return torch.add(self._s.task, self._s.cell, alpha=2)

    @property
    def terminated(self) -> torch.Tensor:
        """``[B]`` whether each world's last step ended its episode (the dynamics part's ``terminated``; False after
        a reset): a new tensor where no world's can end."""
        terminated = self._s.terminated
        return torch.zeros(self.num_worlds, dtype=torch.bool, device=self.device) if terminated is None else terminated

    def _rates(
        self, cell: torch.Tensor, task: torch.Tensor, code: torch.Tensor, worlds: torch.Tensor | None = None
    ) -> torch.Tensor:
        """``[W, 2]`` (R_PU, R_SE) of the configurations ``cell``, ``task`` (``code``) ``[W, N]`` of all worlds (or of
        ``worlds``): a fresh draw of a random channel (the fading part), else the mean channel's per-code tables."""
        cfg = self.cfg
        if not self.fading.random:
            if self._pair_rates is not None:
                return self._pair_rates.index_select(0, torch.add(code[:, 1], code[:, 0], alpha=2 * self.num_positions))
            return self._sum_rates(code, worlds)
        s = self._s
        keys, counters = (s.keys, s.counters) if worlds is None else (s.keys[worlds], s.counters[worlds])
        rows = self._per_cell(self._fading_table, cell, worlds)
        contrib = relay_contributions(self.fading.gains(rows, keys, counters), cfg)
        direct = self._direct_of(worlds).expand(len(cell), 2)
        if cfg.direct_links:
            direct = self.fading.direct(direct, keys, counters)
        return torch.stack(rates(contrib, task, direct, cfg), -1)

    def reset(self, worlds: torch.Tensor | None = None) -> dict:
        """Start a new episode in ``worlds`` (indices; default all); the outputs of every world, as after a step."""
        B, cfg, dev = self.num_worlds, self.cfg, self.device
        worlds = torch.arange(B, device=dev) if worlds is None else worlds
        s = self._s
        # only the worlds being reset are touched (a partial reset of a few worlds costs little)
        s.counters[worlds] += 1
        if self.layouts.fixed is None:
            self._nodes[worlds] = self.layouts.sample(s.keys[worlds], s.counters[worlds])
            self._set_layout(worlds)
        fresh = worlds[~s.started[worlds]] if cfg.reset_positions == "keep" else worlds
        for name, value in self.dynamics.start(s.keys[fresh], s.counters[fresh]).items():
            getattr(s, name)[fresh] = value
        if self.energy is not None:  # every episode is a mission with fresh batteries (refused with keep)
            for name, value in self.energy.start(s.keys[worlds], s.counters[worlds]).items():
                getattr(s, name)[worlds] = value
        s.started[worlds] = True
        s.steps[worlds] = 0
        s.best[worlds] = 0.0
        if s.messages is not None:
            s.messages[worlds] = 0.0
        if s.cancelled is not None:  # a new tensor: the one a step published stays as it was
            s.cancelled = s.cancelled.index_fill(0, worlds, False)
        if s.terminated is not None:  # a new tensor: the one a step published stays as it was
            s.terminated = s.terminated.index_fill(0, worlds, False)
        code = self.code
        s.r[worlds] = self._rates(s.cell[worlds], s.task[worlds], code[worlds], worlds)
        # a partial first reset leaves worlds without cells: read the flags until every world has been reset
        s.was_reset = s.was_reset or len(worlds) == B or bool(s.started.all())
        return self._observe(code, s.cell, s.task, self._no_counts, self._no_counts)

    def start_at(self, code: torch.Tensor) -> dict:
        """Start every world's episode at the configurations ``code`` ``[B, N]`` (``2 cell + task``) chosen elsewhere,
        e.g. another world's starts repeated; a fixed layout only.  The outputs of every world, as :meth:`reset`'s."""
        if self.layouts.fixed is None:
            raise ValueError("World.start_at needs a fixed layout: with layout='random' a reset draws the layout")
        s = self._s
        s.counters += 1
        code = code.to(self.device)
        s.cell, s.task = code >> 1, code & 1
        if self.energy is not None:
            for name, value in self.energy.start(s.keys, s.counters).items():
                setattr(s, name, value)
        s.started.fill_(True)
        s.steps.zero_()
        s.best.zero_()
        if s.messages is not None:
            s.messages = torch.zeros_like(s.messages)
        if s.cancelled is not None:
            s.cancelled = torch.zeros_like(s.cancelled)
        s.terminated = None
        s.r = self._rates(s.cell, s.task, code)
        s.was_reset = True
        return self._observe(code, s.cell, s.task, self._no_counts, self._no_counts)

    def _no_counts(self) -> torch.Tensor:
        """``[B]`` zero moves or switches (a reset)."""
        return torch.zeros(self.num_worlds, dtype=torch.long, device=self.device)

    def step(
        self, action: torch.Tensor, messages: torch.Tensor | None = None
    ) -> tuple[dict, torch.Tensor, torch.Tensor]:
        """Every world takes the UAVs' ``action`` ``[B, N]`` (0..5, 6 to return under recharging; checked by the
        caller); with ``message_size`` the UAVs send ``messages`` ``[B, N, message_size]`` (clipped to [-1, 1]; None:
        zeros), which those within range read in the observation this step returns.

        Returns the outputs (as :meth:`reset`'s), the team reward ``[B]``
        (float64) and whether the episode is over ``[B]`` (truncation after
        ``max_steps``); :attr:`terminated` says which episodes the step ended.
        """
        s = self._s
        cell, task = s.cell, s.task
        code = self._advance(s, action)
        s.counters += 1
        prev = s.r
        s.r = self._rates(s.cell, s.task, code)
        reward, s.best = self.reward(
            s.r, prev, s.best, self._u_star, lambda: (self._sum_rates(code), self._sum_rates(cell * 2 + task))
        )
        s.steps += 1
        if s.messages is not None:
            s.messages = torch.zeros_like(s.messages) if messages is None else messages.float().clamp(-1.0, 1.0)
        s.terminated = self.dynamics.terminated(s) if self.energy is None else self.energy.terminated(s)
        new_cell, new_task = s.cell, s.task
        out = self._observe(
            code, new_cell, new_task, lambda: (new_cell != cell).sum(-1), lambda: (new_task != task).sum(-1)
        )
        return out, reward, s.steps >= self.cfg.max_steps

    def _advance(self, state, action: torch.Tensor) -> torch.Tensor:
        """Set ``state``'s per-UAV variables (:data:`~uavrl.envs.physics.dynamics.UAV_STATE`,
        :data:`~uavrl.envs.physics.energy.ENERGY_STATE`) to those after the joint actions ``[W, N]``: the dynamics
        part's step, then the energy part's; returns the codes ``2 cell + task`` after it."""
        cell = state.cell
        for name, value in self.dynamics.step(state, action).items():
            setattr(state, name, value)
        if self.energy is not None:
            for name, value in self.energy.step(state, cell, action).items():
                setattr(state, name, value)
        return torch.add(state.task, state.cell, alpha=2)

    def successors(
        self, state: dict[str, torch.Tensor], action: torch.Tensor, worlds: torch.Tensor | None = None
    ) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """Any ``W`` states after joint actions, for the solvers: what :meth:`step` does to the per-UAV variables
        and the rates, without the worlds' own state, clock or streams.

        ``state``: ``[W, N]`` tensors by the names of :data:`~uavrl.envs.physics.dynamics.UAV_STATE` (and
        :data:`~uavrl.envs.physics.energy.ENERGY_STATE` under an energy model); ``action`` ``[W, N]``; ``worlds``
        ``[W]``: whose layout each row is in (``None``: a fixed layout's).  Returns the variables after the step and the
        deterministic ``(R_PU, R_SE)`` ``[W, 2]`` float64 of the configurations they reach (the mean channel: a random
        channel is refused).
        """
        if self.fading.random:
            raise ValueError(f"World.successors reads deterministic channels: fading={self.cfg.fading!r} is random")
        if worlds is None and self.layouts.fixed is None:
            raise ValueError("World.successors needs worlds=[W] under layout='random': each world has its own layout")
        after = WorldsState(**state)
        code = self._advance(after, action)
        names = UAV_STATE + (ENERGY_STATE if self.energy is not None else ())
        return {name: getattr(after, name) for name in names}, self._rates(after.cell, after.task, code, worlds)

    @property
    def battery(self) -> torch.Tensor | None:
        """``[B, N]`` float64 every UAV's battery now, in the energy model's units; ``None`` without one."""
        return None if self._s.battery is None else self._s.battery.clone()

    @property
    def status(self) -> torch.Tensor | None:
        """``[B, N]`` every UAV's status now (:data:`~uavrl.envs.physics.energy.SERVING` ... ``WAITING``); ``None``
        without an energy model."""
        return None if self._s.status is None else self._s.status.clone()
