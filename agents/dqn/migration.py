"""Checkpoints of earlier versions, loaded as the current agent would have saved them (a resumed run continues bit for
bit): a replay buffer of full transitions (observations, masks, states; before :mod:`.transitions`) compacted, one
stored as the filled slots of a ``TensorDict``, and the earlier observation layout (the node positions in every UAV's
observation)."""

from __future__ import annotations

from collections.abc import Callable

import torch
from tensordict import TensorDict
from torchrl.data import TensorDictReplayBuffer

from uavrl.envs import NODE_FEATURES
from uavrl.envs.compat import load_buffer_state

from .transitions import CompactTransitions


def load_replay_buffer(
    buffer: TensorDictReplayBuffer,
    transitions: CompactTransitions,
    state: dict,
    observation_size: int,
    device,
    layouts: Callable[[int], torch.Tensor] | None = None,
    frames: int = 1,
) -> None:
    """Fill ``buffer`` from the checkpoint ``state`` of any version (``state["buffer"]``, and
    ``state["buffer_writes"]`` in the oldest).

    Full transitions are compacted by ``transitions``, the buffer's transform.  With random layouts they kept no nodes:
    ``layouts(k)`` gives iteration ``k``'s ``[W, 4, 3]`` (the layouts its worlds were reset to), ``frames`` the
    transitions an iteration writes; a layout is taken only where its observations and states come out bit for bit
    as stored, and a buffer where one does not is refused in one line.
    """
    saved = state["buffer"] if "buffer_writes" in state else state["buffer"]["_storage"]["_storage"]
    if saved is not None and _holds_observations(saved):
        _nodes_out_of_observation(saved, observation_size)
    if "buffer_writes" in state:  # a checkpoint of an earlier version: the filled slots, in slot order
        data = state["buffer"]
        if data is not None and layouts is not None:
            data = _with_layouts(transitions, data, _writes(len(data), state["buffer_writes"]), layouts, frames)
        _load_filled_slots(buffer, data, state["buffer_writes"], device)
        return
    stored = state["buffer"]["_storage"]
    if _holds_observations(stored["_storage"]):
        full = TensorDict().load_state_dict(stored["_storage"], strict=False)
        if layouts is not None:
            writes = _writes(len(full), state["buffer"]["_writer"]["_write_count"])
            full = _with_layouts(transitions, full, writes, layouts, frames, filled=stored["_len"])
        compact = transitions.inv(full)
        if "index" in full.keys():  # each slot's own index, written by TorchRL's writer beside the transition
            compact.set("index", full.get("index"))
        stored = {**stored, "_storage": compact.state_dict()}
    load_buffer_state(buffer, {**state["buffer"], "_storage": stored})


def _writes(size: int, count: int) -> torch.Tensor:
    """``[size]`` which of ``count`` writes (0, 1, ...) each slot of a ring of ``size`` slots holds now."""
    slots = torch.arange(size)
    return slots + size * ((count - 1 - slots).clamp(min=0) // size)


def _holds_observations(storage) -> bool:
    """Whether a stored buffer holds full transitions (the observations) rather than configurations."""
    holder, key = _stored_entry(storage, ("agents", "observation"))
    return holder.get(key, None) is not None


def _with_layouts(
    transitions: CompactTransitions, full, writes: torch.Tensor, layouts, frames: int, filled: int | None = None
):
    """``full`` with each transition's ``nodes``: of the iteration and world its write index says, checked."""
    filled = len(full) if filled is None else filled
    iterations = writes // frames
    nodes = torch.zeros(len(full), 4, 3, dtype=torch.float64)
    for k in iterations[:filled].unique().tolist():
        here = (iterations == k).nonzero().squeeze(-1)
        here = here[here < filled]
        iteration_layouts = layouts(k).cpu()  # [W, 4, 3]
        steps = frames // len(iteration_layouts)  # a world's transitions of the iteration, in a row
        nodes[here] = iteration_layouts[(writes[here] % frames) // steps]
    full = full.clone(False)
    full.set("nodes", nodes.to(full.device))
    rebuilt = transitions(transitions.inv(full[:filled]))
    for key in (("agents", "observation"), "state", ("next", "agents", "observation"), ("next", "state")):
        if not torch.equal(rebuilt.get(key), full.get(key)[:filled]):
            raise ValueError(
                "this checkpoint's replay buffer (random layouts, written before the buffer kept configurations) "
                "holds transitions of layouts that cannot be recovered, so it cannot be compacted: resume or evaluate "
                "it with the uavrl that wrote it"
            )
    return full


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
