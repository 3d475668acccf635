"""Exact optimal control of deterministic channels: the yardstick every agent is measured against.

UAVs are interchangeable (the utility and the moves do not depend on which UAV
is which), so a configuration is a set of N (cell, task) pairs on distinct
cells.  :class:`ConfigurationSpace` numbers these sets,
``k = rank(cells) * 2^N + sum_i task_i 2^i`` (cells sorted, ``rank`` their
combinatorial number, tasks in cell order), and tabulates for every set and
every joint action of its UAVs (taken in cell order) the set it leads to, or
``-1`` for an invalid joint action.  The tables come from the environment's own
dynamics (:mod:`uavrl.envs.physics.grid`) and rates (:func:`uavrl.envs.physics.channel.rates`).

On that graph, for a potential ``P`` (the utility ``U`` for the yardstick,
``beta1 R_PU + beta2 R_SE`` for an agent's delta reward):

- :func:`optimal_values`: backward induction of
  ``V_h(s) = max_valid a [P(s') - P(s) + gamma V_{h-1}(s')]``, ``V_0 = 0``: the
  best discounted sum of ``H`` rewards (``V*_H``), or, without a horizon,
  iterated to its fixed point (the infinite-horizon ``V*``);
- :meth:`ConfigurationSpace.q_values`: ``Q(s, a) = P(s') - P(s) + gamma V(s')``
  at ordered configurations (UAV ``i`` is UAV ``i``);
- :func:`min_steps`: breadth-first distances to a target set (the fewest steps
  to reach, say, ``U >= 0.99 U*``).

Example:
    >>> from uavrl.envs.config import make_config
    >>> cfg = make_config("paper", grid=(3, 3), num_uavs=2)
    >>> space = ConfigurationSpace(cfg.grid, cfg.num_uavs)
    >>> space.num_configurations, space.successors.shape  # C(9, 2) cell sets x 4 task vectors, 36 joint actions
    (144, torch.Size([144, 36]))
    >>> u = space.utility(cfg, *fixed_layout_tables(cfg))
    >>> v = optimal_values(space, u, gamma=0.9, horizon=10)
    >>> bool((v >= 0).all())  # staying put is always allowed, so no start is worth less than 0
    True
"""

from __future__ import annotations

import math

import torch

from ..config import ModelConfig
from ..limits import EXACT_SOLVER_BUDGET, exact_solver_fits, num_configurations, required_bytes
from ..physics.channel import direct_terms, fixed_layout, link_gains, rates, relay_contributions
from ..physics.grid import grid_neighbours, joint_next_tasks, joint_targets, targets_valid
from ..physics.positions import model_positions

MEMORY_BUDGET = EXACT_SOLVER_BUDGET  # bytes of the successor table and one solver sweep

_CHUNK_ELEMENTS = 1 << 23  # gathered values per torch call (uavrl.envs.limits.required_bytes counts it)
_MAX_SWEEPS = 100_000
CONVERGENCE_TOLERANCE = 1e-12  # infinite horizon: stop when a sweep changes no value by more than this x max |P|
UNREACHABLE = torch.iinfo(torch.int32).max


def fits(cfg: ModelConfig, memory_budget: int = MEMORY_BUDGET) -> bool:
    """Whether :class:`ConfigurationSpace` of ``cfg``'s positions and team fits ``memory_budget``."""
    return exact_solver_fits(cfg.num_positions, cfg.num_uavs, memory_budget, cfg.joint_action_base)


def model_space(cfg: ModelConfig, device="cpu", memory_budget: int = MEMORY_BUDGET) -> ConfigurationSpace:
    """The :class:`ConfigurationSpace` of the model ``cfg``: its team on its positions (every altitude level, no
    position inside a building)."""
    neighbours = None if cfg.num_levels == 1 else model_positions(cfg, device).neighbours
    return ConfigurationSpace(cfg.grid, cfg.num_uavs, device, memory_budget, neighbours)


def fixed_layout_tables(cfg: ModelConfig, device=None) -> tuple[torch.Tensor, torch.Tensor]:
    """``(contributions [1, C, 2], direct [1, 2])`` of a fixed layout (not ``layout=random``), from the channel
    model.

    Args:
        cfg: the model; ``layout="random"`` is refused with one line.
        device: the torch device of the tables (float64).
    """
    nodes = fixed_layout(cfg, torch.float64, device)
    if nodes is None:
        raise ValueError(
            "layout='random' has no fixed layout: take each world's tables from env.cell_contributions and env.direct"
        )
    contributions = relay_contributions(link_gains(model_positions(cfg, device).xyz, nodes, cfg), cfg)
    return contributions.unsqueeze(0), direct_terms(nodes, cfg).unsqueeze(0)


class ConfigurationSpace:
    """Every configuration of ``num_uavs`` interchangeable UAVs on ``grid`` and the valid transitions between them.

    Attributes: ``cells`` ``[K, N]`` (ascending positions: cells without altitude levels) and ``tasks`` ``[K, N]``
    of every configuration ``k``; ``successors`` ``[K, A^N]`` int32, the configuration after each joint action of
    the UAVs in position order, ``-1`` where invalid (``A = 6``, 8 with altitude levels).

    Raises ``ValueError`` (one line, with the bytes it would need) when the
    tables exceed ``memory_budget``.

    Args:
        grid: ``(L1, L2)`` cells.
        num_uavs: ``N``.
        device: the torch device of the tables.
        memory_budget: the bytes the tables may take.
        neighbours: the positions' moves ``[P, M]`` (:func:`~uavrl.envs.physics.positions.model_positions`); None:
            the grid's cells at one level.  :func:`model_space` gives a model's.

    Example:
        >>> space = ConfigurationSpace((3, 3), 2)
        >>> space.cells.shape, space.successors.shape  # C(9, 2) cell sets x 4 task vectors; 6^2 joint actions
        (torch.Size([144, 2]), torch.Size([144, 36]))
    """

    def __init__(
        self,
        grid: tuple[int, int],
        num_uavs: int,
        device="cpu",
        memory_budget: int = MEMORY_BUDGET,
        neighbours: torch.Tensor | None = None,
    ):
        dev = torch.device(device)
        # the positions' moves: the grid's cells without altitude levels, else model_positions(cfg).neighbours
        self.neighbours = grid_neighbours(grid, dev) if neighbours is None else neighbours.to(dev)
        N, (L1, L2), C = num_uavs, grid, len(self.neighbours)
        base = self.neighbours.shape[1] + 2
        A = base**num_uavs
        need = required_bytes(C, num_uavs, base)
        if need > memory_budget:
            where = f"{L1}x{L2}" if C == L1 * L2 else f"{C:,} positions of {L1}x{L2}"
            raise ValueError(
                f"the exact solver for {N} UAVs on {where} needs {need:,} bytes ({need / 2**30:.3g} GiB) for "
                f"{num_configurations(C, N):,} configurations x {A:,} joint actions, over its budget of "
                f"{int(memory_budget):,} bytes: the evaluation uses lower bounds there"
            )
        self.grid, self.num_uavs, self.num_joint_actions, self.device = tuple(grid), N, A, dev
        self.num_actions = base
        # binomial[n, r] = C(n, r): the rank of ascending cells c_0 < ... < c_{N-1} is sum_i C(c_i, i + 1)
        self._binomial = torch.tensor(
            [[math.comb(n, r) for r in range(N + 1)] for n in range(C + 1)], dtype=torch.long, device=dev
        )
        self._bits = 2 ** torch.arange(N, device=dev)
        cell_sets = (
            torch.combinations(torch.arange(C, device=dev), r=N) if N > 1 else torch.arange(C, device=dev)[:, None]
        )
        by_rank = torch.empty_like(cell_sets)
        by_rank[self._rank(cell_sets)] = cell_sets
        task_vectors = (torch.arange(2**N, device=dev)[:, None] // self._bits) % 2  # [2^N, N]
        self.cells = by_rank.repeat_interleave(2**N, 0)
        self.tasks = task_vectors.repeat(len(by_rank), 1)
        self.num_configurations = len(self.cells)
        self.successors = torch.empty(self.num_configurations, A, dtype=torch.int32, device=dev)
        step = max(1, _CHUNK_ELEMENTS // (A * N))
        for start in range(0, self.num_configurations, step):
            cells, tasks = self.cells[start : start + step], self.tasks[start : start + step]
            self.successors[start : start + step] = self._successors(cells, tasks).int()

    def _rank(self, ascending_cells: torch.Tensor) -> torch.Tensor:
        place = torch.arange(1, ascending_cells.shape[-1] + 1, device=ascending_cells.device)
        return self._binomial[ascending_cells, place].sum(-1)

    def index(self, cells: torch.Tensor, tasks: torch.Tensor) -> torch.Tensor:
        """Configuration numbers ``[...]`` of ``[..., N]`` distinct cells and their tasks, in any UAV order."""
        ordered, order = cells.sort(-1)
        return self._rank(ordered) * 2**self.num_uavs + (tasks.gather(-1, order) * self._bits).sum(-1)

    def _successors(self, cells: torch.Tensor, tasks: torch.Tensor) -> torch.Tensor:
        """``[..., 6^N]`` configuration after every joint action from ordered ``cells``/``tasks`` ``[..., N]``, -1
        invalid."""
        target = joint_targets(cells, self.neighbours, self.num_uavs)
        valid = targets_valid(target)
        nxt = self.index(target.clamp(min=0), joint_next_tasks(tasks, self.num_uavs, self.num_actions))
        return torch.where(valid, nxt, -1)

    def utility(
        self, cfg: ModelConfig, contributions: torch.Tensor, direct: torch.Tensor, beta=(1.0, 1.0)
    ) -> torch.Tensor:
        """``[B, K]`` potential ``beta1 R_PU + beta2 R_SE`` (default: the utility U) of every configuration in ``B``
        layouts.

        ``contributions`` ``[B, C, 2]`` and ``direct`` ``[B, 2]`` as ``env.cell_contributions`` and ``env.direct``;
        ``cfg`` gives the rate rules; ``beta`` the weights ``(beta1, beta2)``.
        """
        out = torch.empty(len(contributions), self.num_configurations, dtype=torch.float64, device=self.device)
        step = max(1, _CHUNK_ELEMENTS // (len(contributions) * self.num_uavs * 2))
        for start in range(0, self.num_configurations, step):
            cells, tasks = self.cells[start : start + step], self.tasks[start : start + step]
            r_pu, r_se = rates(contributions[:, cells], tasks.expand(len(contributions), -1, -1), direct[:, None], cfg)
            out[:, start : start + step] = beta[0] * r_pu + beta[1] * r_se
        return out

    def q_values(
        self, potential: torch.Tensor, values: torch.Tensor, gamma: float, cells: torch.Tensor, tasks: torch.Tensor
    ) -> torch.Tensor:
        """``[B, ..., 6^N]`` ``Q(s, a) = P(s') - P(s) + gamma V(s')`` at ordered configurations ``[B, ..., N]``, -inf
        where invalid.

        ``potential`` and ``values`` ``[B, K]`` (from :meth:`utility` and :func:`optimal_values`); ``cells``
        ``[B, ..., N]`` ascending and ``tasks`` ``[B, ..., N]`` the configurations.
        """
        B = len(potential)
        k = self.index(cells, tasks).reshape(B, -1)
        nxt = self._successors(cells, tasks).reshape(B, -1)
        gathered = lambda table, idx: table.gather(1, idx.clamp(min=0))  # noqa: E731
        q = gathered(potential + gamma * values, nxt) - gathered(potential, k).repeat_interleave(
            self.num_joint_actions, 1
        )
        return q.masked_fill(nxt < 0, -math.inf).view(*cells.shape[:-1], self.num_joint_actions)


def _best_successor(space: ConfigurationSpace, table: torch.Tensor, reduce: str) -> torch.Tensor:
    """``[B, K]`` max (or min) of ``table`` ``[B, K]`` over each configuration's valid successors."""
    B, K = table.shape
    fill = -math.inf if reduce == "max" else UNREACHABLE
    padded = torch.cat([table, table.new_full((B, 1), fill)], 1)  # invalid actions (-1) index the last: the fill
    out = torch.empty_like(table)
    step = max(1, _CHUNK_ELEMENTS // (B * space.successors.shape[1]))
    for start in range(0, K, step):
        gathered = padded[:, space.successors[start : start + step]]  # [B, k, A]
        out[:, start : start + step] = gathered.amax(-1) if reduce == "max" else gathered.amin(-1)
    return out


def optimal_values(
    space: ConfigurationSpace, potential: torch.Tensor, gamma: float, horizon: int | None = None
) -> torch.Tensor:
    """``[B, K]`` best discounted return ``sum_{t=1..H} gamma^(t-1) (P_t - P_{t-1})`` from every configuration.

    ``horizon=None``: the infinite-horizon value, iterated until no value moves by
    more than ``CONVERGENCE_TOLERANCE x max |P|`` (``gamma < 1``; with
    ``gamma = 1`` the sweeps stop changing once every configuration has seen the
    best one it can reach).

    Args:
        space: the configurations and their transitions.
        potential: the potential ``P`` ``[B, K]`` of every configuration in ``B`` layouts
            (:meth:`ConfigurationSpace.utility`).
        gamma: the discount, in (0, 1].
        horizon: the steps ``H``; None: the infinite horizon.
    """
    if not 0 < gamma <= 1:
        raise ValueError(f"gamma={gamma} is invalid: it must lie in (0, 1]")
    values = torch.zeros_like(potential)
    tolerance = CONVERGENCE_TOLERANCE * float(potential.abs().max().clamp(min=1.0))
    for _ in range(horizon if horizon is not None else _MAX_SWEEPS):
        new = _best_successor(space, potential + gamma * values, "max") - potential
        if horizon is None and float((new - values).abs().max()) <= tolerance:
            return new
        values = new
    return values


def min_steps(space: ConfigurationSpace, target: torch.Tensor) -> torch.Tensor:
    """``[B, K]`` int32 fewest steps from every configuration to one where ``target`` ``[B, K]`` holds (BFS).

    ``UNREACHABLE`` where no valid sequence of joint actions gets there.

    Args:
        space: the configurations and their transitions.
        target: ``[B, K]`` booleans, the configurations to reach in each of ``B`` layouts.
    """
    steps = torch.where(target, 0, UNREACHABLE).int()
    while True:
        via = _best_successor(space, steps, "min")
        new = torch.minimum(steps, torch.where(via < UNREACHABLE, via + 1, UNREACHABLE))
        if torch.equal(new, steps):
            return steps
        steps = new
