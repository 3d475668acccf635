"""What the DQN's networks cost, counted without building them (standard library only, so the commands refuse a run
too large before torch is imported): their parameters, and a gradient step's multiply-adds and float32 values per
world.  :mod:`uavrl.costs` turns them into a run's memory and CPU time; ``tests/commands/test_costs.py`` holds each
count equal to the parameters of the network built.

Example:
    >>> team_parameters(num_uavs=2, num_actions=6, energy=False, head="factored", hidden=16, depth=1)
    2102
"""

from __future__ import annotations

from uavrl.envs.config import NUM_ACTIONS
from uavrl.envs.limits import (
    NODE_FEATURES,
    PAIR_FEATURES,
    local_set_sizes,
    model_observation_size,
    observation_size,
    set_input_size,
    state_size,
)
from uavrl.envs.physics.sensing import common_knowledge

TRAINING_COPIES = 5  # the online parameters, their target copy, their gradients and Adam's two moments
FLOAT = 4  # bytes of a float32


def _linear(inputs: int, outputs: int, bias: bool = True) -> int:
    return inputs * outputs + (outputs if bias else 0)


def _team_input(num_uavs: int, energy: bool, levels: bool = False) -> int:
    """Entries of a UAV's row of the team network's input: its observation and the nodes."""
    return observation_size(num_uavs, energy, levels) + NODE_FEATURES


def _moves(levels: bool) -> int:
    """The positions a UAV's moves reach (the factored head reads which another UAV holds): 4, 6 with levels."""
    return 6 if levels else 4


def _joint_actions(num_uavs: int, levels: bool) -> int:
    """The joint head's outputs: ``A^N``, ``A`` the 6 actions and with levels climb and descend (as
    ``ModelConfig.joint_action_base``; "return" is never in a joint action)."""
    return (NUM_ACTIONS + 2 * levels) ** num_uavs


def local_inputs(model) -> int:
    """Entries of a UAV's input to ``LocalQNet`` (its local observation, one-hot id and the positions its moves reach
    that it hears held) with local observations; 0 with the central one (``TeamQNet``)."""
    if not model.local:
        return 0
    return model_observation_size(model) + model.fleet_size + _moves(model.num_levels > 1)


def team_parameters(
    num_uavs: int,
    num_actions: int,
    energy: bool,
    head: str,
    hidden: int,
    depth: int,
    levels: bool = False,
    local: int = 0,
    message_size: int = 0,
) -> int:
    """Parameters of ``TeamQNet``: the torso over the joint observation (``depth`` hidden layers and an output layer
    of ``hidden`` units), then the joint head (``A^N`` values, ``A`` 6 or 8 with altitude levels) or the shared
    per-UAV head (one hidden layer); with ``local`` inputs (:func:`local_inputs`) ``LocalQNet``'s MLP and its layer
    that sends ``message_size`` numbers."""
    if local:
        speaker = _linear(hidden, message_size) if message_size else 0
        return _linear(local, hidden) + depth * _linear(hidden, hidden) + _linear(hidden, num_actions) + speaker
    N, h, F = num_uavs, hidden, _team_input(num_uavs, energy, levels)
    torso = _linear(N * F, h) + depth * _linear(h, h)
    if head == "joint":
        return torso + _linear(h, _joint_actions(N, levels))
    return torso + _linear(h + F + N + _moves(levels), h) + _linear(h, num_actions)


def qmix_parameters(num_uavs: int, energy: bool, embed: int, levels: bool = False) -> int:
    """Parameters of ``QMix`` (TorchRL ``QMixer``'s layers): the hypernetworks from the state to the mixing weights
    and biases."""
    S = state_size(num_uavs, energy, levels)
    return _linear(S, embed * num_uavs) + 3 * _linear(S, embed) + _linear(embed, 1)


def set_parameters(num_actions: int, energy: bool, hidden: int, heads: int, depth: int, levels: bool = False) -> int:
    """Parameters of ``SetQCore``: the encoder, ``depth`` attention and feed-forward layers, the head; no size in
    any shape."""
    h = hidden
    attention = 4 * _linear(h, h) + _linear(PAIR_FEATURES, h // 2) + _linear(h // 2, heads)
    attention += _linear(PAIR_FEATURES, h, bias=False)
    layer = attention + 2 * _linear(h, h)
    encoder = _linear(set_input_size(energy, levels), h) + _linear(h, h)
    head = _linear(2 * h, h) + _linear(h, num_actions)
    return encoder + depth * layer + head


def local_set_parameters(num_actions: int, energy: bool, hidden: int, depth: int, levels: bool = False) -> int:
    """Parameters of ``LocalSetQCore``: the encoders of a UAV's own input and of each UAV it hears, ``depth`` rounds
    of attention (query, key, value, out) and feed-forward layers, the head; no size in any shape."""
    h = hidden
    own, heard = local_set_sizes(energy, levels)
    encoders = _linear(own, h) + _linear(heard, h) + 2 * _linear(h, h)
    return encoders + depth * 6 * _linear(h, h) + _linear(2 * h, h) + _linear(h, num_actions)


def size_free_parameters(model, a) -> int:
    """Parameters of the size-free core of the settings ``a`` in the model ``model``: ``LocalSetQCore`` with local
    observations, ``SetQCore`` otherwise."""
    energy, levels, hidden, depth = model.energy != "none", model.num_levels > 1, int(a.hidden), int(a.depth)
    if model.local:
        return local_set_parameters(model.num_actions, energy, hidden, depth, levels)
    return set_parameters(model.num_actions, energy, hidden, int(a.heads), depth, levels)


def team_row_macs(num_uavs: int, num_actions: int, energy: bool, a, levels: bool = False, local: int = 0) -> int:
    """Multiply-adds of one world's forward pass: the network (and the QMIX mixer) for every UAV of it (``LocalQNet``
    with ``local`` inputs)."""
    N, h, depth, F = num_uavs, int(a.hidden), int(a.depth), _team_input(num_uavs, energy, levels)
    embed = int(a.mixing_embed_dim)
    mixer = state_size(N, energy, levels) * embed * (N + 3) + embed * (N + 1) if a.mixer == "qmix" else 0
    if local and a.get("network", "team") == "set":  # LocalSetQCore: its own input, each heard UAV, the rounds
        own, heard = local_set_sizes(energy, levels)
        return N * (own * h + h * h + (N - 1) * (heard * h + h * h + 2 * depth * h * h) + depth * 6 * h * h)
    if local:
        return N * (local * h + depth * h * h + h * num_actions) + mixer
    if a.get("network", "team") == "set":
        pairs = N * N * (PAIR_FEATURES * h // 2 + h // 2 * int(a.heads) + PAIR_FEATURES * h + 2 * h)
        layer = N * 6 * h * h + pairs
        return N * (set_input_size(energy, levels) * h + h * h) + depth * layer + N * (2 * h * h + h * num_actions)
    torso = N * F * h + depth * h * h
    if a.head == "joint":
        return torso + h * _joint_actions(N, levels)
    return torso + h * h + N * ((F + N + _moves(levels)) * h + h * num_actions) + mixer


def team_row_values(num_uavs: int, num_actions: int, energy: bool, a, levels: bool = False, local: int = 0) -> int:
    """Float32 values one world's rows hold at the peak of a gradient step: each layer's inputs and outputs, twice
    for the team network (its torso's and head's temporaries), once for the size-free one (measured by the peak
    resident memory of gradient steps of 8 and of 4096 rows, N = 6 on 10x10 with QMIX: 28 KB a row against this
    count's 37 KB; of 8 and of 256 rows for the size-free network, N = 30 on 40x40: 3.2 MB a row, as counted)."""
    N, h, depth, F = num_uavs, int(a.hidden), int(a.depth), _team_input(num_uavs, energy, levels)
    if local and a.get("network", "team") == "set":  # every UAV's and each heard UAV's layers, once
        own, heard = local_set_sizes(energy, levels)
        return N * (own + 2 * h + (N - 1) * (heard + 2 * h + 3 * depth * h) + depth * 8 * h + 4 * h + num_actions)
    if local:  # each layer's inputs and outputs for every UAV, twice (forward and backward), and the mixer's
        return 2 * (N * (local + 2 * (depth + 1) * h + num_actions) + _mixer_values(N, energy, a, levels))
    if a.get("network", "team") == "set":
        pairs = N * N * (PAIR_FEATURES + 2 * (h // 2) + 3 * int(a.heads) + 2 * h)
        own = set_input_size(energy, levels)
        return N * (own + 2 * h) + depth * (N * 12 * h + pairs) + N * (4 * h + num_actions)
    values = N * F + 2 * (depth + 1) * h
    if a.head == "joint":
        return 2 * (values + 3 * _joint_actions(N, levels))
    values += N * (h + F + N + _moves(levels) + 2 * h + num_actions)
    return 2 * (values + _mixer_values(N, energy, a, levels))


def _mixer_values(num_uavs: int, energy: bool, a, levels: bool) -> int:
    """Float32 values of QMIX's pass over one world (its state and hidden layers); none for VDN."""
    if a.mixer != "qmix":
        return 0
    return state_size(num_uavs, energy, levels) + 2 * int(a.mixing_embed_dim) * (num_uavs + 3)


def greedy_cells(model) -> int:
    """The positions of the greedy valid action's occupancy table (``ValidGreedy``): the model's (its cells, at every
    altitude level) and two more where that is fewer than N^2 A comparisons of targets with claims, else none (its
    cost then follows the team, not the grid)."""
    cells = model.num_positions + 2
    return cells if cells <= model.fleet_size**2 * model.num_actions and not model.local else 0


def policy_row_bytes(model, a) -> int:
    """Bytes of one world's row when the Q-network of settings ``a`` values it and picks its greedy valid action:
    the network's float32 values (:func:`team_row_values`) and the occupancy table (:func:`greedy_cells`)."""
    energy, levels = model.energy != "none", model.num_levels > 1
    values = team_row_values(model.fleet_size, model.num_actions, energy, a, levels, local_inputs(model))
    return FLOAT * values + greedy_cells(model)


def greedy_row_bytes(model, a) -> int:
    """Bytes of one world's row when the greedy policy of settings ``a`` acts: :func:`policy_row_bytes`, or where the
    team is common knowledge (:func:`~uavrl.envs.physics.sensing.common_knowledge`) each UAV's rebuilt team
    (``CommonKnowledgeGreedy``): ``N`` rows of every UAV's observation, mask, position and task, valued by the
    network and picked by the central greedy rule with its occupancy table (measured by the peak resident memory of
    a greedy pass over 4,000 worlds, N = 10 on 20x20: 0.19 MB a world against this count's 0.72 MB; the size-free
    network's over 1,000 worlds: 1.4 MB against 2.5 MB)."""
    if not common_knowledge(model):
        return policy_row_bytes(model, a)
    N, P, A = model.fleet_size, model.num_positions, model.num_actions
    rebuilt = N * (FLOAT * model_observation_size(model) + A + 8 * 3)  # observation, mask, (x, y) and task
    central = P + 2 if P + 2 <= N * N * A else 0  # ValidGreedy's occupancy table (greedy_cells, central)
    return N * (policy_row_bytes(model, a) + rebuilt + central)
