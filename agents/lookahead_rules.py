"""``eval.lookahead``'s rules, standard library only: which agents the lookahead (:mod:`uavrl.agents.lookahead`)
reads, and :func:`~uavrl.agents.evaluation.evaluate_agent`'s lookahead keywords from a config, so that a command
checks them without importing TensorDict or the Q-networks."""

from __future__ import annotations

from uavrl.agents.network_sizes import policy_row_bytes
from uavrl.envs.config import InvalidOption
from uavrl.envs.rules import Reader, refuse, whole_within

MAX_ENUMERATED = 6**4  # every allowed joint action is a candidate up to this many (N <= 4), else one-UAV changes
MAX_LOOKAHEAD = 100  # levels of the search, each a level of recursion: deeper would only repeat the greedy line
WIDTH = 8  # eval.lookahead_width's default: candidates played per node
DEPTH = whole_within(0, MAX_LOOKAHEAD)  # eval.lookahead's rule (uavrl/schema.py), the Python API's too
# what reads eval.lookahead_width (uavrl/schema.py) and evaluate_agent's lookahead_width: a lookahead
WIDTH_READ = Reader("lookahead", lambda depth: depth != 0, "lookahead >= 1")


def check_width_read(width, depth) -> None:
    """``evaluate_agent``'s ``lookahead_width`` refused, as ``eval.lookahead_width`` is, where no lookahead reads it."""
    if width != WIDTH and not WIDTH_READ.reads(depth):
        raise InvalidOption("lookahead_width", width, f"only {WIDTH_READ.words} reads it, not lookahead={depth}")


def candidates_per_node(num_uavs: int, num_actions: int, width: int) -> int:
    """How many joint actions the search plays at each node (:mod:`uavrl.agents.lookahead`): ``width``, at most
    every candidate it ranks (every joint action up to :data:`MAX_ENUMERATED`, else the greedy one and each one-UAV
    change of it); ``width=0``: all of them."""
    ranked = num_actions**num_uavs if num_actions**num_uavs <= MAX_ENUMERATED else 1 + num_uavs * num_actions
    return min(width, ranked) if width else ranked


def deepest_level_bytes(model, settings, starts: int, depth: int, per_node: int) -> int:
    """Bytes of the search's deepest level, held at once: each of ``starts`` starts' ``per_node^depth``
    configurations valued by the Q-network of ``settings`` (:func:`~uavrl.agents.network_sizes.policy_row_bytes`)."""
    return starts * per_node**depth * policy_row_bytes(model, settings)


def check_lookahead(a, depth: int, agent_name: str) -> None:
    """One-line errors for ``eval.lookahead=depth`` out of its range, or with agent settings ``a`` (None: an agent
    without settings)."""
    refuse("eval.lookahead", depth, DEPTH)
    if a is None or a.get("name") != "dqn":
        raise ValueError(f"eval.lookahead={depth} needs a Q-network agent (agent=dqn): {agent_name} has none")
    if a.head != "factored" or a.mixer not in ("vdn", "mean"):
        raise ValueError(
            f"eval.lookahead={depth} is invalid with agent.head={a.head!r} agent.mixer={a.mixer!r}: it reads per-UAV "
            "values mixed by their sum or mean (agent.head=factored, agent.mixer=vdn or mean)"
        )


def check_lookahead_levels(depth: int, altitudes_m, observation: str = "central") -> None:
    """A one-line error for ``eval.lookahead=depth`` with altitude levels (``env.altitudes_m``, two or more): its
    search decodes the UAVs' positions as cells of one level; or with local observations (``env.observation``): it
    searches the team's joint actions from the central state."""
    if depth and observation == "local":
        reason = "the lookahead searches the team's joint actions from the central state, not what each UAV hears"
        raise InvalidOption("eval.lookahead", depth, f"{reason} (observation='local'): give eval.lookahead=0")
    if depth and altitudes_m is not None and len(altitudes_m) > 1:
        raise InvalidOption(
            "eval.lookahead",
            depth,
            f"the lookahead searches the cells of one altitude level, not env.altitudes_m={list(altitudes_m)}: "
            "give eval.lookahead=0",
        )


def lookahead_settings(cfg, agent_settings=None) -> dict:
    """``evaluate_agent``'s lookahead keywords from ``cfg.eval`` (none where ``eval.lookahead`` is 0 or absent); the
    agent is checked at once: ``agent_settings`` (an evaluated checkpoint's saved ``agent``), else ``cfg.agent`` (a
    training run's, before it trains)."""
    depth = int(cfg.eval.get("lookahead", 0) or 0)
    a = agent_settings if agent_settings is not None else cfg.get("agent")
    if depth and a is not None:
        check_lookahead(a, depth, f"agent={a.name}")
    env = cfg.get("env") or {}
    check_lookahead_levels(depth, env.get("altitudes_m"), env.get("observation", "central"))
    return {"lookahead": depth, "lookahead_width": int(cfg.eval.get("lookahead_width", WIDTH))} if depth else {}
