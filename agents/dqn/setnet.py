"""A size-free Q network (``agent.network=set``): the same parameters act for any number of UAVs on any grid.

Each UAV reads only what does not depend on N or the grid: its own cell and task (normalised by the grid), the relay
contributions at its cell and the cells its moves reach, which of those cells another UAV holds, the 4 nodes relative
to it, and under an energy model its battery and service flag.  One attention layer per ``agent.depth`` lets every
UAV read the others: the keys and values are the others' embeddings and their positions relative to it (by the
grid's span, and ``exp(-distance in cells)``), so the per-UAV values permute with the UAVs.  A shared head turns each
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

from uavrl.envs.limits import NODE_FEATURES, OWN_FEATURES, PAIR_FEATURES, set_input_size
from uavrl.envs.physics.grid import cells_or_away, grid_neighbours

from .loss import discount
from .networks import Q_INPUTS, ValidGreedy

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

    def __init__(self, num_actions: int, energy: bool, hidden: int, heads: int, depth: int):
        super().__init__()
        self.energy = energy
        self.encode = _mlp(set_input_size(energy), hidden, hidden)
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
    """:class:`SetQCore` acting in a ``grid``: reads ``Q_INPUTS`` (observation, positions, state) of any number of
    UAVs, returns ``[*, N, A]``.  Holds no parameters of its own: views of one core in several grids share them."""

    def __init__(self, core: SetQCore, grid: tuple[int, int]):
        super().__init__()
        self.core, self.grid = core, tuple(grid)
        L1, L2 = self.grid
        device = next(core.parameters()).device
        self.register_buffer("neighbours", grid_neighbours(self.grid, device), persistent=False)
        self.register_buffer(
            "span", torch.tensor([max(L1 - 1, 1), max(L2 - 1, 1)], dtype=torch.float32, device=device), False
        )
        self.register_buffer("size", torch.tensor([L1, L2], dtype=torch.float32, device=device), False)

    def features(self, observation, positions, state) -> tuple[torch.Tensor, torch.Tensor]:
        """``(own [*, N, F], pairs [*, N, N, 3])``: what the core reads, none of it sized by N or the grid."""
        N = positions.shape[-2]
        xy = positions.to(self.span.dtype)
        C = len(self.neighbours)
        cells = cells_or_away(positions, self.grid)
        # which of its neighbouring cells another UAV holds (none, for a UAV out of service)
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
        proximity = torch.exp(-offsets.norm(dim=-1, keepdim=True))
        return torch.cat(parts, -1), torch.cat([offsets / self.span, proximity], -1)

    def forward(self, observation, positions, state) -> torch.Tensor:
        return self.core(*self.features(observation, positions, state))


def team_value(chosen: torch.Tensor, mixer: str) -> torch.Tensor:
    """``[*, 1]`` the team value of the UAVs' chosen values ``[*, N, 1]``: their sum (``vdn``) or mean."""
    return chosen.sum(-2) if mixer == "vdn" else chosen.mean(-2)


class SetDoubleQLoss(nn.Module):
    """The factored head's double-DQN loss (as :class:`~.loss.DoubleQMixerLoss`) for a size-free core.

    ``y = r + gamma^n (1 - terminated) Mix(Q_target(s', a'))`` (``n``: the steps an n-step reward sums) where the
    online core's :class:`ValidGreedy` picks the valid joint action ``a'``; the loss is the Huber distance to
    ``Mix(Q(s, a))``.  ``Mix`` is the sum or mean of :func:`team_value`, so one loss module serves every team size
    and grid (``grid``: the batch's).
    """

    def __init__(self, core: SetQCore, mixer: str, gamma: float, num_actions: int):
        super().__init__()
        self.core, self.mixer, self.gamma, self.num_actions = core, mixer, gamma, num_actions
        self.target = copy.deepcopy(core).requires_grad_(False)
        self._grids: dict = {}

    def _views(self, grid) -> tuple[SetQNet, SetQNet, ValidGreedy]:
        if grid not in self._grids:
            online = SetQNet(self.core, grid)
            self._grids[grid] = (
                online,
                SetQNet(self.target, grid),
                ValidGreedy(online.neighbours, grid[0], self.num_actions),
            )
        return self._grids[grid]

    def forward(self, td: TensorDictBase, grid: tuple[int, int]) -> TensorDictBase:
        online, target, greedy = self._views(tuple(grid))
        nxt = td.get("next")
        chosen = online(*(td.get(k) for k in Q_INPUTS)).gather(-1, td.get(("agents", "action")).unsqueeze(-1))
        value = team_value(chosen, self.mixer)
        with torch.no_grad():
            next_values = online(*(nxt.get(k) for k in Q_INPUTS))
            action = greedy(next_values, nxt.get(("agents", "action_mask")), nxt.get("positions"), nxt.get("tasks"))
            next_value = team_value(
                target(*(nxt.get(k) for k in Q_INPUTS)).gather(-1, action.unsqueeze(-1)), self.mixer
            )
            y = nxt.get("reward") + discount(td, self.gamma) * (~nxt.get("terminated")) * next_value
        return TensorDict({"loss": nn.functional.smooth_l1_loss(value, y)})

    @torch.no_grad()
    def update_target(self, tau: float) -> None:
        """Soft update: ``target <- (1 - tau) target + tau online``."""
        torch._foreach_lerp_(list(self.target.parameters()), list(self.core.parameters()), tau)
