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

Brute force (every set of N cells times every task vector) checks it in tests.
Both evaluate candidates with :func:`uavrl.envs.channel.rates`.
"""

from __future__ import annotations

import itertools
import math

import torch

from .channel import rates
from .config import ModelConfig

BRUTE_FORCE_LIMIT = 200_000  # candidate configurations per world
MAX_EXCHANGE_UAVS = 20
_CHUNK_ELEMENTS = 1 << 24


def optimum(cell_contrib: torch.Tensor, direct: torch.Tensor, cfg: ModelConfig, method: str = "auto"):
    """``(U* [B], cells [B, N], tasks [B, N])`` for per-cell contributions ``[B, C, 2]`` and direct terms ``[B, 2]``.

    ``method``: ``"brute"`` (every configuration), ``"exchange"`` (the exact
    subset method above) or ``"auto"`` (brute force when it has at most
    ``BRUTE_FORCE_LIMIT`` candidates per world).
    """
    N, C = cfg.num_uavs, cfg.num_cells
    brute_size = math.comb(C, N) * 2**N
    if method not in ("auto", "brute", "exchange"):
        raise ValueError(f"method={method!r} is invalid: allowed values are 'auto', 'brute', 'exchange'")
    if method == "auto":
        method = "brute" if brute_size <= BRUTE_FORCE_LIMIT else "exchange"
    if method == "brute":
        if brute_size > 50 * BRUTE_FORCE_LIMIT:
            raise ValueError(
                f"brute force over {brute_size:,} configurations per world is too large: use method='exchange'"
            )
        return _best_of(cell_contrib, direct, cfg, *_all_configurations(C, N, cell_contrib.device))
    if N > MAX_EXCHANGE_UAVS:
        raise ValueError(
            f"num_uavs={N} is too many for the exact optimum: it enumerates 2^N subsets, allowed N <= "
            f"{MAX_EXCHANGE_UAVS}"
        )
    return _exchange(cell_contrib, direct, cfg)


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
