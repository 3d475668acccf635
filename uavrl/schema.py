"""The one home of every command-line setting: its default, type, rule and meaning (standard library only; Hydra is
imported by :func:`register`).

Each setting is a field of a dataclass schema (:func:`uavrl.envs.rules.setting`): the run's here (:class:`RunSchema`,
:class:`ReproduceSchema`, :class:`BenchmarlSchema`), each agent's in :mod:`uavrl.agents.schema`, and the model's
options in :class:`uavrl.envs.ModelConfig`, from whose fields :class:`EnvSchema` is made (every option null: the
preset's value).  From them come

- Hydra's configs: :func:`register` stores the schemas in Hydra's ConfigStore, so ``configs/*.yaml`` hold no
  default and Hydra refuses an unknown key or a value of the wrong type while it composes (``uavrl.cli`` words the
  refusal); the presets of ``envs/config.py`` are the ``env`` group's options;
- the checks of the commands: :mod:`uavrl.settings` reads the rules (:func:`uavrl.envs.rules.rules_of`);
- the library's defaults: :func:`uavrl.agents.evaluation.evaluate` and the agents read the same fields;
- the table of ``docs/settings.md``: :func:`settings_markdown` (``python -m uavrl.schema > docs/settings.md``).

Real-valued settings are typed ``Any``: OmegaConf would turn ``0`` into ``0.0``, and a refusal names the value as
typed.

Example:
    >>> from uavrl.cli import compose_config
    >>> cfg = compose_config("config", ["agent=dqn", "env.grid=[4,4]"])
    >>> type(cfg.agent).__name__, cfg.env.max_steps, cfg.env.layout, cfg.agent.gamma
    ('DictConfig', 30, None, 0.7)
"""

from __future__ import annotations

import dataclasses
import re
import typing
from dataclasses import dataclass
from typing import Any, Optional

from uavrl.agents import AGENTS
from uavrl.agents.lookahead_rules import DEPTH as LOOKAHEAD_DEPTH
from uavrl.agents.lookahead_rules import WIDTH, WIDTH_READ
from uavrl.agents.schema import EvalSchema
from uavrl.envs.config import PHYSICAL_OPTIONS, PRESETS, ModelConfig, make_config, preset_options
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET
from uavrl.envs.rules import (
    DEVICE,
    REAL,
    SEED,
    flag,
    grid_sizes,
    names_among,
    one_of,
    optional,
    path,
    positive,
    section,
    setting,
    shown,
    whole,
    whole_within,
)

MAX_THREADS = 1024  # threads beyond the cores only slow torch; a million of them exhaust the machine's processes
STEP_BUDGET = 10**10  # team steps: ~30 min of the compiled tabular learner, days of the DQN
TIME_BUDGET = 1  # hours of one CPU core, estimated: each scenario's DQN budget is estimated at 1-30 minutes


@dataclass
class TrainSchema:
    checkpoint_every: int = setting(
        50, whole(1), "iterations (episodes for the tabular agent) between atomic checkpoints"
    )
    log_every: int = setting(1, whole(1), "iterations between TensorBoard points")
    step_budget: int = setting(
        STEP_BUDGET, whole(1), "team steps of training and evaluation; a run that needs more is refused at once"
    )
    time_budget: REAL = setting(
        TIME_BUDGET,
        positive(),
        "hours of one CPU core the DQN's training may take, as estimated before it starts from its networks, batch, "
        "gradient steps, worlds and grid (uavrl/costs.py); a run estimated to need more is refused at once",
    )


@dataclass
class RunEvalSchema(EvalSchema):
    """The evaluation of ``uavrl.train`` and ``uavrl.evaluate``, with a video of the greedy policy beside the oracle
    (``uavrl/experiment/video.py``)."""

    video: bool = setting(
        False,
        flag(),
        "also a video of the greedy policy beside the oracle: TensorBoard's eval/video, and video.gif (video.mp4 "
        "with the [video] extra) beside the checkpoint for uavrl.evaluate",
    )
    video_starts: int = setting(3, whole(1), "the evaluation's first starts, one row each")
    video_fps: int = setting(4, whole(1), "frames (steps) per second")
    lookahead: int = setting(
        0,
        LOOKAHEAD_DEPTH,
        "agent=dqn: depth of a search over joint actions through the model (mean channel), the learned team value at "
        "the leaves (uavrl/agents/lookahead.py); 0: the greedy policy",
    )
    lookahead_width: int = setting(
        WIDTH,
        whole(0),
        "eval.lookahead: candidates played per node, best by the values; 0: all",
        read=WIDTH_READ,
    )


def _option_type(hint) -> Any:
    """The type Hydra checks a model option's value against (null always allowed: the preset's value)."""
    if hint in (int, str, bool):
        return Optional[hint]
    tuples = [arg for arg in (hint, *typing.get_args(hint)) if typing.get_origin(arg) is tuple]
    if tuples:  # grid, base: whole numbers; altitudes_m: numbers
        return Optional[list[float if float in typing.get_args(tuples[0]) else int]]
    return REAL


EnvSchema = dataclasses.make_dataclass(
    "EnvSchema",
    [
        ("name", str, setting(ModelConfig.preset, doc="the name of the setting: run directories and reports")),
        ("preset", str, setting(ModelConfig.preset, doc=f"the preset of the options left null: {', '.join(PRESETS)}")),
        *(
            (name, _option_type(hint), setting(None))
            for name, hint in typing.get_type_hints(ModelConfig).items()
            if name != "preset"
        ),
    ],
)
EnvSchema.__module__ = __name__
EnvSchema.__doc__ = """The model's options (:class:`uavrl.envs.ModelConfig`'s fields); null keeps the preset's value."""


def preset_env(preset: str) -> EnvSchema:
    """The ``env`` config of ``env=<preset>``: the preset's shape (grid, UAVs, episode length), the options it sets
    and, for a physical channel, the radio's numbers it runs with (as its runs' ``config.yaml`` record them); the
    others null."""
    model = make_config(preset)
    options = dict(grid=model.grid, num_uavs=model.num_uavs, max_steps=model.max_steps)
    if model.is_physical:
        options |= {name: getattr(model, name) for name in PHYSICAL_OPTIONS}
    options |= preset_options(preset)
    return EnvSchema(
        name=preset, preset=preset, **{k: list(v) if isinstance(v, tuple) else v for k, v in options.items()}
    )


@dataclass
class ScenarioSchema:
    """``configs/scenario/<name>.yaml``: a named setting of the environment; its budgets are in ``budget/``."""

    name: str = setting("paper_6x6", doc="the scenario's name")
    agents: list[str] = setting(
        rule=names_among(tuple(AGENTS), "agents"), doc="the agents it runs", factory=lambda: list(AGENTS)
    )


@dataclass
class RunSchema:
    """``configs/config.yaml``: ``python -m uavrl.train`` and ``uavrl.evaluate``; ``env`` and ``agent`` come from
    their groups."""

    seed: int = setting(0, SEED, "seeds the run: its worlds, networks and exploration")
    device: str = setting("cpu", DEVICE, "the torch device")
    num_threads: int = setting(
        1, whole_within(1, MAX_THREADS), "torch.set_num_threads; 1 is fastest for small tensors on a 2-core CPU"
    )
    run_dir: Optional[str] = setting(
        None,
        optional(path(), "runs/<agent>/<env>/<timestamp>"),
        "the run directory; null: runs/<agent>/<env>/<timestamp> (<agent>: dqn-set for a size-free network)",
    )
    sweep_dir: Optional[str] = setting(
        None,
        optional(path(), "runs/sweeps/<timestamp> for a sweep (-m)"),
        "a sweep's (-m) jobs run in <sweep_dir>/<their overrides>/seed=<seed>; null: runs/sweeps/<timestamp>",
    )
    resume: Optional[str] = setting(
        None, optional(path(), "a new run"), "a run directory to continue from its last checkpoint"
    )
    checkpoint: Optional[str] = setting(
        None, optional(path(), "unset"), "uavrl.evaluate: a checkpoint.pt or run directory to evaluate"
    )
    print_json: bool = setting(
        False, flag(), "uavrl.evaluate: print the metrics as JSON (the file it writes) in place of its summary"
    )
    progress: bool = setting(True, flag(), "a progress bar with rate and ETA")
    train: TrainSchema = section(TrainSchema)
    eval: RunEvalSchema = section(RunEvalSchema)
    env: EnvSchema = section(EnvSchema, "env=<preset>, then any option: the model's options (docs/model.md)")
    agent: Any = None  # agent=<name>: the agent's schema (uavrl/agents/schema.py)
    scenario: Optional[ScenarioSchema] = section(
        ScenarioSchema, "null: env and agent as given; scenario=<name>: configs/scenario/", optional=True
    )


@dataclass
class BenchmarlTaskSchema:
    name: str = setting("paper_6x6", doc="the task's name in BenchMARL")


@dataclass
class BenchmarlSchema:
    """``configs/benchmarl.yaml``: our settings, the model's options and the task (a scenario's name); BenchMARL's
    own groups (``experiment``, ``algorithm``, ``model``, ``critic_model``) bring their schemas from BenchMARL."""

    seed: int = setting(0, SEED, "seeds BenchMARL's experiment")
    num_threads: int = setting(1, whole_within(1, MAX_THREADS), "torch.set_num_threads")
    run_dir: Optional[str] = setting(
        None,
        optional(path(), "runs/benchmarl_<algorithm>/<env>/<timestamp>"),
        "the run directory; null: runs/benchmarl_<algorithm>/<env>/<timestamp>",
    )
    eval: EvalSchema = section(
        EvalSchema, "the shared evaluation, at each of BenchMARL's evaluations and at the end (eval.every: unused)"
    )
    env: EnvSchema = section(EnvSchema)
    task: BenchmarlTaskSchema = section(BenchmarlTaskSchema)
    scenario: Optional[ScenarioSchema] = section(ScenarioSchema, "the task's scenario", optional=True)
    memory_budget: REAL = setting(
        DEFAULT_MEMORY_BUDGET, positive(), "bytes of our part of the run (the training worlds, the evaluation)"
    )
    experiment: Any = None
    algorithm: Any = None
    model: Any = None
    critic_model: Any = None


@dataclass
class ReproduceSchema:
    """``configs/reproduce.yaml``: ``python -m uavrl.reproduce``; the defaults are the paper's protocol."""

    command: str = setting("table2", one_of("table2", "figures", what="commands"), "table2 or figures")
    grids: list[int] = setting(rule=grid_sizes(), doc="the grids of Table II", factory=lambda: [2, 3, 4, 5, 6, 8, 10])
    num_uavs: int = setting(2, whole(1), "UAVs on every grid")
    runs: int = setting(10, whole(1), "independent runs per grid")
    episodes: int = setting(200, whole(1), "episodes per run")
    steps: Optional[int] = setting(
        None,
        optional(whole(1), "Table II's steps for each grid"),
        "steps per episode; null: Table II's for each grid",
    )
    seed: int = setting(0, SEED, "seeds the runs")
    state_includes_tasks: bool = setting(
        False, flag(), "the paper's state is the joint location only (Table I); true: the full configuration"
    )
    eval_starts: int = setting(EvalSchema.num_starts, whole(1), "fixed starts of the final greedy evaluation, per run")
    figure_grid: int = setting(6, whole(1), "the grid of Figs. 3-5")
    out_dir: Optional[str] = setting(
        None,
        optional(path(), "reproduction/<variant>"),
        "null: reproduction/paper for these settings, else reproduction/<the settings that differ>",
    )
    overwrite: bool = setting(
        False, flag(), "true: replace the results of other settings in out_dir (refused otherwise)"
    )
    progress: bool = setting(True, flag(), "a progress bar")
    num_threads: int = setting(1, whole_within(1, MAX_THREADS), "torch threads")
    numba_threads: int = setting(
        0, whole_within(0, MAX_THREADS), "learner threads (runs in parallel); 0: all cores (at most numba's)"
    )
    memory_budget: REAL = setting(
        DEFAULT_MEMORY_BUDGET, positive(), "bytes the learner's tables of one grid may take, all runs together"
    )
    step_budget: int = setting(STEP_BUDGET, whole(1), "team steps of the whole protocol; more is refused at once")


def register() -> None:
    """Store the schemas in Hydra's ConfigStore (before composing): ``run_schema``, ``reproduce_schema``,
    ``benchmarl_schema``, ``schema/env``, ``schema/scenario``, ``schema/agent/<name>``, and ``env/<preset>`` for
    each preset of ``envs/config.py``."""
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance()
    store.store(name="run_schema", node=RunSchema)
    store.store(name="reproduce_schema", node=ReproduceSchema)
    store.store(name="benchmarl_schema", node=BenchmarlSchema)
    store.store(group="schema", name="env", node=EnvSchema)
    store.store(group="schema", name="scenario", node=ScenarioSchema)
    for name, config in AGENTS.items():
        store.store(group="schema/agent", name=name, node=config.schema(name=name))
    for preset in PRESETS:
        store.store(group="env", name=preset, node=preset_env(preset))


# ---------------------------------------------------------------------------------- the table of the docs
def _markdown(text: str) -> str:
    """Text for a cell of a markdown table: ``|``, ``<`` and ``*`` escaped, a docstring's roles as code."""
    text = re.sub(r":\w+:`~?([\w.]+)`", lambda m: f"`{m.group(1).split('.')[-1]}`", " ".join(text.split()))
    return re.sub(r"([|<*])", r"\\\1", text.replace("``", "`"))


def _rows(schema: type, prefix: str = "") -> list[str]:
    """One row per setting of ``schema`` (nested schemas' too; an optional one as one row, null until chosen)."""
    rows = []
    for field in dataclasses.fields(schema):
        name = f"{prefix}.{field.name}" if prefix else field.name
        nested, rule, doc = field.metadata.get("section"), field.metadata.get("rule"), field.metadata.get("doc", "")
        if nested is not None and field.default is dataclasses.MISSING:
            rows += [] if nested is EnvSchema else _rows(nested, name)
            continue
        if rule is None and not doc:
            continue
        default = field.default if field.default_factory is dataclasses.MISSING else field.default_factory()
        shown_default = default if isinstance(default, str) else shown(default)
        allowed = "" if rule is None else rule.allowed
        rows.append(f"| `{name}` | `{shown_default}` | {_markdown(allowed)} | {_markdown(doc)} |")
    return rows


def _table(title: str, lead: str, schema: type, prefix: str = "") -> list[str]:
    header = ["| setting | default | allowed | meaning |", "|---|---|---|---|"]
    return [f"## {title}", "", lead, "", *header, *_rows(schema, prefix), ""]


def settings_markdown() -> str:
    """``docs/settings.md``: every setting of the commands with its default, rule and meaning, from the schemas."""
    agents: dict[type, list[str]] = {}
    for name, config in AGENTS.items():
        agents.setdefault(config.schema, []).append(name)
    lines = [
        "# Settings",
        "",
        "Every setting of the commands, with its default, what it allows and what it means, generated from the",
        "schemas that are the one home of each (`uavrl/schema.py`, `agents/schema.py`) by",
        "`python -m uavrl.schema > docs/settings.md`; `tests/commands/test_schema.py` fails when this file and",
        "the schemas disagree. A value outside its rule, a setting nothing reads under the others, and a setting",
        "typed twice are each refused in one line before anything runs.",
        "",
        "The model's options (`env.*`) are the fields of `ModelConfig` (`envs/config.py`; their meanings:",
        f"docs/model.md). `env=<preset>` ({', '.join(PRESETS)}) chooses a preset of `envs/config.py`, and an",
        "option left null keeps the preset's value.",
        "",
        *_table(
            "python -m uavrl.train, python -m uavrl.evaluate",
            "`configs/config.yaml`; the agent's settings follow, by `agent=<name>`.",
            RunSchema,
        ),
    ]
    for schema, names in agents.items():
        chosen = ", ".join(f"agent={name}" for name in names)
        lines += _table(chosen, _markdown(schema.__doc__), schema, "agent")
    lines += _table("python -m uavrl.reproduce", "`configs/reproduce.yaml`.", ReproduceSchema)
    lines += _table(
        "python -m uavrl.benchmarl",
        "`configs/benchmarl.yaml`; BenchMARL's own `experiment.*`, `algorithm.*` and `model.*` keep their names.",
        BenchmarlSchema,
    )
    return "\n".join(lines).rstrip() + "\n"


if __name__ == "__main__":
    import sys

    if sys.argv[1:]:
        raise SystemExit(
            f"error: {sys.argv[1]} is invalid: python -m uavrl.schema takes no arguments; it prints the settings table "
            "(python -m uavrl.schema > docs/settings.md)"
        )
    print(settings_markdown(), end="")
