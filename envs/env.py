"""The batched TorchRL environment of the UAV spectrum-sharing model (SPEC.md).

``B`` independent worlds live in one set of tensors; a step is a fixed handful
of tensor operations whatever ``B`` is, on CPU or CUDA.
"""
from __future__ import annotations

import math

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Binary, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from . import streams
from .channel import best_so_far_reward, delta_reward, direct_terms, fixed_layout, link_gains, rates, relay_contributions
from .config import NUM_ACTIONS, RELAYING, SENSING, ModelConfig, make_config
from .optimum import optimum as exact_optimum

# (dx, dy) of the four moves: up, down, left, right (SPEC section 2)
MOVES = ((0, -1), (0, 1), (-1, 0), (1, 0))
# purposes of the per-world random streams
_POSITIONS, _TASKS, _FADING, _FADING_DIRECT, _LAYOUT = 1, 2, 3, 4, 16


def _check_batch_size(batch_size) -> int:
    size = batch_size if isinstance(batch_size, int) else (list(batch_size) or [None])[0]
    if isinstance(batch_size, (list, tuple, torch.Size)) and len(batch_size) != 1 or not isinstance(size, int) or size < 1:
        raise ValueError(f"batch_size={batch_size!r} is invalid: give the number of worlds B >= 1 (an int or [B])")
    return size


class UAVSpectrumEnv(EnvBase):
    """``B`` worlds of N UAVs that relay for a primary link or sense for an emergency centre.

    Each step every UAV takes one of 6 actions (0 up, 1 down, 2 left, 3 right,
    4 sensing task, 5 relaying task); the team reward is the change of
    ``beta1 R_PU + beta2 R_SE`` (``reward="delta"``) or the authors'
    best-so-far reward.  Episodes end by truncation after ``max_steps``.

    Keys follow TorchRL's multi-agent convention: a group ``"agents"`` of batch
    ``[B, N]`` with ``observation``, ``action`` and ``action_mask``; at the root
    ``reward``, ``done``/``terminated``/``truncated``, a global ``state``, the
    integer views ``positions`` ``[B, N, 2]`` (x, y), ``tasks`` ``[B, N]`` and
    ``state_index`` ``[B]`` (when the tabular state fits in int64), and the
    step's ``r_pu``, ``r_se``, ``utility``, ``moves``, ``task_switches``.

    World ``i`` draws its randomness from its own stream seeded ``seed + i``, so
    it behaves exactly like world 0 of a batch of one seeded ``seed + i``.

    Args:
        batch_size: number of independent worlds ``B``.
        grid: ``(L1, L2)`` cells.
        num_uavs: ``N``, at most ``L1 * L2``.
        preset: ``"paper"`` or ``"reference_code"`` (SPEC section 8).
        seed: seed of world 0.
        device: where the worlds live.
        max_steps: episode length ``T``.
        config: a complete :class:`~uavrl.envs.config.ModelConfig`; replaces
            ``grid``, ``num_uavs``, ``preset``, ``max_steps`` and the overrides.
        **overrides: any :class:`~uavrl.envs.config.ModelConfig` option
            (``layout``, ``fading``, ``reward``, powers, ...).

    Example:
        >>> env = UAVSpectrumEnv(batch_size=4, grid=(6, 6), num_uavs=2, max_steps=10)
        >>> td = env.rollout(10)
        >>> td["next", "utility"].shape
        torch.Size([4, 10])
        >>> u_star, positions, tasks = env.optimum()
    """

    batch_locked = True

    def __init__(self, batch_size=1, grid=(6, 6), num_uavs=2, preset="paper", seed=0, device="cpu", max_steps=100, *, config: ModelConfig | None = None, **overrides):
        if config is not None and overrides:
            raise ValueError(f"give either config= or model options, not both (got {sorted(overrides)})")
        cfg = config or make_config(preset, grid=grid, num_uavs=num_uavs, max_steps=max_steps, **overrides)
        B = _check_batch_size(batch_size)
        super().__init__(device=device, batch_size=torch.Size([B]))
        self.cfg: ModelConfig = cfg
        self.num_worlds, self.num_uavs = B, cfg.num_uavs
        L1, L2 = cfg.grid
        C, N, dev, f64 = cfg.num_cells, cfg.num_uavs, self.device, torch.float64
        # static geometry: the target cell of each move, -1 when it leaves the grid
        c = torch.arange(C, device=dev)
        x, y = c % L1, c // L1
        nbrs = []
        for dx, dy in MOVES:
            nx, ny = x + dx, y + dy
            inside = (nx >= 0) & (nx < L1) & (ny >= 0) & (ny < L2)
            nbrs.append(torch.where(inside, ny * L1 + nx, -1))
        self._neighbours = torch.stack(nbrs, -1)  # [C, 4]
        self._cell_xyz = torch.stack([x.to(f64), y.to(f64), torch.full((C,), cfg.height, dtype=f64, device=dev)], -1)
        self._others = (torch.arange(N, device=dev)[:, None] + torch.arange(1, N, device=dev)) % N  # [N, N-1]
        base = 2 * C if cfg.state_includes_tasks else C
        self._state_weights = torch.tensor([base**i for i in range(N)], device=dev) if cfg.has_state_index else None
        self._grid_scale = torch.tensor([max(L1 - 1, 1), max(L2 - 1, 1)], dtype=f64, device=dev)
        self._node_scale = torch.tensor([L1, L2, cfg.height], dtype=f64, device=dev)
        layout = fixed_layout(cfg, f64, dev)
        if layout is not None:
            d = torch.cdist(self._cell_xyz, layout).min()
            if d == 0:
                raise ValueError(
                    f"grid={cfg.grid} is invalid for layout={cfg.layout!r}: a node sits on a UAV cell at UAV altitude (zero distance); use a smaller grid or layout='line'"
                )
        # per-cell tables of the layout: one shared row for a fixed layout, one per world for random ones
        Bt = 1 if layout is not None else B
        self._cell_xy = torch.stack([x, y], -1)  # [C, 2]
        self._cell_mask = torch.cat([self._neighbours >= 0, torch.ones(C, 2, dtype=torch.bool, device=dev)], -1)  # [C, 6]
        self._nodes = (layout if layout is not None else torch.zeros(4, 3, dtype=f64, device=dev)).expand(Bt, 4, 3).clone()
        self._cell_gains = torch.zeros(Bt, C, 4, dtype=f64, device=dev)
        self._cell_contrib = torch.zeros(Bt, C, 2, dtype=f64, device=dev)
        self._cell_obs = torch.zeros(Bt, C, 12, dtype=torch.float32, device=dev)
        self._node_obs = torch.zeros(Bt, 12, dtype=torch.float32, device=dev)
        self._direct = torch.zeros(Bt, 2, dtype=f64, device=dev)
        self._world = torch.arange(B, device=dev).unsqueeze(-1)
        self._pos = torch.zeros(B, N, dtype=torch.long, device=dev)
        self._tasks = torch.zeros(B, N, dtype=torch.long, device=dev)
        self._r = torch.zeros(B, 2, dtype=f64, device=dev)
        self._best = torch.zeros(B, dtype=f64, device=dev)
        self._steps = torch.zeros(B, dtype=torch.long, device=dev)
        self._started = torch.zeros(B, dtype=torch.bool, device=dev)
        self._counters = torch.zeros(B, dtype=torch.long, device=dev)
        self._keys = streams.world_keys(0, B, dev)
        if layout is not None:
            self._set_layout(torch.ones(1, dtype=torch.bool, device=dev))
        self._make_specs()
        self.set_seed(seed)

    # ------------------------------------------------------------------ specs
    @property
    def observation_size(self) -> int:
        """Per-UAV features: own (x, y, task), contributions at the own and 4 next cells, the others' (x, y, task), the 4 nodes."""
        return 3 + 10 + 3 * (self.num_uavs - 1) + 12

    @property
    def state_size(self) -> int:
        return 5 * self.num_uavs + 12

    def _make_specs(self):
        N, L1, L2 = self.num_uavs, *self.cfg.grid
        agents = Composite(
            observation=Unbounded((N, self.observation_size), dtype=torch.float32, device=self.device),
            action_mask=Binary(n=NUM_ACTIONS, shape=(N, NUM_ACTIONS), dtype=torch.bool, device=self.device),
            shape=(N,),
            device=self.device,
        )
        obs = Composite(
            agents=agents,
            state=Unbounded((self.state_size,), dtype=torch.float32, device=self.device),
            positions=Unbounded((N, 2), dtype=torch.long, device=self.device),
            tasks=Categorical(2, (N,), dtype=torch.long, device=self.device),
            r_pu=Unbounded((), dtype=torch.float32, device=self.device),
            r_se=Unbounded((), dtype=torch.float32, device=self.device),
            utility=Unbounded((), dtype=torch.float32, device=self.device),
            moves=Unbounded((), dtype=torch.long, device=self.device),
            task_switches=Unbounded((), dtype=torch.long, device=self.device),
            device=self.device,
        )
        if self._state_weights is not None:
            obs["state_index"] = Unbounded((), dtype=torch.long, device=self.device)
        self.full_observation_spec_unbatched = obs
        self.full_action_spec_unbatched = Composite(
            agents=Composite(action=Categorical(NUM_ACTIONS, (N,), dtype=torch.long, device=self.device), shape=(N,), device=self.device),
            device=self.device,
        )
        self.full_reward_spec_unbatched = Composite(reward=Unbounded((1,), dtype=torch.float32, device=self.device), device=self.device)
        self.full_done_spec_unbatched = Composite(
            {k: Categorical(2, (1,), dtype=torch.bool, device=self.device) for k in ("done", "terminated", "truncated")},
            device=self.device,
        )

    # --------------------------------------------------------------- seeding
    def _set_seed(self, seed: int | None):
        seed = 0 if seed is None else int(seed)
        self._keys = streams.world_keys(seed, self.num_worlds, self.device)
        self._counters.zero_()
        self._started.zero_()

    # ---------------------------------------------------------------- layout
    def _set_layout(self, mask: torch.Tensor):
        """Recompute the per-cell tables of the worlds in ``mask`` from ``self._nodes``."""
        cfg, C = self.cfg, self.cfg.num_cells
        gains = link_gains(self._cell_xyz, self._nodes, cfg)  # [Bt, C, 4]
        contrib = relay_contributions(gains, cfg)
        # observation of a UAV in cell c: its (x, y), then the contributions (scaled by the best cell's)
        # at c and at the cells its four moves reach, -1 where a move leaves the grid
        scaled = torch.cat([contrib / contrib.amax(1, keepdim=True), contrib.new_full((contrib.shape[0], 1, 2), -1.0)], 1)
        local = scaled[:, torch.cat([torch.arange(C, device=self.device)[:, None], self._neighbours.where(self._neighbours >= 0, C)], -1)]
        obs = torch.cat([(self._cell_xy / self._grid_scale).unsqueeze(0).expand(len(mask), -1, -1), local.flatten(2)], -1).float()
        node_obs = (self._nodes / self._node_scale).flatten(1).float()
        m = mask[:, None, None]
        self._cell_gains = torch.where(m, gains, self._cell_gains)
        self._cell_contrib = torch.where(m, contrib, self._cell_contrib)
        self._cell_obs = torch.where(m, obs, self._cell_obs)
        self._node_obs = torch.where(mask[:, None], node_obs, self._node_obs)
        self._direct = torch.where(mask[:, None], direct_terms(self._nodes, cfg), self._direct)

    def _per_cell(self, table: torch.Tensor, cells: torch.Tensor) -> torch.Tensor:
        """Rows of a per-cell table ``[Bt, C, ...]`` at ``cells`` ``[B, ...]``."""
        if table.shape[0] == 1:
            return table[0][cells]
        return table[self._world.view(-1, *([1] * (cells.dim() - 1))), cells]

    def _sample_layout(self, mask: torch.Tensor):
        """``layout=random``: nodes uniform in the grid widened by half a grid per side (SPEC section 1).

        PT-PR and S-E must be at least 0.6 grid diagonals apart.  Decision: S and E
        (at UAV altitude) must also be at least half a cell from every cell centre,
        so no UAV is ever at distance 0 from a node.  Rejection rounds run until
        every world in ``mask`` is accepted; each world uses only its own stream.
        """
        L1, L2 = self.cfg.grid
        h = self.cfg.height
        lo = torch.tensor([-L1 / 2, -L2 / 2], dtype=torch.float64, device=self.device)
        span = torch.tensor([2.0 * L1, 2.0 * L2], dtype=torch.float64, device=self.device)
        min_sep = 0.6 * math.hypot(L1, L2)
        nodes = self._nodes.clone()  # [B, 4, 3]
        for pair, z in ((0, 0.0), (1, h)):  # (PT, PR) on the ground, (S, E) at UAV altitude
            pending = mask.clone()
            rnd = 0
            while bool(pending.any()):
                u = streams.uniform(self._keys, self._counters, _LAYOUT + 2 * rnd + pair, 4)
                xy = lo + span * u.view(-1, 2, 2)
                ok = torch.linalg.vector_norm(xy[:, 0] - xy[:, 1], dim=-1) >= min_sep
                if z > 0:
                    nearest = torch.stack([xy[..., 0].round().clamp(0, L1 - 1), xy[..., 1].round().clamp(0, L2 - 1)], -1)
                    ok &= (torch.linalg.vector_norm(xy - nearest, dim=-1) >= 0.5).all(-1)
                take = pending & ok
                xyz = torch.cat([xy, xy.new_full(xy.shape[:-1] + (1,), z)], -1)
                nodes[:, 2 * pair : 2 * pair + 2] = torch.where(take[:, None, None], xyz, nodes[:, 2 * pair : 2 * pair + 2])
                pending &= ~ok
                rnd += 1
        self._nodes = torch.where(mask[:, None, None], nodes, self._nodes)
        self._set_layout(mask)

    # -------------------------------------------------------------- dynamics
    def _observe(self, moves: torch.Tensor, switches: torch.Tensor) -> TensorDict:
        B, N = self.num_worlds, self.num_uavs
        pos, tasks = self._pos, self._tasks
        cell_obs = self._per_cell(self._cell_obs, pos)  # [B, N, 12]
        task_f = tasks.unsqueeze(-1).float()
        xyt = torch.cat([cell_obs[..., :2], task_f], -1)
        nodes = self._node_obs.unsqueeze(1).expand(B, N, 12)
        observation = torch.cat([cell_obs[..., :2], task_f, cell_obs[..., 2:], xyt[:, self._others].flatten(2), nodes], -1)
        state = torch.cat([xyt, cell_obs[..., 2:4]], -1).flatten(1)
        r = self._r.float()
        out = {
            "agents": TensorDict({"observation": observation, "action_mask": self._cell_mask[pos]}, batch_size=(B, N), device=self.device),
            "state": torch.cat([state, nodes[:, 0]], -1),
            "positions": self._cell_xy[pos],
            "tasks": tasks.clone(),
            "r_pu": r[:, 0],
            "r_se": r[:, 1],
            "utility": r.sum(-1),
            "moves": moves,
            "task_switches": switches,
        }
        if self._state_weights is not None:
            digits = 2 * pos + tasks if self.cfg.state_includes_tasks else pos
            out["state_index"] = (digits * self._state_weights).sum(-1)
        return TensorDict(out, batch_size=self.batch_size, device=self.device)

    def _current_rates(self) -> torch.Tensor:
        """``[B, 2]`` (R_PU, R_SE) of the current configuration, drawing fresh fading if enabled."""
        direct = self._direct.expand(self.num_worlds, 2)
        if self.cfg.fading == "none":
            contrib = self._per_cell(self._cell_contrib, self._pos)
        else:
            gains = self._per_cell(self._cell_gains, self._pos)
            u = streams.uniform(self._keys, self._counters, _FADING, 4 * self.num_uavs).view_as(gains)
            contrib = relay_contributions(gains * -torch.log1p(-u), self.cfg)  # Exp(1) power gain per link
            if self.cfg.direct_links:  # the direct links PT->PR and S->E fade too
                direct = direct * -torch.log1p(-streams.uniform(self._keys, self._counters, _FADING_DIRECT, 2))
        return torch.stack(rates(contrib, self._tasks, direct, self.cfg), -1)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        B, N, C, cfg = self.num_worlds, self.num_uavs, self.cfg.num_cells, self.cfg
        mask = tensordict.get("_reset", None) if tensordict is not None else None
        mask = torch.ones(B, dtype=torch.bool, device=self.device) if mask is None else mask.reshape(B).to(self.device)
        self._counters += mask
        if cfg.layout == "random":
            self._sample_layout(mask)
        fresh = mask & ~self._started if cfg.reset_positions == "keep" else mask
        # distinct cells: the N smallest of C random keys; tasks per init_tasks
        cells = streams.random_bits(self._keys, self._counters, _POSITIONS, C).topk(N, dim=-1, largest=False).indices
        if cfg.init_tasks == "random":
            tasks = streams.random_bits(self._keys, self._counters, _TASKS, N) & 1
        else:
            tasks = torch.full((B, N), RELAYING if cfg.init_tasks == "relaying" else SENSING, device=self.device)
        self._pos = torch.where(fresh[:, None], cells, self._pos)
        self._tasks = torch.where(fresh[:, None], tasks, self._tasks)
        self._started |= mask
        self._steps = torch.where(mask, 0, self._steps)
        self._best = torch.where(mask, 0.0, self._best)
        self._r = torch.where(mask[:, None], self._current_rates(), self._r)
        zeros = torch.zeros(B, dtype=torch.long, device=self.device)
        out = self._observe(zeros, zeros)
        done = torch.zeros(B, 1, dtype=torch.bool, device=self.device)
        out.update({"done": done, "terminated": done.clone(), "truncated": done.clone()})
        return out

    def _resolve_moves(self, action: torch.Tensor) -> torch.Tensor:
        """Target cells of a joint action, made valid as SPEC section 2 decides.

        Off-grid moves stay; then, until all targets differ, every moving UAV whose
        target another UAV also targets (a mover or a stayer) is cancelled.
        """
        pos = self._pos
        target = torch.gather(self._neighbours[pos], -1, action.clamp(max=3).unsqueeze(-1)).squeeze(-1)
        target = torch.where((action < 4) & (target >= 0), target, pos)
        eye = torch.eye(self.num_uavs, dtype=torch.bool, device=self.device)
        for _ in range(self.num_uavs):
            clash = ((target.unsqueeze(-1) == target.unsqueeze(-2)) & ~eye).any(-1) & (target != pos)
            if not bool(clash.any()):
                break
            target = torch.where(clash, pos, target)
        return target

    def _check_action(self, action: torch.Tensor):
        shape = (self.num_worlds, self.num_uavs)
        if tuple(action.shape) != shape:
            raise ValueError(f"('agents', 'action') has shape {tuple(action.shape)}: expected {shape} (worlds, UAVs)")
        if action.dtype.is_floating_point or action.dtype.is_complex or action.dtype == torch.bool:
            raise TypeError(f"('agents', 'action') has dtype {action.dtype}: expected an integer dtype with values 0..5")
        if bool(((action < 0) | (action >= NUM_ACTIONS)).any()):
            bad = action[(action < 0) | (action >= NUM_ACTIONS)][0].item()
            raise ValueError(f"('agents', 'action') holds {bad}: actions are 0..5 (up, down, left, right, sense, relay)")

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get(("agents", "action"))
        self._check_action(action)
        action = action.long()
        cfg = self.cfg
        target = self._resolve_moves(action)
        tasks = torch.where(action == 4, SENSING, torch.where(action == 5, RELAYING, self._tasks))
        moves = (target != self._pos).sum(-1)
        switches = (tasks != self._tasks).sum(-1)
        self._pos, self._tasks = target, tasks
        self._counters += 1
        prev = self._r
        self._r = self._current_rates()
        if cfg.reward == "delta":
            reward = delta_reward(self._r[:, 0], self._r[:, 1], prev[:, 0], prev[:, 1], cfg.beta1, cfg.beta2)
        else:
            total = self._r.sum(-1)
            reward = best_so_far_reward(total, self._best)
            self._best = torch.maximum(self._best, total)
        self._steps += 1
        out = self._observe(moves, switches)
        truncated = (self._steps >= cfg.max_steps).unsqueeze(-1)
        out.update(
            {
                "reward": reward.float().unsqueeze(-1),
                "done": truncated,
                "terminated": torch.zeros_like(truncated),
                "truncated": truncated.clone(),
            }
        )
        return out

    # ------------------------------------------------------ shared helpers
    def cells_of(self, positions: torch.Tensor) -> torch.Tensor:
        """Cell indices ``y * L1 + x`` of ``[..., 2]`` (x, y) positions."""
        return positions[..., 1] * self.cfg.grid[0] + positions[..., 0]

    def utility(self, positions: torch.Tensor, tasks: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(R_PU, R_SE, U)`` of configurations of this env's worlds, deterministic channels.

        ``positions`` ``[B, ..., N, 2]`` (x, y) and ``tasks`` ``[B, ..., N]``; results ``[B, ...]`` float64.
        """
        self._require_layout()
        positions, tasks = positions.to(self.device), tasks.to(self.device)
        if positions.shape[0] != self.num_worlds or positions.shape[-2:] != (self.num_uavs, 2) or tasks.shape != positions.shape[:-1]:
            raise ValueError(
                f"positions {tuple(positions.shape)} / tasks {tuple(tasks.shape)} do not fit: expected [B={self.num_worlds}, ..., N={self.num_uavs}, 2] and [B, ..., N]"
            )
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
        u, cells, tasks = exact_optimum(self.cell_contributions, self.direct, self.cfg, method=method)
        L1 = self.cfg.grid[0]
        return u, torch.stack([cells % L1, cells // L1], -1), tasks

    def joint_action_mask(self, positions: torch.Tensor | None = None) -> torch.Tensor:
        """``[B, 6^N]`` valid joint actions (all cells on the grid and distinct) at ``positions`` (default: now)."""
        cells = self._pos if positions is None else self.cells_of(positions.to(self.device))
        return joint_action_valid(cells, self._neighbours, self.num_uavs)

    def _require_layout(self):
        if self.cfg.layout == "random" and not bool(self._started.all()):
            raise RuntimeError("layout='random' draws each world's layout at reset: call env.reset() first")

    @property
    def cell_contributions(self) -> torch.Tensor:
        """``[B, C, 2]`` per-cell relay (PU) and sensing (SE) contributions, deterministic channels."""
        return self._cell_contrib.expand(self.num_worlds, -1, -1)

    @property
    def direct(self) -> torch.Tensor:
        """``[B, 2]`` direct-link SNRs (PT->PR, S->E)."""
        return self._direct.expand(self.num_worlds, -1)

    @property
    def neighbours(self) -> torch.Tensor:
        """``[C, 4]`` target cell of each move, -1 off the grid."""
        return self._neighbours


MAX_JOINT_ACTIONS = 6**7


def decode_joint_actions(num_uavs: int, device=None) -> torch.Tensor:
    """``[6^N, N]`` per-UAV actions of every joint action ``j = sum_i a_i 6^i``."""
    if NUM_ACTIONS**num_uavs > MAX_JOINT_ACTIONS:
        raise ValueError(f"num_uavs={num_uavs} has 6^{num_uavs} joint actions: joint-action tables allow N <= 7")
    j = torch.arange(NUM_ACTIONS**num_uavs, device=device)
    return torch.stack([(j // NUM_ACTIONS**i) % NUM_ACTIONS for i in range(num_uavs)], -1)


def joint_targets(cells: torch.Tensor, neighbours: torch.Tensor, num_uavs: int) -> torch.Tensor:
    """``[..., 6^N, N]`` target cell of every UAV under every joint action from ``[..., N]`` cells (-1: off the grid)."""
    actions = decode_joint_actions(num_uavs, cells.device)  # [A, N]
    moves = neighbours[cells].unsqueeze(-3).expand(*cells.shape[:-1], actions.shape[0], num_uavs, 4)  # [..., A, N, 4]
    moved = torch.gather(moves, -1, actions.clamp(max=3).expand_as(moves[..., 0]).unsqueeze(-1)).squeeze(-1)
    return torch.where(actions < 4, moved, cells.unsqueeze(-2))


def joint_action_valid(cells: torch.Tensor, neighbours: torch.Tensor, num_uavs: int) -> torch.Tensor:
    """``[..., 6^N]`` validity of every joint action at cell configurations ``[..., N]``: on the grid, cells distinct."""
    target = joint_targets(cells, neighbours, num_uavs)
    ordered = target.sort(-1).values
    return (target >= 0).all(-1) & (ordered[..., 1:] != ordered[..., :-1]).all(-1)
