"""Coordination on common knowledge: where every UAV hears every other UAV, each one plays its own part of
the one valid joint action that every UAV computes alike from what it hears (docs/model.md, Local observations and
messages).

UAVs acting on their own greedy values clash: two that move into one free cell are both cancelled, and each clash
costs the team a step (:class:`~uavrl.agents.dqn.networks.YieldToContenders` breaks the tie after it). Where every
UAV hears every other (``env.comm_radius`` null, or at least the grid's diagonal) and without messages, a UAV's
local observation holds its own cell and task and every other UAV's, relative to it: the team's configuration, which
every UAV therefore knows, and knows that the others know. From its own observation alone, UAV ``i`` rebuilds every
UAV's local observation (the model's observation of that configuration,
:meth:`~uavrl.envs.world.World.configurations`: a fixed layout's nodes and mean channels are part of the model),
values each with the team's shared network, and picks the valid joint action the central greedy rule would
(:class:`~uavrl.agents.dqn.networks.ValidGreedy`, UAV by UAV in id order). Every UAV computes the same joint action,
so no two moves clash, and each plays its own entry. This is how MACKRL (Schroeder de Witt et al., NeurIPS 2019)
coordinates a team's actions: on what every member knows that every member knows.

The rule needs no message and reads nothing but the UAV's own observation (a test perturbs every other UAV's
observation and checks that a UAV's action does not change).  Each UAV values the whole team it rebuilds, ``N``
times the central greedy step's valuations (BENCHMARKS.md, The price of decentralisation, times a greedy pass).
"""

from __future__ import annotations

import torch
from torch import nn

from uavrl.envs import UAVSpectrumEnv, World
from uavrl.envs.limits import OWN_FEATURES
from uavrl.envs.physics.sensing import LOCAL_NODE_FEATURES, common_knowledge

from .networks import ValidGreedy, position_numbers


class CommonKnowledgeGreedy(nn.Module):
    """Each UAV's part ``[*, N]`` of the valid joint action every UAV computes from its own local observation
    ``[*, N, F]`` where the model's :func:`~uavrl.envs.physics.sensing.common_knowledge` holds: the team's
    configuration rebuilt from it, every UAV's observation and values (``q``: the team's shared network, observations
    ``[W, N, F]`` to values ``[W, N, A]``) and :class:`~uavrl.agents.dqn.networks.ValidGreedy` over them.  Elsewhere
    (a policy bound to an environment where it does not hold: :meth:`bind`) the actions it is handed pass through.

    Args:
        q: the local network (``LocalQNet``), read at each call.
        env: the environment it acts in (:meth:`bind`).

    Example:
        >>> from uavrl.envs import UAVSpectrumEnv
        >>> env = UAVSpectrumEnv(batch_size=1, grid=(3, 1), num_uavs=2, observation="local", seed=0)
        >>> everyone_right = lambda observation: torch.tensor([0, 0, 0, 9.0, 0, 0]).expand(*observation.shape[:-1], 6)
        >>> greedy = CommonKnowledgeGreedy(everyone_right, env)
        >>> out = env.reset()
        >>> stay = torch.tensor([[4, 4]])  # what a UAV would do on its own values
        >>> out["positions"].tolist(), greedy(out["agents", "observation"], stay).tolist()
        ([[[1, 0], [0, 0]]], [[3, 3]])
    """

    def __init__(self, q, env: UAVSpectrumEnv):
        super().__init__()
        object.__setattr__(self, "q", q)  # read, not owned: its parameters are the Q network's, saved there
        self.bind(env)

    def bind(self, env: UAVSpectrumEnv) -> None:
        """Act in ``env``: where its model is common knowledge, the model's observations of any configuration (a
        World of it), its greedy rule and the layout of a local observation; elsewhere, pass the actions through."""
        cfg, N, device = env.cfg, env.num_uavs, env.device
        self.world = World(cfg, 1, device) if common_knowledge(cfg) else None
        if self.world is None:
            return
        self.greedy = ValidGreedy(env.neighbours, cfg.grid[0], env.num_actions, position_numbers(env.world))
        self.width, self.own = cfg.grid[0], OWN_FEATURES + LOCAL_NODE_FEATURES  # then (dx, dy, task, heard) per UAV
        self.scale = torch.tensor([max(cfg.grid[0] - 1, 1), max(cfg.grid[1] - 1, 1)], device=device)
        # slot k of UAV i holds UAV (i + k + 1) mod N (physics.sensing): order[i, j] is UAV j's entry in UAV i's view
        ids = torch.arange(N, device=device)
        self.order = (ids - ids[:, None]) % N

    def forward(self, observation: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        if self.world is None:
            return action
        *batch, N, _ = observation.shape
        view = observation.reshape(-1, N, observation.shape[-1])  # [W, N, F]: row i is UAV i's observation
        own = view[..., :3]
        slots = view[..., self.own :].unflatten(-1, (N - 1, 4))
        # each UAV's view of the team, itself first, then the others in slot order: (x, y) in cells and task
        xy = torch.cat([own[..., None, :2], own[..., None, :2] + slots[..., :2]], -2) * self.scale
        task = torch.cat([own[..., None, 2], slots[..., 2]], -1)
        code = 2 * (xy[..., 0].round() + self.width * xy[..., 1].round()) + task.round()  # [W, N, N], its view
        team = code.long().gather(-1, self.order.expand(len(view), N, N))  # [W, i, j]: UAV j as UAV i sees it
        rebuilt = self.world.configurations(team.view(-1, N))  # [W N, N, ...]: the team as each UAV sees it
        values = self.q(rebuilt["observation"])
        joint = self.greedy(values, rebuilt["action_mask"], rebuilt["positions"], rebuilt["tasks"]).view(-1, N, N)
        return joint.diagonal(dim1=-2, dim2=-1).reshape(*batch, N)  # UAV i plays its own entry of its joint action
