"""A run directory's greedy policy, as :func:`uavrl.load_policy` returns it (its body: :func:`load_policy`)."""

from __future__ import annotations

import numbers
import os
import warnings

from uavrl.agents.schema import network_refusal
from uavrl.config import model_config
from uavrl.envs.config import ModelConfig
from uavrl.envs.errors import InvalidOption, InvalidType
from uavrl.envs.world import resolve_device
from uavrl.experiment.saved import load_agent


def load_policy(run_dir, device="cpu", run: int = 0, env_config=None):
    """:func:`uavrl.load_policy`'s body: ``(policy, env_config)`` of a run directory.

    Args:
        run_dir: a run directory or a checkpoint file in one.
        device: the torch device of the policy.
        run: which independent run's policy.
        env_config: the model to act in; None: the run's own.

    Returns:
        ``(policy, env_config)``.
    """
    if not isinstance(run_dir, (str, os.PathLike)):
        raise InvalidType("run_dir", run_dir, "give a run directory or a checkpoint.pt in one, a str or a Path")
    if not isinstance(run, numbers.Integral) or isinstance(run, bool):
        raise InvalidType("run", run, "give the whole number of an independent run, 0 for the first")
    if env_config is not None and not isinstance(env_config, ModelConfig):
        reason = "give a ModelConfig (uavrl.envs.make_config(preset, **options)), or None for the run's own model"
        raise InvalidType("env_config", env_config, reason)
    device = resolve_device(device)
    agent, cfg, fallback = load_agent(run_dir, device, setting="run_dir")
    if fallback:
        warnings.warn(fallback, stacklevel=3)  # at the line that called uavrl.load_policy
    if env_config is not None:
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
