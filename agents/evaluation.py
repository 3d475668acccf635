"""One evaluation for every agent and baseline: the exact yardstick.

Evaluations (``eval/...``) of all agents are computed here, and their training curves (``train/...``) by
:mod:`uavrl.agents.episodes`, so their TensorBoard tags and meanings are identical; the references each start is
measured against are :mod:`uavrl.agents.references`'.

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
- ``eval/u_star_gap``, only where U* is not proven exact (:func:`~uavrl.agents.references.u_star_gap`): every
  metric above then uses the best configuration found, within this relative gap of the optimum.

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

import math
import numbers

import torch

from uavrl.agents.episodes import episode_metrics
from uavrl.agents.lookahead_rules import WIDTH, candidates_per_node, check_width_read, deepest_level_bytes
from uavrl.agents.references import (
    LEVELS,
    cached_references,
    placements,
    u_star_gap,
)
from uavrl.agents.schema import EvalSchema
from uavrl.envs import InvalidOption, InvalidType, ModelConfig
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET, evaluation_bytes, evaluation_horizon, gib
from uavrl.envs.limits import default_horizon as default_horizon  # the video's and the tabular evaluation's
from uavrl.envs.physics.grid import on_grid
from uavrl.envs.rules import refuse, rule_of
from uavrl.envs.world import World, check_seed, resolve_device

# the command line's eval.* defaults (uavrl/schema.py): the seed is far from training seeds, so the evaluation's
# worlds (and random layouts) are held out
NUM_STARTS, EVAL_SEED, DEFAULT_GAMMA = EvalSchema.num_starts, EvalSchema.seed, EvalSchema.gamma


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
    references = cached_references(env.world, start, u_star, horizon, gamma)
    steps, batteries = greedy_rollout(env, policy, start, horizon)
    return greedy_metrics(env.world, start, steps, u_star, references, gamma, batteries)


def greedy_rollout(env, policy, start, horizon: int) -> tuple[dict, list | None]:
    """``horizon`` steps of ``policy`` from ``start``, each world once: ``(steps, batteries)``, ``steps`` the
    ``[B, H]`` outputs :func:`greedy_metrics` reads (``r_pu``, ``r_se``, ``task_switches``, ``moves``, and
    ``positions``, ``tasks``, with altitude levels ``levels``), ``legal`` and ``unmasked`` ``[B, H, N]`` (each action
    one its mask allowed; a mask that allowed every action), ``batteries`` the worlds' batteries before and after
    under an energy model (else None)."""
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
    if ("next", "levels") in rollout.keys(True):  # altitude levels
        steps["levels"] = rollout["next", "levels"]
    mask, played = rollout["agents", "action_mask"], rollout["agents", "action"].long().unsqueeze(-1)
    steps.update(legal=mask.gather(-1, played).squeeze(-1), unmasked=mask.all(-1))  # [B, H, N]
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
    return world, start, u_star, cached_references(world, start, u_star, horizon, gamma), horizon


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
    positions = torch.cat([placements(start).unsqueeze(1), placements(steps)], 1)  # with levels (x, y, level)
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


def evaluate_agent(
    agent, cfg: ModelConfig, lookahead: int = 0, lookahead_width: int = WIDTH, **kwargs
) -> dict[str, float]:
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
    check_width_read(lookahead_width, lookahead)
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
    # the search holds its deepest level at once: refused before it starts, as uavrl.costs refuses eval.lookahead
    num_starts, budget = kwargs.get("num_starts", NUM_STARTS), kwargs.get("memory_budget", DEFAULT_MEMORY_BUDGET)
    per_node = candidates_per_node(cfg.num_uavs, cfg.num_actions, lookahead_width)
    need = deepest_level_bytes(cfg, agent.settings, num_starts, lookahead, per_node)
    if need > budget:
        raise InvalidOption(
            "lookahead",
            message=f"lookahead={lookahead} is invalid: the search's deepest level, {per_node}^{lookahead} "
            f"configurations for each of {num_starts} starts, needs about {gib(need)}, over memory_budget={budget}: "
            "lower lookahead, give lookahead_width=<candidates per node>, or raise memory_budget=<bytes>",
        )
    metrics = evaluate(policy, cfg, **kwargs)
    search = policy.lookahead
    metrics["eval/lookahead"] = float(lookahead)
    metrics["eval/lookahead_width"] = float(lookahead_width)
    metrics["eval/lookahead_cpu_s_per_step"] = search.seconds / max(1, search.world_steps)
    return metrics
