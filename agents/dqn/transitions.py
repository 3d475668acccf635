"""The replay buffer's transitions kept compact: configurations, not observations.

A transition the loss reads holds, twice (now and ``"next"``), every UAV's
observation, action mask, position and task and the world's state: about 2 kB
for 6 UAVs on 10x10, 4 kB for 10 on 20x20.  All of it follows from the
configuration (each UAV's code ``2 cell + task``), under an energy model the
UAVs' battery and service flags, and with random layouts the layout's nodes.
:class:`CompactTransitions`, a TorchRL ``Transform`` of the replay buffer,
keeps only those (with the actions, the reward and the done flags) when the
buffer is extended, and rebuilds the full transitions with the World's own
:meth:`~uavrl.envs.world.World.configurations` when it is sampled or read:
the same tensors, bit for bit, at a tenth of the memory or less (BENCHMARKS.md).  With altitude levels a code's
cell is the UAV's position (its cell at its level).

Example:
    >>> import torch
    >>> from uavrl.envs import UAVSpectrumEnv
    >>> env = UAVSpectrumEnv(batch_size=4, grid=(4, 4), num_uavs=3, max_steps=5)
    >>> full = env.rollout(5).reshape(-1)
    >>> compact = CompactTransitions(env.world, [("agents", "action")])
    >>> keys = transition_keys(env.world, [("agents", "action")])
    >>> stored = compact.inv(full.select(*keys))
    >>> sorted(stored.keys()), stored["code"].dtype
    (['action', 'code', 'next'], torch.int16)
    >>> (compact(stored) == full.select(*keys)).all()
    True
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data.postprocs import MultiStep
from torchrl.envs import Transform

from uavrl.envs.world import World

from .networks import LEVELS, PositionIndex, position_numbers

_OBSERVED = [("agents", "observation"), ("agents", "action_mask"), "positions", "tasks", "state"]
_OUTCOME = ["reward", "done", "terminated"]  # of "next", stored as they are
_PREVIOUS = ["heard_messages", "previous_code", "previous_heard", "has_previous"]  # CompactTransitions.with_previous
STEPS = "steps_to_next_obs"  # n-step returns: the steps a reward sums (TorchRL's key, its losses read it)


def transition_keys(world: World, action_keys: list, n_step: int = 1) -> list:
    """The entries of a full transition (what the loss reads), ``"levels"`` with altitude levels, ``"nodes"`` with
    random layouts, ``"steps_to_next_obs"`` with n-step returns (``n_step > 1``), and with messages what
    :meth:`CompactTransitions.with_previous` adds."""
    observed = _observed(world)
    layout = ["nodes"] if world.layouts.fixed is None else []
    steps = [STEPS] if n_step > 1 else []
    heard = [("agents", "message"), *_PREVIOUS] if world.cfg.message_size else []
    energy = ["previous_energy"] if heard and world.energy is not None else []
    return observed + layout + steps + action_keys + heard + energy + [("next", k) for k in observed + _OUTCOME]


def _observed(world: World) -> list:
    """What a step observes: :data:`_OBSERVED`, and each UAV's level with altitude levels."""
    return _OBSERVED + ([LEVELS] if world.cfg.num_levels > 1 else [])


def n_step_returns(episodes: TensorDictBase, n_step: int, gamma: float) -> TensorDictBase:
    """``[W, T]`` episodes with n-step returns (TorchRL's ``MultiStep``): each step's reward the discounted sum of up to
    ``n_step`` rewards within its episode, ``"next"`` the state after the last of them, ``"steps_to_next_obs"`` how many
    they are (the target discounts by ``gamma`` to that power), and ``("next", "terminated")`` that last step's.
    ``n_step=1``: ``episodes`` as they are.

    Example:
        >>> from tensordict import TensorDict
        >>> T = 4
        >>> episodes = TensorDict({"x": torch.arange(T)[None, :, None], "next": {
        ...     "x": torch.arange(1, T + 1)[None, :, None], "reward": torch.ones(1, T, 1),
        ...     "done": (torch.arange(T) == T - 1)[None, :, None], "terminated": torch.zeros(1, T, 1, dtype=bool)}},
        ...     batch_size=[1, T])
        >>> out = n_step_returns(episodes, 2, 0.5)
        >>> out["next", "reward"].flatten().tolist(), out["next", "x"].flatten().tolist()
        ([1.5, 1.5, 1.5, 1.0], [2, 3, 4, 4])
        >>> out["steps_to_next_obs"].flatten().tolist()
        [2, 2, 2, 1]
    """
    if n_step == 1:
        return episodes
    out = MultiStep(gamma, n_step)(episodes)
    steps = out.get(STEPS)
    last = torch.arange(episodes.shape[-1], device=steps.device) + steps - 1  # the step whose successor "next" now is
    terminated = episodes.get(("next", "terminated"))  # MultiStep leaves the done flags where they were
    out.set(("next", "terminated"), terminated.gather(1, last.unsqueeze(-1).expand_as(terminated)))
    return out.exclude("gamma", "nonterminal", ("next", "original_reward"))


class CompactTransitions(Transform):
    """Transitions ``[B]`` kept as configurations: ``inv`` compacts (the buffer's ``extend``), the call rebuilds
    (its ``sample`` and indexing) with ``world`` (the training env's: its grid, its fixed layout's tables).

    Kept per transition: ``code`` and ``("next", "code")`` ``[N]`` (int16 while the codes fit), under an energy
    model ``energy`` and ``("next", "energy")`` ``[N, 2]`` float32 (:meth:`World.energy_features`), with random
    layouts ``nodes`` ``[4, 3]`` float64 (a step keeps its layout), the actions (``action`` ``[N]`` int8;
    ``joint_action`` int16 for the joint head), with n-step returns ``"steps_to_next_obs"`` (int8, wider where
    ``n_step`` and the episode both exceed 127 steps), and ``reward``, ``done``, ``terminated`` of ``"next"``.

    Args:
        world: the training env's :class:`~uavrl.envs.World`.
        action_keys: the action entries a transition stores (``Policies.action_keys``: ``("agents", "action")``,
            and ``"joint_action"`` for the joint head).
        n_step: the n-step returns' horizon: a transition's ``"steps_to_next_obs"`` is at most it and the episode's
            length.
    """

    def __init__(self, world: World, action_keys: list, n_step: int = 1):
        super().__init__(in_keys=[], out_keys=[])
        self.world = world
        self.position = PositionIndex(world.cfg.grid, position_numbers(world))  # a code's cell: its position
        self.joint = "joint_action" in action_keys
        self.code_dtype = torch.int16 if 2 * world.dynamics.slots <= torch.iinfo(torch.int16).max else torch.int32
        longest = min(n_step, world.cfg.max_steps)
        self.steps_dtype = next(d for d in (torch.int8, torch.int16, torch.int32) if longest <= torch.iinfo(d).max)

    def with_previous(self, episodes: TensorDictBase) -> TensorDictBase:
        """``[W, T]`` episodes (each from a reset), with messages (``env.message_size``) given what their transitions'
        messages are rebuilt from: ``heard_messages`` (those sent a step before, which each observation shows),
        ``previous_code``, ``previous_heard`` and under an energy model ``previous_energy`` (the step before's
        configuration and the messages it showed: the senders' previous observations, from which the loss sends the
        messages again) and ``has_previous`` (False at an episode's first step); without messages, as they are."""
        if not self.world.cfg.message_size:
            return episodes

        def before(x: torch.Tensor) -> torch.Tensor:  # each step's value at the step before (zeros at the first)
            return torch.cat([torch.zeros_like(x[:, :1]), x[:, :-1]], 1)

        heard = before(episodes.get(("agents", "message")))
        code = 2 * self.position(episodes.get("positions"), episodes.get(LEVELS, None)) + episodes.get("tasks")
        W, T = episodes.batch_size
        episodes.set("heard_messages", heard)
        episodes.set("previous_heard", before(heard))
        episodes.set("previous_code", before(code))
        episodes.set("has_previous", (torch.arange(T, device=code.device) > 0).expand(W, T))
        if self.world.energy is not None:
            episodes.set("previous_energy", before(self.world.energy_features(episodes.get("state"))))
        return episodes

    def _inv_call(self, td: TensorDictBase) -> TensorDictBase:
        world = self.world
        stored = {"action": td.get(("agents", "action")).to(torch.int8)}
        if world.cfg.message_size:  # the messages each observation shows, and the step before's configuration
            stored.update(messages=td.get("heard_messages"), has_previous=td.get("has_previous"))
            stored.update(previous_code=td.get("previous_code").to(self.code_dtype))
            stored.update(previous_messages=td.get("previous_heard"))
            if world.energy is not None:
                stored["previous_energy"] = td.get("previous_energy")
        if self.joint:
            stored["joint_action"] = td.get("joint_action").to(torch.int16)
        if world.layouts.fixed is None:
            stored["nodes"] = td.get("nodes")
        if STEPS in td.keys():
            stored[STEPS] = td.get(STEPS).to(self.steps_dtype)
        nxt = {key: td.get(("next", key)) for key in _OUTCOME}
        if world.cfg.message_size:  # what the next observation shows: the messages sent at this step
            nxt["messages"] = td.get(("agents", "message"))
        for holder, step in ((stored, td), (nxt, td.get("next"))):
            code = 2 * self.position(step.get("positions"), step.get(LEVELS, None)) + step.get("tasks")
            holder["code"] = code.to(self.code_dtype)
            if world.energy is not None:
                holder["energy"] = world.energy_features(step.get("state")).contiguous()
        stored["next"] = TensorDict(nxt, batch_size=td.batch_size, device=td.device)
        return TensorDict(stored, batch_size=td.batch_size, device=td.device)

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        """The full transitions of the compact ones ``td``, as they were collected."""
        B, nxt = td.batch_size[0], td.get("next")

        def both(key):  # now and next, rebuilt in one call
            return torch.cat([td.get(key), nxt.get(key)])

        world, messages = self.world, self.world.cfg.message_size
        energy = both("energy") if world.energy is not None else None
        nodes = td.get("nodes") if world.layouts.fixed is None else None
        nodes_twice = None if nodes is None else nodes.repeat(2, 1, 1)
        out = world.configurations(both("code").long(), energy, nodes_twice, both("messages") if messages else None)
        now, after = ({key: value[i * B : (i + 1) * B] for key, value in out.items()} for i in (0, 1))
        observed = now["observation"]
        full = self._step(now, B, td.device)
        full.get("agents").set("action", td.get("action").long())
        if self.joint:
            full.set("joint_action", td.get("joint_action").long())
        if nodes is not None:
            full.set("nodes", nodes)
        if STEPS in td.keys():
            full.set(STEPS, td.get(STEPS).long())
        following = self._step(after, B, td.device)
        for key in _OUTCOME:
            following.set(key, nxt.get(key))
        if messages:  # the observations the messages heard were sent from: the step before's, and this one
            energy = td.get("previous_energy") if world.energy is not None else None
            previous = world.configurations(td.get("previous_code").long(), energy, nodes, td.get("previous_messages"))
            full.get("agents").set("previous", previous["observation"])
            full.set("has_previous", td.get("has_previous"))
            following.get("agents").set("previous", observed)
            following.set("has_previous", torch.ones_like(td.get("has_previous")))
        full.set("next", following)
        return full

    @staticmethod
    def _step(out: dict, B: int, device) -> TensorDict:
        agents = {"observation": out.pop("observation"), "action_mask": out.pop("action_mask")}
        N = agents["observation"].shape[1]
        out["agents"] = TensorDict(agents, batch_size=(B, N), device=device)
        return TensorDict(out, batch_size=(B,), device=device)
