"""Team agents (tabular team Q-learning, a factored deep Q-network) and the baselines (random, oracle, the
energy-aware planner).

Every agent subclasses :class:`~uavrl.agents.base.Agent` (the contract that
``uavrl.train`` and ``uavrl.evaluate`` drive) and has a name in :data:`AGENTS`.
The registry maps each name to a function that imports the agent's class, so
that naming an agent (``uavrl.settings`` checks ``agent.name`` before torch is
imported) costs nothing, and ``agent=tabular`` never imports the DQN's modules.
The function reads the run's ``cfg.agent`` where one name has variants:
``agent=dqn agent.network=set`` is the size-free
:class:`~uavrl.agents.dqn.multisize.SetDQNAgent`, every other ``agent=dqn`` the
per-size :class:`~uavrl.agents.dqn.DQNAgent`.

A new agent: a subclass of ``Agent`` in its own module, one entry here, its
settings (defaults and rules) in :mod:`uavrl.agents.schema`, a config
``configs/agent/<name>.yaml``; ``tests/test_agents.py`` then runs the contract
test over it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from .base import Agent


def _tabular(settings: Any) -> type[Agent]:
    from .tabular import TabularAgent

    return TabularAgent


def _dqn(settings: Any) -> type[Agent]:
    if settings is not None and settings.get("network", "team") == "set":  # run configs saved before: no setting
        from .dqn.multisize import SetDQNAgent

        return SetDQNAgent
    from .dqn import DQNAgent

    return DQNAgent


def _random(settings: Any) -> type[Agent]:
    from .baselines import RandomAgent

    return RandomAgent


def _oracle(settings: Any) -> type[Agent]:
    from .baselines import OracleAgent

    return OracleAgent


def _planner(settings: Any) -> type[Agent]:
    from .planner import PlannerAgent

    return PlannerAgent


AGENTS: dict[str, Callable[[Any], type[Agent]]] = {
    "tabular": _tabular,
    "dqn": _dqn,
    "random": _random,
    "oracle": _oracle,
    "planner": _planner,
}


def agent_class(name: str, settings: Any = None) -> type[Agent]:
    """The class of the agent named ``name`` (a key of :data:`AGENTS`) for the run's agent settings ``settings``
    (``cfg.agent``; ``None``: the name's default class)."""
    if name not in AGENTS:
        raise ValueError(f"agent={name!r} is invalid: allowed agents are {', '.join(AGENTS)}")
    return AGENTS[name](settings)
