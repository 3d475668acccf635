"""What a UAV observes on its own and what it hears from the UAVs and nodes within its communication radius
(docs/model.md, Local observations and messages).

Standard library only, like :mod:`.radio` and :mod:`.power`: :class:`~uavrl.envs.config.ModelConfig` applies these
rules before torch is imported, and the World's observations (:mod:`uavrl.envs.world.observations`) are built with
the same sizes.

With ``observation="local"`` UAV ``i`` observes, in this order:

- its own (x, y, task) and the contributions at its cell and at the cells its 4 moves reach, as under ``"central"``
  (what its radio measures of the nodes' signals);
- each of PT, PR, S, E: ``(dx / L1, dy / L2, dz / h, 1)`` from the UAV to the node when the node lies within
  ``comm_radius``, four zeros otherwise (:data:`NODE_SLOT`);
- under an energy model its battery and service flag; with altitude levels its level and the contributions a climb
  and a descent reach;
- each other UAV ``j``, in the order ``i+1, ..., i+N-1`` (mod N): ``(dx / (L1 - 1), dy / (L2 - 1), task, 1)``, under an
  energy model its battery and service flag, with altitude levels its level minus ``i``'s, then the
  ``message_size`` numbers ``j`` sent at the last step, when ``j`` lies within ``comm_radius``; zeros otherwise.

Example:
    >>> local_slot_features(energy=False, levels=False, message_size=2)
    6
"""

from __future__ import annotations

import math
import numbers

from ..errors import InvalidOption

OBSERVATIONS = ("central", "local")
NODE_SLOT = 4  # a node as a UAV hears it: (dx, dy, dz, heard)
LOCAL_NODE_FEATURES = 4 * NODE_SLOT  # PT, PR, S, E
MAX_MESSAGE_SIZE = 64  # numbers a UAV sends a step; a message is a few symbols of a control channel, not a stream
MESSAGE_BOUND = 1.0  # a message's numbers are clipped to [-1, 1]: a radio's bounded symbols


def local_slot_features(energy: bool, levels: bool, message_size: int) -> int:
    """Entries of another UAV's slot in a local observation: ``(dx, dy, task, heard)``, its battery and service flag
    under an energy model (``energy``), its relative level with altitude levels (``levels``), its message."""
    return 4 + (2 if energy else 0) + (1 if levels else 0) + message_size


def check_observation(observation, comm_radius, message_size, physical: bool) -> None:
    """One line refusing an observation setting: ``observation`` one of :data:`OBSERVATIONS`; ``comm_radius`` (cells,
    or metres under a ``physical`` channel) ``None`` for every UAV and node, else a finite number >= 0;
    ``message_size`` a whole number from 0 to :data:`MAX_MESSAGE_SIZE`; both read only under ``"local"``."""
    if observation not in OBSERVATIONS:
        raise InvalidOption("observation", observation, f"allowed values are {', '.join(map(repr, OBSERVATIONS))}")
    unit = "m" if physical else "cells"
    if comm_radius is not None:
        if observation == "central":
            raise InvalidOption("comm_radius", comm_radius, "only observation='local' reads it, not 'central'")
        number = isinstance(comm_radius, numbers.Real) and not isinstance(comm_radius, bool)
        if not (number and math.isfinite(comm_radius) and comm_radius >= 0):
            reason = f"give a finite distance >= 0 in {unit}, or None (null on a command line) for every UAV and node"
            raise InvalidOption("comm_radius", comm_radius, reason)
    integral = isinstance(message_size, numbers.Integral) and not isinstance(message_size, bool)
    if not (integral and 0 <= message_size <= MAX_MESSAGE_SIZE):
        reason = f"give a whole number of numbers a step from 0 (no message) to {MAX_MESSAGE_SIZE}"
        raise InvalidOption("message_size", message_size, reason)
    if message_size and observation == "central":
        raise InvalidOption("message_size", message_size, "only observation='local' reads it, not 'central'")


def common_knowledge(cfg) -> bool:
    """Whether every UAV of the model ``cfg`` (a :class:`~uavrl.envs.config.ModelConfig`) can rebuild every UAV's
    local observation from its own: every UAV hears every other wherever they are (``comm_radius`` None, or at least
    the grid's diagonal), no messages (the others hear the message a UAV sent, which its own observation does not
    hold), one altitude level, no energy model and a fixed layout (the batteries, the levels and a random layout's
    nodes are heard as float32 numbers that two UAVs could round apart).  The greedy local DQN coordinates on it there
    (:mod:`uavrl.agents.dqn.common_knowledge`).

    Example:
        >>> from uavrl.envs import make_config
        >>> common_knowledge(make_config("paper", grid=(6, 6), observation="local", comm_radius=7.1))
        True
        >>> common_knowledge(make_config("paper", grid=(6, 6), observation="local", comm_radius=7.0))
        False
    """
    (L1, L2) = cfg.grid
    return (
        cfg.observation == "local"
        and cfg.comm_radius_cells >= math.hypot(L1 - 1, L2 - 1)
        and cfg.message_size == 0
        and cfg.num_levels == 1
        and cfg.energy == "none"
        and cfg.layout != "random"
    )
