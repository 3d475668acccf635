"""The tabular agent behind ``python -m uavrl.train agent=tabular``: the learner, or the exact table."""

from __future__ import annotations

import time

import torch

from uavrl.agents.base import Agent
from uavrl.agents.schema import AGENTS, TabularSchema
from uavrl.envs import ModelConfig

from .greedy import evaluate_tables
from .learner import TeamQLearner
from .tables import exact_q_table


class TabularAgent(Agent):
    """The tabular agent behind ``python -m uavrl.train agent=tabular`` (contract: :class:`uavrl.agents.base.Agent`).

    ``agent.method=q_learning`` (the paper's learner): one iteration is one
    episode of ``agent.runs`` runs of ``env.max_steps`` steps.
    ``agent.method=value_iteration``: one iteration solves :func:`exact_q_table`.

    Args:
        env_cfg: the run's :class:`~uavrl.envs.ModelConfig` (its ``max_steps`` the episode length); a model with an
            energy model is refused.
        cfg: the full Hydra config; the agent reads ``cfg.agent`` (``configs/agent/tabular.yaml``).
        device: the torch device of the tables and the learner's worlds.
        seed: seeds the learner's episode starts and random numbers (run ``r`` plays worlds from ``seed + r``);
            value iteration draws nothing.
    """

    def __init__(self, env_cfg: ModelConfig, cfg, device, seed: int):
        a = cfg.agent
        AGENTS["tabular"].validate(env_cfg, a)  # a command has checked them: they do not run again
        self.method = a.get("method", TabularSchema.method)  # run directories saved before it existed
        if env_cfg.energy != "none":  # the learner alone takes batteries that outlast its episodes
            raise ValueError(
                f"env.energy={env_cfg.energy!r} is invalid for agent=tabular: its evaluation plays missions until the "
                "batteries run out, which a table without them cannot; use agent=dqn (TeamQLearner itself learns "
                "while no battery reaches its reserve: benchmarks/follow_up_curves.py)"
            )
        self.env_cfg, self.device = env_cfg, torch.device(device)
        if self.method == "value_iteration":
            if not 0 < float(a.gamma) <= 1:
                raise ValueError(f"agent.gamma={a.gamma} is invalid for value iteration: it must lie in (0, 1]")
            self.gamma, self.memory_budget = float(a.gamma), float(a.memory_budget)
            self.learner, self.q, self.num_iterations = None, None, 1
            return
        self.learner = TeamQLearner(
            env_cfg,
            runs=int(a.runs),
            seed=seed,
            alpha=a.alpha,
            gamma=a.gamma,
            epsilon=a.epsilon,
            shared_table=bool(a.shared_table),
            backend=a.backend,
            device=device,
            memory_budget=float(a.memory_budget),
        )
        self.num_iterations = int(a.episodes)

    @property
    def env_steps(self) -> int:
        """Team steps per run so far (all runs advance together); value iteration takes none."""
        return 0 if self.learner is None else self.learner.episode * self.env_cfg.max_steps

    def train_iteration(self) -> dict[str, float]:
        if self.learner is None:
            started = time.perf_counter()
            self.q = exact_q_table(self.env_cfg, self.gamma, self.device, self.memory_budget)
            return {"train/solve_seconds": time.perf_counter() - started}
        per_run = self.learner.run_episode()  # [R] each: the metrics of episodes.EPISODE_METRICS
        self.last_episode = per_run  # for figures
        return {f"train/{k}": v.mean().item() for k, v in per_run.items()}

    def policies(self) -> list:
        from .policy import TabularPolicy  # TorchRL (tensordict), only where a TorchRL policy is asked for

        tables = self.learner.q if self.learner is not None else [self.q]
        return [TabularPolicy(q, self.env_cfg) for q in tables]

    def evaluate(self, env_cfg: ModelConfig, **kwargs) -> list[dict[str, float]]:
        """The evaluation of :meth:`policies` in the model ``env_cfg``, read from the tables in one batched world (no
        TorchRL rollouts); ``kwargs``: the settings of :func:`uavrl.agents.evaluation.evaluate`."""
        return evaluate_tables(self.learner.q if self.learner is not None else self.q[None], env_cfg, **kwargs)

    def state_dict(self) -> dict:
        return (
            self.learner.state_dict() if self.learner is not None else {"q": None if self.q is None else self.q.cpu()}
        )

    def load_state_dict(self, state: dict):
        if self.learner is not None:
            self.learner.load_state_dict(state)
        else:
            self.q = None if state["q"] is None else state["q"].to(self.device)
