"""Lower bounds on the steps to a good configuration, for teams too large for the exact solver.

Two bounds, both provably never above the true fewest steps:

- :func:`relaxed_min_steps` (any level, e.g. 0.99 U*): after ``k`` steps UAV
  ``i`` can only hold a (position, task) with ``distance + [task changed]
  <= k`` (a step either moves or sets the task; the distance ``|dx| + |dy| + |dlevel|`` between positions, a move
  being one cell in the plane or one altitude level, and buildings only lengthening paths).  Forgetting that
  positions must differ, the best utility within reach is the best, over which UAVs relay,
  of every relay taking the largest relay contribution it can reach and every
  sensor the largest sensing contribution (the rates grow with each sum).  No
  real ``k``-step trajectory does better, so the first ``k`` whose relaxed best
  reaches the level is a lower bound.  Up to ``MAX_SPLIT_UAVS`` UAVs every split into relays and sensors is
  tried; beyond (2^N splits per world and step would take minutes), the split itself is relaxed too
  (:func:`uavrl.envs.solvers.optimum.split_relaxation`: one UAV may share its contribution between the tasks), a bound
  no smaller (by 0.02% at most in the layouts measured), computed in ``O(N log N)`` per world and step.
- :func:`assignment_min_steps` (the optimum itself): to end in an optimal set
  of (position, task) pairs, some UAV must make the largest ``distance + [task
  changed]`` of the best assignment of UAVs to that set's pairs (a bottleneck
  assignment); the bound is the least of these over *every* optimal set
  (:func:`optimal_configurations` finds them all).

Positions are a model's (:func:`~uavrl.envs.physics.positions.model_positions`): cells without altitude levels.

Example:
    >>> from uavrl.envs.config import make_config
    >>> from uavrl.envs.solvers.exact import fixed_layout_tables
    >>> from uavrl.envs.solvers.optimum import optimum
    >>> cfg = make_config("paper", grid=(6, 6), num_uavs=3)
    >>> contributions, direct = fixed_layout_tables(cfg)
    >>> u_star, cells, tasks = optimum(contributions, direct, cfg)
    >>> start_cells, start_tasks = torch.tensor([[0, 1, 2]]), torch.tensor([[0, 0, 0]])
    >>> relaxed_min_steps(start_cells, start_tasks, contributions, direct, cfg, u_star[:, None], max_steps=20).tolist()
    [[5]]
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import torch

from ..config import RELAYING, SENSING, ModelConfig
from ..physics.channel import rates, rates_from_sums
from ..physics.positions import Positions, model_positions
from .optimum import SplitSearch, ratio_order, split_relaxation, staffed_scale

OPTIMUM_RTOL = 1e-9  # a configuration "is optimal" when U >= (1 - OPTIMUM_RTOL) U*
MAX_CANDIDATES = 2_000_000  # configurations examined per world by optimal_configurations
MAX_SPLIT_UAVS = 10  # relaxed_best_utility tries every split of up to this many UAVs


_CHUNK_ELEMENTS = 1 << 22  # elements of the largest temporary per torch call: the tables grow with C and 2^N


def reachable_best(
    cells, tasks, contributions, positions: Positions, grid, max_steps: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """``[W, K + 1, N]`` largest relay and sensing contribution UAV ``i`` can hold after ``k = 0..K`` steps.

    ``-inf`` where no position of that task is within reach (a task change alone takes a step).  Per UAV, the best
    value at each cost (:func:`moves_apart` + task change) is bucketed, then the running maximum over the costs gives
    every ``k``: a few ``[w, N, R]`` tensors for a chunk of worlds at a time, ``R`` the positions within ``K`` moves
    of a position (:func:`reach_offsets`) or, where the model has fewer, every position: the cost follows the
    horizon, not the grid.

    Args:
        cells: the UAVs' positions ``[W, N]`` at the start (cells without altitude levels).
        tasks: their tasks ``[W, N]``.
        contributions: each position's relay and sensing contributions ``[W, P, 2]`` (or ``[1, P, 2]``, one layout).
        positions: the model's positions (:func:`~uavrl.envs.physics.positions.model_positions`).
        grid: ``(L1, L2)`` cells.
        max_steps: ``K``.

    Returns:
        The relay and the sensing bests, ``[W, K + 1, N]`` each.
    """
    W, N = cells.shape
    P, K = contributions.shape[-2], max_steps
    L1, L2 = grid
    L = len(positions.number) // (L1 * L2)
    contributions = contributions.expand(W, -1, -1)  # one shared layout, or one per world
    offsets = reach_offsets(K, cells.device, L) if reach_size(K, L) < P else None
    chunk = max(1, _CHUNK_ELEMENTS // (N * (P if offsets is None else len(offsets))))
    where = grid_coordinates(positions).to(cells.device)  # [P, 3] (x, y, level)
    best = {RELAYING: [], SENSING: []}
    for start in range(0, W, chunk):
        here, worlds = where[cells[start : start + chunk]], slice(start, start + chunk)  # [w, N, 3]
        if offsets is None:  # every position
            near, inside = None, None
            distance = sum((here[..., axis, None] - where[:, axis]).abs() for axis in range(3))  # [w, N, P]
        else:  # the positions within K moves: [w, N, R]
            near, inside = _positions_near(here, offsets, positions.number.to(cells.device), (L1, L2, L))
            distance = offsets.abs().sum(-1).expand_as(near)
        for task, column in ((RELAYING, 0), (SENSING, 1)):
            cost = (distance + (tasks[worlds] != task).long().unsqueeze(-1)).clamp(max=K + 1)  # beyond K: one bucket
            value = contributions[worlds, :, column]
            if near is None:
                value = value.unsqueeze(1).expand_as(cost)
            else:
                value = value.gather(1, near.flatten(1)).view_as(cost).masked_fill(~inside, -math.inf)
            at_cost = cost.new_full((*cost.shape[:-1], K + 2), -math.inf, dtype=value.dtype)
            at_cost.scatter_reduce_(-1, cost, value, "amax")
            best[task].append(at_cost[..., : K + 1].cummax(-1).values.transpose(1, 2))  # [w, K + 1, N]
    return torch.cat(best[RELAYING]), torch.cat(best[SENSING])


def _positions_near(here, offsets, number, shape) -> tuple[torch.Tensor, torch.Tensor]:
    """``(positions [w, N, R], inside [w, N, R])`` at ``offsets`` ``[R, 3]`` from ``here`` ``[w, N, 3]`` (x, y,
    level), ``inside`` false (and the position 0) off the grid, off the levels or inside a building (``number`` -1)."""
    L1, L2, L = shape
    x, y, level = (here[..., axis, None] + offsets[:, axis] for axis in range(3))
    inside = (x >= 0) & (x < L1) & (y >= 0) & (y < L2) & (level >= 0) & (level < L)
    near = number[((level * L2 + y) * L1 + x).where(inside, 0)]
    inside &= near >= 0
    return near.where(inside, 0), inside


def grid_coordinates(positions: Positions, index: torch.Tensor | None = None) -> torch.Tensor:
    """``[..., 3]`` long (x, y, level) of the position indices ``index`` ``[...]``; None: ``[P, 3]``, every position's.
    On the positions' device."""
    index = slice(None) if index is None else index.to(positions.level.device)
    return torch.cat([positions.xyz[index, :2].long(), positions.level[index].unsqueeze(-1)], -1)


def moves_apart(positions: Positions, here: torch.Tensor, there: torch.Tensor) -> torch.Tensor:
    """``|dx| + |dy| + |dlevel|`` between position indices ``here`` and ``there`` (broadcast, on ``here``'s device):
    the fewest moves between them with no building in the way, so never more than the fewest with buildings (the
    Manhattan distance of their cells without altitude levels).  Computed from the positions given, never as a
    ``[P, P]`` table."""
    apart = (grid_coordinates(positions, here) - grid_coordinates(positions, there)).abs().sum(-1)
    return apart.to(here.device)


def reach_size(max_steps: int, num_levels: int = 1) -> int:
    """The positions within ``max_steps`` moves of a position on an unbounded grid of ``num_levels`` levels:
    ``2 K (K + 1) + 1`` at one level, that many at ``K - |dlevel|`` moves for every other level within reach."""
    return sum(2 * k * (k + 1) + 1 for k in (max_steps - abs(d) for d in range(1 - num_levels, num_levels)) if k >= 0)


def reach_offsets(max_steps: int, device=None, num_levels: int = 1) -> torch.Tensor:
    """``[reach_size(K, L), 3]`` every (dx, dy, dlevel) with ``|dx| + |dy| + |dlevel| <= K`` and ``|dlevel| < L``."""
    span = torch.arange(-max_steps, max_steps + 1, device=device)
    climb = torch.arange(1 - num_levels, num_levels, device=device)
    box = torch.cartesian_prod(span, span, climb)
    return box[box.abs().sum(-1) <= max_steps]


def relaxed_best_utility(
    cells, tasks, contributions, direct, cfg: ModelConfig, max_steps: int, positions: Positions | None = None
) -> torch.Tensor:
    """``[W, K + 1]`` an upper bound on the utility any valid trajectory reaches after ``k = 0..K`` steps.

    Args:
        cells: the UAVs' positions ``[W, N]`` at the start (cells without altitude levels).
        tasks: their tasks ``[W, N]``.
        contributions: each position's relay and sensing contributions ``[W, P, 2]`` (or ``[1, P, 2]``, one layout).
        direct: the direct-link terms ``[W, 2]`` (or ``[1, 2]``).
        cfg: the model (its positions, ``num_uavs`` and rate model).
        max_steps: ``K``.
        positions: ``cfg``'s positions (e.g. a World's ``dynamics.positions``); None: :func:`model_positions`.
    """
    N = cfg.num_uavs
    positions = model_positions(cfg, cells.device) if positions is None else positions
    best_a, best_b = reachable_best(cells, tasks, contributions, positions, cfg.grid, max_steps)
    W, K1 = best_a.shape[:2]
    if N > MAX_SPLIT_UAVS:
        return _split_relaxed_best(best_a, best_b, direct.expand(W, 2), cfg)
    relays = (
        (torch.arange(2**N, device=cells.device)[:, None] >> torch.arange(N, device=cells.device)) & 1
    ).double()  # [M, N]
    # one row per (world, k), a chunk of rows at a time: every split of the UAVs into relays and sensors is [rows, M]
    best_a, best_b, direct = best_a.reshape(-1, N), best_b.reshape(-1, N), direct.expand(W, 2).repeat_interleave(K1, 0)
    out = []
    step = max(1, _CHUNK_ELEMENTS // len(relays))
    for start in range(0, len(best_a), step):
        a, b, d = best_a[start : start + step], best_b[start : start + step], direct[start : start + step]
        # a split is out of reach while one of its UAVs has no cell of its task in reach
        blocked = (a == -math.inf).double() @ relays.T + (b == -math.inf).double() @ (1 - relays).T  # [rows, M]
        sum_a = a.clamp(min=0) @ relays.T + d[:, None, 0]
        sum_b = b.clamp(min=0) @ (1 - relays).T + d[:, None, 1]
        r = rates_from_sums(torch.stack([sum_a, sum_b], -1), relays.sum(-1).expand_as(sum_a), N, cfg)
        out.append(r.sum(-1).masked_fill(blocked > 0, -math.inf).amax(-1))
    return torch.cat(out).view(W, K1)


def _split_relaxed_best(best_a, best_b, direct, cfg: ModelConfig) -> torch.Tensor:
    """``[W, K + 1]`` :func:`~uavrl.envs.solvers.optimum.split_relaxation` of the best reachable terms ``[W, K + 1,
    N]``: a UAV with no relay cell in reach senses, one with no sensing cell relays, one with neither blocks the
    step."""
    no_a, no_b = best_a == -math.inf, best_b == -math.inf
    both = ~no_a & ~no_b
    zero = best_a.new_zeros(())
    a, b = torch.where(both, best_a, zero), torch.where(both, best_b, zero)
    x = 1 + direct[:, None, 0] + torch.where(no_b & ~no_a, best_a, zero).sum(-1)
    y = 1 + direct[:, None, 1] + torch.where(no_a & ~no_b, best_b, zero).sum(-1) + b.sum(-1)
    order = ratio_order(a, b)
    bound = split_relaxation(a.gather(-1, order), b.gather(-1, order), x, y, staffed_scale(cfg))[0]
    return bound.masked_fill((no_a & no_b).any(-1), -math.inf)


def relaxed_min_steps(
    cells, tasks, contributions, direct, cfg: ModelConfig, levels, max_steps: int, positions: Positions | None = None
) -> torch.Tensor:
    """``[W, L]`` lower bound on the steps from ``[W, N]`` positions/tasks to utility ``>= levels`` ``[W, L]``.

    ``max_steps + 1`` where even the relaxation does not reach a level within ``max_steps``.

    Args:
        cells: the UAVs' positions ``[W, N]`` at the start (cells without altitude levels).
        tasks: their tasks ``[W, N]``.
        contributions: each position's relay and sensing contributions ``[W, P, 2]`` (or ``[1, P, 2]``, one layout).
        direct: the direct-link terms ``[W, 2]`` (or ``[1, 2]``).
        cfg: the model (its positions, ``num_uavs`` and rate model).
        levels: the utilities to reach ``[W, L]`` (bit/s/Hz).
        max_steps: the most steps looked at.
        positions: ``cfg``'s positions; None: :func:`model_positions`.
    """
    best = relaxed_best_utility(cells, tasks, contributions, direct, cfg, max_steps, positions)
    reach = best.unsqueeze(-1) >= levels.unsqueeze(1)  # [W, K + 1, L]
    return torch.where(reach.any(1), reach.double().argmax(1), max_steps + 1).long()


def optimal_configurations(contributions, direct, cfg: ModelConfig, u_star: float, rtol: float = OPTIMUM_RTOL):
    """Every set of (position, task) pairs of one world with ``U >= (1 - rtol) U*``: ``(positions [S, N], tasks [S,
    N])`` (cells without altitude levels).

    ``contributions`` ``[P, 2]`` over the model's positions, ``direct`` ``[2]``.  Why the search is complete:
    a relay on position ``r`` whose relay contribution lies more than ``delta`` below
    the N-th largest could move to an unused position with a larger one (at most N - 1
    of the N best cells are used), raising ``U`` by more than ``rtol U*`` when
    ``delta = (1 + direct + sum of the N largest) (2^(2 rtol U*) - 1)``; so
    relays lie within ``delta`` of the top N relay cells, sensors likewise,
    and the candidates are every split of those cells.

    Args:
        contributions: the world's position contributions ``[P, 2]``.
        direct: its direct-link terms ``[2]``.
        cfg: the model (its ``num_uavs`` and rate model).
        u_star: the world's ``U*``.
        rtol: the relative tolerance below ``U*`` that still counts as optimal.
    """
    N = cfg.num_uavs
    slack = 2.0 ** (2 * rtol * u_star) - 1

    def near_top(column: int) -> set[int]:
        value = contributions[:, column]
        top = value.topk(N).values
        delta = (1 + float(direct[column]) + float(top.sum())) * slack
        return set((value >= top[-1] - delta).nonzero().flatten().tolist())

    relay_cells, sense_cells = sorted(near_top(0)), sorted(near_top(1))
    count = sum(math.comb(len(relay_cells), m) * math.comb(len(sense_cells), N - m) for m in range(N + 1))
    if count > MAX_CANDIDATES:
        return _searched_configurations(contributions, direct, cfg, (1 - rtol) * u_star)
    dev = contributions.device
    candidates = []
    for m in range(N + 1):  # m relays on relay cells, N - m sensors on the other sense cells
        relays = (
            torch.tensor(list(itertools.combinations(relay_cells, m)), dtype=torch.long, device=dev).view(-1, m)
            if m
            else torch.zeros(1, 0, dtype=torch.long, device=dev)
        )
        sensors = (
            torch.tensor(list(itertools.combinations(sense_cells, N - m)), dtype=torch.long, device=dev).view(-1, N - m)
            if m < N
            else torch.zeros(1, 0, dtype=torch.long, device=dev)
        )
        cells = torch.cat([relays.repeat_interleave(len(sensors), 0), sensors.repeat(len(relays), 1)], -1)
        distinct = (cells.sort(-1).values.diff(dim=-1) != 0).all(-1)
        tasks = torch.tensor([RELAYING] * m + [SENSING] * (N - m), device=dev).expand(len(cells), -1)
        candidates.append((cells[distinct], tasks[distinct]))
    cells, tasks = torch.cat([c for c, _ in candidates]), torch.cat([t for _, t in candidates])
    r_pu, r_se = rates(contributions[cells], tasks, direct, cfg)
    optimal = (r_pu + r_se) >= (1 - rtol) * u_star
    return cells[optimal], tasks[optimal]


def _searched_configurations(contributions, direct, cfg: ModelConfig, threshold: float):
    """:func:`optimal_configurations` by search: every configuration with ``U >= threshold``.

    Those the branch and bound of :mod:`uavrl.envs.solvers.optimum` lists (no unused cell before a relay in the ``a``
    order or before a sensor in the ``b`` order), then every configuration one move of a UAV to an unused cell
    away, repeatedly, while ``U`` stays at the threshold.  Complete: from any configuration at the threshold, the
    moves of the exchange argument (each to an unused cell earlier in an order, none lowering ``U``) lead to a
    listed one, and the same moves backwards lead from it to the configuration through configurations at the
    threshold.
    """
    N, C = cfg.num_uavs, contributions.shape[0]
    a, b = contributions[:, 0].double().cpu(), contributions[:, 1].double().cpu()
    search = SplitSearch(a.numpy(), b.numpy(), direct.double().cpu().numpy(), N, cfg)
    lowest = threshold * (1 - OPTIMUM_RTOL)  # room for rounding: the final test below is the one that decides
    queue = [(frozenset(r), frozenset(e)) for r, e in search.at_least(lowest)]
    seen = set(queue)
    d = direct.double().cpu()
    while queue:
        relays, sensors = queue.pop()
        used = torch.zeros(C, dtype=torch.bool)
        used[list(relays | sensors)] = True
        sums = torch.stack([d[0] + a[list(relays)].sum(), d[1] + b[list(sensors)].sum()])
        for cells, column, values in ((relays, 0, a), (sensors, 1, b)):
            if not cells:
                continue
            moved = sorted(cells)
            # every move of one of these UAVs to an unused cell: [UAVs, C] sums
            changed = sums[column] - values[moved, None] + values[None, :]
            pair = torch.stack([changed, sums[1 - column].expand_as(changed)], -1)
            pair = pair if column == 0 else pair.flip(-1)
            u = rates_from_sums(pair, torch.full(changed.shape, len(relays)), N, cfg).sum(-1)
            for i, c in ((u >= lowest) & ~used).nonzero().tolist():
                new = cells - {moved[i]} | {c}
                config = (new, sensors) if column == 0 else (relays, new)
                if config not in seen:
                    if len(seen) >= MAX_CANDIDATES // N:
                        raise ValueError(f"over {len(seen):,} configurations tie near the optimum: too many to list")
                    seen.add(config)
                    queue.append(config)
    listed = sorted((len(r), sorted(r), sorted(e)) for r, e in seen)
    dev = contributions.device
    cells = torch.tensor([r + e for _, r, e in listed], dtype=torch.long, device=dev).view(-1, N)
    tasks = torch.tensor([[RELAYING] * m + [SENSING] * (N - m) for m, _, _ in listed], device=dev).view(-1, N)
    r_pu, r_se = rates(contributions[cells], tasks, direct, cfg)
    optimal = (r_pu + r_se) >= threshold
    return cells[optimal], tasks[optimal]


def assignment_costs(cells, tasks, target_cells, target_tasks, positions: Positions, path_lengths=None) -> torch.Tensor:
    """``[S, N, N]`` steps UAV ``i`` (positions/tasks ``[N]``) needs to hold pair ``j`` of target set ``s``
    (``[S, N]``): the moves plus a task change.

    Args:
        cells: the UAVs' positions ``[N]`` (cells without altitude levels).
        tasks: their tasks ``[N]``.
        target_cells: the target sets' positions ``[S, N]``.
        target_tasks: their tasks ``[S, N]``.
        positions: the model's positions (:func:`~uavrl.envs.physics.positions.model_positions`).
        path_lengths: ``(here, there) ->`` the fewest moves between position indices (broadcast); None:
            :func:`moves_apart`, never more (no building in the way).
    """
    moves = path_lengths or (lambda here, there: moves_apart(positions, here, there))
    distance = moves(cells[:, None, None], target_cells[None])  # [N, S, N]
    return (distance + (tasks[:, None, None] != target_tasks[None])).permute(1, 0, 2)


def best_assignment(costs: torch.Tensor) -> tuple[int, int, np.ndarray]:
    """``(steps, set s, pair of each UAV)`` of the lexicographically least assignment over ``[S, N, N]`` costs.

    Minimising ``sum (N + 1)^cost`` minimises the largest cost first (one pair
    at cost ``m`` outweighs N pairs below ``m``), then how many UAVs need it, and
    so on: the bottleneck assignment, with the fewest UAVs on long paths.  Where
    ``(N + 1)^cost`` would leave float64 (costs of hundreds of steps, large grids),
    each set's bottleneck ``m`` is found first and the weights are ``(N + 1)^(cost - m)``.
    """
    from scipy.optimize import linear_sum_assignment  # scipy (~0.7 s to import) only where an assignment is solved

    costs = costs.cpu().numpy()
    base = float(costs.shape[1] + 1)
    overflows = costs.max() * math.log10(base) > _LOG10_WEIGHT_LIMIT
    best = None
    for s in range(len(costs)):
        bottleneck = _bottleneck(costs[s], linear_sum_assignment) if overflows else 0
        weights = np.where(costs[s] <= bottleneck, base ** (costs[s] - bottleneck), np.inf) if overflows else None
        weights = base ** costs[s] if weights is None else weights
        rows, cols = linear_sum_assignment(weights)
        key = (int(costs[s, rows, cols].max()), float(weights[rows, cols].sum()))
        if best is None or key < best[0]:
            best = (key, s, cols)
    return best[0][0], best[1], best[2]


_LOG10_WEIGHT_LIMIT = 300  # (N + 1)^cost beyond 1e300: the sums of N weights would leave float64


def _bottleneck(cost: np.ndarray, linear_sum_assignment) -> int:
    """The least ``m`` such that every UAV gets its own pair at a cost ``<= m`` (bisection over the costs)."""
    values = np.unique(cost)
    low, high = 0, len(values) - 1
    while low < high:
        middle = (low + high) // 2
        rows, cols = linear_sum_assignment(cost > values[middle])  # 0 where allowed: a total of 0 fits under m
        low, high = (middle + 1, high) if (cost[rows, cols] > values[middle]).any() else (low, middle)
    return int(values[low])


MAX_PERMUTED_UAVS = 6  # assignment_min_steps tries every assignment of up to this many UAVs (720), in one tensor


def assignment_min_steps(cells, tasks, target_cells, target_tasks, positions: Positions) -> torch.Tensor:
    """``[W]`` lower bound on the steps from ``[W, N]`` cells/tasks to any of the sets ``[S, N]`` (per world: lists).

    The least, over the sets and the assignments of UAVs to their pairs, of the largest steps a UAV needs: up to
    ``MAX_PERMUTED_UAVS`` UAVs over every assignment at once, beyond by :func:`best_assignment`.

    Args:
        cells: the UAVs' positions ``[W, N]`` (cells without altitude levels).
        tasks: their tasks ``[W, N]``.
        target_cells: per world, the target sets' positions ``[S, N]`` (a list of ``W``).
        target_tasks: per world, their tasks ``[S, N]``.
        positions: the model's positions (:func:`~uavrl.envs.physics.positions.model_positions`).
    """
    N = cells.shape[-1]
    if N <= MAX_PERMUTED_UAVS:
        orders = torch.tensor(list(itertools.permutations(range(N))), dtype=torch.long)  # [P, N]: UAV i takes pair p_i
        return torch.stack(
            [
                assignment_costs(c, t, tc, tt, positions)[:, torch.arange(N), orders]
                .amax(-1)
                .min()  # [S, P, N] -> bound
                for c, t, tc, tt in zip(cells, tasks, target_cells, target_tasks, strict=True)
            ]
        ).long()
    return torch.tensor(
        [
            best_assignment(assignment_costs(c, t, tc, tt, positions))[0]
            for c, t, tc, tt in zip(cells, tasks, target_cells, target_tasks, strict=True)
        ],
        dtype=torch.long,
    )
