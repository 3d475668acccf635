"""The fading parts: every link's random power gain, drawn anew each step (docs/model.md, Channel models).

``env.fading`` names one part of :data:`FADING_PARTS`; :func:`fading_part` builds it for a model.  A part says

- ``random``: whether a step's rates are random.  A random channel has no fixed rate per configuration, so the
  tabular agent refuses it, and ``reward=log_gap`` and the evaluation measure the gap to ``U*`` on the mean channel;
- ``table(cell_xyz, nodes, mean_gains)``: what its draws need per cell of each of ``k`` layouts, ``[k, C, 4, ...]``
  (``None`` when it draws nothing); the :class:`~uavrl.envs.world.World` keeps its rows beside its other tables;
- ``gains(rows, keys, counters)``: the ``[W, N, 4]`` power gains of the UAVs' links this step, from the table's rows
  at the UAVs' cells ``[W, N, 4, ...]`` and the worlds' random streams (:mod:`.streams`, one purpose per draw);
- ``direct(snr, keys, counters)``: the direct links' SNRs ``[W, 2]`` this step (``direct_links``).

The mean gain is the channel model's (:func:`uavrl.envs.physics.channel.link_gains`), and the Rayleigh and Rician power
gains ``X`` have mean 1, so ``U*``, the exact solver and the bounds are those of the mean channel.

Example:
    >>> import torch
    >>> from uavrl.envs import make_config
    >>> from uavrl.envs.physics import streams
    >>> part = fading_part(make_config("paper", fading="rician", rician_k_db=9.0))
    >>> part.random, [round(share, 4) for share in part.shares]  # K / (K + 1) and 1 / (K + 1), K = 10^0.9
    (True, [0.8882, 0.1118])
    >>> x = part.gains(torch.ones(3, 2, 4), streams.world_keys(0, 3), torch.zeros(3, dtype=torch.long))
    >>> x.shape, bool((x >= 0).all())  # unit mean gains: the draws X themselves
    (torch.Size([3, 2, 4]), True)
"""

from __future__ import annotations

import math

import torch

from ..config import ModelConfig
from . import streams
from .channel import link_state_gains


def _uniforms(keys: torch.Tensor, counters: torch.Tensor, purpose: int, shape) -> torch.Tensor:
    """``shape`` ``[W, ...]`` uniforms in ``[0, 1)``: world ``w``'s draw ``purpose`` at its event ``counters[w]``."""
    return streams.uniform(keys, counters, purpose, math.prod(shape[1:])).view(shape)


def exp1(uniforms: torch.Tensor) -> torch.Tensor:
    """``Exp(1)`` power gains (Rayleigh fading) by inversion of uniforms in ``[0, 1)``."""
    return -torch.log1p(-uniforms)


def rician_shares(k_db: float) -> tuple[float, float]:
    """``(K / (K + 1), 1 / (K + 1))``, the line-of-sight and the scattered share of the mean power, of the K-factor
    ``k_db`` in dB; computed from ``10^(-|k_db| / 10)``, so no finite ``k_db`` overflows."""
    t = 10 ** (-abs(k_db) / 10)
    big, small = 1 / (1 + t), t / (1 + t)
    return (big, small) if k_db >= 0 else (small, big)


def rician_power(uniforms: torch.Tensor, shares: tuple[float, float]) -> torch.Tensor:
    """``X = |sqrt(K / (K + 1)) + sqrt(1 / (K + 1)) CN(0, 1)|^2`` from uniforms ``[..., 2]``: ``[...]``, mean 1.

    Box-Muller turns the pair ``(u1, u2)`` into two independent ``N(0, 1)``, ``r cos(2 pi u2)`` and
    ``r sin(2 pi u2)`` with ``r = sqrt(-2 ln(1 - u1))``; ``CN(0, 1)`` is their sum ``(n1 + i n2) / sqrt(2)``.

    Args:
        uniforms: independent uniforms on [0, 1) ``[..., 2]``.
        shares: ``(K / (K + 1), 1 / (K + 1))``, the line-of-sight and the scattered share of the mean power
            (:func:`rician_shares` of the K-factor in dB).
    """
    u1, u2 = uniforms.unbind(-1)
    scattered = math.sqrt(shares[1] / 2) * torch.sqrt(-2 * torch.log1p(-u1))
    angle = (2 * math.pi) * u2
    return (math.sqrt(shares[0]) + scattered * torch.cos(angle)) ** 2 + (scattered * torch.sin(angle)) ** 2


class Fading:
    """``fading=none``, and the contract every fading part keeps (the module's docstring): no draws, ``X = 1``.

    Args:
        cfg: the model whose links it fades.
    """

    name, random = "none", False

    def __init__(self, cfg: ModelConfig):
        self.cfg = cfg

    def table(self, cell_xyz: torch.Tensor, nodes: torch.Tensor, mean_gains: torch.Tensor) -> torch.Tensor | None:
        """What the draws need per cell of ``k`` layouts (``cell_xyz`` ``[C, 3]``, ``nodes`` ``[k, 4, 3]``,
        ``mean_gains`` ``[k, C, 4]``)."""
        return None

    def gains(self, rows: torch.Tensor, keys: torch.Tensor, counters: torch.Tensor) -> torch.Tensor:
        """``[W, N, 4]`` power gains of the links this step from the table's rows ``[W, N, 4, ...]``, drawn from the
        worlds' streams (``keys``, ``counters`` ``[W]``)."""
        raise NotImplementedError(f"fading={self.name!r} draws nothing: its rates are the mean channel's")

    def direct(self, snr: torch.Tensor, keys: torch.Tensor, counters: torch.Tensor) -> torch.Tensor:
        """``[W, 2]`` the direct links' SNRs this step from their mean ``snr``, drawn from the worlds' streams
        (``keys``, ``counters`` ``[W]``)."""
        return snr


class Rayleigh(Fading):
    """Every link's power gain times a fresh ``X ~ Exp(1)``, the direct links' too."""

    name, random = "rayleigh", True

    def table(self, cell_xyz, nodes, mean_gains):
        return mean_gains

    def gains(self, rows, keys, counters):
        return rows * exp1(_uniforms(keys, counters, streams.FADING, rows.shape))

    def direct(self, snr, keys, counters):
        return snr * exp1(streams.uniform(keys, counters, streams.FADING_DIRECT, 2))


class LosNlos(Fading):
    """Each air-to-ground link in line of sight with probability ``P_LoS``, drawn anew: the LoS or the NLoS gain of
    the physical channel (:func:`uavrl.envs.physics.channel.link_state_gains`); its channels have no direct links."""

    name, random = "los_nlos", True

    def table(self, cell_xyz, nodes, mean_gains):
        return link_state_gains(cell_xyz, nodes, self.cfg)  # [k, C, 4, 3]: P_LoS, LoS gain, NLoS gain

    def gains(self, rows, keys, counters):
        p_los, los, nlos = rows.unbind(-1)
        return torch.where(_uniforms(keys, counters, streams.FADING, p_los.shape) < p_los, los, nlos)


class Rician(Fading):
    """Every link (UAV-node and direct, on any channel model) in line of sight with K-factor ``rician_k_db``: its
    power gain times a fresh Rician ``X`` of mean 1 (:func:`rician_power`).

    Args:
        cfg: the model (its ``rician_k_db``, the K-factor in dB).
    """

    name, random = "rician", True

    def __init__(self, cfg: ModelConfig):
        super().__init__(cfg)
        self.shares = rician_shares(cfg.rician_k_db)

    def table(self, cell_xyz, nodes, mean_gains):
        return mean_gains

    def gains(self, rows, keys, counters):
        return rows * rician_power(_uniforms(keys, counters, streams.RICIAN, (*rows.shape, 2)), self.shares)

    def direct(self, snr, keys, counters):
        return snr * rician_power(_uniforms(keys, counters, streams.RICIAN_DIRECT, (len(snr), 2, 2)), self.shares)


FADING_PARTS: dict[str, type[Fading]] = {part.name: part for part in (Fading, Rayleigh, LosNlos, Rician)}


def fading_part(cfg: ModelConfig) -> Fading:
    """The fading part of the model ``cfg``: an instance of ``FADING_PARTS[cfg.fading]`` (:class:`Fading` for
    ``none``, :class:`Rayleigh`, :class:`Rician`, :class:`LosNlos`), built from ``cfg``'s options.

    >>> from uavrl.envs import make_config
    >>> type(fading_part(make_config("paper", fading="rayleigh"))).__name__
    'Rayleigh'
    """
    return FADING_PARTS[cfg.fading](cfg)
