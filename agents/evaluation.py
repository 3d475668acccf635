"""One evaluation for every agent and baseline: the paper's per-episode metrics and the exact yardstick.

Training curves (``train/...``) and evaluations (``eval/...``) of all agents are
computed here, so their TensorBoard tags and meanings are identical.

The yardstick (docs/model.md, "What the numbers mean") measures what the paper set out to do: reach
the best configuration in as few steps as possible.  From each of
``num_starts`` fixed, seeded starts the greedy policy runs ``horizon`` steps;
with ``U_t`` the mean-channel utility after step ``t`` (faded draws never
decide whether a level is reached):

- ``eval/return``: mean of ``J = sum_{t=1..H} gamma^(t-1) (U_t - U_{t-1})``
  with ``gamma = eval.gamma``; ``eval/return_ratio`` = sum of J over the sum
  of the exact best ``V*_H`` (only where the exact solver fits).
- per level (``99``: 0.99 U*, ``999``: 0.999 U*, ``optimum``: U* within a
  relative 1e-9): ``eval/reach_<level>`` (share of starts reaching it within
  H), and over those starts ``eval/steps_to_<level>`` (first step at the
  level, 0 if the start is there), ``eval/min_steps_to_<level>`` (the fewest
  possible: exact by breadth-first search, or a lower bound where the exact
  solver does not fit; ``eval/min_steps_exact`` says which) and
  ``eval/step_ratio_<level>`` (mean of steps / fewest over starts needing >= 1).
- ``eval/end_at_optimum``; ``eval/optimality`` (final U / U*),
  ``eval/optimality_min`` and ``eval/optimal_fraction`` (final U >= 0.99 U*).
- ``eval/u_star_gap``, only where U* is not proven exact (:func:`u_star_gap`): every metric above then uses the
  best configuration found, within this relative gap of the optimum.

Under an energy model each start is one mission (no restart; the default horizon sees every UAV home) and
:func:`mission_metrics` adds its delivered data, lifetimes, energy per bit and the ratio to an upper bound on what
any policy delivers (:mod:`uavrl.envs.solvers.mission`), and where the exact mission solver fits
(:mod:`uavrl.envs.solvers.mission_exact`) the exact optimum and the share of it delivered; the return, whose exact best
ignores energy, is left out, and the levels and the end are read while the full team serves.

Example:
    >>> from uavrl.agents.baselines import RandomPolicy
    >>> from uavrl.envs import make_config
    >>> cfg = make_config("paper", grid=(3, 3), num_uavs=2)
    >>> metrics = evaluate(RandomPolicy(seed=0), cfg, num_starts=4, horizon=5)
    >>> 0 < metrics["eval/optimality"] <= 1, metrics["eval/min_steps_exact"]
    (True, 1.0)
"""

from __future__ import annotations

import contextlib
import functools
import math
import numbers
import time

import torch

from uavrl.agents.schema import EvalSchema
from uavrl.envs import InvalidOption, InvalidType, ModelConfig
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET, EXACT_SOLVER_BUDGET, evaluation_bytes, evaluation_horizon, gib
from uavrl.envs.limits import default_horizon as default_horizon  # the video's and the tabular evaluation's
from uavrl.envs.physics.grid import cells_of, on_grid
from uavrl.envs.rules import refuse, rule_of
from uavrl.envs.solvers import exact, mission_exact
from uavrl.envs.solvers.bounds import OPTIMUM_RTOL, assignment_min_steps, optimal_configurations, relaxed_min_steps
from uavrl.envs.solvers.mission import delivered_bound, optimum_by_count, service_steps_bound
from uavrl.envs.solvers.optimum import MAX_EXCHANGE_UAVS, optimum_bound
from uavrl.envs.world import World, check_seed, resolve_device

# the command line's eval.* defaults (uavrl/schema.py): the seed is far from training seeds, so the evaluation's
# worlds (and random layouts) are held out
NUM_STARTS, EVAL_SEED, DEFAULT_GAMMA = EvalSchema.num_starts, EvalSchema.seed, EvalSchema.gamma
NINETY_PERCENT = 0.9
# the per-episode metrics of every agent's training (docs/model.md, "What the numbers mean"; train/<name>), in the
# order of episode_metrics and of the running metrics of episode_start / episode_step
EPISODE_METRICS = ("sum_r_pu", "sum_r_se", "sum_utility", "task_switches", "moves", "steps_to_90")
LEVELS = {"99": 0.99, "999": 0.999, "optimum": 1 - OPTIMUM_RTOL}


def check_settings(gamma, horizon, num_starts) -> None:
    """One-line errors for evaluation settings by their rules (:class:`~uavrl.schema.EvalSchema`), named as on the
    command line.

    Args:
        gamma: the yardstick's discount (``eval.gamma``).
        horizon: steps per rollout, or None (``eval.horizon``).
        num_starts: fixed starts of the evaluation (``eval.num_starts``).
    """
    for name, value in (("gamma", gamma), ("horizon", horizon), ("num_starts", num_starts)):
        refuse(f"eval.{name}", value, rule_of(EvalSchema, name))


def check_arguments(policy, cfg, **settings) -> None:
    """:func:`evaluate`'s arguments, refused in one line of :class:`~uavrl.envs.InvalidOption` (an
    :class:`~uavrl.envs.InvalidType` for a wrong type) that names the keyword as the caller typed it."""
    if not callable(policy):
        raise InvalidType("policy", policy, "give a TorchRL policy (a module that writes ('agents', 'action'))")
    if not isinstance(cfg, ModelConfig):
        raise InvalidType("cfg", cfg, "give a ModelConfig (uavrl.envs.make_config(...))")
    for name in ("num_starts", "horizon", "gamma"):
        value, rule = settings[name], rule_of(EvalSchema, name)
        if not rule.accepts(value):
            number = isinstance(value, numbers.Real) and not isinstance(value, bool)
            kind = InvalidOption if number or value is None else InvalidType
            raise kind(name, message=f"{name}={value!r} is invalid: {rule.allowed.replace('null', 'None')}")
    check_seed(settings["seed"])
    resolve_device(settings["device"])
    budget = settings["memory_budget"]
    if not isinstance(budget, numbers.Real) or isinstance(budget, bool):
        raise InvalidType("memory_budget", budget, "give the bytes the evaluation may take, a positive number")
    if not budget > 0:
        raise InvalidOption("memory_budget", budget, "give the bytes the evaluation may take, a positive number")


COMMAND_LINE_NAMES = {
    "horizon": "eval.horizon",
    "num_starts": "eval.num_starts",
    "memory_budget": "agent.memory_budget",
}


def check_memory(
    cfg: ModelConfig, num_starts: int, horizon: int, tables: int, memory_budget, names=COMMAND_LINE_NAMES
) -> None:
    """A one-line refusal, before anything is allocated, when the evaluation would need more than ``memory_budget``
    bytes (:func:`uavrl.envs.limits.evaluation_bytes`), naming the settings as ``names`` has them.

    Args:
        cfg: the evaluated model.
        num_starts: the evaluation's starts (worlds).
        horizon: its steps per rollout.
        tables: how many Q tables the tabular agent plays greedily, each from every start (0: a TorchRL policy's
            rollout).
        memory_budget: the bytes it may take.
        names: how the refusal names ``horizon``, ``num_starts`` and ``memory_budget``: the command line's settings
            (the default) or, from :func:`evaluate`, its keyword arguments.
    """
    need = evaluation_bytes(cfg, num_starts, horizon, tables)
    if need > memory_budget:
        name, value = ("horizon", horizon) if horizon > num_starts else ("num_starts", num_starts)
        name, budget = names[name], names["memory_budget"]
        raise InvalidOption(
            name,
            message=f"{name}={value} is invalid: the evaluation of {num_starts:,} starts x {horizon:,} steps needs "
            f"about {gib(need)}, over {budget}={int(memory_budget)}: lower {name}, or raise {budget}=<bytes>",
        )


def episode_metrics(r_pu, r_se, task_switches, moves, u_star, utility=None) -> dict[str, torch.Tensor]:
    """The per-episode metrics of docs/model.md ("What the numbers mean").  Inputs ``[W, T]`` for ``W`` episodes of
    ``T`` steps, ``u_star`` ``[W]``.

    Returns ``[W]`` tensors: the sums over steps of R_PU, R_SE and U (Fig. 3), of
    task switches and moves (Fig. 4), and the number of steps until U first
    reaches 90% of U* (Fig. 5; T if never).  ``utility`` ``[W, T]``, the
    mean-channel utility, decides that under fading (default: R_PU + R_SE).

    Args:
        r_pu: each step's primary rate R_PU ``[W, T]`` (bit/s/Hz).
        r_se: each step's emergency rate R_SE ``[W, T]`` (bit/s/Hz).
        task_switches: each step's task switches ``[W, T]``.
        moves: each step's moves ``[W, T]``.
        u_star: each episode's best utility U* ``[W]``.
        utility: the mean-channel utility ``[W, T]``, or None.

    Example:
        >>> rates = torch.tensor([[0.5, 1.0, 1.0]])
        >>> metrics = episode_metrics(rates, rates, torch.zeros(1, 3), torch.ones(1, 3), torch.tensor([2.0]))
        >>> metrics["sum_utility"], metrics["moves"], metrics["steps_to_90"]
        (tensor([5.], dtype=torch.float64), tensor([3.], dtype=torch.float64), tensor([2.], dtype=torch.float64))
    """
    sum_utility = (r_pu + r_se).double()
    reach_utility = sum_utility if utility is None else utility.double()
    T = sum_utility.shape[-1]
    reached = reach_utility >= NINETY_PERCENT * u_star.double().unsqueeze(-1)
    first = torch.where(reached.any(-1), reached.double().argmax(-1) + 1, torch.full_like(u_star.double(), T))
    return {  # the order of EPISODE_METRICS
        "sum_r_pu": r_pu.double().sum(-1),
        "sum_r_se": r_se.double().sum(-1),
        "sum_utility": sum_utility.sum(-1),
        "task_switches": task_switches.double().sum(-1),
        "moves": moves.double().sum(-1),
        "steps_to_90": first.double(),
    }


def episode_start(zero, num_steps):
    """The running metrics of an episode of ``num_steps`` steps before its first step: a tuple in the order of
    :data:`EPISODE_METRICS`, each ``zero`` (``0.0``, or a tensor of zeros ``[W]`` for ``W`` episodes) plus its start
    value.  ``steps_to_90`` starts at ``num_steps``, what it stays at if 90% of U* is never reached."""
    return zero, zero, zero, zero, zero, zero + num_steps


def episode_step(metrics, step, r_pu, r_se, task_switches, moves, u90):
    """The running metrics ``metrics`` (:func:`episode_start`) after step number ``step`` (from 1) of the episode,
    to rates ``(r_pu, r_se)`` with ``task_switches`` and ``moves``; ``u90`` is 90% of U*.

    The metrics of :func:`episode_metrics`, one step at a time: the sums add the steps in order; ``steps_to_90``
    becomes the first step whose utility reaches ``u90``.  Arithmetic only, so it serves the tabular learner's
    torch loop (tensors ``[W]``) and, compiled by numba, its scalar loops: both add the same numbers in the same
    order, bit for bit.
    """
    sum_r_pu, sum_r_se, sum_utility, sum_switches, sum_moves, steps_to_90 = metrics
    utility = r_pu + r_se
    first = (utility >= u90) * (step < steps_to_90)
    return (
        sum_r_pu + r_pu,
        sum_r_se + r_se,
        sum_utility + utility,
        sum_switches + task_switches,
        sum_moves + moves,
        steps_to_90 + (step - steps_to_90) * first,
    )


@functools.lru_cache(maxsize=4)
def _space(grid: tuple[int, int], num_uavs: int, device: str) -> exact.ConfigurationSpace:
    return exact.ConfigurationSpace(grid, num_uavs, device)


def start_references(world: World, start, u_star: torch.Tensor, horizon: int, gamma: float) -> dict:
    """Per start ``[B]``: the exact best return ``V*_H`` (or ``None``) and the fewest steps to each level; under an
    energy model no return (it ignores energy) but :func:`mission_references` (``world`` at its starts).

    Exact where the configuration space fits (:func:`uavrl.envs.solvers.exact.fits`),
    else lower bounds (:mod:`uavrl.envs.solvers.bounds`): the relaxation for every
    level, and for the optimum also the bottleneck assignment to every
    optimal configuration.

    Args:
        world: the worlds of the starts, just reset.
        start: the worlds' outputs at the start (:meth:`~uavrl.envs.World.reset`: ``positions``, ``tasks``).
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
    cells, tasks = cells_of(start["positions"][..., :N, :], cfg.grid[0]), start["tasks"][..., :N]
    contributions, direct = world.cell_contributions, world.direct
    thresholds = torch.stack([q * u_star for q in LEVELS.values()], -1)  # [B, L]
    if exact.fits(cfg):
        per_world = cfg.layout == "random"  # one layout for all worlds otherwise
        tables = slice(None) if per_world else slice(0, 1)
        space = _space(cfg.grid, cfg.num_uavs, str(world.device))
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
    fewest = relaxed_min_steps(cells, tasks, contributions, direct, cfg, thresholds, horizon)
    optimal = [
        optimal_configurations(contributions[w], direct[w], cfg, float(u_star[w]))
        for w in range(1 if cfg.layout != "random" else B)
    ]
    optimal = optimal * B if len(optimal) == 1 else optimal
    assignment = assignment_min_steps(
        cells.cpu(), tasks.cpu(), [c.cpu() for c, _ in optimal], [t.cpu() for _, t in optimal], cfg.grid
    )
    fewest[:, -1] = torch.maximum(fewest[:, -1], assignment.to(fewest.device))
    return {"best_return": None, "min_steps": fewest, "exact": False}


def yardstick_metrics(
    utility: torch.Tensor, u_star: torch.Tensor, references: dict, gamma: float, full_team: torch.Tensor | None = None
) -> dict[str, float]:
    """The yardstick from mean-channel utilities ``[B, H + 1]`` (start first) and :func:`start_references`.

    ``full_team`` ``[B]`` (an energy model): the last column at which every UAV served.  The levels count only up to
    it, the end is read there, and the return is left out (its exact best ignores energy).

    Args:
        utility: the mean-channel utility ``[B, H + 1]`` at the start and after each step (bit/s/Hz).
        u_star: each start's best utility U* ``[B]``.
        references: the start references of :func:`start_references`.
        gamma: the discount of ``eval/return`` and ``eval/return_ratio``.
        full_team: the last column at which every UAV served ``[B]``, or None (no energy model).
    """
    H = utility.shape[1] - 1
    if full_team is None:
        discount = gamma ** torch.arange(H, dtype=torch.float64, device=utility.device)
        returns = (utility.diff(dim=1) * discount).sum(-1)
        out = {"eval/return": returns.mean().item(), "eval/min_steps_exact": float(references["exact"])}
        end = utility[:, -1]
    else:
        out = {"eval/min_steps_exact": float(references["exact"])}
        end = utility.gather(1, full_team.unsqueeze(-1)).squeeze(-1)
        later = torch.arange(H + 1, device=utility.device) > full_team.unsqueeze(-1)
        utility = utility.masked_fill(later, -math.inf)
    if references["best_return"] is not None:
        out["eval/return_ratio"] = (returns.sum() / references["best_return"].sum()).item()
    for level, (name, q) in enumerate(LEVELS.items()):
        at = utility >= q * u_star.unsqueeze(-1)
        reached = at.any(-1)
        out[f"eval/reach_{name}"] = reached.double().mean().item()
        if not reached.any():
            continue
        steps, fewest = at.double().argmax(-1)[reached].double(), references["min_steps"][:, level][reached].double()
        out[f"eval/steps_to_{name}"] = steps.mean().item()
        out[f"eval/min_steps_to_{name}"] = fewest.mean().item()
        moving = fewest >= 1
        if moving.any():
            out[f"eval/step_ratio_{name}"] = (steps[moving] / fewest[moving]).mean().item()
    out["eval/end_at_optimum"] = (end >= LEVELS["optimum"] * u_star).double().mean().item()
    return out


@torch.no_grad()
def evaluate(
    policy,
    cfg: ModelConfig,
    *,
    num_starts: int = NUM_STARTS,
    horizon: int | None = None,
    seed: int = EVAL_SEED,
    device="cpu",
    gamma: float = DEFAULT_GAMMA,
    memory_budget: int = DEFAULT_MEMORY_BUDGET,
) -> dict[str, float]:
    """Greedy rollouts of ``policy`` from ``num_starts`` fixed, seeded starts, measured by the yardstick.

    ``policy`` is any TorchRL policy for :class:`~uavrl.envs.UAVSpectrumEnv` (reads the
    observation keys, writes ``("agents", "action")``); one with a ``bind_env``
    method (the oracle) is first given the evaluation's environment.

    Args:
        policy: the policy to score, a TorchRL module (``uavrl.load_policy`` returns one for any saved run).
        cfg: the model (:func:`~uavrl.envs.make_config`) whose worlds it plays.
        num_starts: how many fixed starts (worlds) to play from, each once.
        horizon: steps per rollout; None: ``max(20, 2 (L1 + L2))``, or under an energy model the steps by which
            every UAV is home.
        seed: seeds the starts (the default is held out from every training seed).
        device: the torch device of the evaluation's worlds.
        gamma: the yardstick's discount (``eval/return`` and ``eval/return_ratio``).
        memory_budget: the bytes its worlds may take (``agent.memory_budget`` on the command line); more is refused.

    Returns:
        The metrics by ``eval/...`` key, among them ``eval/optimality`` (final utility over U*),
        ``eval/return_ratio`` (discounted gain over the exact best) and ``eval/reach_999`` (share of starts that
        reach 0.999 U*); docs/yardstick.md explains each.

    The oracle planner on a 4x4 grid, from 4 starts:

    >>> from uavrl.agents.baselines import OraclePolicy
    >>> from uavrl.envs import make_config
    >>> cfg = make_config("paper", grid=(4, 4), num_uavs=2)
    >>> metrics = evaluate(OraclePolicy(cfg), cfg, num_starts=4)
    >>> metrics["eval/optimality"] > 0.99
    True
    """
    from uavrl.envs.env import UAVSpectrumEnv  # TorchRL, only where a TorchRL policy is evaluated

    check_arguments(
        policy,
        cfg,
        num_starts=num_starts,
        horizon=horizon,
        gamma=gamma,
        seed=seed,
        device=device,
        memory_budget=memory_budget,
    )
    horizon = horizon or evaluation_horizon(cfg)
    check_memory(cfg, num_starts, horizon, 0, memory_budget, names={name: name for name in COMMAND_LINE_NAMES})
    env = UAVSpectrumEnv(
        batch_size=num_starts,
        config=cfg.replace(max_steps=horizon),
        seed=seed,
        device=device,
        memory_budget=memory_budget,
    )
    start = env.reset()
    u_star = env.optimum()[0]
    references = _references(env.world, start, u_star, horizon, gamma)
    steps, batteries = greedy_rollout(env, policy, start, horizon)
    return greedy_metrics(env.world, start, steps, u_star, references, gamma, batteries)


def greedy_rollout(env, policy, start, horizon: int) -> tuple[dict, list | None]:
    """``horizon`` steps of ``policy`` from ``start``, each world once: ``(steps, batteries)``, ``steps`` the
    ``[B, H]`` outputs :func:`greedy_metrics` reads (``r_pu``, ``r_se``, ``task_switches``, ``moves``, and
    ``positions``, ``tasks``), ``batteries`` the worlds' batteries before and after under an energy model (else
    None)."""
    if hasattr(policy, "bind_env"):
        policy.bind_env(env)
    if env.cfg.energy == "none":
        rollout = env.rollout(horizon, policy, auto_reset=False, tensordict=start, break_when_any_done=False)
        batteries = None
    else:
        batteries = [env.world.battery]
        rollout = mission_rollout(env, policy, start, horizon)
        batteries.append(env.world.battery)
    steps = {key: rollout["next", key].squeeze(-1) for key in ("r_pu", "r_se", "task_switches", "moves")}  # [B, H]
    steps.update(positions=rollout["next", "positions"], tasks=rollout["next", "tasks"])
    return steps, batteries


def mission_rollout(env, policy, start, horizon: int, after_step=None):
    """``horizon`` steps of ``policy`` in ``env`` from ``start`` (a TorchRL rollout ``[B, H]``) with no reset: TorchRL's
    rollout resets a world whose episode ended, and a mission is played once.  ``after_step(env)``, if given, is
    called after every step (e.g. to read ``env.world``'s batteries)."""
    from torchrl.envs.utils import step_mdp

    frames, tensordict = [], start
    for _ in range(horizon):
        tensordict.update(policy(tensordict))
        frames.append(env.step(tensordict))
        if after_step is not None:
            after_step(env)
        tensordict = step_mdp(frames[-1], keep_other=True, exclude_action=False)
    return torch.stack(frames, 1)


def evaluation_starts(
    cfg: ModelConfig,
    num_starts: int,
    horizon: int | None,
    seed: int,
    device,
    gamma: float,
    memory_budget: int = DEFAULT_MEMORY_BUDGET,
):
    """What :func:`evaluate` measures every policy from, for evaluations that step a world themselves.

    Returns the world of the ``num_starts`` starts (reset), its outputs at the
    start, ``U*`` ``[B]``, the start references and the horizon.

    Args:
        cfg: the evaluated model.
        num_starts: how many fixed starts (worlds).
        horizon: steps per rollout; None: the evaluation's default (as :func:`evaluate`).
        seed: seeds the starts.
        device: the torch device of the world.
        gamma: the yardstick's discount.
        memory_budget: the bytes the world may take; more is refused.
    """
    check_settings(gamma, horizon, num_starts)
    horizon = horizon or evaluation_horizon(cfg)
    world = World(cfg.replace(max_steps=horizon), num_starts, device, seed, memory_budget=memory_budget)
    start = world.reset()
    u_star = world.optimum()[0]
    return world, start, u_star, _references(world, start, u_star, horizon, gamma), horizon


def greedy_metrics(
    world: World, start, steps, u_star: torch.Tensor, references: dict, gamma: float, batteries=None
) -> dict[str, float]:
    """The ``eval/...`` scalars of greedy episodes from the starts of ``world``.

    ``start`` holds the start's ``positions`` and ``tasks``, ``steps`` each
    step's ``positions``, ``tasks``, ``r_pu``, ``r_se``, ``task_switches`` and
    ``moves``, ``[B, H, ...]`` (the per-world scalars ``[B, H]``).  Under an
    energy model, also :func:`mission_metrics` (``batteries``: the UAVs'
    ``[B, N]`` at the start and at the end, or ``None``), and the end of the
    episode is the last step before the first UAV left service.

    Args:
        world: the worlds of the starts (their model, layouts and energy model).
        start: the worlds' outputs at the start.
        steps: each step's outputs by key, ``[B, H, ...]``.
        u_star: each start's best utility U* ``[B]``.
        references: the start references of :func:`start_references`.
        gamma: the yardstick's discount.
        batteries: the UAVs' batteries ``[B, N]`` at the start and at the end (an energy model), or None.
    """
    positions = torch.cat([start["positions"].unsqueeze(1), steps["positions"]], 1)
    tasks = torch.cat([start["tasks"].unsqueeze(1), steps["tasks"]], 1)
    utility = world.utility(positions, tasks)[2]  # [B, H + 1], mean channels
    per_episode = episode_metrics(
        steps["r_pu"], steps["r_se"], steps["task_switches"], steps["moves"], u_star, utility[:, 1:]
    )
    away = None if world.energy is None else _away(world, positions)  # [B, H + 1, N + spares]
    # the full team: num_uavs serving (spares wait at the base); its last column before the first UAV leaves
    full_team = None if away is None else first_step(_leaves(away)) - 1
    end = utility[:, -1] if full_team is None else utility.gather(1, full_team.unsqueeze(-1)).squeeze(-1)
    optimality = end / u_star
    out = {f"eval/{k}": v.mean().item() for k, v in per_episode.items()}
    out["eval/optimality"] = optimality.mean().item()
    out["eval/optimality_min"] = optimality.min().item()
    out["eval/optimal_fraction"] = (optimality >= 0.99).double().mean().item()
    if world.cfg.bandwidth_hz is not None:  # a physical channel: bit/s/Hz times the bandwidth (docs/model.md)
        out["eval/u_star_bit_per_s"] = u_star.double().mean().item() * world.cfg.bandwidth_hz
        out["eval/utility_bit_per_s"] = end.mean().item() * world.cfg.bandwidth_hz
    out.update(yardstick_metrics(utility, u_star, references, gamma, full_team))
    if away is not None:
        out.update(mission_metrics(world.cfg, steps, away, utility, references, batteries))
    gap = u_star_gap(world, u_star)
    if gap > 0:
        out["eval/u_star_gap"] = gap
    return out


def _away(world: World, positions: torch.Tensor) -> torch.Tensor:
    """``[B, T, N]`` whether each UAV is out of service (shown at the base: flying home, charging or a spare)."""
    return ~on_grid(positions, world.cfg.grid)


def _leaves(away: torch.Tensor) -> torch.Tensor:
    """``[B, H]`` whether a UAV serving before each step is out of service after it (``away`` ``[B, H + 1, N]`` from
    the start on)."""
    return (~away[:, :-1] & away[:, 1:]).any(-1)


def first_step(flags: torch.Tensor) -> torch.Tensor:
    """``[B]`` the first step (from 1) whose flag ``[B, H]`` is set, ``H + 1`` where none is.

    Args:
        flags: ``[B, H]`` booleans, one per step.

    Example:
        >>> first_step(torch.tensor([[False, True, True], [False, False, False]]))
        tensor([2, 4])
    """
    H = flags.shape[-1]
    return torch.where(flags.any(-1), flags.long().argmax(-1) + 1, H + 1)


def mission_metrics(cfg: ModelConfig, steps, away, utility, references, batteries) -> dict[str, float]:
    """The mission's ``eval/...`` scalars under an energy model (docs/model.md, What the numbers mean), means over
    the starts: delivered data, lifetimes (``H`` where the event falls outside the horizon), steps in service per
    UAV, the energy per delivered bit (``batteries``: start and end ``[B, N]``) and the upper bounds of
    :func:`mission_references`, and where the exact mission solver fits the mean exact optimum
    (``eval/delivered_optimum``) and the data delivered over it (``eval/delivered_optimality``, sums over the starts
    as ``eval/delivered_ratio``, read from the mean-channel utility).  ``away`` ``[B, H + 1, N]``: who is out of
    service at the start and after each step; ``utility`` ``[B, H + 1]`` the mean-channel utility, which the ratio
    to the bound (proved for mean channels) reads.

    Args:
        cfg: the evaluated model (its energy model, ``slot_s``).
        steps: each step's outputs by key, ``[B, H, ...]`` (``r_pu``, ``r_se``).
        away: who is out of service ``[B, H + 1, N]``.
        utility: the mean-channel utility ``[B, H + 1]``.
        references: the start references (:func:`start_references`, with :func:`mission_references`' bounds).
        batteries: the UAVs' batteries ``[B, N]`` at the start and at the end.
    """
    H = away.shape[1] - 1
    delivered = (steps["r_pu"].double() + steps["r_se"].double()).sum(-1) * cfg.slot_s  # [B] bit/Hz
    bound = references["delivered_bound"]
    out = {
        "eval/horizon": float(H),
        "eval/delivered_bit_per_hz": delivered.mean().item(),
        "eval/delivered_bound": bound.mean().item(),
        "eval/delivered_horizon_bound": references["horizon_bound"].mean().item(),
        "eval/first_leave_steps": first_step(_leaves(away)).clamp(max=H).double().mean().item(),
        "eval/service_lost_steps": first_step(away[:, 1:].all(-1)).clamp(max=H).double().mean().item(),
        "eval/service_steps_per_uav": (~away[:, 1:]).sum(1).double().mean().item(),
    }
    if bound.sum() > 0:
        out["eval/delivered_ratio"] = (utility[:, 1:].sum() * cfg.slot_s / bound.sum()).item()
    optimum = references.get("delivered_optimum")
    if optimum is not None:  # the exact mission solver fitted: the optimum, and the share of it delivered
        out["eval/delivered_optimum"] = optimum.mean().item()
        if optimum.sum() > 0:
            out["eval/delivered_optimality"] = (utility[:, 1:].sum() * cfg.slot_s / optimum.sum()).item()
    delivered_units = delivered.sum()  # bit/Hz, or bits with a bandwidth
    if cfg.bandwidth_hz is not None:
        out["eval/delivered_bits"] = delivered.mean().item() * cfg.bandwidth_hz
        delivered_units = delivered_units * cfg.bandwidth_hz
    if batteries is not None and delivered_units > 0:
        out["eval/energy_per_bit"] = ((batteries[0] - batteries[1]).sum() / delivered_units).item()
    return out


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


class TrainingClock:
    """Seconds spent training so far in this process, wall and CPU, with the evaluations taken along the way left
    out (run them inside :meth:`paused`): a learning curve against time (``time/train_seconds`` and
    ``time/train_cpu_seconds`` beside each evaluation's ``eval/...``) then shows what the training itself cost,
    however often it was measured, for every agent (BenchMARL's too)."""

    def __init__(self):
        self.started, self.started_cpu = time.perf_counter(), time.process_time()
        self.paused_seconds = self.paused_cpu_seconds = 0.0

    @contextlib.contextmanager
    def paused(self):
        began, began_cpu = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self.paused_seconds += time.perf_counter() - began
            self.paused_cpu_seconds += time.process_time() - began_cpu

    def read(self) -> dict[str, float]:
        return {
            "time/train_seconds": time.perf_counter() - self.started - self.paused_seconds,
            "time/train_cpu_seconds": time.process_time() - self.started_cpu - self.paused_cpu_seconds,
        }


_REFERENCE_CACHE: dict = {}


def _references(world, start, u_star, horizon, gamma) -> dict:
    """:func:`start_references`, kept for the last few settings (every run of an agent shares the starts)."""
    key = (
        world.cfg,
        world.num_worlds,
        horizon,
        gamma,
        str(world.device),
        start["positions"].cpu().numpy().tobytes(),
        start["tasks"].cpu().numpy().tobytes(),
        None if world.battery is None else world.battery.cpu().numpy().tobytes(),
    )
    if key not in _REFERENCE_CACHE:
        if len(_REFERENCE_CACHE) >= 4:
            _REFERENCE_CACHE.pop(next(iter(_REFERENCE_CACHE)))
        _REFERENCE_CACHE[key] = start_references(world, start, u_star, horizon, gamma)
    return _REFERENCE_CACHE[key]


def evaluate_agent(agent, cfg: ModelConfig, lookahead: int = 0, lookahead_width: int = 8, **kwargs) -> dict[str, float]:
    """Average :func:`evaluate` over an agent's greedy policies (one per independent run; ``agent.evaluate``);
    the worst start's optimality.  ``lookahead`` > 0 (``eval.lookahead``): its depth-``lookahead`` search instead
    (:mod:`uavrl.agents.lookahead`).

    Args:
        agent: an :class:`~uavrl.agents.base.Agent` (trained, or loaded from a run).
        cfg: the model to evaluate in (the agent's own, or another size for a size-free agent).
        lookahead: the depth of the search over joint actions (``eval.lookahead``; 0: the greedy policy).
        lookahead_width: how many joint actions, the best by the learned team value, the search expands at each
            node (``eval.lookahead_width``; 0: all).
        **kwargs: the settings of :func:`evaluate` (``num_starts``, ``horizon``, ``seed``, ...).

    Example:
        >>> from uavrl.agents.baselines import OracleAgent
        >>> from uavrl.envs import make_config
        >>> cfg = make_config("paper", grid=(4, 4), num_uavs=2)
        >>> metrics = evaluate_agent(OracleAgent(cfg, None, "cpu", 0), cfg, num_starts=4)
        >>> metrics["eval/optimality"] > 0.99
        True
    """
    if lookahead:
        return evaluate_with_lookahead(agent, cfg, lookahead, lookahead_width, **kwargs)
    results = agent.evaluate(cfg, **kwargs)
    out = {}
    for key in dict.fromkeys(k for r in results for k in r):
        values = [r[key] for r in results if key in r]
        out[key] = min(values) if key == "eval/optimality_min" else sum(values) / len(values)
    return out


def evaluate_with_lookahead(agent, cfg: ModelConfig, lookahead: int, lookahead_width: int, **kwargs) -> dict:
    """:func:`evaluate` of the agent's lookahead policy, with ``eval/lookahead`` (its depth),
    ``eval/lookahead_width`` and ``eval/lookahead_cpu_s_per_step`` (its CPU seconds per world and step)."""
    from uavrl.agents.lookahead import lookahead_policy  # tensordict: the tabular commands evaluate without it

    policy = lookahead_policy(agent, cfg, lookahead, lookahead_width)
    metrics = evaluate(policy, cfg, **kwargs)
    search = policy.lookahead
    metrics["eval/lookahead"] = float(lookahead)
    metrics["eval/lookahead_width"] = float(lookahead_width)
    metrics["eval/lookahead_cpu_s_per_step"] = search.seconds / max(1, search.world_steps)
    return metrics
