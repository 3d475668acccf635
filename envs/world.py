"""The physics of the UAV spectrum-sharing model for ``B`` worlds at once, with no TorchRL.

:class:`World` composes the model's parts (docs/architecture.md, The World's parts), VMAS's scenario hooks written
for this model, and holds what they share: every world's layout and the tables computed from it, the UAVs' state and
the per-world random streams.  The parts are

- ``layouts`` (:mod:`.physics.layouts`): where the four nodes are, fixed or drawn at each reset;
- the channel and the rate model (:mod:`.physics.channel`): the mean gain of every link and the AF rates, turned into
  per-cell and per-code tables once per layout;
- ``fading`` (:mod:`.physics.fading`): the links' random power gains drawn each step, and whether the channel is random;
- ``dynamics`` (:mod:`.physics.dynamics`): the per-UAV state variables, their start, their step, the masks, termination;
- ``reward`` (:class:`.physics.rewards.TeamReward`): ``env.reward`` from the rates;
- ``energy`` (:mod:`.physics.energy`, under ``env.energy`` other than ``none``): the batteries, who serves, termination.

A step is their pipeline: dynamics, rates, reward, termination, observation.  :meth:`World.reset` and
:meth:`World.step` return plain tensors (observations, masks, rates, rewards);
:class:`~uavrl.envs.env.UAVSpectrumEnv` is the thin TorchRL ``EnvBase`` on top (specs, keys, seeding); the tabular
learner and the tabular evaluation use a ``World`` directly, so they never import TorchRL.

A step is a fixed handful of tensor operations whatever ``B`` is, on CPU or CUDA.  A UAV's cell and task index the
per-code tables as one code ``2 cell + task``, so rates and observations are lookups in small tables built once per
layout (see BENCHMARKS.md for timings).

Example:
    >>> from uavrl.envs import make_config
    >>> world = World(make_config("paper", grid=(6, 6), num_uavs=2, max_steps=10), batch_size=4)
    >>> first = world.reset()
    >>> out, reward, truncated = world.step(torch.full((4, 2), 5))
    >>> out["utility"].shape, reward.shape, first["observation"].shape, world.terminated.tolist()
    (torch.Size([4]), torch.Size([4]), torch.Size([4, 2, 16]), [False, False, False, False])
"""

from __future__ import annotations

import copy
import dataclasses
import numbers
import weakref

import torch

from .config import NUM_ACTIONS, RELAYING, SENSING, InvalidOption, InvalidType, ModelConfig
from .limits import DEFAULT_MEMORY_BUDGET, gib, world_bytes
from .physics import streams
from .physics.channel import direct_terms, link_gains, rates, rates_from_sums, relay_contributions
from .physics.dynamics import UAV_STATE, Dynamics
from .physics.energy import ENERGY_STATE, energy_part
from .physics.fading import fading_part
from .physics.grid import cells_of, decode_joint_actions, joint_action_valid, targets_valid
from .physics.layouts import Layouts
from .physics.rewards import U_STAR_REWARDS, TeamReward
from .solvers.optimum import optimum as exact_optimum

SEED_LIMIT = 2**63  # world seeds are int64
NODE_FEATURES = 12  # PT, PR, S, E as (x / L1, y / L2, z / h): the last entries of the state
# outputs that describe a step rather than the configuration an agent acts from (World(diagnostics=False) skips them)
DIAGNOSTICS = ("r_pu", "r_se", "utility", "moves", "task_switches", "state_index")


class _SharedTables(dict):
    """What every World of one model and device shares, read-only: the grid's tables and a fixed layout's by attribute
    name, ``dynamics`` (the dynamics part, whose tables are per cell) and ``optima`` (a fixed layout's exact optimum by
    method, once solved)."""

    def __init__(self):
        super().__init__()
        self.dynamics: Dynamics | None = None
        self.optima: dict[str, tuple] = {}


# what World._build_geometry computes for the grid
_GRID_TABLES = (
    "_cell_xyz",
    "_state_base",
    "_grid_scale",
    "_node_scale",
    "_cell_xy",
    "_code_cell",
    "_code_task",
    "_code_xyt",
)

# what World._set_layout computes for a layout (and the two-UAV pair tables from them)
_LAYOUT_TABLES = (
    "_cell_contrib",
    "_code_obs",
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


def observation_with_nodes(observation: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
    """``[*, N, F + 12]``: each UAV's observation followed by its world's node positions (the last 12 of ``state``).

    The nodes are the same for every UAV of a world, so the observation leaves
    them out; a network that wants them beside each UAV's features builds this input.
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
        raise InvalidOption(
            "device",
            message=f"device={device!r} is not available: this torch sees {count} CUDA devices "
            "(docs/getting-started.md, Install)",
        )
    return resolved


def check_seed(seed) -> int:
    """``seed`` as an int; a one-line ValueError outside ``[0, 2^63)``."""
    if not isinstance(seed, numbers.Integral) or isinstance(seed, bool):
        raise InvalidType("seed", seed, "give a whole number in [0, 2^63)")
    if not 0 <= seed < SEED_LIMIT:
        raise InvalidOption("seed", seed, "give a whole number in [0, 2^63)")
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

    Per UAV, one ``[B, N]`` tensor for each name of :data:`~uavrl.envs.physics.dynamics.UAV_STATE` (``cell``, ``task``)
    and, under an energy model, of :data:`~uavrl.envs.physics.energy.ENERGY_STATE` (``battery``, ``status``, ``timer``;
    ``None`` without one); per world: ``r`` ``[B, 2]`` the current (R_PU, R_SE); ``best`` the episode's best
    ``R_PU + R_SE`` (the reward part's memory for ``best_so_far``); ``steps`` the episode clock; ``terminated``
    whether the last step ended the episode (``None``: no world's); ``started`` whether a world has been reset;
    ``keys`` and ``counters`` the per-world random streams; ``was_reset`` whether every world has been reset at least
    once (then every UAV has a cell).
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
    )

    def __init__(self, **tensors):
        for name, value in tensors.items():
            setattr(self, name, value)


class World:
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
        B = _check_batch_size(batch_size)
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
        key = (dataclasses.replace(cfg, max_steps=1), str(dev))  # no table depends on the episode's length
        self._shared_tables = shared = _SHARED_TABLES.get(key)
        if shared is None:
            self._shared_tables = shared = _SHARED_TABLES[key] = _SharedTables()
            shared.dynamics = Dynamics(cfg, dev)
        self.dynamics = copy.copy(shared.dynamics)  # its own part (World.to moves it), the same tables
        self.dynamics.cfg = cfg
        self.reward = TeamReward(cfg, self.fading.random)
        self.energy = energy_part(cfg, dev)
        self._slots = self.dynamics.slots  # the cells a UAV's code can name: C, and one off the grid with energy
        self._share(_GRID_TABLES, self._build_geometry)
        # per-layout tables: one shared row for a fixed layout, one per world for random ones (zeros until a reset)
        C, f64 = cfg.num_cells, torch.float64
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
        self._direct = torch.zeros(Bt, 2, dtype=f64, device=dev)
        self._u_star = torch.zeros(Bt, dtype=f64, device=dev)  # U_STAR_REWARDS only: each layout's exact U*
        self._fading_table = None  # the fading part's table, its shape the part's: made by the first layout
        self._world = torch.arange(B, device=dev).unsqueeze(-1)
        # two UAVs on a fixed layout: whole-pair tables (at most 2^16 rows: grids up to 128 cells)
        self._pairs = self.num_uavs == 2 and Bt == 1 and (2 * C) ** 2 <= 1 << 16 and self.energy is None
        self._pair_obs = self._pair_state = self._pair_rates = None
        N, long = self.num_uavs, torch.long
        energy_state = dict.fromkeys(ENERGY_STATE)  # None without an energy model
        if self.energy is not None:
            energy_state.update(
                battery=torch.zeros(B, N, dtype=f64, device=dev),
                status=torch.zeros(B, N, dtype=long, device=dev),
                timer=torch.zeros(B, N, dtype=long, device=dev),
            )
        self._s = _WorldsState(
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
        )
        if fixed is not None:
            self._share(_LAYOUT_TABLES, lambda: self._set_layout(torch.zeros(1, dtype=long, device=dev)))
        self.set_seed(seed)

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
        C = cfg.num_cells
        c = torch.arange(C, device=dev)
        x, y = c % L1, c // L1
        self._cell_xyz = torch.stack([x.to(f64), y.to(f64), torch.full((C,), cfg.height, dtype=f64, device=dev)], -1)
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

    def to(self, device) -> World:
        """Move every tensor the worlds own (parts, tables, state, random streams) to ``device``; returns ``self``.

        Each stream is a pure function of its key and counter (:mod:`.physics.streams`), so the worlds go on from where
        they were and a step gives the same outputs on any device.
        """
        device = resolve_device(device)
        if device != self.device:  # the moved tables are this World's own from now on
            self._shared_tables = _SharedTables()
        for owner in (self, *self.parts.values()):
            for name, value in vars(owner).items():
                if isinstance(value, torch.Tensor):
                    setattr(owner, name, value.to(device))
        for name in _WorldsState.__slots__:
            value = getattr(self._s, name)
            if isinstance(value, torch.Tensor):
                setattr(self._s, name, value.to(device))
        self.device = device
        return self

    @property
    def parts(self) -> dict:
        """The model's parts by name (docs/architecture.md, The World's parts); ``energy`` under an energy model."""
        parts = {"layouts": self.layouts, "fading": self.fading, "dynamics": self.dynamics, "reward": self.reward}
        return parts if self.energy is None else {**parts, "energy": self.energy}

    # ---------------------------------------------------------- sizes
    @property
    def observation_size(self) -> int:
        """Per-UAV features: own (x, y, task), contributions at the own and 4 next cells, the others' (x, y, task);
        under an energy model then its battery (a fraction of the capacity) and service flag, and the others', in
        the same order as their (x, y, task).

        The 4 nodes' positions are the same for every UAV of a world: they are the last
        :data:`NODE_FEATURES` entries of the world's ``state`` (:func:`observation_with_nodes`)."""
        N = self.num_uavs
        return 13 + 3 * (N - 1) + (0 if self.energy is None else 2 * N)

    @property
    def state_size(self) -> int:
        """Per UAV (x, y, task) and its contributions at its cell (under an energy model then per UAV its battery and
        service flag), then the 4 nodes' (x, y, z)."""
        return (5 if self.energy is None else 7) * self.num_uavs + NODE_FEATURES  # (x, y, task, 2 contributions)

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
        gains = link_gains(self._cell_xyz, nodes, cfg)  # [k, C, 4]: the channel model's mean gains
        contrib = relay_contributions(gains, cfg)  # the rate model's per-cell terms
        code_obs, node_obs = self._observation_tables(contrib, nodes)
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

    def _observation_tables(self, contrib: torch.Tensor, nodes: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(code_obs [k, 2C, 13], node_obs [k, 12])`` of ``k`` layouts: what a UAV at each code observes of its
        layout, and the nodes as the state shows them, from the per-cell contributions ``[k, C, 2]`` and the nodes."""
        C, k, K = self.cfg.num_cells, len(contrib), 2 * self._slots
        # observation of a UAV in cell c: its (x, y, task), then the contributions (scaled by the best cell's)
        # at c and at the cells its four moves reach, -1 where a move leaves the grid
        scaled = torch.cat([contrib / contrib.amax(1, keepdim=True), contrib.new_full((k, 1, 2), -1.0)], 1)
        neighbours = self.dynamics.neighbours
        around = torch.cat([torch.arange(C, device=self.device)[:, None], neighbours.where(neighbours >= 0, C)], -1)
        if self._slots > C:  # a UAV out of service (cell C) sees -1 everywhere, adds nothing and relays for no one
            around = torch.cat([around, around.new_full((1, 5), C)])
        local = scaled.index_select(1, around[self._code_cell].flatten()).view(k, K, 10).float()
        code_obs = torch.cat([self._code_xyt.expand(k, -1, -1), local], -1)
        return code_obs, (nodes / self._node_scale).flatten(1).float()

    def _per_cell(self, table: torch.Tensor, cells: torch.Tensor, worlds: torch.Tensor | None = None) -> torch.Tensor:
        """Rows of a per-cell table ``[Bt, C, ...]`` at ``cells`` ``[W, ...]`` of all worlds (or of ``worlds``)."""
        if table.shape[0] == 1:
            return table[0][cells]
        worlds = self._world.squeeze(-1) if worlds is None else worlds
        return table[worlds.view(-1, *([1] * (cells.dim() - 1))), cells]

    # -------------------------------------------------------------- state
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

    def _assemble(
        self, code: torch.Tensor, energy: torch.Tensor | None = None, tables: tuple | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(observation [W, N, F], state [W, S])`` of ``W`` configurations (one per world, or any ``W`` for a fixed
        layout); under an energy model ``energy`` ``[W, N, 2]`` their features (default: the worlds' batteries now);
        ``tables`` ``(code_obs, node_obs)`` of their own layouts (:meth:`_observation_tables`; default: the
        worlds')."""
        W, N = code.shape
        code_obs, node_obs = (self._code_obs, self._node_obs) if tables is None else tables
        own = self._code_rows(code_obs, code)  # [W, N, 13]: x, y, task, 10 contributions
        parts = [own]
        if N == 2:  # the other UAV's (x, y, task)
            parts.append(self._code_xyt.index_select(0, code.flip(-1).view(-1)).view(W, N, 3))
        elif N > 2:
            # the others' (x, y, task), for UAV i in the order i+1, ..., i+N-1 (mod N): a window over the codes twice
            xyt = self._code_xyt.index_select(0, torch.cat([code, code], 1).view(-1))  # [2 W N, 3]
            parts.append(xyt.as_strided((W, N, 3 * (N - 1)), (6 * N, 3, 1), 3))
        per_uav = [own[..., :5].reshape(W, 5 * N)]
        if self.energy is not None:  # then each UAV's battery and service flag: its own, the others' in that order
            energy = self.energy.features(self._s) if energy is None else energy  # [W, N, 2]
            parts.append(energy)
            if N == 2:
                parts.append(energy.flip(1))
            elif N > 2:
                parts.append(torch.cat([energy, energy], 1).as_strided((W, N, 2 * (N - 1)), (4 * N, 2, 1), 2))
            per_uav.append(energy.reshape(W, 2 * N))
        observation = torch.cat(parts, -1) if len(parts) > 1 else own
        state = torch.cat([*per_uav, node_obs.expand(W, NODE_FEATURES)], -1)
        return observation, state

    def energy_features(self, state: torch.Tensor) -> torch.Tensor | None:
        """``[..., N, 2]`` each UAV's battery and service flag as the ``state`` ``[..., S]`` shows them (what
        :meth:`configurations` takes); ``None`` without an energy model."""
        N = self.num_uavs
        return None if self.energy is None else state[..., 5 * N : 7 * N].unflatten(-1, (N, 2))

    def configurations(
        self, code: torch.Tensor, energy: torch.Tensor | None = None, nodes: torch.Tensor | None = None
    ) -> dict:
        """What an agent acts and learns from (``observation``, ``action_mask``, ``state``, ``positions``, ``tasks``)
        of ``W`` configurations given by their codes ``[W, N]`` (``2 cell + task``), under an energy model their
        features ``[W, N, 2]`` (:meth:`energy_features`), with ``layout=random`` their layouts' nodes ``[W, 4, 3]``:
        what :meth:`reset` and :meth:`step` returned for them, bit for bit.  For a replay buffer that keeps
        configurations rather than observations.

        Example:
            >>> from uavrl.envs import make_config
            >>> world = World(make_config("paper", grid=(4, 4), num_uavs=3), batch_size=2)
            >>> out = world.reset()
            >>> again = world.configurations(world.code)
            >>> all(torch.equal(out[key], again[key]) for key in again)
            True
        """
        if (self.energy is None) != (energy is None) or (self.layouts.fixed is None) == (nodes is None):
            raise ValueError(
                "World.configurations takes energy features exactly under an energy model (env.energy other than "
                "none) and nodes exactly with env.layout=random"
            )
        tables = None
        if nodes is not None:
            tables = self._observation_tables(
                relay_contributions(link_gains(self._cell_xyz, nodes, self.cfg), self.cfg), nodes
            )
        observation, state = self._assemble(code, energy, tables)
        return self._outputs(observation, state, code >> 1, code & 1)

    def _outputs(self, observation, state, cell: torch.Tensor, task: torch.Tensor) -> dict:
        """The outputs an agent acts from, of configurations ``cell``, ``task`` ``[W, N]`` (their observation and
        state assembled)."""
        W, N = cell.shape
        return {
            "observation": observation,
            "action_mask": self.dynamics.masks(cell),
            "state": state,
            "positions": self._cell_xy.index_select(0, cell.view(-1)).view(W, N, 2),
            "tasks": task,
        }

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

    def _observe(self, code: torch.Tensor, cell: torch.Tensor, task: torch.Tensor, moves, switches) -> dict:
        """The outputs of the configurations ``cell``, ``task`` ``[B, N]`` (``code`` their codes) after a step;
        ``moves()`` and ``switches()`` count the step's moves and task switches ``[B]`` (called for the diagnostics
        only)."""
        B, N = self.num_worlds, self.num_uavs
        if self._pair_obs is not None:
            pair = torch.add(code.flip(-1), code, alpha=2 * self.cfg.num_cells)  # [B, 2]: rows (a, b) and (b, a)
            observation = self._pair_obs.index_select(0, pair.view(-1)).view(B, N, -1)
            state = self._pair_state.index_select(0, pair[:, 0])
        else:
            observation, state = self._assemble(code)
        out = self._outputs(observation, state, cell, task.clone())  # the state's own tensor stays the World's
        if not self.diagnostics:
            return out
        r = self._s.r.float()
        out.update(r_pu=r[:, 0], r_se=r[:, 1], utility=r[:, 0] + r[:, 1], moves=moves(), task_switches=switches())
        if self._state_base is not None:
            digits = code if self.cfg.state_includes_tasks else cell
            index = digits[:, N - 1]
            for i in range(N - 2, -1, -1):  # Horner: d_0 + base (d_1 + base (...)); sums over tiny dims are slow
                index = torch.add(digits[:, i], index, alpha=self._state_base)
            out["state_index"] = index.clone() if N == 1 else index
        return out

    def _direct_of(self, worlds: torch.Tensor | None) -> torch.Tensor:
        """Direct-link SNRs ``[Bt or W, 2]`` broadcastable to all worlds (or to ``worlds``)."""
        return self._direct if worlds is None or len(self._direct) == 1 else self._direct[worlds]

    def _rates(
        self, cell: torch.Tensor, task: torch.Tensor, code: torch.Tensor, worlds: torch.Tensor | None = None
    ) -> torch.Tensor:
        """``[W, 2]`` (R_PU, R_SE) of the configurations ``cell``, ``task`` (``code``) ``[W, N]`` of all worlds (or of
        ``worlds``): a fresh draw of a random channel (the fading part), else the mean channel's per-code tables."""
        cfg = self.cfg
        if not self.fading.random:
            if self._pair_rates is not None:
                return self._pair_rates.index_select(0, torch.add(code[:, 1], code[:, 0], alpha=2 * cfg.num_cells))
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
        s.terminated = None
        s.r = self._rates(s.cell, s.task, code)
        s.was_reset = True
        return self._observe(code, s.cell, s.task, self._no_counts, self._no_counts)

    def _no_counts(self) -> torch.Tensor:
        """``[B]`` zero moves or switches (a reset)."""
        return torch.zeros(self.num_worlds, dtype=torch.long, device=self.device)

    def step(self, action: torch.Tensor) -> tuple[dict, torch.Tensor, torch.Tensor]:
        """Every world takes the UAVs' ``action`` ``[B, N]`` (0..5, 6 to return under recharging; checked by the
        caller).

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
        s.terminated = self.dynamics.terminated(s) if self.energy is None else self.energy.terminated(s)
        new_cell, new_task = s.cell, s.task
        out = self._observe(
            code, new_cell, new_task, lambda: (new_cell != cell).sum(-1), lambda: (new_task != task).sum(-1)
        )
        return out, reward, s.steps >= self.cfg.max_steps

    def _advance(self, state, action: torch.Tensor) -> torch.Tensor:
        """Set ``state``'s per-UAV variables (:data:`~.physics.dynamics.UAV_STATE`,
        :data:`~.physics.energy.ENERGY_STATE`) to those after the joint actions ``[W, N]``: the dynamics part's step,
        then the energy part's; returns the codes ``2 cell + task`` after it."""
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

        ``state``: ``[W, N]`` tensors by the names of :data:`~.physics.dynamics.UAV_STATE` (and
        :data:`~.physics.energy.ENERGY_STATE` under an energy model); ``action`` ``[W, N]``; ``worlds`` ``[W]``: whose
        layout each row is in (``None``: a fixed layout's).  Returns the variables after the step and the deterministic
        ``(R_PU, R_SE)`` ``[W, 2]`` float64 of the configurations they reach (the mean channel: a random channel is
        refused).
        """
        if self.fading.random:
            raise ValueError(f"World.successors reads deterministic channels: fading={self.cfg.fading!r} is random")
        if worlds is None and self.layouts.fixed is None:
            raise ValueError("World.successors needs worlds=[W] under layout='random': each world has its own layout")
        after = _WorldsState(**state)
        code = self._advance(after, action)
        names = UAV_STATE + (ENERGY_STATE if self.energy is not None else ())
        return {name: getattr(after, name) for name in names}, self._rates(after.cell, after.task, code, worlds)

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
        if self.energy is not None:  # a UAV out of service is at the base: it adds nothing
            away = (x == self.cfg.base[0]) & (y == self.cfg.base[1])
            off_grid, tasks = off_grid & ~away, tasks.masked_fill(away, SENSING)
            positions = positions.masked_fill(away.unsqueeze(-1), 0)
        if off_grid.any():
            where = tuple(positions[off_grid][0].tolist())
            raise ValueError(f"positions hold {where}, off the {L1}x{L2} grid: x lies in 0..{L1 - 1}, y in 0..{L2 - 1}")
        bad_task = (tasks != SENSING) & (tasks != RELAYING)
        if bad_task.any():
            raise ValueError(f"tasks hold {tasks[bad_task][0].item()}: a task is 0 (sensing) or 1 (relaying)")
        cells = self.cells_of(positions)
        contrib = self._per_cell(self._cell_contrib, cells)
        if self.energy is not None:
            contrib = contrib.masked_fill(away.unsqueeze(-1), 0.0)
        direct = self.direct.view(self.num_worlds, *([1] * (cells.dim() - 2)), 2)
        r_pu, r_se = rates(contrib, tasks, direct, self.cfg)
        return r_pu, r_se, r_pu + r_se

    def optimum(self, method: str = "auto") -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Exact ``U*`` ``[B]`` and one optimal configuration per world (positions ``[B, N, 2]``, tasks ``[B, N]``).

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
        B, L1 = self.num_worlds, self.cfg.grid[0]
        if len(u) != B:
            u, cells, tasks = u.expand(B), cells.expand(B, -1), tasks.expand(B, -1)
        return u.clone(), torch.stack([cells % L1, cells // L1], -1), tasks.clone()

    def joint_action_mask(self, positions: torch.Tensor | None = None) -> torch.Tensor:
        """``[B, 6^N]`` valid joint actions (all cells on the grid and distinct) at ``positions`` (default: now).

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
        row = cells.unsqueeze(-2) * NUM_ACTIONS + actions  # [..., A, N]: each UAV's (cell, action) row
        allowed = self.dynamics.cell_mask.view(-1).index_select(0, row.view(-1)).view_as(row)
        target = self.dynamics.move_to.index_select(0, row.view(-1)).view_as(row)
        # the UAVs away all sit on one cell: give each its own, past the grid's, so they clash with no one
        target = torch.where(target == self.energy.away, self.energy.away + torch.arange(N, device=self.device), target)
        return allowed.all(-1) & targets_valid(target)

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
        return self.dynamics.neighbours

    @property
    def battery(self) -> torch.Tensor | None:
        """``[B, N]`` float64 every UAV's battery now, in the energy model's units; ``None`` without one."""
        return None if self._s.battery is None else self._s.battery.clone()

    @property
    def status(self) -> torch.Tensor | None:
        """``[B, N]`` every UAV's status now (:data:`~uavrl.envs.physics.energy.SERVING` ... ``WAITING``); ``None``
        without an energy model."""
        return None if self._s.status is None else self._s.status.clone()
