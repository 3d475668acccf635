"""What every command-line setting allows, checked before torch is imported.

The rules live with the settings' defaults in the schemas (:mod:`uavrl.schema`, :mod:`uavrl.agents.schema`); the
tables here are read from them: the run's settings, then the chosen agent's own (another agent's rules never
apply).  A setting missing from a config (one a saved run's config predates) is skipped.  A refusal is one line
that names the setting, the value and what is allowed::

    agent.episodes=0 is invalid: it must be a whole number >= 1

Only the standard library and omegaconf are imported, so a bad override is refused in a fraction of a second; what a
command costs is :mod:`uavrl.costs`' to refuse.
"""

from __future__ import annotations

import dataclasses

from omegaconf import DictConfig, OmegaConf

from uavrl.agents import AGENTS
from uavrl.envs.rules import Rule, check, flag, one_of, rules_of
from uavrl.schema import BenchmarlSchema, EnvSchema, ReproduceSchema, RunSchema

# python -m uavrl.train and python -m uavrl.evaluate (configs/config.yaml): the run's settings and the agent's name;
# the env.* options are checked by the model itself (uavrl.envs.ModelConfig)
RUN_SETTINGS: dict[str, Rule] = rules_of(RunSchema) | {"agent.name": one_of(*AGENTS, what="agents")}
# the settings of each agent (configs/agent/<name>.yaml), from its schema in the registry
AGENT_SETTINGS: dict[str, dict[str, Rule]] = {name: config.rules() for name, config in AGENTS.items()}
# python -m uavrl.reproduce (configs/reproduce.yaml) and python -m uavrl.benchmarl (configs/benchmarl.yaml)
REPRODUCE_SETTINGS: dict[str, Rule] = rules_of(ReproduceSchema)
BENCHMARL_SETTINGS: dict[str, Rule] = rules_of(BenchmarlSchema)


def check_run(cfg: DictConfig) -> None:
    """A one-line ValueError for the first setting of a run's config that breaks its rule: the run's settings, then
    those of its agent (:meth:`~uavrl.agents.schema.AgentConfig.check_each`)."""
    check(cfg, RUN_SETTINGS)
    name = OmegaConf.select(cfg, "agent.name")
    if name is not None:
        AGENTS[name].check_each(cfg.agent)


def check_agent_settings(cfg: DictConfig, model) -> None:
    """A one-line ValueError for agent settings that cannot go together on ``model`` (the DQN's network, head,
    mixer and training teams: :meth:`~uavrl.agents.schema.AgentConfig.check_together`), before torch is imported.
    The rules that passed here (and in :func:`check_run`) do not run again when the command builds its agent."""
    name = OmegaConf.select(cfg, "agent.name")
    if name is not None:
        AGENTS[name].check_together(model, cfg.agent)


# what each command of configs/config.yaml does not read, and what reads it instead
UNREAD = {
    "train": {"checkpoint": "python -m uavrl.evaluate's", "print_json": "python -m uavrl.evaluate's"},
    "evaluate": {
        "agent": "the checkpoint's agent is evaluated with its saved settings",
        "scenario": "the checkpoint's run chose its scenario",
        "train": "python -m uavrl.train's",
        "resume": "python -m uavrl.train's",
        "run_dir": "the evaluation writes beside the checkpoint",
        "sweep_dir": "python -m uavrl.train's",
    },
}
READ_ANYWAY = ("agent.memory_budget",)  # the evaluation's own budget


def check_read(overrides, command: str) -> None:
    """A one-line ValueError for an override the command would ignore (``checkpoint=`` on ``uavrl.train``,
    ``agent.hidden=`` on ``uavrl.evaluate``, whose policy is the checkpoint's), naming what reads it."""
    for override in overrides or ():
        key = str(override).partition("=")[0].lstrip("+~")
        if key in READ_ANYWAY:
            continue
        for name, reader in UNREAD[command].items():
            if key == name or key.startswith(f"{name}."):
                typed = str(override).lstrip("+~")
                raise ValueError(f"{typed} is invalid for python -m uavrl.{command}, which does not read it: {reader}")


def check_typed(cfg: DictConfig, overrides, table: dict[str, Rule], schema: type | None = None) -> None:
    """What composing lets through: a key added with ``+`` that no schema has (``+agent.new_key=1``; ``schema``: the
    command's, else the chosen agent's for ``agent.*``), and a true/false setting typed as a number (``2``, which the
    config reads as true)."""
    agent = OmegaConf.select(cfg, "agent.name")
    for override in overrides or ():
        key, _, value = str(override).lstrip("+~").partition("=")
        section, _, name = key.partition(".")
        known = _fields(schema) if schema is not None else set()
        if schema is None and section == "agent" and name and agent in AGENTS:
            known, key_name = _fields(AGENTS[agent].schema), name
        elif schema is None and section == "env" and name:
            known, key_name = _fields(EnvSchema), name
        else:
            key_name = key
        if str(override).startswith("+") and (known and key_name.split(".")[0] not in known):
            raise ValueError(f"{key}={value} is invalid: no such setting (docs/settings.md lists them)")
        rule = table.get(key)
        if rule is not None and rule.allowed == flag().allowed and value.strip().lower() not in ("true", "false"):
            raise ValueError(f"{key}={value} is invalid: {rule.allowed}")


def _fields(schema: type) -> set[str]:
    return {field.name for field in dataclasses.fields(schema)}


def check_scenario(cfg: DictConfig) -> None:
    """A one-line ValueError when the chosen scenario (``configs/scenario/``) does not run the chosen agent."""
    scenario = OmegaConf.select(cfg, "scenario")
    if scenario is not None and cfg.agent.name not in scenario.agents:
        allowed = ", ".join(map(repr, scenario.agents))
        raise ValueError(f"agent={cfg.agent.name} is invalid with scenario={scenario.name}: its agents are {allowed}")
