"""Counter-based random streams, one per world, vectorised over the batch.

Every world owns a key (derived from ``seed + world index``) and a counter.  A
draw is a hash of ``(key, counter, purpose, lane)``, so world ``i`` of a batch of
``B`` sees exactly the numbers of a batch of one seeded ``seed + i``, on any
device, without a Python loop over worlds (the idea of Philox / JAX keys; the
hash is a 32-bit integer mixer kept inside int64 so it runs on every backend).

Example:
    >>> import torch
    >>> keys = world_keys(seed=0, num_worlds=3)
    >>> u = uniform(keys, torch.zeros(3, dtype=torch.long), purpose=1, n=4)
    >>> u.shape, bool((u >= 0).all() and (u < 1).all())
    (torch.Size([3, 4]), True)
"""

from __future__ import annotations

import torch

_M32 = 0xFFFFFFFF
_GOLDEN = 0x61C88647  # below 2**31, so 32-bit values times it fit in int64

# The purposes of the worlds' draws, one each, so a new draw changes none of the others: a reset's cells and tasks,
# a step's fading of the UAV-node links and of the direct links (Rayleigh and LoS/NLoS; Rician), and round r of
# layout=random's rejection sampler for its node pair p (every purpose from LAYOUT up: LAYOUT + 2 r + p), and a
# reset's battery levels (battery_init=uniform).
POSITIONS, TASKS, FADING, FADING_DIRECT, RICIAN, RICIAN_DIRECT, BATTERY = 1, 2, 3, 4, 5, 6, 7
LAYOUT = 16


def _mix32(x: torch.Tensor) -> torch.Tensor:
    # multipliers stay below 2**31 so products of 32-bit values fit in int64
    x = x ^ (x >> 16)
    x = (x * 0x7FEB352D) & _M32
    x = x ^ (x >> 15)
    x = (x * 0x68E31DA5) & _M32
    return x ^ (x >> 16)


def world_keys(seed: int, num_worlds: int, device=None) -> torch.Tensor:
    """``[B]`` int64 keys of worlds ``seed, seed + 1, ..., seed + B - 1``."""
    world_seed = torch.arange(num_worlds, dtype=torch.long, device=device) + int(seed)
    return _mix32(_mix32(world_seed & _M32) ^ ((world_seed >> 32) & _M32))


def stream_heads(keys: torch.Tensor, counters: torch.Tensor, purpose: int) -> torch.Tensor:
    """``[B]`` the hash of ``(key, counter, purpose)`` that lane ``l`` of a draw mixes with ``l``
    (:func:`lane_bits`): compiled loops can make a draw's lanes themselves from it."""
    h = _mix32((keys + (counters & _M32) * _GOLDEN) & _M32)
    return _mix32((h + purpose * _GOLDEN) & _M32)


def lane_bits(heads, lanes):
    """Uniform 32-bit integers (int64) of lanes ``lanes`` of draws with heads ``heads`` (tensors, or ints in a
    compiled loop: the same operations)."""
    return _mix32((heads + lanes * _GOLDEN) & _M32)


def random_bits(keys: torch.Tensor, counters: torch.Tensor, purpose: int, n: int) -> torch.Tensor:
    """``[B, n]`` uniform 32-bit integers (as int64) for event ``counters`` ``[B]`` of each world."""
    lanes = torch.arange(n, dtype=torch.long, device=keys.device)
    return lane_bits(stream_heads(keys, counters, purpose).unsqueeze(-1), lanes)


UNIFORM_SCALE = 1.0 / 2**32  # a uniform is its 32 random bits times this


def _cells_of_draws(heads: torch.Tensor, draws: torch.Tensor, num_cells: int) -> torch.Tensor:
    """Uniform cells ``[k, m]`` of draws ``draws`` ``[k, m]`` of the streams with heads ``heads`` ``[k]``: 62 random
    bits (lanes ``2 d`` and ``2 d + 1``) modulo ``num_cells``, a bias below ``num_cells / 2^62``."""
    high = lane_bits(heads.unsqueeze(-1), 2 * draws) & 0x7FFFFFFF
    low = lane_bits(heads.unsqueeze(-1), 2 * draws + 1) & 0x7FFFFFFF
    return ((high << 31) | low) % num_cells


def distinct_cells(keys: torch.Tensor, counters: torch.Tensor, purpose: int, num_cells: int, n: int) -> torch.Tensor:
    """``[B, n]`` distinct cells of ``0 .. num_cells - 1`` per world, uniform over the ordered n-tuples, with no work
    per cell.

    UAV ``i`` takes the first of its draws ``i, n + i, 2 n + i, ...`` (uniform cells) that no UAV before it took.
    All first draws at once, then, only in the worlds where two of them coincide (rare while ``n^2`` is small
    beside the cells), UAV by UAV until each cell is free.

    >>> cells = distinct_cells(world_keys(0, 2), torch.ones(2, dtype=torch.long), 1, num_cells=10**6, n=3)
    >>> cells.shape, bool((cells >= 0).all() and (cells < 10**6).all())
    (torch.Size([2, 3]), True)
    """
    heads = stream_heads(keys, counters, purpose)
    cells = _cells_of_draws(heads, torch.arange(n, device=keys.device).expand(len(keys), n), num_cells)
    ordered = cells.sort(-1).values
    clashing = (ordered[:, 1:] == ordered[:, :-1]).any(-1).nonzero().squeeze(-1)
    if len(clashing):
        redone, heads = cells[clashing], heads[clashing]
        for i in range(1, n):
            taken = (redone[:, i : i + 1] == redone[:, :i]).any(-1).nonzero().squeeze(-1)
            draw = i
            while len(taken):
                draw += n
                fresh = _cells_of_draws(heads[taken], taken.new_full((len(taken), 1), draw), num_cells)
                redone[taken, i] = fresh.squeeze(-1)
                taken = taken[(redone[taken, i : i + 1] == redone[taken, :i]).any(-1)]
        cells[clashing] = redone
    return cells


def uniform(keys: torch.Tensor, counters: torch.Tensor, purpose: int, n: int, dtype=torch.float64) -> torch.Tensor:
    """``[B, n]`` uniforms in ``[0, 1)`` with 32 bits of resolution."""
    return random_bits(keys, counters, purpose, n).to(dtype) * UNIFORM_SCALE
