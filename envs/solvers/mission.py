"""An upper bound on the data a mission can deliver under an energy model (docs/model.md, What the numbers mean).

A UAV of battery ``b0`` serves at most ``S(b0) = floor((b0 - r_min) / c_min)`` steps, with ``c_min`` the cheapest
step of a serving UAV and ``r_min`` the least reserve of a cell on the grid (:func:`service_steps_bound`).  With
``k`` UAVs serving, a step's utility is at most ``U*_k``, the exact optimum of ``k`` UAVs (:func:`optimum_by_count`),
and ``U*_k`` grows with ``k``.  So after step ``t`` at most ``m_t = #{i : S_i >= t}`` UAVs serve, and a mission of
``H`` steps delivers at most ``slot_s sum_{t=1..H} U*_{m_t}`` (:func:`delivered_bound`); the proof is in
docs/model.md.

Example:
    >>> import torch
    >>> from uavrl.envs import make_config
    >>> from uavrl.envs.world import World
    >>> world = World(make_config("paper", grid=(3, 3), num_uavs=2, energy="rotary_wing", base=(-1, 0),
    ...                           battery_wh=0.4), 1)
    >>> _ = world.reset()
    >>> service_steps_bound(world.energy, world.battery).tolist()
    [[7, 7]]
    >>> u = optimum_by_count(world.cell_contributions, world.direct, world.cfg)
    >>> bool((u[:, 0] == 0).all() and (u.diff(dim=-1) >= 0).all())
    True
"""

from __future__ import annotations

import torch

from ..physics.channel import rates
from .optimum import optimum

# a battery's running sum is float64: a UAV at its exact limit is given the step its rounding might allow
ROUNDING = 1e-6


def service_steps_bound(energy, battery: torch.Tensor) -> torch.Tensor:
    """``[..., N]`` the most steps after which each UAV of ``battery`` ``[..., N]`` (its level at the start) can
    still serve, under the energy part ``energy`` (:class:`~uavrl.envs.physics.energy.Energy`)."""
    cheapest = min(energy.energies.move, energy.energies.stay)
    least_reserve = energy.reserve[: energy.away].min()
    return ((battery - least_reserve) / cheapest + ROUNDING).floor().clamp(min=0).long()


def optimum_by_count(cell_contributions: torch.Tensor, direct: torch.Tensor, cfg) -> torch.Tensor:
    """``[B, N + 1]`` float64 ``U*_k`` for ``k = 0..N`` UAVs on the layouts of ``[B, C, 2]`` contributions and
    ``[B, 2]`` direct terms (``U*_0``: the direct links alone).

    Args:
        cell_contributions: each cell's relay and sensing contributions ``[B, C, 2]``.
        direct: the direct-link terms ``[B, 2]``.
        cfg: the model (``num_uavs`` is the largest ``k``).
    """
    none = rates(cell_contributions.new_zeros(len(direct), 0, 2), direct.new_zeros(len(direct), 0).long(), direct, cfg)
    by_count = [none[0] + none[1]]
    for k in range(1, cfg.num_uavs + 1):
        by_count.append(optimum(cell_contributions, direct, cfg.replace(num_uavs=k))[0])
    return torch.stack(by_count, -1)


def delivered_bound(service_steps: torch.Tensor, u_star_by_count: torch.Tensor, horizon: int, slot_s: float):
    """``[B]`` the most data (bit/Hz) ``H = horizon`` steps of ``slot_s`` seconds can deliver: ``slot_s sum_t
    U*_{m_t}``, ``m_t`` the UAVs whose ``service_steps`` ``[B, N]`` reach step ``t``.

    Args:
        service_steps: the most steps each UAV can serve ``[B, N]``.
        u_star_by_count: ``U*_k`` ``[B, N + 1]`` in bit/s/Hz (:func:`optimum_by_count`).
        horizon: the mission's steps ``H``.
        slot_s: a step's duration in s.

    Example:
        >>> u_star_by_count = torch.tensor([[0.0, 1.0, 1.5]])  # no UAV, one, two
        >>> delivered_bound(torch.tensor([[2, 5]]), u_star_by_count, horizon=4, slot_s=1.0)  # two UAVs, then one
        tensor([5.], dtype=torch.float64)
    """
    ends = service_steps.clamp(max=horizon).sort(-1).values  # after the k-th smallest (from 1), N - k can serve
    edges = torch.cat([ends.new_zeros(len(ends), 1), ends, ends.new_full((len(ends), 1), horizon)], -1)
    steps_with = edges.diff(dim=-1).double()  # [B, N + 1]: steps with N, N - 1, ..., 0 UAVs able to serve
    return slot_s * (steps_with * u_star_by_count.flip(-1)).sum(-1)
