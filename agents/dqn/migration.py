"""Checkpoints of earlier versions, loaded as the current agent would have saved them (a resumed run continues bit for
bit): a replay buffer stored as the filled slots of a ``TensorDict``, and the earlier observation layout (the node
positions in every UAV's observation)."""

from __future__ import annotations

import torch
from torchrl.data import TensorDictReplayBuffer

from uavrl.compat import load_buffer_state
from uavrl.envs import NODE_FEATURES


def load_replay_buffer(buffer: TensorDictReplayBuffer, state: dict, observation_size: int, device) -> None:
    """Fill ``buffer`` from the checkpoint ``state`` of any version (``state["buffer"]``, and
    ``state["buffer_writes"]`` in the oldest)."""
    transitions = state["buffer"] if "buffer_writes" in state else state["buffer"]["_storage"]["_storage"]
    if transitions is not None:
        _nodes_out_of_observation(transitions, observation_size)
    if "buffer_writes" in state:  # a checkpoint of an earlier version: the filled slots, in slot order
        _load_filled_slots(buffer, state["buffer"], state["buffer_writes"], device)
    else:
        load_buffer_state(buffer, state["buffer"])


def _load_filled_slots(buffer: TensorDictReplayBuffer, data, writes: int, device) -> None:
    buffer.empty()
    if data is not None:
        data = data.to(device)
        buffer.extend(data)
        wrapped = writes % len(data) if writes > len(data) else 0
        if wrapped:  # rewrite the first slots with themselves so the next write lands where it would have
            buffer.extend(data[:wrapped])


def _nodes_out_of_observation(transitions, observation_size: int) -> None:
    """A replay buffer of the earlier observation layout (the node positions in every UAV's observation, the state
    only with QMIX) becomes the current one in place, so a run saved in that layout resumes bit for bit.

    ``transitions``: the storage of a buffer's ``state_dict`` or the ``TensorDict`` of the oldest checkpoints.
    """
    for step in ((), ("next",)):
        holder, key = _stored_entry(transitions, (*step, "agents", "observation"))
        observation = holder[key]
        if observation.shape[-1] != observation_size + NODE_FEATURES:
            return
        holder[key] = observation[..., :observation_size].contiguous()
        holder, key = _stored_entry(transitions, (*step, "state"))
        if key not in holder.keys():  # per UAV its first 5 entries, then the nodes (World._assemble)
            own, nodes = observation[..., :5].flatten(-2), observation[..., 0, observation_size:]
            holder[key] = torch.cat([own, nodes], -1)


def _stored_entry(transitions, names: tuple):
    """``(mapping, key)`` of the entry ``names`` of a stored buffer: a ``TensorDict`` (tuple keys), torchrl 0.14's
    flat ``state_dict`` (keys joined by dots) or torchrl 0.11's nested dicts."""
    if not isinstance(transitions, dict):
        return transitions, names
    if ".".join(names) in transitions or names[0] not in transitions:
        return transitions, ".".join(names)
    holder = transitions
    for name in names[:-1]:
        holder = holder[name]
    return holder, names[-1]
