"""The checks of ``agent.*`` before any work: the schema's rules, then what the head can hold."""

from __future__ import annotations

from uavrl.agents.schema import agent_rules
from uavrl.envs import NUM_ACTIONS, ModelConfig
from uavrl.rules import check

MAX_JOINT_ACTIONS = NUM_ACTIONS**4  # the joint head is for small teams: N <= 4


def check_settings(env_cfg: ModelConfig, a) -> None:
    """One-line errors for settings the agent cannot run: the rules of its schema (:mod:`uavrl.agents.schema`), then
    the head's size."""
    check(a, agent_rules("dqn"), section="agent")
    if a.get("network", "team") == "team":  # run configs saved before: no setting
        if a.mixer == "mean":
            raise ValueError(
                "agent.mixer='mean' is invalid with agent.network='team': use vdn or qmix, or agent.network=set"
            )
        for lever, off in (("demonstrations", "none"), ("curriculum", "none")):
            if a.get(lever, off) != off:
                raise ValueError(
                    f"agent.{lever}={a[lever]!r} is invalid with agent.network='team': use agent.network=set"
                )
        if a.get("sizes"):
            raise ValueError(
                f"agent.sizes={list(a.sizes)} is invalid with agent.network='team', which is sized by the run's env: "
                "use agent.network=set"
            )
    if a.get("demonstrations", "none") != "none" and env_cfg.energy != "none":
        raise ValueError(
            f"agent.demonstrations={a.demonstrations!r} is invalid with env.energy={env_cfg.energy!r}: the oracle's "
            "demonstrations ignore the batteries; use agent.demonstrations=none"
        )
    if a.head == "joint" and env_cfg.num_joint_actions > MAX_JOINT_ACTIONS:
        raise ValueError(
            f"agent.head='joint' with num_uavs={env_cfg.num_uavs} needs 6^{env_cfg.num_uavs} = "
            f"{env_cfg.num_joint_actions:,} outputs, over {MAX_JOINT_ACTIONS:,} (N <= 4): use agent.head=factored"
        )
    if a.head == "joint" and env_cfg.energy != "none":
        raise ValueError(
            f"agent.head='joint' is invalid with env.energy={env_cfg.energy!r}: its joint action mask knows no UAV out "
            "of service; use agent.head=factored"
        )
