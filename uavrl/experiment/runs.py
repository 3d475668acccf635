"""What the commands share about a run (standard library and omegaconf; the run directory's lock from
:mod:`uavrl.experiment.rundir`): a new run's directory, its evaluation's settings, its settings as flat names, the
line of its yardstick.  The commands' library (``uavrl.experiment.training``, ``evaluating``, ``benchmarl``,
``reporting``) imports them from here.

Example:
    >>> flat_settings({"agent": {"name": "dqn", "gamma": 0.7}, "env": {"grid": [6, 6]}})
    {'agent.name': 'dqn', 'agent.gamma': 0.7, 'env.grid': [6, 6]}
"""

from __future__ import annotations

import math
from datetime import datetime
from pathlib import Path
from typing import Callable

from omegaconf import DictConfig, OmegaConf

from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET
from uavrl.experiment.io import claim_dir, quoted
from uavrl.experiment.rundir import RunDirectory, hold, missing_parents, path_argument


def claim_run_dir(run_dir, agent: str, env: str, holds_run: Callable[[Path], bool], refusal: str) -> RunDirectory:
    """The held directory of a new run (:mod:`uavrl.experiment.rundir`): ``run_dir`` if given, refused with
    ``refusal`` when it holds a run (``holds_run``) once locked (a run may have started there since the settings
    were checked); else a new ``runs/<agent>/<env>/<timestamp>`` (``-1``, ``-2``, ... when taken), removed with the
    folders made for it if the run fails before it saved anything."""
    if run_dir:
        held = hold(run_dir, "run_dir")
        if holds_run(held.path):
            held.release()
            raise FileExistsError(refusal)
        return held
    base = Path("runs") / agent / env / datetime.now().strftime("%Y%m%d-%H%M%S")
    parents = missing_parents(base)
    return hold(claim_dir(base), "run_dir", created=True, created_parents=parents)


def eval_settings(cfg: DictConfig, device) -> dict:
    """Keyword arguments of :func:`uavrl.agents.evaluation.evaluate` from ``cfg.eval``."""
    return dict(
        num_starts=cfg.eval.num_starts,
        horizon=cfg.eval.horizon,
        seed=int(cfg.eval.seed),
        device=device,
        gamma=cfg.eval.gamma,
        memory_budget=run_memory_budget(cfg),
    )


def run_memory_budget(cfg: DictConfig):
    """``agent.memory_budget``, or a BenchMARL run's ``memory_budget`` (it has no agent group)."""
    budget = OmegaConf.select(cfg, "agent.memory_budget", default=None)
    return budget if budget is not None else OmegaConf.select(cfg, "memory_budget", default=DEFAULT_MEMORY_BUDGET)


def flat_settings(config: dict, prefix: str = "") -> dict:
    """A nested config's leaves by dotted name (``agent.gamma``), as they are."""
    out = {}
    for key, value in config.items():
        if isinstance(value, dict):
            out.update(flat_settings(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def flat_hparams(cfg: DictConfig) -> dict:
    """Scalar hyper-parameters with dotted names (TensorBoard's hparams reject nesting)."""
    settings = flat_settings(OmegaConf.to_container(cfg, resolve=True))
    return {name: v if isinstance(v, (int, float, str, bool)) else str(v) for name, v in settings.items()}


def share_of_starts(fraction: float) -> str:
    """A share of starts as a percentage rounded down to 0.1%: 199 of 200 reads 99.5%, never 100%."""
    return f"{math.floor(fraction * 1000 + 1e-9) / 10:g}%"


def yardstick_line(cfg: DictConfig, result: dict) -> str:
    """Against exact optimal control (docs/yardstick.md): return ratio and steps to 0.999 U*."""
    parts = []
    if "eval/return_ratio" in result:
        parts.append(
            f"return ratio {result['eval/return_ratio']:.4f} (discounted gain / the exact best, gamma {cfg.eval.gamma})"
        )
    if "eval/delivered_ratio" in result:  # an energy model's mission (docs/model.md, What the numbers mean)
        parts.append(
            f"the mission delivered {result['eval/delivered_ratio']:.1%} of its upper bound, the first UAV left "
            f"service at step {result['eval/first_leave_steps']:.1f} on average"
        )
    reach = f"0.999 U* reached from {share_of_starts(result['eval/reach_999'])} of starts"
    if "eval/step_ratio_999" in result:
        fewest = "fewest" if result["eval/min_steps_exact"] == 1.0 else "a lower bound on the fewest"
        reach += f" in {result['eval/step_ratio_999']:.2f}x {fewest} steps"
    return "yardstick: " + "; ".join([*parts, reach])


# agents with nothing to learn: a run of one is its evaluation (agents/baselines.py, agents/planner.py)
BASELINE_AGENTS = ("random", "oracle", "planner")


def is_size_free(cfg: DictConfig) -> bool:
    """Whether the run's agent is the DQN with a size-free network (``agent=dqn agent.network=set``)."""
    return cfg.agent.name == "dqn" and OmegaConf.select(cfg, "agent.network", default="team") == "set"


def agent_label(cfg: DictConfig) -> str:
    """The name a run is filed under (``runs/<label>/<env>/``): ``agent.name``, ``dqn-set`` for a size-free network.

    Example:
        >>> agent_label(OmegaConf.create({"agent": {"name": "dqn", "network": "set"}}))
        'dqn-set'
    """
    return f"{cfg.agent.name}-set" if is_size_free(cfg) else cfg.agent.name


def agent_words(cfg: DictConfig) -> str:
    """The run's agent as its summaries name it: a baseline says it does not train, a size-free network says so.

    Example:
        >>> agent_words(OmegaConf.create({"agent": {"name": "oracle"}}))
        'the oracle baseline (no training)'
    """
    if cfg.agent.name in BASELINE_AGENTS:
        return f"the {cfg.agent.name} baseline (no training)"
    if is_size_free(cfg):
        return "dqn with a size-free network (agent.network=set)"
    return cfg.agent.name


def team_words(num_uavs: int, grid) -> str:
    """``N = 6 on 10x10``."""
    return f"N = {num_uavs} on {grid[0]}x{grid[1]}"


def model_words(env_cfg) -> str:
    """A model (:class:`uavrl.envs.ModelConfig`) in a few words: grid, team, layout, channel, fading, energy model.

    Example:
        >>> from uavrl.envs import make_config
        >>> model_words(make_config("paper", grid=(10, 10), num_uavs=6))
        "10x10 grid, 6 UAVs, layout 'line', channel 'paper'"
    """
    words = [f"{env_cfg.grid[0]}x{env_cfg.grid[1]} grid", f"{env_cfg.num_uavs} UAVs", f"layout {env_cfg.layout!r}"]
    fading = f" with {env_cfg.fading} fading" if env_cfg.fading != "none" else ""
    words.append(f"channel {env_cfg.channel!r}{fading}")
    if env_cfg.energy != "none":
        spares = f" + {env_cfg.num_spares} spares" if env_cfg.num_spares else ""
        words.append(f"energy model {env_cfg.energy!r} ({env_cfg.battery_wh:g} Wh{spares})")
    return ", ".join(words)


def size_free_teams(cfg: DictConfig, env_cfg) -> str:
    """The teams, layouts and cities a size-free run trained on (``agent.sizes``, ``agent.layouts``, ``agent.cities``;
    empty: the run's own).

    Example:
        >>> from uavrl.envs import make_config
        >>> cfg = OmegaConf.create({"agent": {"name": "dqn", "network": "set", "sizes": [[2, 6, 6], [6, 10, 10]],
        ...                                   "layouts": ["line", "random"]}})
        >>> size_free_teams(cfg, make_config("paper"))
        "2 teams (N = 2 on 6x6, N = 6 on 10x10) in layouts 'line', 'random'"
    """
    sizes = list(OmegaConf.select(cfg, "agent.sizes", default=None) or []) or [[env_cfg.num_uavs, *env_cfg.grid]]
    layouts = list(OmegaConf.select(cfg, "agent.layouts", default=None) or []) or [env_cfg.layout]
    teams = ", ".join(team_words(n, (l1, l2)) for n, l1, l2 in sizes)
    count = f"{len(sizes)} teams" if len(sizes) > 1 else "1 team"
    in_layouts = ", ".join(repr(layout) for layout in layouts)
    cities = list(OmegaConf.select(cfg, "agent.cities", default=None) or [])  # agent.cities: each its own group
    in_cities = f", in {len(cities)} {env_cfg.city} cities (env.city_seed {', '.join(map(str, cities))})"
    return f"{count} ({teams}) in layout{'s' if len(layouts) > 1 else ''} {in_layouts}{in_cities if cities else ''}"


def policy_words(agent_name: str, result: dict) -> str:
    """The policy an evaluation played: the baselines', a lookahead's (``eval/lookahead`` in ``result``), else the
    greedy one.

    Example:
        >>> policy_words("dqn", {"eval/lookahead": 2.0}), policy_words("random", {})
        ('the greedy policy with a depth-2 lookahead', 'the random policy')
    """
    if agent_name == "random":
        return "the random policy"
    if agent_name in ("oracle", "planner"):
        return "the oracle planner"
    depth = int(result.get("eval/lookahead", 0))
    return f"the greedy policy with a depth-{depth} lookahead" if depth else "the greedy policy"


def optimality_line(cfg: DictConfig, result: dict, agent_name: str) -> str:
    """The final configuration's utility against U*, in words (``agent_name``: the run's ``agent.name``)."""
    optimality, worst = result["eval/optimality"], result["eval/optimality_min"]
    policy = policy_words(agent_name, result)
    return (
        f"optimality {optimality:.4f}: from {cfg.eval.num_starts} fixed starts, {policy} ends at {optimality:.1%} "
        f"of the best possible utility U* on average (worst start {worst:.1%}; "
        f"{share_of_starts(result['eval/optimal_fraction'])} of starts within 1% of U*)"
    )


def already_a_run(run_dir) -> str:
    """The refusal of a new run into ``run_dir``, which holds a run's checkpoint."""
    return (
        f"run_dir={quoted(run_dir)} already holds a run: continue it with {path_argument('resume', run_dir)}, "
        "or pick another run_dir"
    )


def finished(run_dir: Path) -> bool:
    """Whether ``run_dir`` holds a finished ``python -m uavrl.benchmarl`` run (its ``metrics.json``)."""
    return (run_dir / "metrics.json").exists()


def already_finished(run_dir) -> str:
    """The refusal of a BenchMARL run into ``run_dir``, which holds a finished one."""
    return f"run_dir={run_dir!r} already holds a finished run: pick another run_dir"
