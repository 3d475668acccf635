"""uavrl: learning spectrum sharing and task allocation in UAV networks with TorchRL."""


def __getattr__(name):
    """``uavrl.__version__``, read from the installed package's metadata (pyproject.toml's version, written nowhere
    else) when first asked for: importlib.metadata costs tens of milliseconds, and every command imports uavrl to
    refuse a bad setting before anything heavy."""
    if name == "__version__":
        from importlib.metadata import version

        globals()["__version__"] = version("uavrl")
        return globals()["__version__"]
    raise AttributeError(f"module 'uavrl' has no attribute {name!r}")


def load_policy(run_dir, device="cpu", run: int = 0, env_config=None):
    """``(policy, env_config)`` of a run directory written by ``python -m uavrl.train``, for any agent or baseline.

    ``policy`` is the agent's greedy TorchRL policy (of independent run ``run``
    where the agent trained several), ``env_config`` the run's
    :class:`~uavrl.envs.ModelConfig`, so that::

        policy, env_config = load_policy("runs/dqn/paper/20261125-120000")
        env = UAVSpectrumEnv(batch_size=64, config=env_config)
        td = env.rollout(40, policy)

    The policy acts only in environments of its run's grid, number of UAVs
    and layout: ``policy.bind_env(env)`` checks an environment up front, and
    every tensordict the policy gets is checked too (a ValueError in one line).
    ``env_config`` (a :class:`~uavrl.envs.ModelConfig`) asks for the policy in
    another team size or grid of the run's model: a size-free network
    (``agent=dqn agent.network=set``) acts there, any other policy is refused
    in one line.

    Args:
        run_dir: a run directory (``runs/<agent>/<env>/<stamp>``, or the ``run_dir=`` given to train) or a
            checkpoint file in one.
        device: the torch device of the policy.
        run: which independent run's policy, for agents that train several (the tabular agent's ``agent.runs``).
        env_config: the model to act in; None: the run's own.

    Returns:
        ``(policy, env_config)``: the greedy TorchRL policy and the model it acts in.

    Reading the run executes nothing its files hold (``weights_only`` loads): a
    file holding objects uavrl does not write is refused.  When ``checkpoint.pt``
    is missing or unreadable, a warning names the file and iteration used instead.
    """
    from uavrl.experiment.policy import load_policy  # torch and the agents: ``import uavrl`` imports neither

    return load_policy(run_dir, device, run, env_config)
