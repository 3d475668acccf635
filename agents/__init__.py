"""Team agents (tabular team Q-learning, a factored deep Q-network) and the baselines (random, oracle).

Every agent has the same shape, so ``uavrl.train`` and ``uavrl.evaluate`` drive any of them:

- ``Agent(env_cfg, cfg, device, seed)``: ``env_cfg`` a :class:`~uavrl.envs.ModelConfig`,
  ``cfg`` the full Hydra config (``cfg.agent``, ``cfg.train``);
- ``num_iterations``: how many ``train_iteration()`` calls make the whole run;
- ``train_iteration() -> dict[str, float]``: one unit of training, returning
  ``train/...`` scalars (episode metrics from :func:`uavrl.evaluation.episode_metrics`);
- ``env_steps``: team steps consumed so far, the x axis of every curve;
- ``policies()``: greedy TorchRL policies, one per independent run;
- ``state_dict()`` / ``load_state_dict()``: everything a checkpoint needs to resume.
"""

import importlib

AGENTS = {
    "tabular": "uavrl.agents.tabular:TabularAgent",
    "dqn": "uavrl.agents.dqn:DQNAgent",
    "random": "uavrl.agents.baselines:RandomAgent",
    "oracle": "uavrl.agents.baselines:OracleAgent",
}


def agent_class(name: str):
    if name not in AGENTS:
        raise ValueError(f"agent={name!r} is invalid: allowed agents are {', '.join(AGENTS)}")
    module, cls = AGENTS[name].split(":")
    return getattr(importlib.import_module(module), cls)
