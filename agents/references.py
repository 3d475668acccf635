"""The yardstick's references from each start of an evaluation (docs/model.md, "What the numbers mean"): the exact best
discounted return ``V*_H`` and the fewest steps to each level of ``U*`` where the exact solver fits, certified lower
bounds beyond it, a mission's bounds and exact optimum under an energy model, and how far ``U*`` may be from the
optimum where its search stopped early.  :mod:`uavrl.agents.evaluation` measures every policy against them.
"""

from __future__ import annotations

import torch

from uavrl.envs.config import ModelConfig
from uavrl.envs.limits import EXACT_SOLVER_BUDGET
from uavrl.envs.physics.positions import model_positions
from uavrl.envs.solvers import exact, mission_exact
from uavrl.envs.solvers.bounds import OPTIMUM_RTOL, assignment_min_steps, optimal_configurations, relaxed_min_steps
from uavrl.envs.solvers.mission import delivered_bound, optimum_by_count, service_steps_bound
from uavrl.envs.solvers.optimum import MAX_EXCHANGE_UAVS, optimum_bound
from uavrl.envs.world import World

# the levels of U* a policy's steps are counted to (eval/reach_<level>, eval/steps_to_<level>, ...)
LEVELS = {"99": 0.99, "999": 0.999, "optimum": 1 - OPTIMUM_RTOL}


_SPACES: dict = {}  # the last few configuration spaces (up to 1 GiB each), by what they depend on


def _space(cfg: ModelConfig, device: str) -> exact.ConfigurationSpace:
    """:func:`~uavrl.envs.solvers.exact.model_space` of ``cfg``, kept for the last few grids, teams and moves: models
    that differ in their channels only share one."""
    key = (cfg.grid, cfg.num_uavs, device, model_positions(cfg).neighbours.numpy().tobytes())
    if key not in _SPACES:
        if len(_SPACES) >= 4:
            _SPACES.pop(next(iter(_SPACES)))
        _SPACES[key] = exact.model_space(cfg, device)
    return _SPACES[key]


def placements(outputs) -> torch.Tensor:
    """``[..., N, 2]`` the UAVs' (x, y) in a World's or env's outputs, with altitude levels ``[..., N, 3]`` (x, y,
    level): what :meth:`~uavrl.envs.World.utility` and :meth:`~uavrl.envs.World.cells_of` read."""
    if "levels" not in outputs:
        return outputs["positions"]
    return torch.cat([outputs["positions"], outputs["levels"].unsqueeze(-1)], -1)


def start_references(world: World, start, u_star: torch.Tensor, horizon: int, gamma: float) -> dict:
    """Per start ``[B]``: the exact best return ``V*_H`` (or ``None``) and the fewest steps to each level; under an
    energy model no return (it ignores energy) but :func:`mission_references` (``world`` at its starts).

    Exact where the configuration space fits (:func:`uavrl.envs.solvers.exact.fits`),
    else lower bounds (:mod:`uavrl.envs.solvers.bounds`): the relaxation for every
    level, and for the optimum also the bottleneck assignment to every
    optimal configuration.

    Args:
        world: the worlds of the starts, just reset.
        start: the worlds' outputs at the start (:meth:`~uavrl.envs.World.reset`: ``positions``, ``tasks``, with
            altitude levels ``levels``).
        u_star: each world's best utility U* ``[B]``.
        horizon: the evaluation's steps per rollout ``H``.
        gamma: the discount of the best return.

    Returns:
        ``best_return`` ``[B]`` (or None), ``min_steps`` ``[B, 3]`` (the fewest steps to 0.99 U*, 0.999 U* and U*)
        and ``exact`` (whether they are exact or lower bounds).
    """
    if world.energy is not None:  # the exact return ignores energy: a mission is measured by its delivered data
        return {**_level_references(world, start, u_star, horizon, gamma, False), **mission_references(world, horizon)}
    return _level_references(world, start, u_star, horizon, gamma, True)


def mission_references(world: World, horizon: int) -> dict:
    """Per start ``[B]`` under an energy model, from the batteries ``world`` starts with: the most data (bit/Hz) a
    mission of ``horizon`` steps can deliver (:func:`uavrl.envs.solvers.mission.delivered_bound`), ``U* H slot_s``, and
    where the exact mission solver fits (:func:`mission_optimum`) the exact most data, else ``None``."""
    cfg = world.cfg
    u_star_by_count = optimum_by_count(world.cell_contributions, world.direct, cfg)
    horizon_bound = u_star_by_count[:, -1] * horizon * cfg.slot_s
    if cfg.recharge_steps is not None:  # a recharged UAV serves again: only U* H slot_s is proved
        return {"delivered_bound": horizon_bound, "horizon_bound": horizon_bound, "delivered_optimum": None}
    bound = delivered_bound(service_steps_bound(world.energy, world.battery), u_star_by_count, horizon, cfg.slot_s)
    return {
        "delivered_bound": bound,
        "horizon_bound": horizon_bound,
        "delivered_optimum": mission_optimum(world, horizon),
    }


def mission_optimum(world: World, horizon: int) -> torch.Tensor | None:
    """``[B]`` the exact most data (bit/Hz) of each start's mission
    (:func:`uavrl.envs.solvers.mission_exact.optimal_mission`) where it fits: 1 or 2 UAVs, deterministic channels, no
    recharging, and the solver's estimate within :data:`~uavrl.envs.limits.EXACT_SOLVER_BUDGET` (at most ~20 s of CPU:
    4x4 with 2 UAVs and missions up to ~38 steps); ``None`` elsewhere.

    Args:
        world: the worlds of the starts under an energy model, just reset (their batteries the missions' own).
        horizon: the mission's steps ``H``.
    """
    try:
        mission_exact.check_world(world)
        return mission_exact.optimal_mission(world, horizon, memory_budget=EXACT_SOLVER_BUDGET).value
    except (mission_exact.MissionTooLarge, mission_exact.NotCovered):
        return None


def _level_references(world: World, start, u_star: torch.Tensor, horizon: int, gamma: float, returns: bool) -> dict:
    """:func:`start_references`' fewest steps to each level, and the exact best return where ``returns``."""
    cfg, B, N = world.cfg, world.num_worlds, world.cfg.num_uavs
    # the N serving UAVs: spares (env.num_spares) are the last agents and wait at the base at a start
    cells, tasks = world.cells_of(placements(start)[..., :N, :]), start["tasks"][..., :N]
    contributions, direct = world.cell_contributions, world.direct
    thresholds = torch.stack([q * u_star for q in LEVELS.values()], -1)  # [B, L]
    if exact.fits(cfg):
        per_world = cfg.layout == "random"  # one layout for all worlds otherwise
        tables = slice(None) if per_world else slice(0, 1)
        space = _space(cfg, str(world.device))
        potential = space.utility(cfg, contributions[tables], direct[tables])
        which = (
            torch.arange(B, device=world.device) if per_world else torch.zeros(B, dtype=torch.long, device=world.device)
        )
        start_index = space.index(cells, tasks)
        best_return = exact.optimal_values(space, potential, gamma, horizon)[which, start_index] if returns else None
        fewest = [
            exact.min_steps(space, potential >= thresholds[tables, level, None])[which, start_index].long()
            for level in range(len(LEVELS))
        ]
        return {"best_return": best_return, "min_steps": torch.stack(fewest, -1), "exact": True}
    positions = world.dynamics.positions
    fewest = relaxed_min_steps(cells, tasks, contributions, direct, cfg, thresholds, horizon, positions)
    optimal = [
        optimal_configurations(contributions[w], direct[w], cfg, float(u_star[w]))
        for w in range(1 if cfg.layout != "random" else B)
    ]
    optimal = optimal * B if len(optimal) == 1 else optimal
    assignment = assignment_min_steps(
        cells.cpu(), tasks.cpu(), [c.cpu() for c, _ in optimal], [t.cpu() for _, t in optimal], positions
    )
    fewest[:, -1] = torch.maximum(fewest[:, -1], assignment.to(fewest.device))
    return {"best_return": None, "min_steps": fewest, "exact": False}


def u_star_gap(world: World, u_star: torch.Tensor) -> float:
    """The largest relative gap ``(bound - U*) / U*`` over the worlds between a certified upper bound and the
    ``U*`` every metric divides by: 0 wherever ``U*`` is exact (always but where the search of
    :mod:`uavrl.envs.solvers.optimum` stopped at its node limit), and then the evaluation reports it as
    ``eval/u_star_gap``.

    Args:
        world: the evaluated worlds (their layouts' tables).
        u_star: the ``U*`` ``[B]`` the evaluation computed for them.
    """
    if world.cfg.num_uavs <= MAX_EXCHANGE_UAVS:  # the exchange method or brute force: exact
        return 0.0
    upper = optimum_bound(world.cell_contributions, world.direct, world.cfg).expand_as(u_star)
    return ((upper - u_star) / u_star).max().item()


_REFERENCE_CACHE: dict = {}


def cached_references(world, start, u_star, horizon, gamma) -> dict:
    """:func:`start_references`, kept for the last few settings (every run of an agent shares the starts)."""
    key = (
        world.cfg,
        world.num_worlds,
        horizon,
        gamma,
        str(world.device),
        start["positions"].cpu().numpy().tobytes(),
        start["tasks"].cpu().numpy().tobytes(),
        None if "levels" not in start else start["levels"].cpu().numpy().tobytes(),
        None if world.battery is None else world.battery.cpu().numpy().tobytes(),
    )
    if key not in _REFERENCE_CACHE:
        if len(_REFERENCE_CACHE) >= 4:
            _REFERENCE_CACHE.pop(next(iter(_REFERENCE_CACHE)))
        _REFERENCE_CACHE[key] = start_references(world, start, u_star, horizon, gamma)
    return _REFERENCE_CACHE[key]
