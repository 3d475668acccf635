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
    import numbers
    import os
    import warnings

    from uavrl.config import model_config
    from uavrl.envs.config import InvalidOption, InvalidType, ModelConfig
    from uavrl.experiment.saved import load_agent

    if not isinstance(run_dir, (str, os.PathLike)):
        raise InvalidType("run_dir", run_dir, "give a run directory or a checkpoint.pt in one, a str or a Path")
    if not isinstance(run, numbers.Integral) or isinstance(run, bool):
        raise InvalidType("run", run, "give the whole number of an independent run, 0 for the first")
    if env_config is not None and not isinstance(env_config, ModelConfig):
        reason = "give a ModelConfig (uavrl.envs.make_config(preset, **options)), or None for the run's own model"
        raise InvalidType("env_config", env_config, reason)
    from uavrl.envs.world import resolve_device

    device = resolve_device(device)
    agent, cfg, fallback = load_agent(run_dir, device, setting="run_dir")
    if fallback:
        warnings.warn(fallback, stacklevel=2)
    if env_config is not None:
        from uavrl.agents.schema import network_refusal

        refusal = network_refusal(cfg, env_config, model_config(cfg))
        if refusal:
            message = f"env_config={env_config.num_uavs} UAVs on {env_config.grid} is invalid: {refusal}"
            raise InvalidOption("env_config", message=message)
    runs = len(agent.policies())
    if not 0 <= run < runs:
        message = f"run={run} is invalid: this run directory holds {runs} trained run(s), 0 to {runs - 1}"
        raise InvalidOption("run", message=message)
    env_config = model_config(cfg) if env_config is None else env_config
    return agent.policy_for(env_config, run), env_config
