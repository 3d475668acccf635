"""What every command-line setting allows, checked before torch is imported.

One table maps each setting, dotted as typed on the command line, to its rule.
A setting missing from a config (another agent's, or one a newer config adds)
is skipped, so a new setting is one line here.  A refusal is one line that
names the setting, the value and what is allowed::

    agent.episodes=0 is invalid: it must be a whole number >= 1

Only the standard library and omegaconf are imported, so a bad override is
refused in a fraction of a second.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Callable

from omegaconf import DictConfig, ListConfig, OmegaConf

from uavrl.agents import AGENTS
from uavrl.envs.config import make_config
from uavrl.envs.limits import (
    DEFAULT_MEMORY_BUDGET,
    MAX_EXACT_UAVS,
    default_horizon,
    evaluation_bytes,
    frame_bytes,
    gib,
    table_bytes,
    world_bytes,
)

_ABSENT = object()
PANEL_BYTES = 480 * 360 * 3  # one world drawn by envs/render.py's WorldRenderer at its default size


@dataclass(frozen=True)
class Rule:
    accepts: Callable[[Any], bool]
    allowed: str  # completes "<setting>=<value> is invalid: ..."


def _is_whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_real(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def whole(low: int) -> Rule:
    return Rule(lambda v: _is_whole(v) and v >= low, f"it must be a whole number >= {low}")


def interval(low: float, high: float, *, low_open: bool = False) -> Rule:
    def accepts(v):
        return _is_real(v) and (low < v if low_open else low <= v) and v <= high

    return Rule(accepts, f"it must lie in {'(' if low_open else '['}{low}, {high}]")


def positive() -> Rule:
    return Rule(lambda v: _is_real(v) and v > 0, "it must be positive")


def one_of(*choices: str, what: str = "values") -> Rule:
    return Rule(lambda v: v in choices, f"allowed {what} are {', '.join(map(repr, choices))}")


def flag() -> Rule:
    return Rule(lambda v: isinstance(v, bool), "it must be true or false")


def path() -> Rule:
    return Rule(lambda v: isinstance(v, str) and v != "", "it must be a path")


def optional(rule: Rule, meaning: str) -> Rule:
    return Rule(lambda v: v is None or rule.accepts(v), f"{rule.allowed}, or null ({meaning})")


def grid_sizes() -> Rule:
    def accepts(v):
        return isinstance(v, list) and len(v) > 0 and all(_is_whole(g) and g >= 1 for g in v)

    return Rule(accepts, "give a list of grid sizes >= 1, e.g. [2,3,6]")


def agent_names() -> Rule:
    return Rule(
        lambda v: isinstance(v, list) and len(v) > 0 and set(v) <= set(AGENTS),
        f"give a list of agents among {', '.join(map(repr, AGENTS))}",
    )


SEED = Rule(lambda v: _is_whole(v) and 0 <= v < 2**63, "it must be a whole number in [0, 2^63)")
DEVICE = Rule(
    lambda v: isinstance(v, str) and bool(re.fullmatch(r"cpu|cuda(:\d+)?", v)), "use 'cpu', 'cuda' or 'cuda:<index>'"
)
UNIT = interval(0.0, 1.0)

# python -m uavrl.train and python -m uavrl.evaluate (configs/config.yaml and configs/agent/*.yaml);
# the env.* options are checked by the model itself (uavrl.envs.ModelConfig)
RUN_SETTINGS: dict[str, Rule] = {
    "seed": SEED,
    "device": DEVICE,
    "num_threads": whole(1),
    "run_dir": optional(path(), "runs/<agent>/<env>/<timestamp>"),
    "resume": optional(path(), "a new run"),  # its files are checked by uavrl.train
    "checkpoint": optional(path(), "unset"),  # its files are checked by uavrl.evaluate
    "progress": flag(),
    "train.checkpoint_every": whole(1),
    "train.log_every": whole(1),
    "train.step_budget": whole(1),
    "eval.num_starts": whole(1),
    "eval.horizon": optional(whole(1), "max(20, 2 (L1 + L2)) steps"),
    "eval.seed": SEED,
    "eval.every": whole(0),
    "eval.gamma": interval(0.0, 1.0, low_open=True),
    "eval.video": flag(),
    "eval.video_starts": whole(1),
    "eval.video_fps": whole(1),
    "agent.name": one_of(*AGENTS, what="agents"),
    "sweep_dir": optional(path(), "runs/sweeps/<timestamp> for a sweep (-m)"),
    "scenario.agents": agent_names(),
    # agent=tabular
    "agent.method": one_of("q_learning", "value_iteration", what="methods"),
    "agent.alpha": interval(0.0, 1.0, low_open=True),
    "agent.epsilon": UNIT,
    "agent.shared_table": flag(),
    "agent.backend": one_of("numba", "torch", what="backends"),
    "agent.memory_budget": positive(),
    "agent.episodes": whole(1),
    "agent.runs": whole(1),
    # agent=dqn
    "agent.iterations": whole(1),
    "agent.head": one_of("factored", "joint", what="heads"),
    "agent.mixer": one_of("vdn", "qmix", what="mixers"),
    "agent.objective": one_of("delta", "log_gap", what="objectives"),
    "agent.gap_floor": positive(),
    "agent.worlds": whole(1),
    "agent.hidden": whole(1),
    "agent.depth": whole(1),
    "agent.mixing_embed_dim": whole(1),
    "agent.batch_size": whole(1),
    "agent.buffer_size": whole(1),
    "agent.updates": whole(1),
    "agent.learning_starts": whole(0),
    "agent.tau": UNIT,
    "agent.eps_start": UNIT,
    "agent.eps_end": UNIT,
    "agent.eps_fraction": UNIT,
    "agent.lr": positive(),
    "agent.lr_end": positive(),
    "agent.max_grad_norm": positive(),
    # agent=tabular and agent=dqn
    "agent.gamma": UNIT,
}

# python -m uavrl.reproduce (configs/reproduce.yaml)
REPRODUCE_SETTINGS: dict[str, Rule] = {
    "command": one_of("table2", "figures", what="commands"),
    "grids": grid_sizes(),
    "num_uavs": whole(1),
    "runs": whole(1),
    "episodes": whole(1),
    "steps": optional(whole(1), "Table II's steps for each grid"),
    "seed": SEED,
    "state_includes_tasks": flag(),
    "eval_starts": whole(1),
    "figure_grid": whole(1),
    "out_dir": optional(path(), "reproduction/<variant>"),
    "overwrite": flag(),
    "progress": flag(),
    "num_threads": whole(1),
    "numba_threads": whole(0),
    "memory_budget": positive(),
    "step_budget": whole(1),
}


def check_scenario(cfg: DictConfig) -> None:
    """A one-line ValueError when the chosen scenario (``configs/scenario/``) does not run the chosen agent."""
    scenario = OmegaConf.select(cfg, "scenario")
    if scenario is not None and cfg.agent.name not in scenario.agents:
        allowed = ", ".join(map(repr, scenario.agents))
        raise ValueError(f"agent={cfg.agent.name} is invalid with scenario={scenario.name}: its agents are {allowed}")


def shown(value) -> str:
    """A value as it is typed in an override: ``null``, ``true``, ``'text'``, ``[2, 3]``."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(shown(v) for v in value) + "]"
    return repr(value)


def check(cfg: DictConfig, table: dict[str, Rule], section: str = "") -> None:
    """A one-line ValueError for the first setting of ``table`` (within ``section`` of ``cfg``) that breaks its rule."""
    prefix = f"{section}." if section else ""
    for name, rule in table.items():
        if not name.startswith(prefix):
            continue
        value = OmegaConf.select(cfg, name[len(prefix) :], default=_ABSENT)
        if value is _ABSENT:
            continue
        if isinstance(value, (DictConfig, ListConfig)):
            value = OmegaConf.to_container(value, resolve=True)
        if not rule.accepts(value):
            raise ValueError(f"{name}={shown(value)} is invalid: {rule.allowed}")


# ------------------------------------------------------------------------------------------ what a run costs
DEFAULT_STEP_BUDGET = 10**10  # team steps: ~30 min of the compiled tabular learner, days of the DQN
START_BLOCK = 256  # agents/tabular/learner.py: episodes whose starts one World draws for all runs


@dataclass(frozen=True)
class Cost:
    """What one part of a command needs: ``amount`` (bytes or steps), the settings it grows with and their values
    (``agent.episodes x agent.runs x env.max_steps``), and what the part is, in words."""

    amount: int
    factors: dict[str, int]
    what: str
    fixed: tuple[str, ...] = ()  # factors that are no setting

    def blamed(self) -> str:
        """The setting among the factors with the largest value: the one most likely typed too large."""
        settings = [name for name in self.factors if name not in self.fixed] or list(self.factors)
        return max(settings, key=lambda name: self.factors[name])

    def formula(self) -> str:
        names, values = " x ".join(self.factors), " x ".join(f"{v:,}" for v in self.factors.values())
        return f"{self.what} ({names} = {values})"


def refuse_over(costs: list[Cost], budget, budget_name: str, unit: str) -> None:
    """A one-line ValueError naming the setting that grows the part over ``budget``, the estimate and what to type."""
    for cost in costs:
        if cost.amount > budget:
            name = cost.blamed()
            estimate = gib(cost.amount) if unit == "bytes" else f"{cost.amount:,} team steps"
            raise ValueError(
                f"{name}={cost.factors[name]} is invalid: {cost.formula()} needs about {estimate}, over "
                f"{budget_name}={int(budget)}: lower {name}, or raise {budget_name}=<{unit}>"
            )


def evaluation_costs(model, num_starts: int, horizon: int, tables: int, names: tuple[str, str, str]) -> Cost:
    """The memory of an evaluation (:mod:`uavrl.evaluation`): the starts' worlds, the greedy rollouts (``tables``
    > 0: the tabular agent's ``tables x num_starts`` worlds stepped together; else a TorchRL rollout) and the
    references: the exact solver where it fits, else the lower bounds.  ``names``: how the number of starts, the
    horizon and the number of tables are typed."""
    factors = {names[0]: num_starts, names[1]: horizon} | ({names[2]: tables} if tables > 1 else {})
    fixed = () if "." in names[1] else (names[1],)  # reproduce has no horizon setting
    return Cost(evaluation_bytes(model, num_starts, horizon, tables), factors, "the evaluation", fixed)


def starts_worlds(model, runs: int, runs_name: str) -> Cost:
    """The tabular learner's World that draws the episode starts of ``START_BLOCK`` episodes of every run."""
    factors = {runs_name: runs, "episodes per block": START_BLOCK}
    fixed = ("episodes per block",)
    return Cost(world_bytes(model, START_BLOCK * runs), factors, "the worlds of the episode starts", fixed)


def q_tables(model, tables: int, names: tuple[str, str], budget) -> Cost:
    """The tabular learner's Q tables, one per run, and the model tables beside them; named by the number of UAVs
    (``names[1]``) when one table alone is over ``budget``, else by the number of runs (``names[0]``)."""
    what = f"the team Q tables on {model.grid[0]}x{model.grid[1]} ({model.num_states:,} states x "
    what += f"{model.num_joint_actions:,} joint actions each, with the model's lookup tables)"
    blamed = {names[1]: model.num_uavs} if table_bytes(model, 1) > budget else {names[0]: tables}
    return Cost(table_bytes(model, tables), blamed, what)


def check_run_costs(cfg: DictConfig, model) -> None:
    """A one-line refusal, before anything is built, when a run of ``python -m uavrl.train`` would need more memory
    than ``agent.memory_budget`` or more team steps than ``train.step_budget``, or no exact optimum exists for it."""
    check_optimum_exists(model, "env.num_uavs")
    a = cfg.agent
    memory_budget = a.get("memory_budget", DEFAULT_MEMORY_BUDGET)
    step_budget = OmegaConf.select(cfg, "train.step_budget", default=DEFAULT_STEP_BUDGET)
    horizon = cfg.eval.horizon or default_horizon(model)
    starts = int(cfg.eval.num_starts)
    T, steps, memory, tables = model.max_steps, [], [], 0
    if a.name == "tabular" and a.get("method", "q_learning") == "q_learning":
        tables = 1 if a.shared_table else int(a.runs)
        training = {"agent.episodes": int(a.episodes), "agent.runs": int(a.runs), "env.max_steps": T}
        steps.append(Cost(_product(training), training, "training"))
        memory.append(starts_worlds(model, int(a.runs), "agent.runs"))
        memory.append(q_tables(model, tables, ("agent.runs", "env.num_uavs"), memory_budget))
    elif a.name == "tabular":
        tables = 1
    elif a.name == "dqn":
        worlds = int(a.worlds)
        training = {"agent.iterations": int(a.iterations), "agent.worlds": worlds, "env.max_steps": T}
        steps.append(Cost(_product(training), training, "training"))
        batch = {"agent.worlds": worlds, "env.max_steps": T}
        memory.append(Cost(world_bytes(model, worlds), {"agent.worlds": worlds}, "the training worlds"))
        memory.append(Cost(worlds * T * frame_bytes(model), batch, "each iteration's batch of transitions"))
        buffer = {"agent.buffer_size": int(a.buffer_size)}
        memory.append(Cost(int(a.buffer_size) * frame_bytes(model), buffer, "the replay buffer"))
    evaluations = max(tables, 1) * starts * horizon
    eval_factors = {"eval.num_starts": starts, "eval.horizon": horizon} | ({"agent.runs": tables} if tables > 1 else {})
    steps.append(Cost(evaluations, eval_factors, "the evaluation"))
    memory.append(evaluation_costs(model, starts, horizon, tables, ("eval.num_starts", "eval.horizon", "agent.runs")))
    if cfg.eval.get("video", False):
        memory.append(video_cost(int(cfg.eval.video_starts), horizon))
    refuse_over(memory, memory_budget, "agent.memory_budget", "bytes")
    refuse_over([total_steps(steps)], step_budget, "train.step_budget", "steps")


def video_cost(starts: int, horizon: int) -> Cost:
    """The frames of a video (:mod:`uavrl.video`): every step's panels of the policy and the oracle, their tiles and
    the stacked frames, each panel ``PANEL_BYTES``."""
    factors = {"eval.video_starts": starts, "eval.horizon": horizon}
    return Cost(3 * 2 * starts * (horizon + 1) * PANEL_BYTES, factors, "the video's frames (eval.video)")


def check_evaluation_floor(cfg: DictConfig, video: bool) -> None:
    """Before ``python -m uavrl.evaluate`` or ``uavrl.render`` reads a checkpoint (its model still unknown): a
    one-line refusal when the evaluation's starts, or the ``video``'s, need more than ``agent.memory_budget`` even
    for the smallest model (one UAV on one cell, the shortest default horizon): every evaluation builds its starts'
    worlds.  The model's own estimate follows once the checkpoint is read."""
    smallest = make_config("paper", grid=(1, 1), num_uavs=1)
    horizon = cfg.eval.horizon or default_horizon(smallest)
    starts = int(cfg.eval.num_starts)
    what = "the evaluation's worlds, even of the smallest model (1 UAV on 1 cell)"
    costs = [Cost(world_bytes(smallest, starts), {"eval.num_starts": starts}, what)]
    if video:
        costs.append(video_cost(int(cfg.eval.video_starts), horizon))
    budget = OmegaConf.select(cfg, "agent.memory_budget", default=DEFAULT_MEMORY_BUDGET)
    refuse_over(costs, budget, "agent.memory_budget", "bytes")


def check_video_cost(cfg: DictConfig, model) -> None:
    """A one-line refusal, before any frame is drawn, when the video of ``cfg.eval`` on ``model`` (a run read from
    its checkpoint) would need more than ``agent.memory_budget``."""
    horizon = cfg.eval.horizon or default_horizon(model)
    budget = OmegaConf.select(cfg, "agent.memory_budget", default=DEFAULT_MEMORY_BUDGET)
    refuse_over([video_cost(int(cfg.eval.video_starts), horizon)], budget, "agent.memory_budget", "bytes")


def total_steps(parts: list[Cost]) -> Cost:
    """The steps of every part together, named by the largest part."""
    largest = max(parts, key=lambda part: part.amount)
    return Cost(sum(part.amount for part in parts), largest.factors, largest.what, largest.fixed)


def check_optimum_exists(model, num_uavs_name: str) -> None:
    """The evaluation measures against the exact optimum U*: refused in one line where it is 0 or cannot be found."""
    if model.num_uavs > MAX_EXACT_UAVS:
        raise ValueError(
            f"{num_uavs_name}={model.num_uavs} is invalid: the evaluation's exact optimum U* enumerates 2^N subsets "
            f"of the best cells, for 1 to {MAX_EXACT_UAVS} UAVs"
        )
    if model.rate_model == "reference_code" and model.num_uavs < 2:
        raise ValueError(
            f"{num_uavs_name}={model.num_uavs} is invalid with the authors' rate_model='reference_code': it pays "
            "neither network unless both tasks are staffed, so U* = 0 and U / U* is undefined; give 2 or more"
        )


def _product(factors: dict[str, int]) -> int:
    return math.prod(factors.values())


def check_reproduce_costs(cfg: DictConfig, models: list) -> None:
    """A one-line refusal, before anything is built, when the protocol of ``python -m uavrl.reproduce`` would need
    more memory on one grid than ``memory_budget`` or more team steps in all than ``step_budget``."""
    runs, episodes, starts, steps = int(cfg.runs), int(cfg.episodes), int(cfg.eval_starts), []
    for model in models:
        check_optimum_exists(model, "num_uavs")
        horizon = default_horizon(model)
        training = {"runs": runs, "episodes": episodes, "steps": model.max_steps}
        steps.append(Cost(_product(training), training, f"training on {model.grid[0]}x{model.grid[1]}"))
        evaluation = {"eval_starts": starts, "runs": runs, "its horizon": horizon}
        steps.append(Cost(_product(evaluation), evaluation, "the evaluation", ("its horizon",)))
        memory = [
            q_tables(model, runs, ("runs", "num_uavs"), cfg.memory_budget),
            starts_worlds(model, runs, "runs"),
            evaluation_costs(model, starts, horizon, runs, ("eval_starts", "its horizon", "runs")),
        ]
        refuse_over(memory, cfg.memory_budget, "memory_budget", "bytes")
    refuse_over([total_steps(steps)], cfg.step_budget, "step_budget", "steps")
