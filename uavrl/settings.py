"""What every command-line setting allows, checked before torch is imported.

The rules live with the settings' defaults in the schemas (:mod:`uavrl.schema`, :mod:`uavrl.agents.schema`); the
tables here are read from them: the run's settings, then the chosen agent's own (another agent's rules never
apply).  A setting missing from a config (one a saved run's config predates) is skipped.  A refusal is one line
that names the setting, the value and what is allowed::

    agent.episodes=0 is invalid: it must be a whole number >= 1

Before anything is built, :func:`check_run_costs` and :func:`check_reproduce_costs` refuse a run that would need
more memory or team steps than its budgets.  Only the standard library and omegaconf are imported, so a bad
override is refused in a fraction of a second.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from omegaconf import DictConfig, OmegaConf

from uavrl.agents import AGENTS
from uavrl.agents.schema import AGENT_SCHEMAS, TabularSchema, agent_rules, training_models
from uavrl.envs.config import make_config
from uavrl.envs.limits import (
    DEFAULT_MEMORY_BUDGET,
    default_horizon,
    evaluation_bytes,
    evaluation_horizon,
    frame_bytes,
    gib,
    stored_transition_bytes,
    table_bytes,
    world_bytes,
)
from uavrl.rules import Rule, check, one_of, rules_of
from uavrl.schema import BenchmarlSchema, ReproduceSchema, RunSchema, TrainSchema

PANEL_BYTES = 480 * 360 * 3  # one world drawn by envs/render.py's WorldRenderer at its default size

# python -m uavrl.train and python -m uavrl.evaluate (configs/config.yaml): the run's settings and the agent's name;
# the env.* options are checked by the model itself (uavrl.envs.ModelConfig)
RUN_SETTINGS: dict[str, Rule] = rules_of(RunSchema) | {"agent.name": one_of(*AGENTS, what="agents")}
# the settings of each agent (configs/agent/<name>.yaml)
AGENT_SETTINGS: dict[str, dict[str, Rule]] = {name: agent_rules(name) for name in AGENT_SCHEMAS}
# python -m uavrl.reproduce (configs/reproduce.yaml) and python -m uavrl.benchmarl (configs/benchmarl.yaml)
REPRODUCE_SETTINGS: dict[str, Rule] = rules_of(ReproduceSchema)
BENCHMARL_SETTINGS: dict[str, Rule] = rules_of(BenchmarlSchema)


def check_run(cfg: DictConfig) -> None:
    """A one-line ValueError for the first setting of a run's config that breaks its rule: the run's settings, then
    those of its agent."""
    check(cfg, RUN_SETTINGS)
    name = OmegaConf.select(cfg, "agent.name")
    if name is not None:
        check(cfg, AGENT_SETTINGS[name])


def check_scenario(cfg: DictConfig) -> None:
    """A one-line ValueError when the chosen scenario (``configs/scenario/``) does not run the chosen agent."""
    scenario = OmegaConf.select(cfg, "scenario")
    if scenario is not None and cfg.agent.name not in scenario.agents:
        allowed = ", ".join(map(repr, scenario.agents))
        raise ValueError(f"agent={cfg.agent.name} is invalid with scenario={scenario.name}: its agents are {allowed}")


# ------------------------------------------------------------------------------------------ what a run costs
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
    step_budget = OmegaConf.select(cfg, "train.step_budget", default=TrainSchema.step_budget)
    horizon = cfg.eval.horizon or evaluation_horizon(model)
    starts = int(cfg.eval.num_starts)
    T, steps, memory, tables = model.max_steps, [], [], 0
    if a.name == "tabular" and a.get("method", TabularSchema.method) == "q_learning":
        tables = 1 if a.shared_table else int(a.runs)
        training = {"agent.episodes": int(a.episodes), "agent.runs": int(a.runs), "env.max_steps": T}
        steps.append(Cost(_product(training), training, "training"))
        memory.append(starts_worlds(model, int(a.runs), "agent.runs"))
        memory.append(q_tables(model, tables, ("agent.runs", "env.num_uavs"), memory_budget))
    elif a.name == "tabular":
        tables = 1
    elif a.name == "dqn":
        # a size-free run trains every team of agent.sizes in every layout of agent.layouts: each group has its own
        # worlds, batch and replay buffer (agents/dqn/multisize.py)
        groups = training_models(model, a)
        for group in groups:
            check_optimum_exists(group, "agent.sizes")
        worlds, buffer_size = int(a.worlds), int(a.buffer_size)
        each = {"groups (agent.sizes x agent.layouts)": len(groups)} if len(groups) > 1 else {}
        fixed = tuple(each)
        training = {"agent.iterations": int(a.iterations), "agent.worlds": worlds, "env.max_steps": T} | each
        steps.append(Cost(_product(training), training, "training", fixed))
        batch = {"agent.worlds": worlds, "env.max_steps": T} | each
        buffer = {"agent.buffer_size": buffer_size} | each
        memory += [
            Cost(
                sum(world_bytes(m, worlds) for m in groups),
                {"agent.worlds": worlds} | each,
                "the training worlds",
                fixed,
            ),
            Cost(worlds * T * sum(map(frame_bytes, groups)), batch, "each iteration's batch of transitions", fixed),
            Cost(buffer_size * sum(map(stored_transition_bytes, groups)), buffer, "the replay buffers", fixed),
        ]
    evaluations = max(tables, 1) * starts * horizon
    eval_factors = {"eval.num_starts": starts, "eval.horizon": horizon} | ({"agent.runs": tables} if tables > 1 else {})
    steps.append(Cost(evaluations, eval_factors, "the evaluation"))
    memory.append(evaluation_costs(model, starts, horizon, tables, ("eval.num_starts", "eval.horizon", "agent.runs")))
    if cfg.eval.get("video", False):
        memory.append(video_cost(int(cfg.eval.video_starts), cfg.eval.horizon or default_horizon(model.grid)))
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
    horizon = cfg.eval.horizon or default_horizon(smallest.grid)
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
    horizon = cfg.eval.horizon or default_horizon(model.grid)
    budget = OmegaConf.select(cfg, "agent.memory_budget", default=DEFAULT_MEMORY_BUDGET)
    refuse_over([video_cost(int(cfg.eval.video_starts), horizon)], budget, "agent.memory_budget", "bytes")


def total_steps(parts: list[Cost]) -> Cost:
    """The steps of every part together, named by the largest part."""
    largest = max(parts, key=lambda part: part.amount)
    return Cost(sum(part.amount for part in parts), largest.factors, largest.what, largest.fixed)


def check_optimum_exists(model, num_uavs_name: str) -> None:
    """The evaluation measures against the optimum U*: refused in one line where it is 0."""
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
        horizon = default_horizon(model.grid)
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
