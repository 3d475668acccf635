"""The exact optimum U* of deterministic channels.

UAVs are interchangeable, so a configuration is a set R of relaying cells and a
disjoint set E of sensing cells with ``|R| + |E| = N``.  ``U`` grows with
``A = sum_R a`` and with ``B = sum_E b`` for a fixed ``|R|`` (``a``, ``b`` the
per-cell relay and sensing contributions), which gives the exact method:

*Exchange argument.*  Take an optimum (R, E).  If some r in R is not among the
N cells of largest ``a``, one of those N cells is unused (R and E hold N cells,
r is one of them); moving r there does not lower A and leaves B alone.  Repeat,
then do the same for E with the N cells of largest ``b``.  So an optimum has
``R within top_a`` and ``E within top_b``.  Given R, the best E is the ``N - |R|``
cells of largest ``b`` in ``top_b`` minus R.  Enumerating the ``2^N`` subsets R
of ``top_a`` is therefore exact: 1,024 candidates for N = 10 on any grid.

*Branch and bound* (``method="search"``, N > 10).  Order the cells by ``a`` and by ``b`` (ties by index).  Moving
a relay to an unused cell earlier in the ``a`` order, or a sensor to one earlier in the ``b`` order, never lowers
``U``, and each move lowers the sum of the ranks, so some optimum has no unused cell before a relay (``a`` order) or
before a sensor (``b`` order).  Its cells are then exactly a prefix of the ``a`` order plus a prefix of the ``b``
order: at most N + 1 such sets of N cells.  In each, the cells only in the ``a`` prefix relay, those only in the
``b`` prefix sense, and the cells in both (``D``) are split between the tasks.  The split is a concave knapsack,
solved by depth-first branch and bound: both rate models are ``c log2(1 + sum)`` per network, so the relaxation
that lets one cell split its contribution is solved in closed form along the cells sorted by ``a / b``, and bounds
every split below a node (the lease and both-tasks rules only lower ``U``).  Sets and nodes whose bound is below the
best found are cut.  Where ``D`` is empty (the two networks' best cells do not overlap, the common case on large
grids) there is nothing to split.  The search stops after ``SEARCH_NODE_LIMIT`` nodes per world and then returns
the best found; :func:`optimum_bound` returns a certified upper bound, equal to ``U*`` wherever the search ended.

Brute force (every set of N cells times every task vector) checks them in tests.
All evaluate candidates with :func:`uavrl.envs.physics.channel.rates` (or
:func:`~uavrl.envs.physics.channel.rates_from_sums`).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import torch

from ..config import RELAYING, SENSING, InvalidOption, ModelConfig
from ..physics.channel import rates, rates_from_sums

BRUTE_FORCE_LIMIT = 200_000  # candidate configurations per world
MAX_EXCHANGE_UAVS = 20
# auto: the exchange method up to this many UAVs, the search beyond (measured per world, 20x20 and 100x100 grids:
# both ~1 ms at N = 10; at N = 12 the exchange takes 2-5x, at N = 20 ~10 s against the search's ~0.02 s)
AUTO_EXCHANGE_UAVS = 10
SEARCH_NODE_LIMIT = 200_000  # branch-and-bound nodes per world before the search returns its best and a bound
_CHUNK_ELEMENTS = 1 << 24


def optimum(cell_contrib: torch.Tensor, direct: torch.Tensor, cfg: ModelConfig, method: str = "auto"):
    """``(U* [B], cells [B, N], tasks [B, N])`` for per-cell contributions ``[B, C, 2]`` and direct terms ``[B, 2]``.

    ``method``: ``"brute"`` (every configuration), ``"exchange"`` (the exact
    subset method above, N <= 20), ``"search"`` (the branch and bound above) or ``"auto"`` (the fastest exact one:
    brute force when it has at most ``BRUTE_FORCE_LIMIT`` candidates per world, else the exchange method up to
    ``AUTO_EXCHANGE_UAVS``, else the search, and the exchange method in the worlds where the search stopped at its
    node limit, up to ``MAX_EXCHANGE_UAVS``).  Where the search stopped at its node limit beyond, ``U*`` is the best
    found (:func:`optimum_bound`).

    Args:
        cell_contrib: each cell's contributions ``[B, C, 2]`` when relaying and when sensing
            (``env.cell_contributions``, or :func:`~uavrl.envs.solvers.exact.fixed_layout_tables`).
        direct: the direct-link terms ``[B, 2]`` (``env.direct``).
        cfg: the model (its ``num_uavs`` and rate model).
        method: ``"auto"``, ``"brute"``, ``"exchange"`` or ``"search"``.

    Returns:
        ``U*`` ``[B]`` in bit/s/Hz, and an optimal configuration: the UAVs' cells ``[B, N]`` and tasks ``[B, N]``.

    Example:
        >>> from uavrl.envs import make_config
        >>> from uavrl.envs.solvers.exact import fixed_layout_tables
        >>> cfg = make_config("paper", grid=(4, 4), num_uavs=2)
        >>> u_star, cells, tasks = optimum(*fixed_layout_tables(cfg), cfg)
        >>> u_star.shape, cells.shape, tasks.shape
        (torch.Size([1]), torch.Size([1, 2]), torch.Size([1, 2]))
        >>> sorted(tasks[0].tolist())  # one relays for the primary link, one senses
        [0, 1]
    """
    return solve(cell_contrib, direct, cfg, method)[:3]


def optimum_bound(cell_contrib: torch.Tensor, direct: torch.Tensor, cfg: ModelConfig) -> torch.Tensor:
    """``[B]`` a certified upper bound on ``U*``: ``U*`` itself wherever :func:`optimum` is exact (everywhere but
    where the search stopped at ``SEARCH_NODE_LIMIT`` nodes).

    Args:
        cell_contrib: each cell's contributions ``[B, C, 2]`` when relaying and when sensing
            (``env.cell_contributions``, or :func:`~uavrl.envs.solvers.exact.fixed_layout_tables`).
        direct: the direct-link terms ``[B, 2]`` (``env.direct``).
        cfg: the model (its ``num_uavs`` and rate model).
    """
    return solve(cell_contrib, direct, cfg)[3]


def solve(cell_contrib: torch.Tensor, direct: torch.Tensor, cfg: ModelConfig, method: str = "auto"):
    """``(U [B], cells [B, N], tasks [B, N], upper [B])``: :func:`optimum` with its certified upper bound.

    Args:
        cell_contrib: each cell's contributions ``[B, C, 2]`` when relaying and when sensing
            (``env.cell_contributions``, or :func:`~uavrl.envs.solvers.exact.fixed_layout_tables`).
        direct: the direct-link terms ``[B, 2]`` (``env.direct``).
        cfg: the model (its ``num_uavs`` and rate model).
        method: as :func:`optimum`'s.
    """
    N, C = cfg.num_uavs, cell_contrib.shape[1]  # the positions a UAV may take: the table's rows
    brute_size = math.comb(C, N) * 2**N
    if method not in ("auto", "brute", "exchange", "search"):
        raise InvalidOption("method", method, "allowed values are 'auto', 'brute', 'exchange', 'search'")
    if method == "auto":
        method = "brute" if brute_size <= BRUTE_FORCE_LIMIT else "exchange" if N <= AUTO_EXCHANGE_UAVS else "search"
        if method == "search":
            return _search_or_exchange(cell_contrib, direct, cfg)
    if method == "search":
        return _search(cell_contrib, direct, cfg)
    if method == "brute":
        if brute_size > 50 * BRUTE_FORCE_LIMIT:
            raise ValueError(
                f"brute force over {brute_size:,} configurations per world is too large: use method='exchange'"
            )
        u, cells, tasks = _best_of(cell_contrib, direct, cfg, *_all_configurations(C, N, cell_contrib.device))
        return u, cells, tasks, u
    if N > MAX_EXCHANGE_UAVS:
        raise ValueError(
            f"num_uavs={N} is too many for method='exchange': it enumerates 2^N subsets, allowed N <= "
            f"{MAX_EXCHANGE_UAVS}; method='search' has no such limit"
        )
    u, cells, tasks = _exchange(cell_contrib, direct, cfg)
    return u, cells, tasks, u


def _search_or_exchange(cell_contrib, direct, cfg):
    """The search, then the exchange method in the worlds where the search stopped at its node limit (N <= 20)."""
    u, cells, tasks, upper = _search(cell_contrib, direct, cfg)
    stopped = (upper > u).nonzero().squeeze(-1)
    if len(stopped) and cfg.num_uavs <= MAX_EXCHANGE_UAVS:
        u[stopped], cells[stopped], tasks[stopped] = _exchange(cell_contrib[stopped], direct[stopped], cfg)
        upper[stopped] = u[stopped]
    return u, cells, tasks, upper


def _all_configurations(C: int, N: int, device):
    sets = torch.tensor(list(itertools.combinations(range(C), N)), dtype=torch.long, device=device)  # [K, N]
    tasks = torch.tensor(list(itertools.product((0, 1), repeat=N)), dtype=torch.long, device=device)  # [T, N]
    cells = sets.repeat_interleave(len(tasks), 0)
    return cells, tasks.repeat(len(sets), 1)


def _best_of(cell_contrib, direct, cfg, cells, tasks):
    """Evaluate shared candidates ``cells``/``tasks`` ``[K, N]`` in every world, chunked; keep the best."""
    B, K, N = cell_contrib.shape[0], cells.shape[0], cells.shape[1]
    best_u = torch.full((B,), -math.inf, dtype=cell_contrib.dtype, device=cell_contrib.device)
    best_k = torch.zeros(B, dtype=torch.long, device=cell_contrib.device)
    step = max(1, _CHUNK_ELEMENTS // max(1, B * N))
    for start in range(0, K, step):
        c, t = cells[start : start + step], tasks[start : start + step]
        contrib = cell_contrib[:, c]  # [B, k, N, 2]
        r_pu, r_se = rates(contrib, t.expand(B, -1, -1), direct[:, None], cfg)
        u, k = (r_pu + r_se).max(-1)
        better = u > best_u
        best_u = torch.where(better, u, best_u)
        best_k = torch.where(better, k + start, best_k)
    return best_u, cells[best_k], tasks[best_k]


def _exchange(cell_contrib, direct, cfg):
    B, C, _ = cell_contrib.shape
    N = cfg.num_uavs
    dev = cell_contrib.device
    top_a = cell_contrib[..., 0].topk(N, dim=1).indices  # [B, N]
    top_b = cell_contrib[..., 1].topk(N, dim=1).indices  # [B, N], largest b first
    subsets = torch.arange(2**N, device=dev)
    in_r = ((subsets[:, None] >> torch.arange(N, device=dev)) & 1).bool()  # [M, N]: bit i puts top_a[i] in R
    n_sense = N - in_r.sum(-1)  # [M]
    u_out, cells_out, tasks_out = [], [], []
    step = max(1, _CHUNK_ELEMENTS // (2**N * N * N))
    for start in range(0, B, step):
        ta, tb = top_a[start : start + step], top_b[start : start + step]
        b = ta.shape[0]
        # top_b cells already relaying in subset m
        taken = ((tb[:, None, :, None] == ta[:, None, None, :]) & in_r[None, :, None, :]).any(-1)  # [b, M, N]
        free = ~taken
        sense = free & (free.cumsum(-1) <= n_sense[None, :, None])
        # compact the N used slots of (top_a relaying) + (top_b sensing)
        slot_cells = torch.cat([ta[:, None].expand(-1, 2**N, -1), tb[:, None].expand(-1, 2**N, -1)], -1)
        used = torch.cat([in_r.expand(b, -1, -1), sense], -1)
        slot_tasks = torch.cat(
            [torch.ones_like(ta)[:, None].expand(-1, 2**N, -1), torch.zeros_like(tb)[:, None].expand(-1, 2**N, -1)], -1
        )
        order = (~used).to(torch.int8).argsort(dim=-1, stable=True)[..., :N]
        cells = torch.gather(slot_cells, -1, order)
        tasks = torch.gather(slot_tasks, -1, order)
        contrib = torch.gather(cell_contrib[start : start + step], 1, cells.view(b, -1, 1).expand(-1, -1, 2)).view(
            b, 2**N, N, 2
        )
        r_pu, r_se = rates(contrib, tasks, direct[start : start + step, None], cfg)
        u, k = (r_pu + r_se).max(-1)
        u_out.append(u)
        cells_out.append(cells[torch.arange(b, device=dev), k])
        tasks_out.append(tasks[torch.arange(b, device=dev), k])
    return torch.cat(u_out), torch.cat(cells_out), torch.cat(tasks_out)


_ROUNDING = 1e-12  # relative slack on a bound before it cuts: rounding never cuts a better configuration


def _search(cell_contrib, direct, cfg):
    """:func:`solve` by branch and bound, world by world (module doc)."""
    B, N = cell_contrib.shape[0], cfg.num_uavs
    contrib, sums = cell_contrib.detach().cpu().double().numpy(), direct.detach().cpu().double().numpy()
    cells, tasks, upper = [], [], []
    for w in range(B):
        search = SplitSearch(contrib[w, :, 0], contrib[w, :, 1], sums[w], N, cfg)
        (relays, sensors), bound = search.best()
        cells.append(relays + sensors)
        tasks.append([RELAYING] * len(relays) + [SENSING] * len(sensors))
        upper.append(math.nan if bound is None else bound)
    dev = cell_contrib.device
    cells = torch.tensor(cells, dtype=torch.long, device=dev).view(B, N)
    tasks = torch.tensor(tasks, dtype=torch.long, device=dev).view(B, N)
    r_pu, r_se = rates(torch.gather(cell_contrib, 1, cells.unsqueeze(-1).expand(-1, -1, 2)), tasks, direct, cfg)
    u = r_pu + r_se
    upper = torch.tensor(upper, dtype=u.dtype, device=dev)
    return u, cells, tasks, torch.where(upper.isnan(), u, torch.maximum(upper, u))


class SplitSearch:
    """The branch and bound of one world (module doc): its candidate cell sets and the search over each set's split.

    ``a``, ``b``: ``[C]`` relay and sensing contributions; ``direct``: ``[2]``.  Sums ``X = 1 + direct + A`` and
    ``Y = 1 + direct + B`` are what the two logs take.

    Args:
        a: the cells' relay contributions ``[C]``.
        b: the cells' sensing contributions ``[C]``.
        direct: the world's direct-link terms ``[2]``.
        num_uavs: ``N``.
        cfg: the model (its rate model).
    """

    def __init__(self, a: np.ndarray, b: np.ndarray, direct: np.ndarray, num_uavs: int, cfg: ModelConfig):
        self.a, self.b, self.N, self.cfg = a, b, num_uavs, cfg
        self.nodes = 0
        self.scale = staffed_scale(cfg)
        N = num_uavs
        top_a = np.argsort(-a, kind="stable")[:N]
        top_b = np.argsort(-b, kind="stable")[:N]
        rank_a, rank_b = np.full(len(a), N), np.full(len(b), N)
        rank_a[top_a], rank_b[top_b] = np.arange(N), np.arange(N)
        self.sets = []
        seen = set()
        for p in range(N + 1):
            # the longest b prefix that fits beside the a prefix of length p, then the longest a prefix in that union
            q = int(np.searchsorted(np.cumsum(rank_a[top_b] >= p), N - p, side="right"))
            outside = np.flatnonzero(rank_b[top_a[p:]] >= q)
            p_full = p + (int(outside[0]) if len(outside) else N - p)
            if (p_full, q) in seen:
                continue
            seen.add((p_full, q))
            in_b = rank_b[top_a[:p_full]] < q
            relays, split = top_a[:p_full][~in_b], top_a[:p_full][in_b]
            sensors = top_b[:q][rank_a[top_b[:q]] >= p_full]
            split = split[ratio_order(torch.from_numpy(a[split]), torch.from_numpy(b[split])).numpy()]
            x = 1 + direct[0] + a[relays].sum()
            y = 1 + direct[1] + b[sensors].sum() + b[split].sum()
            self.sets.append((relays.tolist(), sensors.tolist(), split, x, y))

    def utility(self, x: float, y: float, num_relaying: int) -> float:
        sums = torch.tensor([[x - 1, y - 1]], dtype=torch.float64)
        return float(rates_from_sums(sums, torch.tensor([num_relaying]), self.N, self.cfg).sum())

    def relaxation(self, split: np.ndarray, free: np.ndarray, x: float, y: float) -> tuple[float, int, float]:
        """:func:`split_relaxation` of the free cells of ``split`` (kept in ``a / b`` order) from sums ``x, y``."""
        items = split[free]
        bound, j, theta = split_relaxation(
            torch.from_numpy(self.a[items]),
            torch.from_numpy(self.b[items]),
            torch.tensor(x),
            torch.tensor(y),
            self.scale,
        )
        return float(bound), int(j), float(theta)

    def best(self, limit: int | None = None) -> tuple[tuple[list[int], list[int]], float | None]:
        """``((relay cells, sensing cells), upper bound)`` of the best configuration (module doc); the bound is None
        where the search ended within ``limit`` nodes (default ``SEARCH_NODE_LIMIT``: the configuration is
        optimal)."""
        best, _, open_bounds = self._branch(None, SEARCH_NODE_LIMIT if limit is None else limit)
        return best, max(open_bounds) if open_bounds else None

    def at_least(self, threshold: float, limit: int = SEARCH_NODE_LIMIT) -> list[tuple[list[int], list[int]]]:
        """Every configuration of the candidate sets (module doc) with ``U >= threshold``: ``(relays, sensors)``;
        a one-line error beyond ``limit`` search nodes."""
        _, found, open_bounds = self._branch(threshold, limit)
        if open_bounds:
            raise ValueError(f"listing the configurations with U >= {threshold} took over {limit:,} search nodes")
        return found

    def _branch(self, threshold: float | None, limit: int):
        """Depth-first branch and bound over every candidate set's split: the best configuration (``threshold``
        None; a node ends where a configuration beside its relaxation's optimum reaches its bound) or every one at
        ``threshold`` or above (to the leaves).  Returns the best, those found and the bounds left open."""
        roots = sorted(
            (
                (self.relaxation(split, np.arange(len(split)), x, y)[0], index)
                for index, (_, _, split, x, y) in enumerate(self.sets)
            ),
            reverse=True,
        )
        best_u, best, found, open_bounds = -math.inf, None, [], []

        def configuration(relays, sensors, split, chosen):
            picked = np.zeros(len(split), dtype=bool)
            picked[list(chosen)] = True
            return relays + split[picked].tolist(), sensors + split[~picked].tolist()

        for root_bound, index in roots:
            cut = (best_u if threshold is None else threshold) * (1 - _ROUNDING)
            if root_bound < cut:
                continue
            if self.nodes >= limit:
                open_bounds.append(root_bound)
                continue
            relays, sensors, split, x, y = self.sets[index]
            stack = [(np.arange(len(split)), x, y, len(relays), ())]
            while stack:
                if self.nodes >= limit:
                    open_bounds.extend(self.relaxation(split, f, xx, yy)[0] for f, xx, yy, _, _ in stack)
                    break
                free, x, y, k, chosen = stack.pop()
                self.nodes += 1
                bound, j, theta = self.relaxation(split, free, x, y)
                if bound < (best_u if threshold is None else threshold) * (1 - _ROUNDING):
                    continue
                fa, fb = self.a[split[free]], self.b[split[free]]
                if threshold is not None:
                    if not len(free):
                        if self.utility(x, y, k) >= threshold:
                            found.append(configuration(relays, sensors, split, chosen))
                        continue
                else:
                    for m in {j, min(j + 1, len(free))}:  # the integral points beside the relaxation's optimum
                        u = self.utility(x + fa[:m].sum(), y - fb[:m].sum(), k + m)
                        if u > best_u:
                            best_u, best = u, (relays, sensors, split, chosen + tuple(free[:m].tolist()))
                        if u >= bound * (1 - _ROUNDING):  # nothing below this node beats it
                            free = free[:0]
                    if not len(free):
                        continue
                i = min(j, len(free) - 1)
                rest = np.delete(free, i)
                relay = (rest, x + fa[i], y - fb[i], k + 1, chosen + (int(free[i]),))
                sense = (rest, x, y, k, chosen)
                stack.extend([sense, relay] if theta >= 0.5 else [relay, sense])
        return (None if best is None else configuration(*best)), found, open_bounds


def staffed_scale(cfg: ModelConfig) -> float:
    """``c`` of ``U = c (log2(1 + sum_PU) + log2(1 + sum_SE))`` with both tasks staffed, read from the rate model
    itself (:func:`~uavrl.envs.physics.channel.rates_from_sums`); the lease and both-tasks rules only lower ``U``.

    Args:
        cfg: the model (its ``rate_model``: 1/2 for ``af``, 1 for ``reference_code``).
    """
    return float(rates_from_sums(torch.ones(1, 2, dtype=torch.float64), torch.ones(1), 2, cfg)[0, 0])


def ratio_order(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Indices that sort items ``[..., n]`` by ``a / b``, largest first (``b = 0`` first, ties in index order)."""
    return torch.atan2(a, b).argsort(dim=-1, descending=True, stable=True)


def split_relaxation(a: torch.Tensor, b: torch.Tensor, x: torch.Tensor, y: torch.Tensor, scale: float):
    """The most ``U = scale (log2 X + log2 Y)`` when items ``[..., n]`` in :func:`ratio_order` each add ``a`` to
    ``X`` (relaying) or keep ``b`` in ``Y`` (sensing; ``y`` counts every item as sensing), and may split: ``(bound,
    j, theta)`` ``[...]``, reached with the first ``j`` items relaying and a share ``theta`` of item ``j``.

    The split relaxation is concave; where it is best, items with the larger ``a / b`` relay, so its maximum lies
    on the path that moves the items in that order, at most one of them in part.  On each item's segment
    ``d/dtheta [log(X + theta a) + log(Y - theta b)] = 0`` at ``theta = (a Y - b X) / (2 a b)``.  No split of the
    items, with ``X, Y >= 1``, has a larger ``U``: an upper bound for every integral split.

    Args:
        a: each item's relay contribution ``[..., n]``, in :func:`ratio_order`.
        b: each item's sensing contribution ``[..., n]``, in the same order.
        x: the sum ``X`` ``[...]`` before any item relays.
        y: the sum ``Y`` ``[...]`` with every item sensing.
        scale: the rate model's ``c`` (:func:`staffed_scale`).
    """
    if a.shape[-1] == 0:
        zero = torch.zeros(a.shape[:-1], dtype=torch.long)
        return scale * (torch.log2(x) + torch.log2(y)), zero, zero.to(a.dtype)
    xs = x.unsqueeze(-1) + a.cumsum(-1) - a
    ys = y.unsqueeze(-1) - (b.cumsum(-1) - b)
    ratio = (a * ys - b * xs) / (2 * a * b)
    theta = torch.where(b > 0, torch.where(a > 0, ratio, 0.0), 1.0).clamp(0.0, 1.0)
    values = scale * (torch.log2(xs + theta * a) + torch.log2(ys - theta * b))
    bound, j = values.max(-1)
    return bound, j, theta.gather(-1, j.unsqueeze(-1)).squeeze(-1)
