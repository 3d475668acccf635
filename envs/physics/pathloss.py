"""The mean path loss of the physical channel models, in dB (docs/model.md, Channel models).

Only the links PT-UAV and UAV-PR are air-to-ground: S and E fly at the UAVs' height, so UAV-S and UAV-E are
air-to-air, free space and line of sight.  The mean of a model with a LoS and an NLoS state is the LoS-probability
weighted mean of the two losses in dB (Al-Hourani et al. define their mean path loss so; for TR 36.777 the same rule
keeps the two models comparable, see docs/model.md).  Shadowing is zero-mean in dB and left out of the mean.

Example:
    >>> import torch
    >>> round(uma_av_los_probability(torch.tensor(200.0), torch.tensor(50.0)).item(), 3)  # the issue's check value
    0.967
"""

from __future__ import annotations

import torch

from . import radio
from .buildings import city_part
from .radio import AL_HOURANI, TR36777, tr36777_los_parameters, tr36777_losses_db

AIR_TO_GROUND = (True, True, False, False)  # per node (PT, PR, S, E): is the UAV's link to it air-to-ground?


def free_space_db(distance_m: torch.Tensor, carrier_ghz: float) -> torch.Tensor:
    """``FSPL = 20 log10(4 pi f_c d / c)``, ``d`` in metres, ``f_c`` in GHz.

    Args:
        distance_m: the distances ``d`` in m, any shape.
        carrier_ghz: the carrier frequency ``f_c`` in GHz.

    Returns:
        The free-space path loss in dB, the shape of ``distance_m``.

    Example:
        >>> free_space_db(torch.tensor([100.0, 1000.0]), carrier_ghz=2.0)
        tensor([78.4684, 98.4684])
    """
    return radio.free_space_db(distance_m, carrier_ghz, torch.log10)


def al_hourani_los_probability(elevation_deg: torch.Tensor, environment: str) -> torch.Tensor:
    """``P_LoS = 1 / (1 + a exp(-b (theta - a)))``, ``theta`` the elevation angle in degrees (Al-Hourani et al.
    2014).

    Args:
        elevation_deg: the elevation angles ``theta`` in degrees, any shape.
        environment: ``"suburban"``, ``"urban"``, ``"dense_urban"`` or ``"highrise"`` (its ``a``, ``b``).
    """
    a, b, _, _ = AL_HOURANI[environment]
    return 1 / (1 + a * torch.exp(-b * (elevation_deg - a)))


def al_hourani_states(
    horizontal_m: torch.Tensor, height_m: torch.Tensor, distance_m: torch.Tensor, carrier_ghz: float, environment: str
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(P_LoS, PL_LoS, PL_NLoS)``: ``PL = FSPL(d) + eta`` in dB in each state (Al-Hourani et al. 2014), the excess
    loss eta in dB added to the free-space loss in dB.

    Args:
        horizontal_m: the horizontal distances in m.
        height_m: the UAV's heights above the ground node in m.
        distance_m: the 3-D distances in m.
        carrier_ghz: the carrier frequency in GHz.
        environment: ``"suburban"``, ``"urban"``, ``"dense_urban"`` or ``"highrise"``.
    """
    _, _, eta_los, eta_nlos = AL_HOURANI[environment]
    p_los = al_hourani_los_probability(torch.rad2deg(torch.atan2(height_m, horizontal_m)), environment)
    free = free_space_db(distance_m, carrier_ghz)
    return p_los, free + eta_los, free + eta_nlos


def _maximum(x: torch.Tensor, y) -> torch.Tensor:
    return torch.maximum(x, y) if isinstance(y, torch.Tensor) else x.clamp(min=y)


def tr36777_los_probability(channel: str, horizontal_m: torch.Tensor, height_m: torch.Tensor) -> torch.Tensor:
    """TR 36.777 Table B-1: 1 within ``d_1`` (and above the scenario's all-LoS height), else ``d_1 / d_2D +
    exp(-d_2D / p_1) (1 - d_1 / d_2D)``, the scenario's ``p_1`` and ``d_1`` from
    :func:`.radio.tr36777_los_parameters`.

    Args:
        channel: ``"tr36777_uma"``, ``"tr36777_umi"`` or ``"tr36777_rma"``.
        horizontal_m: the horizontal distances ``d_2D`` in m.
        height_m: the UAV's heights ``h`` in m.
    """
    p1, d1 = tr36777_los_parameters(channel, torch.log10(height_m), _maximum)
    ratio = d1 / horizontal_m.clamp(min=d1)  # 1 within d_1: the formula then gives 1 too
    p_los = ratio + torch.exp(-horizontal_m / p1) * (1 - ratio)
    return torch.where(height_m > TR36777[channel].all_los_above_m, torch.ones_like(p_los), p_los)


def uma_av_los_probability(horizontal_m: torch.Tensor, height_m: torch.Tensor) -> torch.Tensor:
    """TR 36.777 Table B-1, UMa-AV: ``p_1 = 4300 log10(h) - 3800`` and ``d_1 = max(460 log10(h) - 700, 18)`` metres,
    ``P_LoS = 1`` above 100 m.

    Args:
        horizontal_m: the horizontal distances ``d_2D`` in m.
        height_m: the UAV's heights ``h`` in m.
    """
    return tr36777_los_probability("tr36777_uma", horizontal_m, height_m)


def tr36777_states(
    channel: str, horizontal_m: torch.Tensor, height_m: torch.Tensor, distance_m: torch.Tensor, carrier_ghz: float
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """TR 36.777 Tables B-1 and B-2 (``channel`` ``tr36777_uma``, ``tr36777_umi`` or ``tr36777_rma``): ``(P_LoS,
    PL_LoS, PL_NLoS)`` in dB (:func:`.radio.tr36777_losses_db`).

    Args:
        channel: the scenario.
        horizontal_m: the horizontal distances ``d_2D`` in m.
        height_m: the UAV's heights ``h`` in m.
        distance_m: the 3-D distances ``d_3D`` in m.
        carrier_ghz: the carrier frequency in GHz.
    """
    log_h = torch.log10(height_m)
    los, nlos = tr36777_losses_db(channel, torch.log10(distance_m), log_h, carrier_ghz, _maximum)
    return tr36777_los_probability(channel, horizontal_m, height_m), los, nlos


def _mean(p_los: torch.Tensor, los_db: torch.Tensor, nlos_db: torch.Tensor) -> torch.Tensor:
    """The LoS-probability weighted mean path loss in dB."""
    return p_los * los_db + (1 - p_los) * nlos_db


def link_states_db(uav_xyz: torch.Tensor, nodes: torch.Tensor, cfg) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(P_LoS, PL_LoS, PL_NLoS)`` ``[..., N, 4]`` in dB from every UAV ``[..., N, 3]`` to every node ``[..., 4, 3]``
    (cells).

    Air-to-ground links (PT, PR) follow ``cfg.channel``; air-to-air ones (S, E) are free space in line of sight
    (``P_LoS = 1``).  In a city with ``los="geometric"`` an air-to-ground link's ``P_LoS`` is 1 when its segment clears
    every building and 0 otherwise (:mod:`.buildings`), so the mean is the LoS or the NLoS loss.  ``h`` is the UAV's
    height above the ground node, ``d_2D`` the horizontal and ``d_3D`` the 3-D distance, all in metres.

    Args:
        uav_xyz: the UAVs' positions ``[..., N, 3]`` in cells.
        nodes: PT, PR, S and E ``[..., 4, 3]`` in cells.
        cfg: the model (a physical channel, its ``cell_size``, ``carrier_ghz`` and ``environment``).
    """
    delta = (uav_xyz.unsqueeze(-2) - nodes.unsqueeze(-3)) * cfg.cell_size
    horizontal = torch.linalg.vector_norm(delta[..., :2], dim=-1)
    height = delta[..., 2].abs()
    distance = torch.linalg.vector_norm(delta, dim=-1)
    if cfg.channel == "al_hourani":
        ground = al_hourani_states(horizontal, height, distance, cfg.carrier_ghz, cfg.environment)
    else:
        ground = tr36777_states(cfg.channel, horizontal, height, distance, cfg.carrier_ghz)
    air = torch.tensor(AIR_TO_GROUND, device=uav_xyz.device)
    free = free_space_db(distance, cfg.carrier_ghz)
    p_los, los, nlos = ground
    if cfg.geometric_los:  # a city's link is in line of sight or not: its segment clears every building or not
        p_los = city_part(cfg).line_of_sight(uav_xyz, nodes).to(p_los.dtype)
    return torch.where(air, p_los, torch.ones_like(p_los)), torch.where(air, los, free), torch.where(air, nlos, free)


def mean_path_loss_db(uav_xyz: torch.Tensor, nodes: torch.Tensor, cfg) -> torch.Tensor:
    """``[..., N, 4]`` mean path loss in dB of :func:`link_states_db` (free space on the air-to-air links):
    ``P_LoS PL_LoS + (1 - P_LoS) PL_NLoS``.

    Args:
        uav_xyz: the UAVs' positions ``[..., N, 3]`` in cells.
        nodes: PT, PR, S and E ``[..., 4, 3]`` in cells.
        cfg: the model (a physical channel).
    """
    return _mean(*link_states_db(uav_xyz, nodes, cfg))


def gain_from_db(path_loss_db: torch.Tensor) -> torch.Tensor:
    """The power gain ``|h|^2 = 10^(-PL / 10)`` of a path loss in dB.

    Args:
        path_loss_db: path losses ``PL`` in dB, any shape.

    Example:
        >>> gain_from_db(torch.tensor([30.0, 100.0]))
        tensor([1.0000e-03, 1.0000e-10])
    """
    return torch.pow(10.0, -path_loss_db / 10)
