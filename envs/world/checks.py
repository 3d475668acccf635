"""The World's argument checks: one-line refusals (:class:`~uavrl.envs.config.InvalidOption`) of a device, a seed,
a number of worlds or a memory budget, before anything is allocated."""

from __future__ import annotations

import numbers

import torch

from ..config import ModelConfig
from ..errors import InvalidOption, InvalidType
from ..limits import SEED_LIMIT, gib, world_bytes


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


def check_batch_size(batch_size) -> int:
    """``B`` of ``batch_size`` (``B`` or ``[B]``); a one-line refusal for anything else (a bool, a float, a tensor)."""
    size = batch_size
    if isinstance(batch_size, (list, tuple, torch.Size)):
        size = batch_size[0] if len(batch_size) == 1 else None
    if not isinstance(size, numbers.Integral) or isinstance(size, bool) or size < 1:
        raise InvalidOption("batch_size", batch_size, "give the number of worlds B >= 1, a whole number or [B]")
    return int(size)


def check_memory(
    cfg: ModelConfig,
    batch_size: int,
    memory_budget,
    size=world_bytes,
    batch: str = "batch_size",
    budget="memory_budget",
) -> None:
    """A one-line refusal, before anything is allocated, when ``batch_size`` worlds of ``cfg`` would take more than
    ``memory_budget`` bytes (``size(cfg, batch_size)``: :func:`uavrl.envs.limits.world_bytes`, or the env's
    :func:`~uavrl.envs.limits.env_bytes`), naming what to lower: the worlds (``batch``: the argument that gives
    them) where one world fits, else the spares, the team or the grid, the first whose least would fit; ``budget``:
    the argument that raises ``memory_budget`` (``None``: none does)."""
    if not isinstance(memory_budget, numbers.Real) or isinstance(memory_budget, bool) or not memory_budget > 0:
        raise InvalidOption("memory_budget", memory_budget, "give the bytes the worlds may take, a positive number")
    need = size(cfg, batch_size)
    if need <= memory_budget:
        return
    L1, L2 = cfg.grid
    what = f"{batch_size:,} worlds of {cfg.fleet_size} UAVs on {L1}x{L2} need about {gib(need)}, over memory_budget="
    what += f"{int(memory_budget):,} bytes"
    raise_it = f", or raise {budget}" if budget else ""
    if size(cfg, 1) <= memory_budget:
        raise InvalidOption(batch, batch_size, f"{what}: use fewer worlds{raise_it}")
    for name, least in (("num_spares", 0), ("num_uavs", 1)):
        if getattr(cfg, name) > least and size(cfg.replace(**{name: least}), 1) <= memory_budget:
            raise InvalidOption(name, getattr(cfg, name), f"{what}: lower {name}{raise_it}")
    raise InvalidOption("grid", cfg.grid, f"{what}: lower grid{raise_it}")
