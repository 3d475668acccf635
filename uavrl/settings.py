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

_ABSENT = object()


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
