"""The checks of ``agent.*`` before any work: the schema's rules, then what the network, its head and its mixer
allow (:func:`uavrl.agents.schema.check_dqn_settings`, standard library only: the commands run it before torch is
imported)."""

from __future__ import annotations

from uavrl.agents.schema import MAX_JOINT_UAVS, check_dqn_settings
from uavrl.envs import NUM_ACTIONS, ModelConfig

MAX_JOINT_ACTIONS = NUM_ACTIONS**MAX_JOINT_UAVS  # the joint head is for small teams: N <= 4


def check_settings(env_cfg: ModelConfig, a) -> None:
    """One-line errors for settings the agent cannot run (:func:`uavrl.agents.schema.check_dqn_settings`)."""
    check_dqn_settings(env_cfg, a)
