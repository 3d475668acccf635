"""What a command costs, estimated before it builds anything: the one cost model of memory, team steps and CPU time
(standard library and omegaconf only, so a run too large is refused before torch is imported).

It reads the validated configs: the model (:class:`~uavrl.envs.ModelConfig`, its sizes its own properties), the
agent's settings and the budgets.  The byte counts of the World, a transition, the Q tables, the exact solver and the
bounds are :mod:`uavrl.envs.limits`' (the World's own memory check reads them too); the DQN's networks' parameters,
multiply-adds and float32 values are :mod:`uavrl.agents.network_sizes`' (counted layer by layer beside the
networks they count).  :func:`check_run_costs`, :func:`check_evaluation_costs`,
:func:`check_benchmarl_costs` and :func:`check_reproduce_costs` refuse, in one line (:mod:`uavrl.budgets`), a
command over its budgets, naming the setting typed that grows the part and the changes that would fit it::

    agent.hidden=100000000 is invalid: the networks ... needs about ..., over agent.memory_budget=...: ...

"""

from __future__ import annotations

import dataclasses
import math

from omegaconf import DictConfig, OmegaConf

from uavrl.agents.lookahead_rules import WIDTH, candidates_per_node, deepest_level_bytes
from uavrl.agents.network_sizes import (
    FLOAT,
    TRAINING_COPIES,
    greedy_cells,
    greedy_row_bytes,
    local_inputs,
    policy_row_bytes,
    qmix_parameters,
    size_free_parameters,
    team_parameters,
    team_row_macs,
)
from uavrl.agents.schema import START_BLOCK, TabularSchema, training_models
from uavrl.budgets import Cost, Factor, Typed, count, product, refuse_over, total
from uavrl.envs.config import ModelConfig, make_config
from uavrl.envs.limits import (
    DEFAULT_MEMORY_BUDGET,
    default_horizon,
    evaluation_bytes,
    evaluation_horizon,
    frame_bytes,
    stored_transition_bytes,
    table_bytes,
    world_bytes,
)
from uavrl.schema import TrainSchema

PANEL_BYTES = 480 * 360 * 3  # one world drawn by envs/render.py's WorldRenderer at its default size


# ------------------------------------------------------------------------------------------ what a run costs
# The DQN's CPU time on one core of the machine of BENCHMARKS.md: a batched environment step and a gradient step cost
# a fixed overhead and more per UAV (the greedy valid action picks UAV by UAV), the networks' multiply-adds at
# MACS_PER_SECOND and the greedy action's occupancy table (per world and per sampled transition: the grid's cells,
# where it has fewer than N^2 A, else none; agents/dqn/networks.py ValidGreedy) at CELLS_PER_SECOND.  Measured CPU
# seconds an iteration against this estimate: the defaults on 6x6 0.56 (0.44), N = 6 on 10x10 with QMIX 0.63 idle,
# 0.86 loaded (0.82).
STEP_SECONDS, UPDATE_SECONDS, UAV_SECONDS = 2e-3, 3e-3, 0.5e-3
MACS_PER_SECOND, CELLS_PER_SECOND = 1.5e10, 8e8
MODEL_NAMES = ("env.grid", "env.num_uavs")  # how the grid and the team are typed: uavrl.train, uavrl.evaluate
REPRODUCE_NAMES = ("grids", "num_uavs")  # uavrl.reproduce
TABLE_FREE = "or use agent=dqn, which keeps no table"
LEVELS = "env.altitudes_m"  # how the altitude levels are typed


class _Resized:
    """A model with its grid, team, spares or altitude levels made the least a setting allows: what a cost would be
    with them (the sizes that follow are :class:`~uavrl.envs.ModelConfig`'s own properties, read over the lowered
    ones)."""

    def __init__(self, model, lowered: frozenset, grid: str = "env.grid", team: str = "env.num_uavs"):
        self._model = model
        self.num_uavs = 1 if team in lowered else model.num_uavs
        self.num_spares = 0 if "env.num_spares" in lowered else model.num_spares
        self.grid = (self.num_uavs + self.num_spares, 1) if grid in lowered else model.grid
        self.altitudes_m = None if LEVELS in lowered else model.altitudes_m

    def __getattr__(self, name):
        return getattr(self._model, name)

    num_cells = ModelConfig.num_cells
    num_levels = ModelConfig.num_levels
    num_positions = ModelConfig.num_positions
    fleet_size = ModelConfig.fleet_size
    num_actions = ModelConfig.num_actions
    joint_action_base = ModelConfig.joint_action_base
    num_joint_actions = ModelConfig.num_joint_actions
    num_states = ModelConfig.num_states


def model_factors(model, names: tuple[str, str] = ("env.grid", "env.num_uavs")) -> list[Factor]:
    """The grid's cells, the team (and its spares) and the altitude levels as factors of a cost, named as typed
    (``names``: the grid's and the team's setting)."""
    grid, team = names
    factors = [
        Factor(grid, model.num_cells, model.fleet_size, label=f"the cells of {grid}", multiplies=False),
        Factor(team, model.num_uavs, multiplies=False),
    ]
    if model.num_spares:
        factors.append(Factor("env.num_spares", model.num_spares, 0, multiplies=False))
    if model.num_levels > 1:  # a UAV's positions: every cell at every level (an upper bound in a city)
        factors.append(Factor(LEVELS, model.num_levels, label=f"the levels of {LEVELS}", multiplies=False))
    return factors


def horizon_factor(cfg: DictConfig, model, name: str = "eval.horizon") -> Factor:
    """``eval.horizon``, or the default it takes when null: crossing the grid twice, or under an energy model the
    whole mission, which the battery, the energy numbers and the base set."""
    horizon = OmegaConf.select(cfg, name, default=None)
    if horizon:
        return Factor(name, int(horizon))
    if model.energy == "none":
        return Factor(name, default_horizon(model.grid), origin=("env.grid",), label=f"{name} (null: 2 (L1 + L2))")
    origin = ("env.battery_wh", "env.slot_s", "env.circuit_power_w", "env.base", "env.energy", "env.grid")
    return Factor(name, evaluation_horizon(model), origin=origin, label=f"{name} (null: the whole mission)")


def evaluation_costs(model, starts: Factor, horizon: Factor, tables: Factor | None, names=MODEL_NAMES) -> Cost:
    """The memory of an evaluation (:mod:`uavrl.agents.evaluation`): the starts' worlds, the greedy rollouts
    (``tables``:
    the tabular agent's ``tables x num_starts`` worlds stepped together; else a TorchRL rollout) and the
    references: the exact solver where it fits, else the lower bounds.  ``names``: the grid's and the team's
    setting."""
    factors = [starts, horizon, *([tables] if tables and tables.size > 1 else []), *model_factors(model, names)]

    def estimate(low):
        sizes = {f.name: f.at(low) for f in factors}
        n_tables = sizes[tables.name] if tables and tables.size > 1 else (1 if tables else 0)
        resized = _Resized(model, low, *names)
        return evaluation_bytes(resized, sizes[starts.name], sizes[horizon.name], n_tables)

    return Cost("the evaluation", tuple(factors), estimate)


def check_run_costs(cfg: DictConfig, model, overrides=None) -> None:
    """A one-line refusal, before anything is built, when a run of ``python -m uavrl.train`` would need more memory
    than ``agent.memory_budget``, more team steps than ``train.step_budget`` or (the DQN) more CPU time than
    ``train.time_budget``, or no exact optimum exists for it.  ``overrides``: the command line's, so a refusal names
    what was typed (``None``: every setting counts as typed)."""
    typed = Typed(cfg, overrides)
    check_optimum_exists(model, "env.num_uavs")
    a = cfg.agent
    step_budget = OmegaConf.select(cfg, "train.step_budget", default=TrainSchema.step_budget)
    time_budget = OmegaConf.select(cfg, "train.time_budget", default=TrainSchema.time_budget)
    horizon = horizon_factor(cfg, model)
    starts = Factor("eval.num_starts", int(cfg.eval.num_starts))
    T = Factor("env.max_steps", model.max_steps)
    steps, memory, seconds, tables = [], [], [], None
    if a.name == "tabular" and a.get("method", TabularSchema.method) == "q_learning":
        runs = Factor("agent.runs", int(a.runs))
        tables = runs if not a.shared_table else Factor("agent.runs", 1, fixed=True)
        steps.append(product("training", [Factor("agent.episodes", int(a.episodes)), runs, T]))
        memory.append(starts_worlds(model, runs))
        memory.append(q_tables(model, tables, hint=TABLE_FREE))
    elif a.name == "tabular":
        tables = Factor("agent.runs", 1, fixed=True)
    elif a.name == "dqn":
        dqn_memory, dqn_steps, dqn_seconds = dqn_costs(cfg, model, T)
        memory += dqn_memory
        steps += dqn_steps
        seconds += dqn_seconds
    runs_shown = [tables] if tables and tables.size > 1 else []
    steps.append(product("the evaluation", [starts, horizon, *runs_shown]))
    memory.append(evaluation_costs(model, starts, horizon, tables))
    if a.name == "dqn":
        memory += [policy_pass(model, a, starts), *lookahead_cost(cfg, model, a, starts)]
    if cfg.eval.get("video", False):
        memory.append(video_cost(cfg, model))
    refuse_memory(memory, cfg, typed)
    refuse_over([total(steps)], step_budget, "train.step_budget", "steps", typed)
    if seconds:
        refuse_over([total(seconds)], time_budget, "train.time_budget", "seconds", typed)


class _Grid:
    """A model seen without its energy model: the video's default length is the grid's, not the mission's."""

    def __init__(self, model):
        self.grid, self.energy = model.grid, "none"


class _Agent(dict):
    """An agent's settings as the networks' counts read them, some lowered to their least."""

    __getattr__ = dict.__getitem__

    @classmethod
    def of(cls, a) -> "_Agent":
        return cls({k: a.get(k) for k in ("network", "head", "mixer", "hidden", "depth", "heads", "mixing_embed_dim")})


def dqn_costs(cfg: DictConfig, model, T: Factor) -> tuple[list[Cost], list[Cost], list[Cost]]:
    """The DQN's memory (the worlds, a batch of transitions, the replay buffers, the networks with their target,
    gradients and Adam's moments, a gradient step), its team steps and its CPU time.  A size-free run trains every
    team of ``agent.sizes`` in every layout of ``agent.layouts`` and city of ``agent.cities``: each group has its own
    worlds, buffer and share of the batch (agents/dqn/multisize.py)."""
    a = cfg.agent
    settings = _Agent.of(a)
    size_free = settings["network"] == "set"
    groups = training_models(model, a)
    for group in groups:
        check_optimum_exists(group, "agent.sizes" if a.get("sizes") else "env.num_uavs")
    sized = bool(a.get("sizes"))
    grid_name, team_name = ("agent.sizes", "agent.sizes") if sized else ("env.grid", "env.num_uavs")
    largest = max(groups, key=lambda m: m.num_cells * m.fleet_size)
    worlds = Factor("agent.worlds", int(a.worlds))
    buffer = Factor("agent.buffer_size", int(a.buffer_size))
    batch = Factor("agent.batch_size", int(a.batch_size))
    iterations, updates = Factor("agent.iterations", int(a.iterations)), Factor("agent.updates", int(a.updates))
    n_step = Factor("agent.n_step", int(a.get("n_step", 1)), multiplies=False)
    demos = Factor("agent.demo_transitions", int(a.get("demo_transitions", 1)))
    per_iteration = [dataclasses.replace(f, multiplies=False) for f in (updates, batch, worlds, T)]
    grouped = Factor("groups (agent.sizes x agent.layouts x agent.cities)", len(groups), fixed=True)
    each = [grouped] if len(groups) > 1 else []
    shape = model_factors(largest, (grid_name, team_name))
    if sized:  # agent.sizes names the grid and the team at once
        del shape[1]
    network = [
        Factor("agent.hidden", int(a.hidden), multiplies=False),
        Factor("agent.depth", int(a.depth), multiplies=False),
    ]
    if size_free:
        network.append(Factor("agent.heads", int(a.heads), multiplies=False))
    elif a.mixer == "qmix" and a.head == "factored":
        network.append(Factor("agent.mixing_embed_dim", int(a.mixing_embed_dim), multiplies=False))

    def models(low):
        return [_Resized(m, low, grid_name, team_name) for m in groups]

    def agent(low):
        lowered = _Agent(settings)
        for f in network:
            if f.name in low:
                lowered[f.name.split(".")[1]] = f.least
        return lowered

    def group_batch(low) -> int:
        rows = batch.at(low)
        return max(1, rows // len(groups)) if size_free else rows  # agents/dqn/multisize.py

    def network_bytes(low) -> int:
        s = agent(low)
        if size_free:
            return TRAINING_COPIES * FLOAT * size_free_parameters(model, s)
        m = models(low)[0]
        params = team_parameters(
            m.fleet_size,
            m.num_actions,
            _e(m),
            s.head,
            int(s.hidden),
            int(s.depth),
            _l(m),
            local_inputs(m),
            m.message_size,
        )
        if s.head == "factored" and s.mixer == "qmix":
            params += qmix_parameters(m.fleet_size, _e(m), int(s.mixing_embed_dim), _l(m))
        return TRAINING_COPIES * FLOAT * params

    def step_bytes(low) -> int:
        s, rows = agent(low), group_batch(low)
        return sum(rows * (frame_bytes(m) + policy_row_bytes(m, s)) for m in models(low))

    def world_memory(low) -> int:
        return sum(world_bytes(m, worlds.at(low)) for m in models(low))

    def batch_memory(low) -> int:  # n-step returns: MultiStep's copy of the frames and its padded rewards
        copies, padded = (2, FLOAT * worlds.at(low) * (T.at(low) + n_step.at(low))) if n_step.at(low) > 1 else (1, 0)
        return copies * worlds.at(low) * T.at(low) * sum(frame_bytes(m) for m in models(low)) + padded

    def buffer_memory(low) -> int:
        return buffer.at(low) * sum(stored_transition_bytes(m) for m in models(low))

    def demonstration_memory(low) -> int:  # each team's kept transitions, and the oracle's worlds and episodes
        per_group, need = max(1, demos.at(low) // len(groups)), 0
        for m in models(low):
            played = math.ceil(per_group / m.max_steps)
            need += per_group * stored_transition_bytes(m) + world_bytes(m, played)
            need += played * m.max_steps * frame_bytes(m)
        return need

    def cpu_seconds(low) -> int:
        s, total_seconds, rows = agent(low), 0.0, group_batch(low)
        for m in models(low):
            macs = team_row_macs(m.fleet_size, m.num_actions, _e(m), s, _l(m), local_inputs(m))
            macs *= 2 if m.message_size else 1  # the loss sends the messages heard again: a second pass
            per_step = STEP_SECONDS + UAV_SECONDS * m.fleet_size
            per_step += worlds.at(low) * (2 * macs / MACS_PER_SECOND + greedy_cells(m) / CELLS_PER_SECOND)
            per_update = UPDATE_SECONDS + UAV_SECONDS * m.fleet_size
            per_update += rows * (6 * macs / MACS_PER_SECOND + greedy_cells(m) / CELLS_PER_SECOND)
            total_seconds += T.at(low) * per_step + updates.at(low) * per_update
        return math.ceil(iterations.at(low) * total_seconds)

    memory = [
        Cost("the training worlds", (worlds, *shape, *each), world_memory),
        Cost(
            "each iteration's batch of transitions",
            (worlds, T, *([n_step] if n_step.size > 1 else []), *shape[1:], *each),
            batch_memory,
        ),
        Cost("the replay buffers", (buffer, *shape[1:], *each), buffer_memory),
        Cost(
            "the networks with their targets, gradients and Adam's moments",
            (*network, *([] if size_free else shape[1:])),
            network_bytes,
        ),
        Cost(  # agent.batch_size is shared out among the groups of a size-free run
            "a gradient step's batch and activations",
            (batch, *network, *shape, *(dataclasses.replace(f, multiplies=False) for f in each)),
            step_bytes,
        ),
    ]
    if a.get("demonstrations", "none") != "none":
        memory.append(Cost("the oracle's demonstrations", (demos, *shape[1:], *each), demonstration_memory))
    steps = [product("training", [iterations, worlds, T, *each])]
    seconds = [Cost("training", (iterations, *per_iteration, *network, *shape, *each), cpu_seconds)]
    return memory, steps, seconds


def _e(model) -> bool:
    return model.energy != "none"


def _l(model) -> bool:
    return model.num_levels > 1


def policy_pass(model, a, starts: Factor) -> Cost:
    """The DQN policy's forward pass over the evaluation's starts: its activations and the greedy action's
    occupancy table, and where the team is common knowledge every UAV's rebuilt team
    (:func:`~uavrl.agents.network_sizes.greedy_row_bytes`)."""
    settings = _Agent.of(a)

    def estimate(low):
        return starts.at(low) * greedy_row_bytes(_Resized(model, low), settings)

    return Cost("the policy's pass over the evaluation's starts", (starts, *model_factors(model)), estimate)


def lookahead_cost(cfg: DictConfig, model, a, starts: Factor) -> list[Cost]:
    """The deepest level of ``eval.lookahead``'s search (:mod:`uavrl.agents.lookahead`), held at once: every
    start's ``K^depth`` configurations (``K``: the candidates per node, :func:`candidates_per_node`) observed and
    valued by the policy's network; none without a lookahead."""
    depth = int(OmegaConf.select(cfg, "eval.lookahead", default=0) or 0)
    if not depth:
        return []
    settings, width = _Agent.of(a), int(OmegaConf.select(cfg, "eval.lookahead_width", default=WIDTH))
    candidates = candidates_per_node(model.num_uavs, model.num_actions, width)
    levels = Factor("eval.lookahead", depth, multiplies=False)
    # eval.lookahead_width=0 plays every candidate: no smaller number to lower it to, but a width to give
    per_node = Factor("eval.lookahead_width", candidates, label="K", fixed=not width, multiplies=False)
    hint = "" if width else "give eval.lookahead_width=<candidates per node>"

    def estimate(low):
        return deepest_level_bytes(_Resized(model, low), settings, starts.at(low), levels.at(low), per_node.at(low))

    what = "the lookahead's deepest level, K^eval.lookahead configurations a start"
    return [Cost(what, (starts, levels, per_node), estimate, hint)]


def video_cost(cfg: DictConfig, model) -> Cost:
    """The frames of a video of ``cfg.eval`` on ``model`` (:mod:`uavrl.experiment.video`; its default length the
    grid's, not a mission's): every step's panels of the policy and the oracle, their tiles and the stacked frames,
    each panel ``PANEL_BYTES``."""
    horizon = horizon_factor(cfg, _Grid(model))
    factors = (Factor("eval.video_starts", int(cfg.eval.video_starts)), horizon)

    def estimate(low):
        return 3 * 2 * factors[0].at(low) * (horizon.at(low) + 1) * PANEL_BYTES

    return Cost("the video's frames (eval.video)", factors, estimate)


def check_evaluation_floor(cfg: DictConfig, video: bool, overrides=None) -> None:
    """Before ``python -m uavrl.evaluate`` or ``uavrl.render`` knows the model: a one-line refusal when the
    evaluation's starts, or the ``video``'s, need more than ``agent.memory_budget`` even for the smallest model (one
    UAV on one cell, the shortest default horizon): every evaluation builds its starts' worlds."""
    typed = Typed(cfg, overrides)
    smallest = make_config("paper", grid=(1, 1), num_uavs=1)
    starts = Factor("eval.num_starts", int(cfg.eval.num_starts))
    what = "the evaluation's worlds, even of the smallest model (1 UAV on 1 cell)"
    parts = [product(what, [starts], world_bytes(smallest, 1))]
    if video:
        parts.append(video_cost(cfg, smallest))
    refuse_memory(parts, cfg, typed)


def check_evaluation_costs(cfg: DictConfig, saved: DictConfig, model, video: bool, overrides=None) -> None:
    """Once the saved run's config is read (``saved``, its agent; ``model`` the model evaluated): a one-line
    refusal when the evaluation, the policy's pass or the video would need more than ``agent.memory_budget``."""
    typed = Typed(cfg, overrides)
    horizon = horizon_factor(cfg, model)
    starts = Factor("eval.num_starts", int(cfg.eval.num_starts))
    tables = Factor("agent.runs", 1, fixed=True) if saved.agent.name == "tabular" else None
    parts = [evaluation_costs(model, starts, horizon, tables)]
    if saved.agent.name == "dqn":
        parts += [policy_pass(model, saved.agent, starts), *lookahead_cost(cfg, model, saved.agent, starts)]
    if video:
        parts.append(video_cost(cfg, model))
    refuse_memory(parts, cfg, typed)


def check_video_cost(cfg: DictConfig, model, overrides=None) -> None:
    """A one-line refusal, before any frame is drawn, when the video of ``cfg.eval`` on ``model`` (a run read from
    its checkpoint) would need more than ``agent.memory_budget``."""
    refuse_memory([video_cost(cfg, model)], cfg, Typed(cfg, overrides))


def refuse_memory(parts: list[Cost], cfg: DictConfig, typed: Typed) -> None:
    """:func:`refuse_over` of the run's ``agent.memory_budget`` (its schema's default where the config has none)."""
    budget = OmegaConf.select(cfg, "agent.memory_budget", default=DEFAULT_MEMORY_BUDGET)
    refuse_over(parts, budget, "agent.memory_budget", "bytes", typed)


def starts_worlds(model, runs: Factor, names=MODEL_NAMES) -> Cost:
    """The tabular learner's World that draws the episode starts of ``START_BLOCK`` episodes of every run."""
    block = Factor("episodes per block", START_BLOCK, fixed=True)
    factors = (runs, block, *model_factors(model, names))

    def estimate(low):
        n = runs.at(low)
        return world_bytes(_Resized(model, low, *names), START_BLOCK * n)

    return Cost("the worlds of the episode starts", factors, estimate)


def q_tables(model, tables: Factor, names=MODEL_NAMES, hint: str = "") -> Cost:
    """The tabular learner's Q tables, one per run (``tables``), and the model tables beside them; the DQN has no
    table, and a refusal says so where one table alone is over the budget."""
    levels = f" at {model.num_levels} altitude levels" if model.num_levels > 1 else ""
    what = f"the team Q tables on {model.grid[0]}x{model.grid[1]}{levels} ({count(model.num_states)} states x "
    what += f"{count(model.num_joint_actions)} joint actions each, with the model's lookup tables)"
    factors = (tables, *model_factors(model, names))

    def estimate(low):
        n = tables.at(low)
        return table_bytes(_Resized(model, low, *names), n)

    return Cost(what, factors, estimate, hint)


def check_benchmarl_costs(cfg: DictConfig, model, overrides=None) -> None:
    """A one-line refusal, before BenchMARL builds anything, when our part of ``python -m uavrl.benchmarl`` would need
    more than ``memory_budget``: the batched worlds BenchMARL collects from (the larger of its on- and off-policy
    ``experiment.*_n_envs_per_worker``) and the evaluation at each of its evaluations.  BenchMARL's own networks
    and buffers are its experiment's to size."""
    typed = Typed(cfg, overrides)
    check_optimum_exists(model, "env.num_uavs")
    counts = [f"experiment.{kind}_n_envs_per_worker" for kind in ("on_policy", "off_policy")]
    name = max(counts, key=lambda n: int(OmegaConf.select(cfg, n, default=1)))
    worlds = Factor(name, int(OmegaConf.select(cfg, name, default=1)))
    starts = Factor("eval.num_starts", int(cfg.eval.num_starts))
    memory = [
        Cost(
            "the training worlds",
            (worlds, *model_factors(model)),
            lambda low: world_bytes(_Resized(model, low), worlds.at(low)),
        ),
        evaluation_costs(model, starts, horizon_factor(cfg, model), None),
    ]
    refuse_over(memory, cfg.memory_budget, "memory_budget", "bytes", typed)


def check_optimum_exists(model, num_uavs_name: str) -> None:
    """The evaluation measures against the optimum U*: refused in one line where it is 0."""
    if model.rate_model == "reference_code" and model.num_uavs < 2:
        raise ValueError(
            f"{num_uavs_name}={model.num_uavs} is invalid with the authors' rate_model='reference_code': it pays "
            "neither network unless both tasks are staffed, so U* = 0 and U / U* is undefined; give 2 or more"
        )


def check_reproduce_costs(cfg: DictConfig, models: list, overrides=None) -> None:
    """A one-line refusal, before anything is built, when the protocol of ``python -m uavrl.reproduce`` would need
    more memory on one grid than ``memory_budget`` or more team steps in all than ``step_budget``."""
    typed = Typed(cfg, overrides)
    runs, episodes = Factor("runs", int(cfg.runs)), Factor("episodes", int(cfg.episodes))
    starts, steps = Factor("eval_starts", int(cfg.eval_starts)), []
    for model in models:
        check_optimum_exists(model, "num_uavs")
        horizon = Factor("its horizon", default_horizon(model.grid), fixed=True)
        length = Factor("steps", model.max_steps, origin=() if cfg.steps else ("grids",))
        steps.append(product(f"training on {model.grid[0]}x{model.grid[1]}", [runs, episodes, length]))
        steps.append(product("the evaluation", [starts, runs, horizon]))
        memory = [
            q_tables(model, runs, REPRODUCE_NAMES),
            starts_worlds(model, runs, REPRODUCE_NAMES),
            evaluation_costs(model, starts, horizon, runs, REPRODUCE_NAMES),
        ]
        refuse_over(memory, cfg.memory_budget, "memory_budget", "bytes", typed)
    refuse_over([total(steps)], cfg.step_budget, "step_budget", "steps", typed)
