"""The model as lookup tables for the tabular learner, and the exact ``Q*`` table (value iteration).

:class:`TabularModel` tabulates, with the functions the environment steps with, the
rates of every configuration and the effect of every joint action;
:func:`exact_q_table` solves the paper's "offline" table on the configuration
graph (:mod:`uavrl.envs.solvers.exact`).  This module uses no TorchRL (the package still imports it: learner, policy).
"""

from __future__ import annotations

import functools
import math

import torch

from uavrl.envs.config import ModelConfig
from uavrl.envs.limits import DEFAULT_MEMORY_BUDGET, row_itemsize, valid_list_itemsize
from uavrl.envs.physics.channel import rates
from uavrl.envs.physics.fading import fading_part
from uavrl.envs.physics.grid import cells_of, decode_joint_actions, joint_action_valid, joint_targets
from uavrl.envs.physics.positions import model_positions
from uavrl.envs.solvers.exact import fixed_layout_tables, model_space, optimal_values
from uavrl.envs.solvers.optimum import optimum

_TABLE_CHUNK = 1 << 22  # configurations x joint actions built per torch call


_TORCH_INTEGERS = {1: torch.uint8, 2: torch.int16, 4: torch.int32, 8: torch.int64}


def _valid_list_dtype(num_joint_actions: int) -> torch.dtype:
    """The smallest integer type of a joint action index: the learner's valid-action lists are read every step, and
    the smaller they are, the fewer cache lines a step touches."""
    return _TORCH_INTEGERS[valid_list_itemsize(num_joint_actions)]


def _row_dtype(cfg: ModelConfig) -> torch.dtype:
    return _TORCH_INTEGERS[row_itemsize(cfg)]


def position_indices(
    cfg: ModelConfig, number: torch.Tensor, xy: torch.Tensor, levels: torch.Tensor | None
) -> torch.Tensor:
    """The position indices ``[..., N]`` of ``[..., N, 2]`` (x, y) and, with altitude levels, ``[..., N]`` levels (the
    World's outputs ``positions`` and ``levels``); ``number``: the model's
    :attr:`~uavrl.envs.physics.positions.Positions.number`."""
    cells = cells_of(xy, cfg.grid[0])
    if cfg.num_levels == 1:
        return cells
    if levels is None:
        raise ValueError(f"altitudes_m={list(cfg.altitudes_m)} needs each UAV's level beside its (x, y): none given")
    return number[levels * cfg.num_cells + cells]


def table_place(cfg: ModelConfig) -> str:
    """Where a table's team flies, for its refusals: ``3x3``, with altitude levels ``3x3 at 3 altitude levels``."""
    where = f"{cfg.grid[0]}x{cfg.grid[1]}"
    return where if cfg.num_levels == 1 else f"{where} at {cfg.num_levels} altitude levels"


class TabularModel:
    """The model of ``cfg`` as lookup tables, computed by the model's own functions (no TorchRL).

    The geometry comes from :mod:`uavrl.envs.physics.grid`, the per-cell rate terms of
    the fixed layout from :func:`uavrl.envs.solvers.exact.fixed_layout_tables`, the
    rates from :func:`uavrl.envs.physics.channel.rates` and ``U*`` from
    :func:`uavrl.envs.solvers.optimum.optimum`: the functions the environment steps with.

    Configurations are numbered ``k = p * 2^N + t`` with ``p = sum_i c_i P^i``
    the positions (:func:`~uavrl.envs.physics.positions.model_positions`: the cells without altitude levels) and
    ``t = sum_i task_i 2^i`` the tasks.  Tables (torch, on ``device``):
    ``rates[k]`` = (R_PU, R_SE) (also as ``r_pu[k]``, ``r_se[k]``), ``row[k]`` (the Q row: the env's
    ``state_index``), ``valid[p, j]`` (and the same as lists: ``valid_actions[p, :num_valid[p]]``),
    ``next_cells[p, j]``, ``moves[p, j]``, ``next_tasks[t, j]``, ``switches[t, j]``.  The tables a learning step
    reads together are stored together and in the smallest integer types (``rates``, ``row``, ``valid_actions``):
    on a 10x10 grid that makes the compiled step ~1.5x faster (BENCHMARKS.md, Team Q-learning).
    """

    def __init__(self, cfg: ModelConfig, device="cpu"):
        if cfg.layout == "random":
            raise ValueError(
                "layout='random' is invalid for agent=tabular: its state has no layout, so one table cannot serve "
                "many; use agent=dqn"
            )
        if fading_part(cfg).random:
            raise ValueError(
                f"fading={cfg.fading!r} is invalid for agent=tabular: its tables need deterministic channels; use "
                "fading='none'"
            )
        # a battery that cannot reach its reserve within an episode changes nothing the table sees: without it, the
        # table is exact (the follow-up's state has no energy either: docs/model.md, Energy and lifetime)
        if cfg.energy != "none" and (cfg.recharge_steps is not None or cfg.max_steps > cfg.steps_before_reserve):
            levels = 100  # a battery in 1% steps, the coarsest that still tells a reserve from a full battery
            raise ValueError(
                f"energy={cfg.energy!r} is invalid for agent=tabular with max_steps={cfg.max_steps}"
                f"{'' if cfg.recharge_steps is None else ' and recharge_steps'}: its state would need each UAV's "
                f"battery and service, {cfg.num_states:,} x ({levels} levels x 3 states)^{cfg.num_uavs} = "
                f"{cfg.num_states * (3 * levels) ** cfg.num_uavs:.3g} rows; use agent=dqn, or without recharging "
                f"max_steps <= {cfg.steps_before_reserve} (no battery reaches its reserve)"
            )
        self.cfg, self.device = cfg, torch.device(device)
        N, A = cfg.num_uavs, cfg.num_joint_actions
        dev = self.device
        self.positions = model_positions(cfg, dev)  # a UAV's "cell" is one of these: a cell at a level
        C, neighbours = len(self.positions), self.positions.neighbours
        contributions, direct = fixed_layout_tables(cfg, dev)  # [1, C, 2], [1, 2]
        self.num_placements, self.num_task_codes = C**N, 2**N
        place = torch.tensor([C**i for i in range(N)], device=dev)
        bits = torch.tensor([2**i for i in range(N)], device=dev)
        task_codes = torch.arange(2**N, device=dev)
        tasks = (task_codes[:, None] // bits) % 2  # [2^N, N]
        # tasks after every joint action, and how many UAVs switched
        actions = decode_joint_actions(N, dev, cfg.joint_action_base)  # [A, N]
        new_tasks = torch.where(actions == 4, 0, torch.where(actions == 5, 1, tasks[:, None, :]))  # [2^N, A, N]
        self.next_tasks = (new_tasks * bits).sum(-1).int()
        self.switches = (new_tasks != tasks[:, None, :]).sum(-1).to(torch.int8)
        self.valid = torch.empty(C**N, A, dtype=torch.bool, device=dev)
        self.next_cells = torch.empty(C**N, A, dtype=torch.int32, device=dev)
        self.moves = torch.empty(C**N, A, dtype=torch.int8, device=dev)
        self.rates = torch.empty(C**N * 2**N, 2, dtype=torch.float64, device=dev)
        self.r_pu, self.r_se = self.rates.unbind(-1)
        self.row = torch.empty(C**N * 2**N, dtype=_row_dtype(cfg), device=dev)
        base = 2 * C if cfg.state_includes_tasks else C
        row_place = torch.tensor([base**i for i in range(N)], device=dev)
        step = max(1, _TABLE_CHUNK // (A * N))
        for start in range(0, C**N, step):
            p = torch.arange(start, min(start + step, C**N), device=dev)
            cells = (p[:, None] // place) % C  # [P, N]
            target = joint_targets(cells, neighbours, N)  # [P, A, N]
            self.valid[p] = joint_action_valid(cells, neighbours, N)
            self.next_cells[p] = (target.clamp(min=0) * place).sum(-1).int()
            self.moves[p] = (target != cells[:, None, :]).sum(-1).to(torch.int8)
            k = (p[:, None] * 2**N + task_codes).reshape(-1)
            cells_k = cells[:, None].expand(-1, 2**N, -1).reshape(1, -1, N)
            tasks_k = tasks[None].expand(len(p), -1, -1).reshape(1, -1, N)
            r_pu, r_se = rates(contributions[0][cells_k], tasks_k, direct.view(1, 1, 2), cfg)
            self.rates[k] = torch.stack([r_pu[0], r_se[0]], -1)
            digits = (
                2 * cells[:, None, :] + tasks[None]
                if cfg.state_includes_tasks
                else cells[:, None, :].expand(-1, 2**N, -1)
            )
            self.row[k] = (digits * row_place).sum(-1).reshape(-1).to(self.row.dtype)
        self.num_valid = self.valid.sum(-1).int()
        self.valid_actions = (~self.valid).to(torch.int8).argsort(dim=-1, stable=True).to(_valid_list_dtype(A))
        self.u_star = optimum(contributions, direct, cfg)[0].item()

    @functools.cached_property
    def kernel_tables(self) -> tuple:
        """The tables of a compiled learning step, as numpy views of this model's tensors (the order
        :func:`~uavrl.agents.tabular.kernels._run_episode` unpacks)."""
        tables = (self.rates, self.row, self.valid_actions, self.num_valid, self.next_cells, self.next_tasks)
        return tuple(t.numpy() for t in (*tables, self.moves, self.switches))

    def configuration_ids(
        self, positions: torch.Tensor, tasks: torch.Tensor, levels: torch.Tensor | None = None
    ) -> torch.Tensor:
        """``k`` of ``[..., N, 2]`` positions (x, y), ``[..., N]`` tasks and, with altitude levels, ``[..., N]``
        levels (the World's outputs ``positions``, ``tasks`` and ``levels``)."""
        N, C = self.cfg.num_uavs, len(self.positions)
        cells = position_indices(self.cfg, self.positions.number, positions, levels)
        place = torch.tensor([C**i for i in range(N)], device=positions.device)
        bits = torch.tensor([2**i for i in range(N)], device=positions.device)
        return (cells * place).sum(-1) * 2**N + (tasks * bits).sum(-1)


def exact_q_table(cfg: ModelConfig, gamma: float, device="cpu", memory_budget=DEFAULT_MEMORY_BUDGET) -> torch.Tensor:
    """The paper's "offline" table: exact ``Q*`` ``[S, A^N]`` (``A`` 6, 8 with altitude levels) of the delta reward
    for the tabular state (docs/model.md, "What the agents see and learn").

    Solved on the configuration graph (:mod:`uavrl.envs.solvers.exact`, the environment's
    own dynamics and rates), infinite horizon, discount ``gamma``.  With
    ``state_includes_tasks`` a row is one configuration and holds ``Q*`` itself.
    The paper's location-only state hides the tasks, so no row can be exact for
    every task vector behind it: a row holds the mean of ``Q*`` over the task
    vectors an episode starts with (all ``2^N`` for ``init_tasks=random``, else
    the one), the value of acting from that location when the tasks are known
    only to come from the reset (QMDP).  Its greedy policy is the best such a
    table can express, not an optimal policy.  Invalid joint actions hold 0, as
    in a learned table (policies mask them).

    Args:
        cfg: the model (:func:`~uavrl.envs.make_config`) to solve: the delta reward, a fixed layout and
            deterministic channels (others are refused).
        gamma: the discount, in (0, 1].
        device: the torch device the graph is solved on.
        memory_budget: the bytes the solve may take; a larger model is refused with one line.

    Returns:
        ``Q*`` ``[S, A^N]`` float64 on ``device``.
    """
    if cfg.reward != "delta":
        raise ValueError(
            f"env.reward={cfg.reward!r} is invalid for agent.method=value_iteration: it solves the paper's reward "
            "(the best_so_far reward depends on the episode's past, not on the configuration); use env.reward=delta"
        )
    if cfg.layout == "random" or fading_part(cfg).random:
        raise ValueError(
            "agent.method=value_iteration needs a fixed layout and deterministic channels (env.layout=line or "
            "reference_code, env.fading=none)"
        )
    need = cfg.num_states * cfg.num_joint_actions * 8
    if not cfg.has_state_index or need > memory_budget:
        raise ValueError(
            f"the exact Q table of {cfg.num_uavs} UAVs on {table_place(cfg)} would need "
            f"{cfg.num_states * cfg.num_joint_actions * 8:,} bytes, over the memory budget of {int(memory_budget):,} "
            "bytes; raise agent.memory_budget or use agent=dqn"
        )
    N, A, dev = cfg.num_uavs, cfg.num_joint_actions, torch.device(device)
    space = model_space(cfg, dev)
    C = len(space.neighbours)  # the positions: the cells without altitude levels
    potential = space.utility(cfg, *fixed_layout_tables(cfg, dev), beta=(cfg.beta1, cfg.beta2))
    values = optimal_values(space, potential, gamma)
    task_vectors = (torch.arange(2**N, device=dev)[:, None] >> torch.arange(N, device=dev)) & 1  # [2^N, N]
    start_tasks = {"random": task_vectors, "sensing": task_vectors[:1], "relaying": task_vectors[-1:]}[cfg.init_tasks]
    tasks = task_vectors if cfg.state_includes_tasks else start_tasks
    place = C ** torch.arange(N, device=dev)
    q = torch.zeros(cfg.num_states, A, dtype=torch.float64, device=dev)
    step = max(1, _TABLE_CHUNK // (A * len(tasks)))
    for start in range(0, C**N, step):
        cells = (
            torch.arange(start, min(start + step, C**N), device=dev)[:, None] // place
        ) % C  # [P, N] every placement
        distinct = (cells.sort(-1).values.diff(dim=-1) != 0).all(-1)
        cells = cells[distinct]
        both = (cells[:, None].expand(-1, len(tasks), -1), tasks[None].expand(len(cells), -1, -1))  # [P, T, N] each
        q_star = space.q_values(potential, values, gamma, both[0][None], both[1][None])[0]  # [P, T, A]
        q_star = q_star.masked_fill(q_star == -math.inf, 0.0)
        if cfg.state_includes_tasks:
            rows = ((2 * both[0] + both[1]) * (2 * C) ** torch.arange(N, device=dev)).sum(-1)
            q[rows.flatten()] = q_star.reshape(-1, A)
        else:
            q[(cells * place).sum(-1)] = q_star.mean(1)
    return q
