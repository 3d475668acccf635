"""uavrl: learning spectrum sharing and task allocation in UAV networks with TorchRL."""

__version__ = "0.1.0"


def load_policy(run_dir, device="cpu", run: int = 0):
    """``(policy, env_config)`` of a run directory written by ``python -m uavrl.train``, for any agent or baseline.

    ``policy`` is the agent's greedy TorchRL policy (of independent run ``run``
    where the agent trained several), ``env_config`` the run's
    :class:`~uavrl.envs.ModelConfig`, so that::

        policy, env_config = load_policy("runs/dqn/paper/20261125-120000")
        env = UAVSpectrumEnv(batch_size=64, config=env_config)
        td = env.rollout(40, policy)

    The oracle with ``layout="random"`` reads the layouts from the environment
    it acts in: call ``policy.bind_env(env)`` first.
    """
    from uavrl.config import model_config
    from uavrl.evaluate import load_agent

    agent, cfg = load_agent(run_dir, device)
    policies = agent.policies()
    if not 0 <= run < len(policies):
        raise ValueError(
            f"run={run} is invalid: this run directory holds {len(policies)} trained run(s), 0 to {len(policies) - 1}"
        )
    return policies[run], model_config(cfg)
