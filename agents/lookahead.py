"""Lookahead at evaluation time (``eval.lookahead=k``): a depth-``k`` search over joint actions through the World's
own deterministic model, scored by a Q-network agent's learned team value at the leaves.

At each node (one configuration of one world) the candidates are the joint actions the learned values rank best:
every joint action the UAVs' masks allow where there are at most :data:`MAX_ENUMERATED` of them (N <= 4), else the
greedy valid joint action (:class:`~uavrl.agents.dqn.networks.ValidGreedy`) and every joint action that changes one
UAV's action in it.  The ``eval.lookahead_width`` best by the learned team value ``Mix_i Q_i(s, a_i)`` (0: all) are
played through the model: the dynamics part of the World (:mod:`uavrl.envs.physics.dynamics`, the environment's own
step, collisions resolved as there) and the mean-channel rates (:mod:`uavrl.envs.physics.channel`).  A candidate's
score is ``r(s, a) + gamma V(s')``, with ``r`` the agent's own objective (``log_gap``: the change of
``-log(1 - U / U* + agent.gap_floor)``, U* solved for the layout; ``delta``: the change of U) and ``gamma``
``agent.gamma``; ``V(s')`` is the best score of ``s'``'s candidates one level deeper, and at depth ``k`` the learned
team value of the greedy valid joint action.  The root plays its best candidate.  Depth 1 with the true values is
the one-step optimum; with learned values it corrects the greedy rule where the model shows a better step.

It needs the model: the oracle's knowledge of the channel and the layout (which the greedy policy does not use), and
costs one evaluation of the network per candidate and level: ``eval/lookahead_cpu_s_per_step``, the policy's CPU
seconds per world and step, is reported beside its gain.

Example:
    >>> from uavrl.envs import UAVSpectrumEnv, make_config
    >>> from uavrl.agents.dqn.setnet import SetQCore, SetQNet
    >>> cfg = make_config("paper", grid=(4, 4), num_uavs=2)
    >>> core = SetQCore(num_actions=6, energy=False, hidden=16, heads=2, depth=1)
    >>> policy = LookaheadPolicy(SetQNet(core, cfg.grid), "mean", cfg, depth=1, width=4, gamma=0.7)
    >>> env = UAVSpectrumEnv(batch_size=3, config=cfg)
    >>> tuple(policy(env.reset())["agents", "action"].shape)
    (3, 2)
"""

from __future__ import annotations

import itertools
import math
import time

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import nn

from uavrl.agents.dqn.networks import ValidGreedy
from uavrl.agents.dqn.setnet import SetQNet
from uavrl.agents.env_check import CheckedPolicy
from uavrl.agents.lookahead_rules import MAX_ENUMERATED, check_lookahead, check_lookahead_levels
from uavrl.envs import ModelConfig
from uavrl.envs._moved import moved_names
from uavrl.envs.physics.channel import cell_xyz, direct_terms, link_gains, rates, relay_contributions
from uavrl.envs.physics.grid import cells_of
from uavrl.envs.physics.rewards import log_gap_reward
from uavrl.envs.solvers.exact import fixed_layout_tables
from uavrl.envs.solvers.optimum import optimum
from uavrl.envs.world import World

_OBJECTIVES = ("log_gap", "delta")


class _Configurations:
    """``cell``, ``task`` ``[M, N]``: the per-UAV variables the dynamics part steps."""

    def __init__(self, cell: torch.Tensor, task: torch.Tensor):
        self.cell, self.task = cell, task


class LookaheadPolicy(TensorDictModuleBase):
    """Depth-``depth`` lookahead (module doc) with per-UAV values ``values(observation, positions, state)``
    ``[*, N, A]`` mixed by ``mixer`` (``vdn``: sum; ``mean``), in environments of ``cfg`` (no energy model).

    ``leaf_value(code [M, N], world [M]) -> [M]``, if given, replaces the learned team value at the leaves (e.g. the
    true values, in a test).  ``seconds`` and ``world_steps`` count the policy's CPU time and the world-steps it
    chose.
    """

    out_keys = [("agents", "action")]

    def __init__(
        self,
        values: nn.Module,
        mixer: str,
        cfg: ModelConfig,
        *,
        depth: int,
        width: int,
        gamma: float,
        objective: str = "log_gap",
        gap_floor: float = 1e-4,
        leaf_value=None,
    ):
        super().__init__()
        if cfg.energy != "none":
            raise ValueError(f"eval.lookahead is invalid with env.energy={cfg.energy!r}: its model has no batteries")
        check_lookahead_levels(depth, cfg.altitudes_m, cfg.observation)
        if objective not in _OBJECTIVES:
            raise ValueError(f"eval.lookahead scores the objectives {', '.join(_OBJECTIVES)}, not {objective!r}")
        self.values, self.mixer, self.cfg = values, mixer, cfg
        self.depth, self.width, self.gamma = int(depth), int(width), float(gamma)
        self.objective, self.gap_floor, self.leaf_value = objective, float(gap_floor), leaf_value
        self.random_layout = cfg.layout == "random"
        self.in_keys = ["positions", "tasks"] + (["nodes"] if self.random_layout else [])
        self.model = World(cfg, batch_size=1)  # the observations of any configuration, the dynamics
        self.greedy = _valid_greedy(self.model, cfg)
        self._layout = None  # (nodes or None, contributions [B or 1, C, 2], direct [B or 1, 2], U* [B or 1])
        self.seconds, self.world_steps = 0.0, 0

    def _tables(self, nodes: torch.Tensor | None):
        """The layouts' mean-channel tables and U*, kept while the layouts stay (an episode)."""
        if self._layout is not None and (nodes is None or torch.equal(self._layout[0], nodes)):
            return self._layout[1:]
        if nodes is None:
            contributions, direct = fixed_layout_tables(self.cfg)
        else:
            xyz = cell_xyz(self.cfg, torch.float64, nodes.device)
            contributions = relay_contributions(link_gains(xyz, nodes.double(), self.cfg), self.cfg)
            direct = direct_terms(nodes.double(), self.cfg)
        u_star = optimum(contributions, direct, self.cfg)[0]
        self._layout = (None if nodes is None else nodes.clone(), contributions, direct, u_star)
        return self._layout[1:]

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        began = time.process_time()
        positions, tasks = td.get("positions"), td.get("tasks")
        code = 2 * cells_of(positions, self.cfg.grid[0]) + tasks
        self._nodes = td.get("nodes").reshape(-1, 4, 3) if self.random_layout else None
        tables = self._tables(self._nodes)
        worlds = torch.arange(len(code), device=code.device)
        with torch.no_grad():
            action = self.search(code.reshape(-1, self.cfg.num_uavs), worlds, self.depth, tables)[1]
        td.set(("agents", "action"), action.view(tasks.shape))
        self.seconds += time.process_time() - began
        self.world_steps += len(code)
        return td

    def utility(self, code: torch.Tensor, worlds: torch.Tensor, tables) -> torch.Tensor:
        """``[M]`` the mean-channel utility of configurations ``code`` ``[M, N]`` in the layouts of ``worlds``."""
        contributions, direct = tables[0], tables[1]
        at = worlds if len(contributions) > 1 else torch.zeros_like(worlds)
        r_pu, r_se = rates(contributions[at[:, None], code >> 1], code & 1, direct[at], self.cfg)
        return r_pu + r_se

    def observe(self, code: torch.Tensor, worlds: torch.Tensor) -> dict:
        """What the network reads of configurations ``code`` ``[M, N]`` (the World's own observations)."""
        nodes = None if self._nodes is None else self._nodes[worlds].double()
        return self.model.configurations(code, None, nodes)

    def search(self, code: torch.Tensor, worlds: torch.Tensor, depth: int, tables) -> tuple[torch.Tensor, torch.Tensor]:
        """``(value [M], joint action [M, N])``: the best score of each configuration's candidates ``depth`` levels
        deep (module doc) and the candidate that reaches it."""
        out = self.observe(code, worlds)
        q = self.values(out["observation"], out["positions"], out["state"])  # [M, N, A]
        allowed = out["action_mask"]
        greedy = self.greedy(q, allowed, out["positions"], out["tasks"])
        if depth == 0:
            if self.leaf_value is not None:
                return self.leaf_value(code, worlds), greedy
            return _team_value(q.gather(-1, greedy.unsqueeze(-1)).squeeze(-1), self.mixer), greedy
        actions, learned = self.candidates(q, allowed, greedy)  # [M, K, N], [M, K]
        if self.width and self.width < actions.shape[1]:
            top = learned.topk(self.width, -1).indices
            actions, learned = (
                actions.gather(1, top.unsqueeze(-1).expand(-1, -1, actions.shape[-1])),
                learned.gather(1, top),
            )
        M, K, N = actions.shape
        ok = learned > -math.inf
        after = self.step(code.repeat_interleave(K, 0), actions.reshape(M * K, N))
        repeated = worlds.repeat_interleave(K)
        reward = self.reward(self.utility(after, repeated, tables), self.utility(code, worlds, tables), worlds, tables)
        below = self.search(after, repeated, depth - 1, tables)[0].view(M, K)
        score = (reward.view(M, K) if reward.dim() == 1 else reward) + self.gamma * below
        score = score.masked_fill(~ok, -math.inf)
        best = score.argmax(-1)
        return score.gather(1, best.unsqueeze(-1)).squeeze(-1), actions[torch.arange(M), best]

    def reward(self, after: torch.Tensor, now: torch.Tensor, worlds: torch.Tensor, tables) -> torch.Tensor:
        """``[M K]`` the objective's reward of each candidate's step (``after`` ``[M K]``, ``now`` ``[M]``)."""
        K = len(after) // len(now)
        now = now.repeat_interleave(K)
        if self.objective == "delta":
            return after - now
        u_star = tables[2]
        u_star = (u_star[worlds] if len(u_star) > 1 else u_star.expand(len(worlds))).repeat_interleave(K)
        return log_gap_reward(after, now, u_star, self.gap_floor)

    def step(self, code: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """``[M, N]`` the configurations after joint actions ``action`` from ``code``: the environment's dynamics."""
        after = self.model.dynamics.step(_Configurations(code >> 1, code & 1), action)
        return 2 * after["cell"] + after["task"]

    def candidates(
        self, q: torch.Tensor, allowed: torch.Tensor, greedy: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(joint actions [M, K, N], their learned team values [M, K])``; a joint action a mask forbids, or a
        repeat of the greedy one, has value ``-inf``."""
        M, N, A = q.shape
        if A**N <= MAX_ENUMERATED:
            joint = torch.tensor(list(itertools.product(range(A), repeat=N)), device=q.device)  # [K, N]
            actions = joint.expand(M, -1, -1)
            rows = torch.arange(N, device=q.device)
            chosen = q[:, rows, joint]  # [M, K, N]: q[m, i, joint[k, i]]
            legal = allowed[:, rows, joint].all(-1)
            return actions, _team_value(chosen, self.mixer).masked_fill(~legal, -math.inf)
        base = q.gather(-1, greedy.unsqueeze(-1)).squeeze(-1)  # [M, N]
        actions = greedy.unsqueeze(1).repeat(1, 1 + N * A, 1)  # [M, 1 + N A, N]: greedy, then UAV i takes b
        uav, other = torch.arange(N, device=q.device).repeat_interleave(A), torch.arange(A, device=q.device).repeat(N)
        actions[:, 1 + torch.arange(N * A, device=q.device), uav] = other
        chosen = base.unsqueeze(1).repeat(1, 1 + N * A, 1)
        chosen[:, 1 + torch.arange(N * A, device=q.device), uav] = q[:, uav, other]
        legal = torch.cat(
            [torch.ones(M, 1, dtype=torch.bool, device=q.device), allowed[:, uav, other] & (greedy[:, uav] != other)], 1
        )
        return actions, _team_value(chosen, self.mixer).masked_fill(~legal, -math.inf)


def _team_value(chosen: torch.Tensor, mixer: str) -> torch.Tensor:
    """``[...]`` the team value of per-UAV chosen values ``[..., N]``: the sum (vdn) or the mean."""
    return chosen.sum(-1) if mixer == "vdn" else chosen.mean(-1)


def _valid_greedy(world: World, cfg: ModelConfig):
    return ValidGreedy(world.neighbours, cfg.grid[0], cfg.num_actions)


def lookahead_policy(agent, env_cfg: ModelConfig, depth: int, width: int) -> CheckedPolicy:
    """The depth-``depth`` lookahead of a Q-network agent (``agent=dqn``, factored head, ``vdn`` or ``mean`` mixer)
    in environments of ``env_cfg``; a one-line ValueError for any other agent."""
    a = getattr(agent, "settings", None)
    check_lookahead(a, depth, type(agent).__name__)
    if hasattr(agent, "core"):  # the size-free network: any grid and team
        agent.policy_for(env_cfg)  # its one-line refusals (another model)
        values = SetQNet(agent.core, env_cfg.grid)
    else:
        values = agent.greedy[0].module  # the TeamQNet: the run's own grid and team only
        if env_cfg.replace(max_steps=agent.env_cfg.max_steps) != agent.env_cfg:
            raise ValueError("eval.lookahead with agent.network=team acts only in its run's model")
    policy = LookaheadPolicy(
        values,
        a.mixer,
        env_cfg,
        depth=depth,
        width=width,
        gamma=float(a.gamma),
        objective=a.objective,
        gap_floor=float(a.gap_floor),
    )
    checked = CheckedPolicy(policy, env_cfg)
    checked.lookahead = policy
    return checked


# 0.2's evaluate_with_lookahead and lookahead_settings of this module, moved: deprecated aliases until 0.4
__getattr__ = moved_names(__name__, "uavrl.agents.evaluation", "uavrl.agents.lookahead_rules")
