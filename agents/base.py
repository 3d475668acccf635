"""The agent contract: what ``uavrl.train``, ``uavrl.evaluate`` and the reports need from every agent.

Standard library only, so :mod:`uavrl.settings` can name the agents before torch is imported.

Example:
    >>> class Idle(Agent):
    ...     num_iterations = 1
    ...     env_steps = 0
    ...     def train_iteration(self): return {}
    ...     def policies(self): return []
    ...     def state_dict(self): return {}
    ...     def load_state_dict(self, state): pass
    >>> Idle().train_iteration()
    {}
"""

from __future__ import annotations

import abc
from typing import Any


class Agent(abc.ABC):
    """A team agent: ``Agent(env_cfg, cfg, device, seed)``.

    ``env_cfg`` is the run's :class:`~uavrl.envs.ModelConfig` (its ``max_steps``
    the episode length), ``cfg`` the full Hydra config (``cfg.agent``,
    ``cfg.train``).  A subclass sets ``num_iterations`` in its constructor and
    implements the five members below; ``uavrl.train`` calls
    ``train_iteration()`` ``num_iterations`` times, checkpoints
    ``state_dict()`` and, on resume, calls ``load_state_dict()`` on a freshly
    built agent of the same settings: the resumed run must then end exactly as
    the uninterrupted one.
    """

    num_iterations: int
    """How many :meth:`train_iteration` calls make the whole run."""

    @property
    @abc.abstractmethod
    def env_steps(self) -> int:
        """Team steps consumed so far, the x axis of every curve."""

    @abc.abstractmethod
    def train_iteration(self) -> dict[str, float]:
        """One unit of training; ``train/...`` scalars (see :func:`uavrl.agents.episodes.episode_metrics`)."""

    @abc.abstractmethod
    def policies(self) -> list:
        """Greedy TorchRL policies, one per independent run (read the env's keys, write ``("agents", "action")``)."""

    def policy_for(self, env_cfg, run: int = 0):
        """The greedy policy of run ``run`` for environments of ``env_cfg``.  Here the run's own policy, which acts
        only in its run's environment; a size-free agent overrides it to act at any size."""
        return self.policies()[run]

    def evaluate(self, env_cfg, **kwargs) -> list[dict[str, float]]:
        """:func:`uavrl.agents.evaluation.evaluate` in the model ``env_cfg`` (``kwargs``: its settings) of each of
        :meth:`policies`.

        An agent may override it with a faster evaluation of the same greedy
        policies that gives the same numbers (the tabular agent reads its tables).
        """
        from uavrl.agents.evaluation import evaluate  # torch and the solvers: the contract itself imports neither

        return [evaluate(policy, env_cfg, **kwargs) for policy in self.policies()]

    @abc.abstractmethod
    def state_dict(self) -> dict[str, Any]:
        """Everything a checkpoint needs to resume exactly."""

    @abc.abstractmethod
    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from ``state``, the :meth:`state_dict` of an agent built with the same settings."""
