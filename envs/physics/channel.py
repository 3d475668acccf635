"""The physics of the model: node layouts, channel gains and AF rates.

This is the one implementation of docs/model.md (Where the four nodes are, How good a configuration is, Channel
models).  The environment, the exact optimum, the tabular learners' lookup tables and the tests all call these
functions, so they cannot disagree about a rate.  It holds two of the World's parts (docs/architecture.md):

- the channel model: :func:`link_gains`, the mean power gain ``|h|^2`` of every UAV-node link (the power laws, or a
  physical model's mean path loss from :mod:`.pathloss`), :func:`direct_terms` of the direct links, and
  :func:`link_state_gains`, the LoS and NLoS gains ``fading=los_nlos`` draws from; a fading part
  (:mod:`.fading`) multiplies or picks among these gains, never recomputes them;
- the rate model (``rate_model``: ``af``, or the authors' ``reference_code``): :func:`relay_contributions`, what a
  UAV adds inside its network's logarithm from its links' gains, and :func:`rates` / :func:`rates_from_sums`, the
  rates from those sums (the 1/2 factor, the lease rule, the authors' both-tasks rule).

Shapes: ``...`` is any batch shape (worlds, configurations); ``N`` UAVs; the
four fixed nodes are ordered ``(PT, PR, S, E)``.  Positions are in cell units.

Example:
    >>> import torch
    >>> from uavrl.envs.config import make_config
    >>> cfg = make_config("paper", grid=(6, 6))
    >>> nodes = fixed_layout(cfg, torch.float64)
    >>> contrib = relay_contributions(link_gains(cell_xyz(cfg, torch.float64), nodes, cfg), cfg)
    >>> contrib.shape  # per cell: (relay contribution to PU, sensing contribution to SE)
    torch.Size([36, 2])
"""

from __future__ import annotations

import torch

from ..config import RELAYING, ModelConfig
from ..limits import fixed_node_positions
from .buildings import city_part
from .pathloss import gain_from_db, link_states_db, mean_path_loss_db

PT, PR, S, E = range(4)


def fixed_layout(cfg: ModelConfig, dtype=torch.float64, device=None) -> torch.Tensor | None:
    """The ``[4, 3]`` node positions of a fixed layout, or ``None`` for ``layout=random``.

    Args:
        cfg: the model (its ``layout``, ``grid`` and height).
        dtype: the positions' dtype.
        device: their torch device.

    Returns:
        ``(x, y, z)`` in cells of PT, PR, S and E, one row each; in a city PT and PR stand on the roof of the building
        they are in, if any.

    Example:
        >>> from uavrl.envs import make_config
        >>> fixed_layout(make_config("paper", grid=(4, 4)))
        tensor([[ 0.,  2.,  0.],
                [ 4.,  2.,  0.],
                [-2.,  2.,  4.],
                [ 6.,  2.,  4.]], dtype=torch.float64)
    """
    rows = fixed_node_positions(cfg.layout, cfg.grid, cfg.height)
    if rows is None:
        return None
    city = city_part(cfg)
    nodes = torch.tensor(rows, dtype=dtype, device=device)
    return nodes if city is None else city.on_roofs(nodes)


def cell_xyz(cfg: ModelConfig, dtype=torch.float64, device=None) -> torch.Tensor:
    """``[C, 3]`` centre of every cell at UAV altitude, in cell index order ``c = y * L1 + x``, in cells.

    Args:
        cfg: the model (its ``grid`` and height).
        dtype: the positions' dtype.
        device: their torch device.
    """
    L1, L2 = cfg.grid
    c = torch.arange(L1 * L2, device=device)
    return torch.stack(
        [(c % L1).to(dtype), (c // L1).to(dtype), torch.full((L1 * L2,), cfg.height, dtype=dtype, device=device)], -1
    )


def link_gains(
    uav_xyz: torch.Tensor, nodes: torch.Tensor, cfg: ModelConfig, fading: torch.Tensor | None = None
) -> torch.Tensor:
    """``|h|^2 X`` from every UAV ``[..., N, 3]`` to every node ``[..., 4, 3]``: ``[..., N, 4]``.

    The mean gain ``|h|^2`` is ``g0 d^-alpha`` for the power laws (``channel`` ``paper`` and ``reference_code``),
    ``10^(-PL / 10)`` of the mean path loss in dB for the physical models (:mod:`.pathloss`); ``d`` is the 3-D
    distance in metres (cells times ``cell_size``).  ``fading`` is the ``[..., N, 4]`` power gain ``X`` (Exp(1) for
    Rayleigh), 1 when omitted.

    Args:
        uav_xyz: the UAVs' positions ``[..., N, 3]`` in cells.
        nodes: PT, PR, S and E ``[..., 4, 3]`` in cells.
        cfg: the model (its channel and ``cell_size``).
        fading: the power gains ``X`` ``[..., N, 4]``, or None for 1.

    Example:
        >>> from uavrl.envs import make_config
        >>> cfg = make_config("paper", grid=(4, 4))
        >>> link_gains(cell_xyz(cfg), fixed_layout(cfg), cfg).shape  # every cell to every node
        torch.Size([16, 4])
    """
    if cfg.is_physical:
        gain = gain_from_db(mean_path_loss_db(uav_xyz, nodes, cfg))
        return gain if fading is None else gain * fading
    d = torch.linalg.vector_norm(uav_xyz.unsqueeze(-2) - nodes.unsqueeze(-3), dim=-1) * cfg.cell_size
    gain = cfg.g0 * d.pow(-cfg.alpha)
    return gain if fading is None else gain * fading


def link_state_gains(uav_xyz: torch.Tensor, nodes: torch.Tensor, cfg: ModelConfig) -> torch.Tensor:
    """``[..., N, 4, 3]``: per link ``P_LoS`` and the gains ``10^(-PL / 10)`` in line of sight and out of it, what
    ``fading="los_nlos"`` draws from (physical channels; docs/model.md, Channel models).

    Args:
        uav_xyz: the UAVs' positions ``[..., N, 3]`` in cells.
        nodes: PT, PR, S and E ``[..., 4, 3]`` in cells.
        cfg: the model (a physical channel, its ``cell_size``).
    """
    p_los, los, nlos = link_states_db(uav_xyz, nodes, cfg)
    return torch.stack([p_los, gain_from_db(los), gain_from_db(nlos)], -1)


def relay_contributions(gains: torch.Tensor, cfg: ModelConfig) -> torch.Tensor:
    """Per UAV, what it adds inside the log when relaying for PU and when sensing for SE: ``[..., N, 2]``.

    ``af``: ``g1 g2 / (1 + g1 + g2)`` with ``g1 = P_src |h_src,j|^2 / sigma^2`` and
    ``g2 = P_U |h_j,dst|^2 / sigma^2`` (docs/model.md, How good a configuration is; powers and noise in W).
    ``reference_code``: ``A / (1 + A)`` with ``A = reference_gain |h_a,j|^2 |h_j,b|^2`` (docs/model.md, The
    authors' code as a preset).

    Args:
        gains: the power gains ``[..., N, 4]`` from every UAV to PT, PR, S and E (:func:`link_gains`).
        cfg: the model (its ``rate_model``, powers and noise).
    """
    src = gains[..., [PT, S]]
    dst = gains[..., [PR, E]]
    if cfg.rate_model == "reference_code":
        a = cfg.reference_gain * src * dst
        return a / (1 + a)
    p_pt, p_s, p_u = cfg.powers_w
    p_src = torch.tensor([p_pt, p_s], dtype=gains.dtype, device=gains.device)
    g1 = src * (p_src / cfg.noise_w)
    g2 = dst * (p_u / cfg.noise_w)
    return g1 * g2 / (1 + g1 + g2)


def direct_terms(nodes: torch.Tensor, cfg: ModelConfig) -> torch.Tensor:
    """``[..., 2]`` direct-link SNRs ``(PT->PR, S->E)``; zeros unless ``direct_links``.

    Args:
        nodes: PT, PR, S and E ``[..., 4, 3]`` in cells.
        cfg: the model (its ``direct_links``, channel, powers and noise).
    """
    if not cfg.direct_links:
        return nodes.new_zeros(nodes.shape[:-2] + (2,))
    gains = link_gains(nodes[..., [PT, S], :], nodes[..., [PR, E], :], cfg)  # [..., 2, 2]
    p_src = torch.tensor([cfg.p_pt, cfg.p_s], dtype=nodes.dtype, device=nodes.device)
    return torch.diagonal(gains, dim1=-2, dim2=-1) * p_src / cfg.noise


def rates(
    contributions: torch.Tensor, tasks: torch.Tensor, direct: torch.Tensor, cfg: ModelConfig
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(R_PU, R_SE)`` in bit/s/Hz of configurations, each of shape ``[...]``.

    ``contributions`` ``[..., N, 2]`` come from :func:`relay_contributions` at
    the UAVs' cells, ``tasks`` ``[..., N]`` (0 sensing, 1 relaying), ``direct``
    ``[..., 2]`` from :func:`direct_terms`.  Times ``cfg.bandwidth_hz`` they are in bit/s (physical channels).
    """
    relaying = tasks == RELAYING
    zero = contributions.new_zeros(())
    sum_pu = direct[..., 0] + torch.where(relaying, contributions[..., 0], zero).sum(-1)
    sum_se = direct[..., 1] + torch.where(relaying, zero, contributions[..., 1]).sum(-1)
    r = rates_from_sums(torch.stack([sum_pu, sum_se], -1), relaying.sum(-1), tasks.shape[-1], cfg)
    return r[..., 0], r[..., 1]


def rates_from_sums(sums: torch.Tensor, num_relaying: torch.Tensor, num_uavs: int, cfg: ModelConfig) -> torch.Tensor:
    """``[..., 2]`` (R_PU, R_SE) from the sums inside the two logs ``[..., 2]`` and the number of relaying UAVs
    ``[...]``.

    The sums hold the direct terms plus the contributions of the relaying (PU) and
    sensing (SE) UAVs; this applies the 1/2 factor (``af``), the lease rule and the
    authors' "both tasks staffed" rule.

    Args:
        sums: the sums inside the logarithms of R_PU and R_SE ``[..., 2]``.
        num_relaying: the number of relaying UAVs ``[...]``.
        num_uavs: ``N``, the UAVs in service.
        cfg: the model (its ``rate_model`` and ``lease_rule``).

    Returns:
        (R_PU, R_SE) ``[..., 2]`` in bit/s/Hz.
    """
    r = torch.log2(1 + sums)  # a fresh tensor: the rules below edit it in place
    if cfg.rate_model == "reference_code":
        # the authors' code pays neither network unless both tasks are staffed
        return r.masked_fill_(((num_relaying == 0) | (num_relaying == num_uavs)).unsqueeze(-1), 0.0)
    r.mul_(0.5)
    if cfg.lease_rule:
        r.select(-1, 1).masked_fill_(num_relaying == 0, 0.0)
    return r
