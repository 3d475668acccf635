"""Team agents (tabular team Q-learning, a factored deep Q-network) and the baselines (random, oracle, the
energy-aware planner).

Every agent subclasses :class:`~uavrl.agents.base.Agent` (the contract that
``uavrl.train`` and ``uavrl.evaluate`` drive) and has a name in the registry
:data:`AGENTS` (:mod:`uavrl.agents.schema`), which maps it to its
:class:`~uavrl.agents.schema.AgentConfig`: the schema of its settings, the rules
they follow, and the class that runs them, named there and imported only by
:meth:`~uavrl.agents.schema.AgentConfig.associated_class`, so that naming an
agent (``uavrl.settings`` checks ``agent.name`` before torch is imported) costs
nothing, and ``agent=tabular`` never imports the DQN's modules.  The class
depends on the run's ``cfg.agent`` where one name has variants:
``agent=dqn agent.network=set`` is the size-free
:class:`~uavrl.agents.dqn.multisize.SetDQNAgent`, every other ``agent=dqn`` the
per-size :class:`~uavrl.agents.dqn.DQNAgent`.

A new agent: a subclass of ``Agent`` in its own module, one ``AgentConfig``
entry (its schema: defaults and rules) in :mod:`uavrl.agents.schema`, a config
``configs/agent/<name>.yaml``; ``tests/agents/test_agents.py`` then runs the contract
test over it (docs/architecture.md, Adding an agent).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .schema import AGENTS

if TYPE_CHECKING:
    from .base import Agent


def agent_class(name: str, settings: Any = None) -> type[Agent]:
    """The class of the agent named ``name`` (a key of :data:`AGENTS`) for the run's agent settings ``settings``
    (``cfg.agent``; ``None``: the name's default class): ``AGENTS[name].associated_class(settings)``."""
    if name not in AGENTS:
        raise ValueError(f"agent={name!r} is invalid: allowed agents are {', '.join(AGENTS)}")
    return AGENTS[name].associated_class(settings)
