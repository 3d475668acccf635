"""A size-free Q network (``agent.network=set``): the same parameters act for any number of UAVs on any grid.

Each UAV reads only what does not depend on N or the grid: its own cell and task (normalised by the grid), the relay
contributions at its cell and the cells its moves reach, which of those cells another UAV holds, the 4 nodes relative
to it, under an energy model its battery and service flag, and with altitude levels its level, the contributions a
climb and a descent reach (its observation's vertical features) and which of the 6 positions its moves reach another
UAV holds.  One attention layer per ``agent.depth`` lets every UAV read the others: the keys and values are the
others' embeddings and their positions relative to it (by the grid's span, and ``exp(-distance in cells)``, in 3-D
with altitude levels), so the per-UAV values permute with the UAVs.  A shared head turns each
UAV's result into its action values; the team value is their sum (VDN) or mean (``agent.mixer``), so nothing grows
with N.

- :class:`SetQCore`: the parameters (what a checkpoint holds; no size in any shape);
- :class:`SetQNet`: the core acting in one grid (the grid's span and move table beside it, no parameters);
- :class:`SetDoubleQLoss`: the double-DQN loss of the core with its target, one team size at a time.

Example:
    >>> from uavrl.envs import UAVSpectrumEnv
    >>> core = SetQCore(num_actions=6, energy=False, hidden=16, heads=2, depth=1)
    >>> small, large = (UAVSpectrumEnv(batch_size=2, grid=g, num_uavs=n) for g, n in (((6, 6), 2), ((12, 12), 9)))
    >>> [tuple(SetQNet(core, env.cfg.grid)(*(env.reset()[k] for k in Q_INPUTS)).shape) for env in (small, large)]
    [(2, 2, 6), (2, 9, 6)]
"""

from __future__ import annotations

import copy
import math

import torch
from tensordict import TensorDict, TensorDictBase
from torch import nn

from uavrl.envs import UAVSpectrumEnv
from uavrl.envs.limits import (
    NODE_FEATURES,
    OWN_FEATURES,
    PAIR_FEATURES,
    VERTICAL_FEATURES,
    local_set_sizes,
    set_input_size,
)
from uavrl.envs.physics.grid import grid_neighbours
from uavrl.envs.physics.positions import Positions

from .loss import discount
from .networks import LEVELS, Q_INPUTS, HeardMoves, LocalGreedy, PositionIndex, ValidGreedy

MIXERS = ("vdn", "mean")  # the size-free team values: the sum or the mean of the UAVs' chosen values


def _mlp(inputs: int, hidden: int, outputs: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(inputs, hidden), nn.ReLU(), nn.Linear(hidden, outputs))


class RelativeAttention(nn.Module):
    """Multi-head attention of every UAV over the others: logits ``q_i k_j / sqrt(d)`` plus a learned function of
    their relative position, values ``v_j`` plus a linear map of it; a UAV does not attend to itself."""

    def __init__(self, hidden: int, heads: int):
        super().__init__()
        self.heads, self.size = heads, hidden // heads
        self.query, self.key, self.value = (nn.Linear(hidden, hidden) for _ in range(3))
        self.pair_logit = _mlp(PAIR_FEATURES, hidden // 2, heads)
        self.pair_value = nn.Linear(PAIR_FEATURES, hidden, bias=False)
        self.out = nn.Linear(hidden, hidden)

    def forward(self, h: torch.Tensor, pairs: torch.Tensor) -> torch.Tensor:
        """``h`` ``[*, N, H]``, ``pairs`` ``[*, N, N, 3]`` (row i: the others relative to UAV i); ``[*, N, H]``."""
        *batch, N, _ = h.shape

        def split(x):  # [*, N, H] -> [*, heads, N, size]
            return x.view(*batch, N, self.heads, self.size).transpose(-2, -3)

        q, k, v = split(self.query(h)), split(self.key(h)), split(self.value(h))
        logits = q @ k.transpose(-1, -2) / math.sqrt(self.size) + self.pair_logit(pairs).movedim(-1, -3)
        itself = torch.eye(N, dtype=torch.bool, device=h.device)
        weights = logits.masked_fill(itself, -math.inf).softmax(-1)  # [*, heads, N, N]
        mixed = (weights @ v).transpose(-2, -3).reshape(*batch, N, -1)  # sum_j w_ij v_j
        # sum_j w_ij W pair_ij, each head's weights on its own slice of W pair_ij
        relative = self.pair_value(pairs).view(*batch, N, N, self.heads, self.size)
        mixed = mixed + torch.einsum("...hij,...ijhs->...ihs", weights, relative).reshape(*batch, N, -1)
        return self.out(mixed)


class SetQCore(nn.Module):
    """The size-free parameters: an encoder of each UAV's own features, ``depth`` attention layers over the others,
    a head of ``num_actions`` values per UAV (inputs: :meth:`SetQNet.features`)."""

    def __init__(self, num_actions: int, energy: bool, hidden: int, heads: int, depth: int, levels: bool = False):
        super().__init__()
        self.energy, self.levels = energy, levels
        self.encode = _mlp(set_input_size(energy, levels), hidden, hidden)
        self.attention = nn.ModuleList(RelativeAttention(hidden, heads) for _ in range(depth))
        self.feed = nn.ModuleList(_mlp(hidden, hidden, hidden) for _ in range(depth))
        self.head = _mlp(2 * hidden, hidden, num_actions)  # the UAV's result and the team's mean

    def forward(self, own: torch.Tensor, pairs: torch.Tensor) -> torch.Tensor:
        h = self.encode(own)
        if own.shape[-2] > 1:  # a lone UAV has no one to attend to
            for attention, feed in zip(self.attention, self.feed, strict=True):
                h = h + torch.relu(attention(h, pairs))
                h = h + torch.relu(feed(h))
        return self.head(torch.cat([h, h.mean(-2, keepdim=True).expand_as(h)], -1))


class SetQNet(nn.Module):
    """:class:`SetQCore` acting in a ``grid``: reads ``Q_INPUTS`` (observation, positions, state; then the levels
    with altitude levels) of any number of UAVs, returns ``[*, N, A]``.  Holds no parameters of its own: views of one
    core in several grids (and cities) share them.

    Args:
        core: the parameters.
        grid: ``(L1, L2)``.
        positions: with altitude levels, the model's positions (``World.dynamics.positions``: its moves, its
            buildings); None with one level.
    """

    def __init__(self, core: SetQCore, grid: tuple[int, int], positions: Positions | None = None):
        super().__init__()
        self.core, self.grid, self.positions = core, tuple(grid), positions
        L1, L2 = self.grid
        device = next(core.parameters()).device
        if (positions is not None) != core.levels:
            raise ValueError("SetQNet: give the model's positions exactly for a core of altitude levels")
        if positions is None:
            self.register_buffer("neighbours", grid_neighbours(self.grid, device), persistent=False)
            self.position = PositionIndex(self.grid)
        else:
            self.register_buffer("neighbours", positions.neighbours.to(device), persistent=False)
            self.position = PositionIndex(self.grid, positions.number.to(device).view(-1, L1 * L2))
            # each position's height in cells: the vertical part of the distance between two UAVs
            self.register_buffer("heights", positions.xyz[:, 2].to(device, torch.float32), persistent=False)
        self.register_buffer(
            "span", torch.tensor([max(L1 - 1, 1), max(L2 - 1, 1)], dtype=torch.float32, device=device), False
        )
        self.register_buffer("size", torch.tensor([L1, L2], dtype=torch.float32, device=device), False)

    def features(self, observation, positions, state, levels=None) -> tuple[torch.Tensor, torch.Tensor]:
        """``(own [*, N, F], pairs [*, N, N, 3])``: what the core reads, none of it sized by N or the grid."""
        N = positions.shape[-2]
        xy = positions.to(self.span.dtype)
        C = len(self.neighbours)
        cells = self.position(positions, levels)
        # which of the positions its moves reach another UAV holds (none, for a UAV out of service)
        held = (self.neighbours[cells.clamp(max=C - 1)].unsqueeze(-1) == cells[..., None, None, :]).any(-1)
        held &= (cells < C).unsqueeze(-1)
        nodes = state[..., -NODE_FEATURES:].unflatten(-1, (4, 3))  # (x / L1, y / L2, z / h) of PT, PR, S, E
        towards = (nodes[..., None, :, :2] * self.size - xy[..., None, :]) / self.span  # [*, N, 4, 2]
        heights = nodes[..., None, :, 2:].expand(*towards.shape[:-1], 1)
        parts = [observation[..., :OWN_FEATURES], torch.cat([towards, heights], -1).flatten(-2), held.to(xy.dtype)]
        if (
            self.core.energy
        ):  # its battery and service flag follow the others' (x, y, task) (envs/world/observations.py)
            start = OWN_FEATURES + 3 * (N - 1)
            parts.append(observation[..., start : start + 2])
        offsets = xy[..., None, :, :] - xy[..., :, None, :]  # [*, N, N, 2]: row i, UAV j relative to UAV i
        if self.positions is None:
            proximity = torch.exp(-offsets.norm(dim=-1, keepdim=True))
        else:  # its own level and what a climb and a descent reach: the observation's vertical features
            start = observation.shape[-1] - (VERTICAL_FEATURES + N - 1)  # the others' levels follow them
            parts.append(observation[..., start : start + VERTICAL_FEATURES])
            height = self.heights[cells]
            rise = (height[..., None, :] - height[..., :, None]).unsqueeze(-1)
            proximity = torch.exp(-torch.cat([offsets, rise], -1).norm(dim=-1, keepdim=True))
        return torch.cat(parts, -1), torch.cat([offsets / self.span, proximity], -1)

    def forward(self, observation, positions, state, levels=None) -> torch.Tensor:
        return self.core(*self.features(observation, positions, state, levels))

    def acting(self, core: SetQCore) -> SetQNet:
        """A view of ``core`` (the target's) in this one's grid and positions."""
        return SetQNet(core, self.grid, self.positions)

    def greedy_rule(self, num_actions: int) -> tuple[ValidGreedy, list]:
        """The loss's rule for the next greedy action and what it reads after the values and the mask."""
        greedy = ValidGreedy(self.neighbours, self.grid[0], num_actions, self.position.numbers)
        return greedy, ["positions", "tasks", *self.in_keys[len(Q_INPUTS) :]]  # and the levels

    @property
    def in_keys(self) -> list:
        """What it reads, in order: :data:`Q_INPUTS`, then the levels with altitude levels."""
        return [*Q_INPUTS, LEVELS] if self.positions is not None else list(Q_INPUTS)


class LocalSetQCore(nn.Module):
    """The size-free parameters on local observations (``env.observation=local``): an encoder of each UAV's own input
    (what it senses and the nodes it hears, :func:`~uavrl.envs.limits.local_set_sizes`), ``depth`` rounds of
    attention over the UAVs it hears, whose keys and values come from what it hears of each (never from another UAV's
    own observation), and a head of ``num_actions`` values: a UAV's values change only with what it observes."""

    def __init__(self, num_actions: int, energy: bool, hidden: int, heads: int, depth: int, levels: bool = False):
        super().__init__()
        self.energy, self.levels, self.heads, self.size = energy, levels, heads, hidden // heads
        own, heard = local_set_sizes(energy, levels)
        self.encode, self.heard = _mlp(own, hidden, hidden), _mlp(heard, hidden, hidden)
        self.query, self.key, self.value, self.out = (
            nn.ModuleList(nn.Linear(hidden, hidden) for _ in range(depth)) for _ in range(4)
        )
        self.feed = nn.ModuleList(_mlp(hidden, hidden, hidden) for _ in range(depth))
        self.head = _mlp(2 * hidden, hidden, num_actions)  # the UAV's result and its own encoding

    def forward(self, own: torch.Tensor, others: torch.Tensor, heard: torch.Tensor) -> torch.Tensor:
        """``own`` ``[*, N, F]``, ``others`` ``[*, N, N - 1, G]`` and ``heard`` ``[*, N, N - 1]`` (row i: the UAVs
        UAV i hears); ``[*, N, A]``."""
        mine = h = self.encode(own)
        if others.shape[-2]:  # a lone UAV hears no one
            slots = self.heard(others)
            unheard = ~heard.unsqueeze(-2)  # [*, N, 1, N - 1]
            alone = ~heard.any(-1)[..., None, None]  # [*, N, 1, 1]: a UAV that hears no one attends to nothing
            for query, key, value, out, feed in zip(self.query, self.key, self.value, self.out, self.feed, strict=True):
                q = query(h).unflatten(-1, (self.heads, self.size))  # [*, N, heads, size]
                k, v = (layer(slots).unflatten(-1, (self.heads, self.size)) for layer in (key, value))
                logits = torch.einsum("...nhs,...nkhs->...nhk", q, k) / math.sqrt(self.size)
                # finite logits where no one is heard, then zero weights: no NaN forward or backward
                weights = (
                    logits.masked_fill(unheard, -math.inf).masked_fill(alone, 0.0).softmax(-1).masked_fill(alone, 0)
                )
                h = h + torch.relu(out(torch.einsum("...nhk,...nkhs->...nhs", weights, v).flatten(-2)))
                h = h + torch.relu(feed(h))
        return self.head(torch.cat([h, mine], -1))


class LocalSetQNet(nn.Module):
    """:class:`LocalSetQCore` acting in one model's environment: reads each UAV's local observation ``[*, N, F]``
    alone (the slots parsed by :class:`~.networks.HeardMoves`), returns ``[*, N, A]``.  Holds no parameters of its
    own: views of one core in several grids share them.

    Args:
        core: the parameters.
        held: the model's slot reader (``HeardMoves(env)``).
    """

    def __init__(self, core: LocalSetQCore, held: HeardMoves):
        super().__init__()
        self.core, self.held = core, held

    @classmethod
    def of(cls, core: LocalSetQCore, env: UAVSpectrumEnv) -> LocalSetQNet:
        return cls(core, HeardMoves(env))

    def features(self, observation: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(own, others, heard)``: what the core reads, none of it sized by N or the grid."""
        held = self.held
        slots, (offset, heard) = held.slots(observation), held.offsets(observation)  # offsets in cells and levels
        own = torch.cat([observation[..., : held.own], held.reached(offset, heard).to(observation.dtype)], -1)
        span = [slots[..., :2]] + ([slots[..., held.level_entry : held.level_entry + 1]] if held.levels else [])
        proximity = torch.exp(-offset.norm(dim=-1, keepdim=True))
        energy = [slots[..., 4:6]] if self.core.energy else []  # its battery and service flag: after (dx, dy, task, 1)
        others = torch.cat([*span, proximity, slots[..., 2:3], *energy], -1)
        return own, others, heard.squeeze(-1)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return self.core(*self.features(observation))

    def acting(self, core: LocalSetQCore) -> LocalSetQNet:
        """A view of ``core`` (the target's) in this one's model."""
        return LocalSetQNet(core, self.held)

    def greedy_rule(self, num_actions: int) -> tuple[LocalGreedy, list]:
        """The loss's rule for the next greedy action (each UAV by its own values) and what it reads."""
        return LocalGreedy(self.held), [("agents", "observation")]

    @property
    def in_keys(self) -> list:
        return [("agents", "observation")]


def team_value(chosen: torch.Tensor, mixer: str) -> torch.Tensor:
    """``[*, 1]`` the team value of the UAVs' chosen values ``[*, N, 1]``: their sum (``vdn``) or mean."""
    return chosen.sum(-2) if mixer == "vdn" else chosen.mean(-2)


class SetDoubleQLoss(nn.Module):
    """The factored head's double-DQN loss (as :class:`~.loss.DoubleQMixerLoss`) for a size-free core.

    ``y = r + gamma^n (1 - terminated) Mix(Q_target(s', a'))`` (``n``: the steps an n-step reward sums) where the
    online core's :class:`ValidGreedy` picks the valid joint action ``a'``; the loss is the Huber distance to
    ``Mix(Q(s, a))``.  ``Mix`` is the sum or mean of :func:`team_value`, so one loss module serves every team size,
    grid and city (``online``: the core's view in the batch's, :meth:`SetNetwork.values`).
    """

    def __init__(self, core: SetQCore, mixer: str, gamma: float, num_actions: int):
        super().__init__()
        self.core, self.mixer, self.gamma, self.num_actions = core, mixer, gamma, num_actions
        self.target = copy.deepcopy(core).requires_grad_(False)
        self._views: dict = {}

    def _target_and_greedy(self, online: SetQNet | LocalSetQNet) -> tuple:
        if online not in self._views:
            self._views[online] = (online.acting(self.target), *online.greedy_rule(self.num_actions))
        return self._views[online]

    def forward(self, td: TensorDictBase, online: SetQNet | LocalSetQNet) -> TensorDictBase:
        target, greedy, where = self._target_and_greedy(online)
        nxt, inputs = td.get("next"), online.in_keys
        chosen = online(*(td.get(k) for k in inputs)).gather(-1, td.get(("agents", "action")).unsqueeze(-1))
        value = team_value(chosen, self.mixer)
        with torch.no_grad():
            next_values = online(*(nxt.get(k) for k in inputs))
            action = greedy(next_values, nxt.get(("agents", "action_mask")), *(nxt.get(k) for k in where))
            next_value = team_value(target(*(nxt.get(k) for k in inputs)).gather(-1, action.unsqueeze(-1)), self.mixer)
            y = nxt.get("reward") + discount(td, self.gamma) * (~nxt.get("terminated")) * next_value
        return TensorDict({"loss": nn.functional.smooth_l1_loss(value, y)})

    @torch.no_grad()
    def update_target(self, tau: float) -> None:
        """Soft update: ``target <- (1 - tau) target + tau online``."""
        torch._foreach_lerp_(list(self.target.parameters()), list(self.core.parameters()), tau)
