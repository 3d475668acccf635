"""The agents' registry :data:`AGENTS` and every agent's settings (``agent.*``): each one's default, type, rule and
meaning, declared once in the agent's schema (standard library and :mod:`uavrl.envs.rules` only).

:data:`AGENTS` maps each agent's name to its :class:`AgentConfig` (as BenchMARL's ``algorithm_config_registry``
maps an algorithm's name to its config): the schema of its settings, the class that runs them, named and imported on
first use (:meth:`AgentConfig.associated_class`: naming an agent imports no torch), and the rules its settings follow
together (:meth:`AgentConfig.validate`).

Hydra starts ``configs/agent/<name>.yaml`` from the agent's schema (registered by :mod:`uavrl.schema`), the commands
check ``agent.*`` against the rules of the chosen agent's schema only (a new agent's ``agent.alpha`` follows its own
rule, or none), the library's defaults (:class:`~uavrl.agents.tabular.TeamQLearner`) read the same fields, and
``docs/settings.md`` is generated from them.

Example:
    >>> TabularSchema.alpha, agent_rules("tabular")["agent.alpha"].allowed
    (0.1, 'it must lie in (0.0, 1.0]')
    >>> "agent.alpha" in agent_rules("dqn")
    False
    >>> AGENTS["dqn"].schema is DQNSchema, AGENTS["dqn"].associated_class({"network": "set"}).__name__
    (True, 'SetDQNAgent')
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Callable, Optional

from uavrl.envs.config import CITY_OPTIONS, HELD_OUT_CITY_SEEDS, LAYOUTS, NUM_ACTIONS, InvalidOption
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET
from uavrl.envs.rules import (
    REAL,
    SEED,
    UNIT,
    Rule,
    check,
    flag,
    interval,
    one_of,
    optional,
    positive,
    read_if,
    rules_of,
    setting,
    shown,
    whole,
)

if TYPE_CHECKING:
    from uavrl.envs.config import ModelConfig

    from .base import Agent

METHODS = ("q_learning", "value_iteration")
DEMONSTRATIONS = ("none", "oracle")
CURRICULA = ("none", "loss")
START_BLOCK = 256  # episodes whose starts one World draws for all the tabular learner's runs (tabular/learner.py)
MEMORY_BUDGET = positive()


def team_sizes_rule() -> Rule:
    """A list of teams ``[N, L1, L2]`` (whole numbers >= 1), or ``[]``."""

    def accepts(v):
        return isinstance(v, list) and all(
            isinstance(t, list) and len(t) == 3 and all(whole(1).accepts(x) for x in t) for t in v
        )

    return Rule(accepts, "give a list of teams [num_uavs, L1, L2], e.g. [[2,6,6],[6,10,10]], or [] (the run's own)")


def team_sizes(env_cfg: ModelConfig, a) -> list[tuple[int, tuple[int, int]]]:
    """``[(N, (L1, L2))]`` the teams of ``agent.sizes``, or the run's own."""
    sizes = list(a.get("sizes") or [])
    return [(int(n), (int(l1), int(l2))) for n, l1, l2 in sizes] or [(env_cfg.num_uavs, tuple(env_cfg.grid))]


def training_models(env_cfg: ModelConfig, a) -> list[ModelConfig]:
    """The models one run trains on: every team of :func:`team_sizes` in every layout of ``agent.layouts`` (or
    ``env.layout``) and every city of ``agent.cities`` (or ``env.city_seed``), the run's model otherwise."""
    layouts = list(a.get("layouts") or []) or [env_cfg.layout]
    cities = list(a.get("cities") or []) or [env_cfg.city_seed]
    return [
        env_cfg.replace(num_uavs=n, grid=grid, layout=layout, city_seed=city)
        for n, grid in team_sizes(env_cfg, a)
        for layout in layouts
        for city in cities
    ]


MAX_CITIES = 16  # agent.cities: the groups, and with them the memory and the time, multiply by the cities


def cities_rule() -> Rule:
    """``agent.cities``: null, or 1 to :data:`MAX_CITIES` distinct city seeds below the benchmark's held-out ones
    (:data:`~uavrl.envs.config.HELD_OUT_CITY_SEEDS`)."""

    def accepts(v):
        seeds = isinstance(v, list) and all(whole(0).accepts(s) and s < HELD_OUT_CITY_SEEDS for s in v)
        return v is None or (seeds and 1 <= len(v) <= MAX_CITIES and len(set(v)) == len(v))

    return Rule(
        accepts,
        f"give null (env.city_seed's city) or a list of 1 to {MAX_CITIES} distinct city seeds, whole numbers in "
        "[0, 2^62) (seeds from 2^62 are the benchmark's held-out cities)",
    )


@dataclass
class TabularSchema:
    """``agent=tabular`` (:class:`~uavrl.agents.tabular.TabularAgent`): the defaults are the paper's learner (eqs.
    9-10) and protocol (10 runs x 200 episodes of ``env.max_steps`` steps)."""

    name: str = setting("tabular")
    method: str = setting(
        "q_learning",
        one_of(*METHODS, what="methods"),
        "q_learning (the paper's learner) or value_iteration (exact Q*, the paper's \"offline\" remark)",
    )
    alpha: REAL = setting(0.1, interval(0.0, 1.0, low_open=True), "the learning rate of eq. 9")
    gamma: REAL = setting(0.3, UNIT, "the discount of the learner's (or the solved) Q")
    epsilon: REAL = setting(0.1, UNIT, "the exploration rate of the epsilon-greedy joint action")
    shared_table: bool = setting(False, flag(), "true: the runs' worlds feed one table instead of one table each")
    backend: str = setting(
        "numba", one_of("numba", "torch", what="backends"), "numba (compiled CPU loop) or torch (batched, any device)"
    )
    memory_budget: REAL = setting(
        DEFAULT_MEMORY_BUDGET, MEMORY_BUDGET, "bytes of the tables, the worlds or the evaluation; more is refused"
    )
    episodes: int = setting(200, whole(1), "iterations: one episode of every run each")
    runs: int = setting(10, whole(1), "independent runs (each its own table)")


@dataclass
class DQNSchema:
    """``agent=dqn`` (:class:`~uavrl.agents.dqn.DQNAgent`)."""

    name: str = setting("dqn")
    head: str = setting(
        "factored",
        one_of("factored", "joint", what="heads"),
        "factored: per-UAV heads mixed by agent.mixer; joint: one head over the 6^N joint actions (N <= 4)",
    )
    mixer: str = setting(
        "vdn",
        one_of("vdn", "qmix", "mean", what="mixers"),
        "vdn (the sum of the UAVs' values), qmix (monotonic, state-conditioned) or mean (agent.network=set only); "
        "factored head only",
    )
    network: str = setting(
        "team",
        one_of("team", "set", what="networks"),
        "team: a torso over the joint observation, sized by N and the grid; set: size-free (attention over the "
        "other UAVs, or with env.observation=local over those each UAV hears; any N and grid: agents/dqn/setnet.py)",
    )
    sizes: list[Any] = setting(
        rule=team_sizes_rule(),
        doc="agent.network=set: the teams [num_uavs, L1, L2] one run trains on ([]: env.num_uavs on env.grid)",
        factory=list,
    )
    layouts: list[str] = setting(
        rule=Rule(lambda v: isinstance(v, list) and set(v) <= set(LAYOUTS), f"give a list among {', '.join(LAYOUTS)}"),
        doc="agent.network=set: the layouts each team trains on ([]: env.layout)",
        factory=list,
    )
    cities: Optional[list[int]] = setting(
        None,
        cities_rule(),
        "agent.network=set with env.city: the city seeds each team and layout trains in, one group of agent.worlds "
        "worlds each (null: env.city_seed)",
    )
    heads: int = setting(
        4, whole(1), "agent.network=set: attention heads (they divide agent.hidden)", read=read_if("network", "set")
    )
    demonstrations: str = setting(
        "none",
        one_of(*DEMONSTRATIONS, what="demonstrations"),
        "agent.network=set: oracle keeps the oracle planner's trajectories in the replay and adds DQfD's margin loss "
        "(agents/dqn/demonstrations.py); none: pure RL",
    )
    demo_transitions: int = setting(
        20000,
        whole(1),
        "agent.demonstrations=oracle: transitions, split over the teams, kept beside the replay buffer (not in it)",
        read=read_if("demonstrations", "oracle"),
    )
    demo_batch_share: REAL = setting(
        0.25,
        interval(0.0, 0.9, low_open=True),
        "agent.demonstrations=oracle: the demonstrations' share of a batch",
        read=read_if("demonstrations", "oracle"),
    )
    margin: REAL = setting(
        0.8,
        positive(),
        "agent.demonstrations=oracle: the margin of DQfD's supervised loss",
        read=read_if("demonstrations", "oracle"),
    )
    curriculum: str = setting(
        "none",
        one_of(*CURRICULA, what="curricula"),
        "agent.network=set: loss gives each team and layout a share of every batch by its recent TD loss "
        "(agents/dqn/curriculum.py); none: equal shares",
    )
    worlds: int = setting(64, whole(1), "parallel worlds, each plays one episode per iteration")
    hidden: int = setting(128, whole(1), "units per hidden layer")
    depth: int = setting(
        2, whole(1), "hidden layers of the torso over the joint observation (agent.network=set: attention layers)"
    )
    mixing_embed_dim: int = setting(32, whole(1), "qmix only", read=read_if("mixer", "qmix"))
    objective: str = setting(
        "log_gap",
        one_of("delta", "log_gap", what="objectives"),
        "log_gap: the change of -log(1 - U/U* + gap_floor) (BENCHMARKS.md, The yardstick); delta: the env's reward "
        "(env.reward: delta by default, delivered for a mission's data)",
    )
    gap_floor: REAL = setting(
        0.0001,
        positive(),
        "log_gap only: gaps below this fraction of U* count as closed",
        read=read_if("objective", "log_gap"),
    )
    gamma: REAL = setting(0.7, UNIT, "the discount; 0.9 left greedy policies oscillating near U* (BENCHMARKS.md)")
    n_step: int = setting(
        1,
        whole(1),
        "n-step returns: a target sums up to this many rewards of its episode before it bootstraps (at most "
        "env.max_steps)",
    )
    lr: REAL = setting(0.0005, positive(), "Adam's learning rate, annealed linearly over the run to agent.lr_end")
    lr_end: REAL = setting(0.00005, positive(), "the learning rate at the end of the run")
    batch_size: int = setting(256, whole(1), "transitions per gradient step")
    buffer_size: int = setting(50000, whole(1), "transitions (the checkpoint keeps them: ~3 MB for N = 6 on 10x10)")
    replay: str = setting(
        "uniform",
        one_of("uniform", "prioritized", what="replays"),
        "prioritized: each transition drawn by its last TD error (Schaul et al. 2016, agents/dqn/priorities.py), "
        "agent.network=team only",
    )
    priority_alpha: REAL = setting(
        0.6,
        interval(0.0, 1.0, low_open=True),
        "agent.replay=prioritized: how much the TD errors count",
        read=read_if("replay", "prioritized"),
    )
    priority_beta: REAL = setting(
        0.4,
        UNIT,
        "agent.replay=prioritized: the importance weights' exponent, annealed linearly to 1 over the run",
        read=read_if("replay", "prioritized"),
    )
    updates: int = setting(32, whole(1), "gradient steps per iteration")
    learning_starts: int = setting(2000, whole(0), "transitions in the buffer before the first gradient step")
    tau: REAL = setting(0.01, UNIT, "soft target update per gradient step")
    eps_start: REAL = setting(1.0, UNIT, "epsilon-greedy exploration, annealed linearly from this...")
    eps_end: REAL = setting(0.05, UNIT, "...to this...")
    eps_fraction: REAL = setting(0.5, UNIT, "...over this fraction of the run's frames")
    max_grad_norm: REAL = setting(10.0, positive(), "the gradients' norm is clipped to this")
    iterations: int = setting(500, whole(1), "one episode in every world per iteration")
    memory_budget: REAL = setting(
        DEFAULT_MEMORY_BUDGET,
        MEMORY_BUDGET,
        "bytes of the worlds, a batch, the replay buffer or the evaluation; more is refused",
    )


@dataclass
class BaselineSchema:
    """``agent=random``, ``agent=oracle`` (:mod:`uavrl.agents.baselines`) and ``agent=planner``
    (:mod:`uavrl.agents.planner`): nothing to train."""

    name: str = setting("random")
    memory_budget: REAL = setting(DEFAULT_MEMORY_BUDGET, MEMORY_BUDGET, "bytes of the evaluation; more is refused")


MAX_JOINT_UAVS = 4  # the joint head's 6^N outputs are for small teams
MAX_JOINT_ACTIONS = NUM_ACTIONS**MAX_JOINT_UAVS  # the joint head is for small teams: N <= 4


def _plain(value):
    """A list setting as plain lists (a config's list of lists is one of its own types)."""
    return [_plain(v) for v in value] if not isinstance(value, (str, int, float)) else value


def check_local_dqn(env_cfg: ModelConfig, a, network: str) -> None:
    """One-line errors for DQN settings that need the central observation (``env.observation=local`` is set): the
    joint head (one value per joint action), messages with the size-free network (not built: it learns none) and
    n-step returns with messages."""
    if a.head == "joint":
        raise ValueError(
            "agent.head='joint' is invalid with env.observation='local': one value per joint action is a central "
            "controller's; use agent.head=factored (each UAV from its own observation)"
        )
    if network == "set" and env_cfg.message_size:
        raise ValueError(
            f"agent.network='set' is invalid with env.message_size={env_cfg.message_size}: the size-free network on "
            "local observations learns no messages; use agent.network=team, or env.message_size=0"
        )
    if env_cfg.message_size and int(a.get("n_step", 1)) > 1:
        raise ValueError(
            f"agent.n_step={a.n_step} is invalid with env.message_size={env_cfg.message_size}: the messages are "
            "learned through one step of communication; give agent.n_step=1"
        )


def check_tabular_settings(env_cfg: ModelConfig, a) -> None:
    """A one-line error for the tabular agent with local observations: its Q table is indexed by the team's
    state."""
    if env_cfg.local:
        raise ValueError(
            "env.observation='local' is invalid for agent=tabular: its Q table is indexed by every UAV's cell, which "
            "no UAV observes alone; use agent=dqn"
        )


def check_dqn_settings(env_cfg: ModelConfig, a) -> None:
    """One-line errors for DQN settings that cannot go together (after the schema's rules), before torch is
    imported: what the network (``team`` or ``set``) and its head and mixer allow, and the teams of a size-free run,
    each a model of its own (``agent.sizes`` x ``agent.layouts`` x ``agent.cities``)."""
    network = a.get("network", "team")  # run configs saved before: no setting
    if int(a.get("n_step", 1)) > env_cfg.max_steps:  # MultiStep's memory and time grow with it, its returns do not
        raise ValueError(
            f"agent.n_step={a.n_step} is invalid with env.max_steps={env_cfg.max_steps}: a target sums at most the "
            f"rewards of its episode; give a whole number in [1, {env_cfg.max_steps}]"
        )
    if a.get("cities") and env_cfg.city == "none":
        raise ValueError(
            f"agent.cities={shown(_plain(a.cities), label=True)} is invalid with env.city='none': the seeds lay out a "
            "city's buildings; give env.city (e.g. env.city=urban) or agent.cities=null"
        )
    if env_cfg.local:
        check_local_dqn(env_cfg, a, network)
    if network == "team":
        if a.mixer == "mean":
            raise ValueError(
                "agent.mixer='mean' is invalid with agent.network='team': use vdn or qmix, or agent.network=set"
            )
        for lever, off in (("demonstrations", "none"), ("curriculum", "none")):
            if a.get(lever, off) != off:
                raise ValueError(
                    f"agent.{lever}={a[lever]!r} is invalid with agent.network='team': use agent.network=set"
                )
        for name in ("sizes", "layouts", "cities"):
            if a.get(name):
                value = shown(_plain(a.get(name)), label=True)
                raise ValueError(
                    f"agent.{name}={value} is invalid with agent.network='team', which is sized by the run's env and "
                    "trains on it alone: use agent.network=set"
                )
        if a.head == "joint" and env_cfg.num_uavs > MAX_JOINT_UAVS:
            N, A = env_cfg.num_uavs, env_cfg.joint_action_base
            raise ValueError(
                f"agent.head='joint' is invalid with env.num_uavs={N}: it needs {A}^{N} outputs, and it is for teams "
                f"of at most {MAX_JOINT_UAVS} UAVs ({A}^{MAX_JOINT_UAVS} = {A**MAX_JOINT_UAVS:,}); use "
                "agent.head=factored"
            )
        if a.head == "joint" and env_cfg.energy != "none":
            raise ValueError(
                f"agent.head='joint' is invalid with env.energy={env_cfg.energy!r}: its joint action mask knows no UAV "
                "out of service; use agent.head=factored"
            )
        return
    if a.get("replay", "uniform") != "uniform":
        raise ValueError(
            f"agent.replay={a.replay!r} is invalid with agent.network='set': each team's share of a batch is drawn "
            "uniformly from its own buffer (agent.curriculum sets the shares); use agent.replay=uniform"
        )
    if a.get("curriculum", "none") != "none" and len(training_models(env_cfg, a)) == 1:
        raise ValueError(
            f"agent.curriculum={a.curriculum!r} is invalid with one team and layout to train on: it shares each batch "
            "among several; give agent.sizes or agent.layouts, or agent.curriculum=none"
        )
    if a.get("demonstrations", "none") != "none" and env_cfg.energy != "none":
        raise ValueError(
            f"agent.demonstrations={a.demonstrations!r} is invalid with env.energy={env_cfg.energy!r}: the oracle's "
            "demonstrations ignore the batteries; use agent.demonstrations=none"
        )
    if a.head != "factored":
        raise ValueError(f"agent.head={a.head!r} is invalid with agent.network='set': use agent.head=factored")
    if a.mixer not in ("vdn", "mean"):
        raise ValueError(
            f"agent.mixer={a.mixer!r} is invalid with agent.network='set': its mixing weights grow with N; use "
            "vdn (the sum) or mean"
        )
    if int(a.hidden) % int(a.heads):
        raise ValueError(
            f"agent.heads={a.heads} is invalid with agent.hidden={a.hidden}: the heads split the hidden units, so "
            "they must divide agent.hidden"
        )
    for n, grid in team_sizes(env_cfg, a):
        if not a.get("sizes"):
            break
        team = f"[{n}, {grid[0]}, {grid[1]}]"
        if n > grid[0] * grid[1]:
            raise ValueError(
                f"agent.sizes={shown(_plain(a.sizes), label=True)} is invalid: its team {team} has {n} UAVs for the "
                f"{grid[0] * grid[1]} cells of a {grid[0]}x{grid[1]} grid (one per cell)"
            )
        try:
            env_cfg.replace(num_uavs=n, grid=grid)
        except InvalidOption as err:
            raise ValueError(
                f"agent.sizes={shown(list(a.sizes), label=True)} is invalid: its team {team}: {err}"
            ) from None


# ------------------------------------------------------------------------------------------------ the registry
@dataclass(frozen=True)
class AgentConfig:
    """One agent of :data:`AGENTS`: the schema of its settings, the class that runs them and the rules they follow
    together (standard library only: the class is named, and imported only by :meth:`associated_class`).

    Args:
        schema: the dataclass of its settings (``configs/agent/<name>.yaml`` starts from it): each field's default,
            rule and meaning.
        agent: its class, ``"<module under uavrl.agents>:<class>"``.
        variants: ``(setting, value, class)``: the settings with that value run that class instead (``agent=dqn
            agent.network=set`` is the size-free ``SetDQNAgent``).
        together: ``(env_cfg, settings)``: a one-line ValueError for settings that cannot go together on the model
            ``env_cfg``, after each setting's own rule; ``None``: none.
    """

    schema: type
    agent: str
    variants: tuple[tuple[str, Any, str], ...] = ()
    together: Callable[[ModelConfig, Any], None] | None = None

    def associated_class(self, settings: Any = None) -> type[Agent]:
        """The class that runs ``settings`` (the run's ``cfg.agent``; ``None``: the default class), imported now."""
        path = self.agent
        for name, value, variant in self.variants:
            if settings is not None and settings.get(name, getattr(self.schema, name)) == value:
                path = variant  # run configs saved before the setting existed: its default
                break
        module, _, cls = path.partition(":")
        return getattr(importlib.import_module(f"uavrl.agents.{module}"), cls)  # naming an agent imports no torch

    def rules(self) -> dict[str, Rule]:
        """Each setting's rule, as typed (``agent.alpha``)."""
        return dict(_rules(self.schema))

    def check_each(self, settings) -> None:
        """A one-line ValueError for the first setting of ``settings`` (``cfg.agent``) that breaks its own rule."""
        _once(("each", self.schema, _frozen(settings)), lambda: check(settings, _rules(self.schema), section="agent"))

    def check_together(self, env_cfg: ModelConfig, settings) -> None:
        """A one-line ValueError for settings that cannot go together on the model ``env_cfg`` (after
        :meth:`check_each`)."""
        if self.together is not None:
            model = (env_cfg, getattr(env_cfg, "preset", None))  # ModelConfig's == leaves its preset out
            _once(("together", self.together, model, _frozen(settings)), lambda: self.together(env_cfg, settings))

    def validate(self, env_cfg: ModelConfig, settings) -> None:
        """Every rule of ``settings`` on ``env_cfg``: each setting's own, then together.  An agent's constructor
        calls it; a rule already passed by the same settings on the same model (a command checks them before it
        builds the agent: :mod:`uavrl.settings`) does not run again."""
        self.check_each(settings)
        self.check_together(env_cfg, settings)


@functools.cache
def _rules(schema: type) -> dict[str, Rule]:
    return rules_of(schema, "agent")


def _frozen(value):
    """``value`` (a config, a dict, a list) as nested tuples of ``(type, value)`` leaves: settings compared by content
    and type (``1`` is not ``True``)."""
    if isinstance(value, Mapping):
        return tuple((key, _frozen(value[key])) for key in sorted(value, key=str))
    if isinstance(value, Sequence) and not isinstance(value, str):
        return tuple(_frozen(v) for v in value)
    return type(value), value


_PASSED: dict[tuple, None] = {}  # the rules (with their settings and model) that passed, the newest 64


def _once(key: tuple, rules: Callable[[], None]) -> None:
    """Run ``rules`` (a one-line ValueError when they refuse) unless they passed for ``key`` before."""
    try:
        if key in _PASSED:
            return
    except TypeError:  # a value that cannot be compared by content: the rules run every time
        rules()
        return
    rules()
    _PASSED[key] = None
    while len(_PASSED) > 64:
        del _PASSED[next(iter(_PASSED))]


# The agents by name: ``agent=<name>`` (``configs/agent/<name>.yaml``) runs ``AGENTS[name]``.
AGENTS: dict[str, AgentConfig] = {
    "tabular": AgentConfig(TabularSchema, "tabular:TabularAgent", together=check_tabular_settings),
    "dqn": AgentConfig(
        DQNSchema,
        "dqn:DQNAgent",
        variants=(("network", "set", "dqn.multisize:SetDQNAgent"),),
        together=check_dqn_settings,
    ),
    "random": AgentConfig(BaselineSchema, "baselines:RandomAgent"),
    "oracle": AgentConfig(BaselineSchema, "baselines:OracleAgent"),
    "planner": AgentConfig(BaselineSchema, "planner:PlannerAgent"),
}
# the schema of each agent, by name (read from AGENTS)
AGENT_SCHEMAS: Mapping[str, type] = MappingProxyType({name: config.schema for name, config in AGENTS.items()})


def agent_rules(name: str) -> dict[str, Rule]:
    """The rules of the settings of the agent ``name``, as typed (``agent.alpha``)."""
    return AGENTS[name].rules()


# what a size-free policy trained in a city may meet in another city (a city for a city, levels for levels)
CITY_MODEL_OPTIONS = ("city", *CITY_OPTIONS, "environment", "altitudes_m", "altitude_m")


def run_city(env_cfg: ModelConfig, run_cfg: ModelConfig) -> dict:
    """The run's city settings (:data:`CITY_MODEL_OPTIONS`) where both models have a city, else none: what
    ``env_cfg.replace(**run_city(env_cfg, run_cfg))`` takes back to the run's model when a policy acts in another
    city of it (its buildings, channel environment and levels)."""
    if env_cfg.city == "none" or run_cfg.city == "none":
        return {}
    return {name: getattr(run_cfg, name) for name in CITY_MODEL_OPTIONS}


def network_refusal(saved_cfg, env_cfg: ModelConfig, run_cfg: ModelConfig) -> str | None:
    """Why the policy of a run with config ``saved_cfg`` (its model ``run_cfg``) cannot act in ``env_cfg``; ``None``
    when it can: a per-size policy only in its run's model, a size-free one (which reads the nodes) in any grid,
    number of UAVs and layout; either, trained in a city, in any other city (its environment, seed, channel
    environment and altitudes) of the same model otherwise; neither with altitude levels where it was trained
    without, or the reverse."""
    levels, trained = env_cfg.num_levels > 1, run_cfg.num_levels > 1
    if levels != trained:
        return (
            f"its policy was trained {'with altitude levels' if trained else 'at one altitude'} (env.altitudes_m="
            f"{shown(run_cfg.altitudes_m and list(run_cfg.altitudes_m), label=True)}), and a UAV's observations and "
            f"actions {'at one altitude' if trained else 'with altitude levels'} differ"
        )
    size_free = saved_cfg.agent.name == "dqn" and saved_cfg.agent.get("network", "team") == "set"
    same = dict(max_steps=run_cfg.max_steps, **run_city(env_cfg, run_cfg))
    cities = ", the city (env.city and its options, env.environment) and the levels" if "city" in same else ""
    if size_free:
        if env_cfg.replace(grid=run_cfg.grid, num_uavs=run_cfg.num_uavs, layout=run_cfg.layout, **same) != run_cfg:
            return f"only env.grid, env.num_uavs, env.layout{cities} may differ from the saved run's"
        return None
    if env_cfg.replace(**same) == run_cfg:
        return None
    network = f"agent.network={saved_cfg.agent.get('network', 'team')}" if saved_cfg.agent.name == "dqn" else "table"
    heard = ""
    if run_cfg.local:  # a local policy's model includes what its UAVs hear
        radius = "every UAV" if run_cfg.comm_radius is None else f"env.comm_radius={run_cfg.comm_radius:g}"
        heard = f", local observations ({radius}, env.message_size={run_cfg.message_size})"
    return (
        f"its {saved_cfg.agent.name} policy ({network}) acts only in its run's model ({run_cfg.grid[0]}x"
        f"{run_cfg.grid[1]} grid, {run_cfg.num_uavs} UAVs, layout {run_cfg.layout!r}{heard}"
        f"{'; of the city only' + cities.removeprefix(',') + ' may differ' if cities else ''}); only a size-free "
        "network (agent=dqn agent.network=set) acts on any size"
    )


@dataclass
class EvalSchema:
    """The shared evaluation (:mod:`uavrl.agents.evaluation`, ``eval.*``), whose library defaults these are too."""

    num_starts: int = setting(64, whole(1), "fixed, seeded starts of the greedy evaluation")
    horizon: Optional[int] = setting(
        None,
        optional(whole(1), "max(20, 2 (L1 + L2)) steps, or the mission's under an energy model"),
        "steps per greedy rollout; null: max(20, 2 (L1 + L2)), or under an energy model the steps by which every UAV "
        "is home (docs/model.md, What the numbers mean)",
    )
    gamma: REAL = setting(
        0.9,
        interval(0.0, 1.0, low_open=True),
        "the yardstick's discount (eval/return, eval/return_ratio), whatever the agent trains with",
    )
    seed: int = setting(1_000_003, SEED, "held out from training seeds (and layouts)")
    every: int = setting(0, whole(0), "iterations between evaluations during training; 0: only at the end")
