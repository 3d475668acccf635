"""Tabular team Q-learning (the paper's eqs. 9-10), with the Q table as a torch tensor.

One controller learns ``Q[s, j]`` over the joint state ``s`` (SPEC section 6:
the joint location, optionally with tasks) and the joint action
``j = sum_i a_i 6^i``.  Each step it picks an epsilon-greedy *valid* joint
action (every UAV on the grid, cells distinct), ties broken uniformly at random,
and updates ``Q[s, j] <- (1 - alpha) Q[s, j] + alpha (r + gamma max_valid Q[s', .])``.

Speed comes from tabulating the model once.  For deterministic channels the
environment's own functions give, for every configuration, the rates (from
:func:`uavrl.envs.channel.rates`) and, for every joint action, the next cells
(:func:`uavrl.envs.joint_targets`).  A learning step is then a handful of table
lookups, run by one of two interchangeable loops over the same tables and the
same random numbers:

- ``backend="numba"``: a compiled loop on the torch tensors' memory, runs in
  parallel (the paper's 10 iterations side by side on the CPU's cores);
- ``backend="torch"``: the same step batched over runs in torch, on any device.

They give bit-identical Q tables (tests/test_tabular.py).

``R`` independent runs each own a table (the paper's repetitions), or, with
``shared_table``, ``R`` worlds feed one table: every step all worlds read the
table, then each visited ``(s, j)`` moves towards the mean target of the worlds
that visited it (synchronous, so both loops agree exactly).

Example:
    >>> from uavrl.envs import make_config
    >>> learner = TeamQLearner(make_config("paper", grid=(3, 3), max_steps=50), runs=2, seed=0)
    >>> metrics = learner.run_episode()
    >>> learner.q.shape, metrics["r_pu"].shape
    (torch.Size([2, 81, 36]), torch.Size([2, 50]))
"""

from __future__ import annotations

import math
import os
import time

import numba
import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from uavrl.envs import ModelConfig, UAVSpectrumEnv, decode_joint_actions, joint_action_valid, joint_targets
from uavrl.envs.channel import best_so_far_reward, delta_reward
from uavrl.envs.exact import ConfigurationSpace, fixed_layout_tables, optimal_values
from uavrl.evaluation import episode_metrics

# numba's OpenMP layer shares the process with torch's OpenMP runtime and costs ~15 ms a
# parallel call here (threads waking up); the workqueue layer costs microseconds.
if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"

DEFAULT_MEMORY_BUDGET = 4 * 2**30
METHODS = ("q_learning", "value_iteration")
_TABLE_CHUNK = 1 << 22  # configurations x joint actions built per torch call
_START_BLOCK = 256  # episodes whose starts are drawn together


def table_bytes(cfg: ModelConfig, num_tables: int) -> int:
    """Bytes of the Q tables plus the model tables the learner keeps beside them."""
    A = cfg.num_joint_actions
    positions = cfg.num_cells**cfg.num_uavs
    configs = positions * 2**cfg.num_uavs
    return num_tables * cfg.num_states * A * 8 + positions * A * (4 + 4 + 1 + 1) + configs * (8 + 8 + 8)


class TabularModel:
    """The model of ``cfg`` as lookup tables, computed by the environment's own functions.

    Configurations are numbered ``k = p * 2^N + t`` with ``p = sum_i c_i C^i``
    the cells and ``t = sum_i task_i 2^i`` the tasks.  Tables (torch, on ``device``):
    ``r_pu[k]``, ``r_se[k]``, ``row[k]`` (the Q row: the env's ``state_index``),
    ``valid[p, j]`` (and the same as lists: ``valid_actions[p, :num_valid[p]]``),
    ``next_cells[p, j]``, ``moves[p, j]``, ``next_tasks[t, j]``, ``switches[t, j]``.
    """

    def __init__(self, cfg: ModelConfig, device="cpu"):
        if cfg.layout == "random":
            raise ValueError(
                "layout='random' is invalid for agent=tabular: its state has no layout, so one table cannot serve "
                "many; use agent=dqn"
            )
        if cfg.fading != "none":
            raise ValueError(
                f"fading={cfg.fading!r} is invalid for agent=tabular: its tables need deterministic channels; use "
                "fading='none'"
            )
        self.cfg, self.device = cfg, torch.device(device)
        N, C, A = cfg.num_uavs, cfg.num_cells, cfg.num_joint_actions
        env = UAVSpectrumEnv(batch_size=1, config=cfg, device=self.device)
        dev = self.device
        self.num_positions, self.num_task_codes = C**N, 2**N
        place = torch.tensor([C**i for i in range(N)], device=dev)
        bits = torch.tensor([2**i for i in range(N)], device=dev)
        task_codes = torch.arange(2**N, device=dev)
        tasks = (task_codes[:, None] // bits) % 2  # [2^N, N]
        # tasks after every joint action, and how many UAVs switched
        actions = decode_joint_actions(N, dev)  # [A, N]
        new_tasks = torch.where(actions == 4, 0, torch.where(actions == 5, 1, tasks[:, None, :]))  # [2^N, A, N]
        self.next_tasks = (new_tasks * bits).sum(-1).int()
        self.switches = (new_tasks != tasks[:, None, :]).sum(-1).to(torch.int8)
        self.valid = torch.empty(C**N, A, dtype=torch.bool, device=dev)
        self.next_cells = torch.empty(C**N, A, dtype=torch.int32, device=dev)
        self.moves = torch.empty(C**N, A, dtype=torch.int8, device=dev)
        self.r_pu = torch.empty(C**N * 2**N, dtype=torch.float64, device=dev)
        self.r_se = torch.empty_like(self.r_pu)
        self.row = torch.empty(C**N * 2**N, dtype=torch.long, device=dev)
        base = 2 * C if cfg.state_includes_tasks else C
        row_place = torch.tensor([base**i for i in range(N)], device=dev)
        step = max(1, _TABLE_CHUNK // (A * N))
        for start in range(0, C**N, step):
            p = torch.arange(start, min(start + step, C**N), device=dev)
            cells = (p[:, None] // place) % C  # [P, N]
            target = joint_targets(cells, env.neighbours, N)  # [P, A, N]
            self.valid[p] = joint_action_valid(cells, env.neighbours, N)
            self.next_cells[p] = (target.clamp(min=0) * place).sum(-1).int()
            self.moves[p] = (target != cells[:, None, :]).sum(-1).to(torch.int8)
            positions = torch.stack([cells % cfg.grid[0], cells // cfg.grid[0]], -1)  # [P, N, 2]
            k = (p[:, None] * 2**N + task_codes).reshape(-1)
            pos_k = positions[:, None].expand(-1, 2**N, -1, -1).reshape(1, -1, N, 2)
            tasks_k = tasks[None].expand(len(p), -1, -1).reshape(1, -1, N)
            r_pu, r_se, _ = env.utility(pos_k, tasks_k)
            self.r_pu[k], self.r_se[k] = r_pu[0], r_se[0]
            digits = (
                2 * cells[:, None, :] + tasks[None]
                if cfg.state_includes_tasks
                else cells[:, None, :].expand(-1, 2**N, -1)
            )
            self.row[k] = (digits * row_place).sum(-1).reshape(-1)
        self.num_valid = self.valid.sum(-1).int()
        self.valid_actions = (~self.valid).to(torch.int8).argsort(dim=-1, stable=True).int()
        self.u_star = env.optimum()[0].item()

    def configuration_ids(self, positions: torch.Tensor, tasks: torch.Tensor) -> torch.Tensor:
        """``k`` of ``[..., N, 2]`` positions and ``[..., N]`` tasks."""
        N, C, L1 = self.cfg.num_uavs, self.cfg.num_cells, self.cfg.grid[0]
        cells = positions[..., 1] * L1 + positions[..., 0]
        place = torch.tensor([C**i for i in range(N)], device=positions.device)
        bits = torch.tensor([2**i for i in range(N)], device=positions.device)
        return (cells * place).sum(-1) * 2**N + (tasks * bits).sum(-1)


# ----------------------------------------------------------------------------- the compiled loop
_best_so_far = numba.njit(best_so_far_reward)
_delta = numba.njit(delta_reward)


@numba.njit(cache=True, inline="always")
def _scan(q_row, actions, n_valid):
    """Best value over the ``n_valid`` valid joint ``actions``, how many tie for it, and the first of them."""
    best, ties, best_j = -np.inf, 0, -1
    for i in range(n_valid):
        value = q_row[actions[i]]
        if value > best:
            best, ties, best_j = value, 1, actions[i]
        elif value == best:
            ties += 1
    return best, ties, best_j


@numba.njit(cache=True, inline="always")
def _choose(q_row, actions, n_valid, u, epsilon, best, ties, best_j):
    """Epsilon-greedy action among the valid ``actions`` (ascending) from one uniform ``u``, given the row's
    :func:`_scan`.

    ``u < epsilon`` explores, and then ``u / epsilon`` is a fresh uniform that
    picks the valid action; otherwise ``(u - epsilon) / (1 - epsilon)`` picks
    among the tied best ones.
    """
    if u < epsilon:
        return actions[int(u / epsilon * n_valid)]
    if ties == 1:
        return best_j
    n = int((u - epsilon) / (1 - epsilon) * ties)
    for i in range(n_valid):
        if q_row[actions[i]] == best:
            if n == 0:
                return actions[i]
            n -= 1
    return -1


@numba.njit(cache=True, inline="always")
def _transition(w, cfg_k, j, r_pu_t, r_se_t, next_cells, next_tasks, prev, best, beta1, beta2, use_best, T2):
    """Apply joint action ``j`` in configuration ``cfg_k`` of world ``w``; return (next configuration, reward)."""
    k2 = next_cells[cfg_k // T2, j] * T2 + next_tasks[cfg_k % T2, j]
    r_pu, r_se = r_pu_t[k2], r_se_t[k2]
    if use_best:
        reward = _best_so_far(r_pu + r_se, best[w])
        best[w] = max(best[w], r_pu + r_se)
    else:
        reward = _delta(r_pu, r_se, prev[w, 0], prev[w, 1], beta1, beta2)
    prev[w, 0], prev[w, 1] = r_pu, r_se
    return k2, reward


@numba.njit(cache=True, parallel=True)
def _episode_per_run(
    q,
    k0,
    uniforms,
    r_pu_t,
    r_se_t,
    row_t,
    valid,
    n_valid,
    next_cells,
    next_tasks,
    moves_t,
    switches_t,
    alpha,
    gamma,
    epsilon,
    beta1,
    beta2,
    use_best,
    out,
):
    """One episode of ``R`` independent runs, run ``r`` on table ``q[r]``; ``out[r, t]`` = (R_PU, R_SE, moves,
    switches).

    The scan of the next state's row that gives the target's max is also the
    next step's greedy choice, so each step scans one row (two when it stays
    in the row it just updated).
    """
    R, T = uniforms.shape[0], uniforms.shape[1]
    T2 = next_tasks.shape[0]
    prev = np.empty((R, 2))
    best = np.zeros(R)
    for r in numba.prange(R):
        qr = q[r]
        k = k0[r]
        prev[r, 0], prev[r, 1] = r_pu_t[k], r_se_t[k]
        p = k // T2
        v_best, ties, best_j = _scan(qr[row_t[k]], valid[p], n_valid[p])
        for step in range(T):
            s, p = row_t[k], k // T2
            j = _choose(qr[s], valid[p], n_valid[p], uniforms[r, step], epsilon, v_best, ties, best_j)
            k2, reward = _transition(
                r, k, j, r_pu_t, r_se_t, next_cells, next_tasks, prev, best, beta1, beta2, use_best, T2
            )
            s2, p2 = row_t[k2], k2 // T2
            v_best, ties, best_j = _scan(qr[s2], valid[p2], n_valid[p2])
            qr[s, j] = (1 - alpha) * qr[s, j] + alpha * (reward + gamma * v_best)
            if s2 == s:
                v_best, ties, best_j = _scan(qr[s2], valid[p2], n_valid[p2])
            out[r, step, 0], out[r, step, 1] = prev[r, 0], prev[r, 1]
            out[r, step, 2] = moves_t[p, j]
            out[r, step, 3] = switches_t[k % T2, j]
            k = k2
        k0[r] = k


@numba.njit(cache=True)
def _episode_shared(
    q,
    k0,
    uniforms,
    r_pu_t,
    r_se_t,
    row_t,
    valid,
    n_valid,
    next_cells,
    next_tasks,
    moves_t,
    switches_t,
    alpha,
    gamma,
    epsilon,
    beta1,
    beta2,
    use_best,
    out,
):
    """One episode of ``R`` worlds feeding the single table ``q[0]`` synchronously (see module doc)."""
    R, T = uniforms.shape[0], uniforms.shape[1]
    T2 = next_tasks.shape[0]
    A = q.shape[2]
    qt = q[0]
    prev = np.empty((R, 2))
    best = np.zeros(R)
    s_w = np.empty(R, np.int64)
    j_w = np.empty(R, np.int64)
    target_w = np.empty(R)
    total = np.zeros(q.shape[1] * A)
    count = np.zeros(q.shape[1] * A, np.int64)
    for w in range(R):
        prev[w, 0], prev[w, 1] = r_pu_t[k0[w]], r_se_t[k0[w]]
    for step in range(T):
        for w in range(R):
            k = k0[w]
            s, p = row_t[k], k // T2
            v_best, ties, best_j = _scan(qt[s], valid[p], n_valid[p])
            j = _choose(qt[s], valid[p], n_valid[p], uniforms[w, step], epsilon, v_best, ties, best_j)
            k2, reward = _transition(
                w, k, j, r_pu_t, r_se_t, next_cells, next_tasks, prev, best, beta1, beta2, use_best, T2
            )
            s_w[w], j_w[w], k0[w] = s, j, k2
            target_w[w] = reward + gamma * _scan(qt[row_t[k2]], valid[k2 // T2], n_valid[k2 // T2])[0]
            out[w, step, 0], out[w, step, 1] = prev[w, 0], prev[w, 1]
            out[w, step, 2] = moves_t[p, j]
            out[w, step, 3] = switches_t[k % T2, j]
        for w in range(R):
            f = s_w[w] * A + j_w[w]
            total[f] += target_w[w]
            count[f] += 1
        for w in range(R):
            f = s_w[w] * A + j_w[w]
            if count[f] > 0:
                qt[s_w[w], j_w[w]] = (1 - alpha) * qt[s_w[w], j_w[w]] + alpha * (total[f] / count[f])
                total[f] = 0.0
                count[f] = 0


# ----------------------------------------------------------------------------- the learner
class TeamQLearner:
    """Team Q-learning over ``runs`` worlds of ``cfg`` (episode length ``cfg.max_steps``).

    Args:
        cfg: the model.
        runs: independent runs (each its own table), or worlds feeding one table with ``shared_table``.
        seed: seeds the episode starts (drawn by the env's reset) and the learner's random numbers.
        alpha, gamma, epsilon: eq. 9-10 constants (paper: 0.1, 0.3, 0.1).
        backend: ``"numba"`` (CPU) or ``"torch"`` (any device).
        memory_budget: refuse tables larger than this many bytes.
    """

    def __init__(
        self,
        cfg: ModelConfig,
        runs: int = 1,
        seed: int = 0,
        alpha=0.1,
        gamma=0.3,
        epsilon=0.1,
        shared_table=False,
        backend="numba",
        device="cpu",
        memory_budget=DEFAULT_MEMORY_BUDGET,
    ):
        if backend not in ("numba", "torch"):
            raise ValueError(f"backend={backend!r} is invalid: allowed values are 'numba', 'torch'")
        if backend == "numba" and torch.device(device).type != "cpu":
            raise ValueError(f"backend='numba' runs on the CPU, not device={device!r}: use backend='torch' there")
        if int(runs) < 1:
            raise ValueError(f"runs={runs} is invalid: give at least 1")
        for name, value, low in (("alpha", alpha, 0.0), ("gamma", gamma, 0.0), ("epsilon", epsilon, 0.0)):
            if not (low <= float(value) <= 1.0) or (name == "alpha" and float(value) == 0.0):
                raise ValueError(
                    f"{name}={value} is invalid: it must lie in {'(0, 1]' if name == 'alpha' else '[0, 1]'}"
                )
        num_tables = 1 if shared_table else int(runs)
        if not cfg.has_state_index:
            raise ValueError(
                f"the team Q table of {cfg.num_uavs} UAVs on {cfg.grid[0]}x{cfg.grid[1]} has {cfg.num_states:.3g} "
                "states: no int64 state index exists; use agent=dqn, which scales further"
            )
        need = table_bytes(cfg, num_tables)
        if need > memory_budget:
            raise ValueError(
                f"the team Q table of {cfg.num_uavs} UAVs on {cfg.grid[0]}x{cfg.grid[1]} would need {need:,} bytes "
                f"({need / 2**30:.3g} GiB) with the model tables, over the memory budget of {int(memory_budget):,} "
                "bytes; raise agent.memory_budget or use agent=dqn, which scales further"
            )
        self.cfg, self.runs, self.seed = cfg, int(runs), int(seed)
        self.alpha, self.gamma, self.epsilon = float(alpha), float(gamma), float(epsilon)
        self.shared_table, self.backend, self.device = bool(shared_table), backend, torch.device(device)
        self.model = TabularModel(cfg, self.device)
        self.q = torch.zeros(num_tables, cfg.num_states, cfg.num_joint_actions, dtype=torch.float64, device=self.device)
        self.episode = 0
        self._configuration = None  # end of the last episode, for reset_positions="keep"
        self._start_block, self._block_starts = -1, None

    def _episode_starts(self) -> torch.Tensor:
        """``[R]`` start configurations: run ``r``'s episode ``e`` starts where the environment's reset puts
        world ``seed + e R + r``; drawn for blocks of episodes in one batched reset."""
        if self.cfg.reset_positions == "keep" and self._configuration is not None:
            return self._configuration.clone()
        block, offset = divmod(self.episode, _START_BLOCK)
        if block != self._start_block:
            worlds = _START_BLOCK * self.runs
            first_world = (self.seed + block * worlds) % 2**63  # world seeds are int64
            env = UAVSpectrumEnv(batch_size=worlds, config=self.cfg, seed=first_world, device=self.device)
            td = env.reset()
            self._block_starts = self.model.configuration_ids(td["positions"], td["tasks"]).view(
                _START_BLOCK, self.runs
            )
            self._start_block = block
        return self._block_starts[offset]

    def _uniforms(self) -> torch.Tensor:
        """``[R, T]`` uniforms of this episode, one per step and world, a pure function of (seed, episode)."""
        g = torch.Generator().manual_seed((self.seed * 1_000_003 + self.episode) % 2**64)  # any seed below 2^63
        return torch.rand(self.runs, self.cfg.max_steps, generator=g, dtype=torch.float64).to(self.device)

    def run_episode(self) -> dict[str, torch.Tensor]:
        """Learn for one episode; returns per-step ``r_pu``, ``r_se``, ``moves``, ``task_switches`` ``[R, T]``."""
        k0 = self._episode_starts()
        u = self._uniforms()
        out = (self._episode_numba if self.backend == "numba" else self._episode_torch)(k0, u)
        self.episode += 1
        return {"r_pu": out[..., 0], "r_se": out[..., 1], "moves": out[..., 2], "task_switches": out[..., 3]}

    def _episode_numba(self, k0, u):
        m, cfg = self.model, self.cfg
        out = np.empty((self.runs, cfg.max_steps, 4))
        k = k0.numpy().copy()
        kernel = _episode_shared if self.shared_table else _episode_per_run
        kernel(
            self.q.numpy(),
            k,
            u.numpy(),
            m.r_pu.numpy(),
            m.r_se.numpy(),
            m.row.numpy(),
            m.valid_actions.numpy(),
            m.num_valid.numpy(),
            m.next_cells.numpy(),
            m.next_tasks.numpy(),
            m.moves.numpy(),
            m.switches.numpy(),
            self.alpha,
            self.gamma,
            self.epsilon,
            cfg.beta1,
            cfg.beta2,
            cfg.reward == "best_so_far",
            out,
        )
        self._configuration = torch.from_numpy(k)
        return torch.from_numpy(out)

    def _episode_torch(self, k0, u):
        m, cfg, q = self.model, self.cfg, self.q
        R, T, T2, A = self.runs, cfg.max_steps, m.num_task_codes, cfg.num_joint_actions
        tables = (
            torch.zeros(R, dtype=torch.long, device=self.device)
            if self.shared_table
            else torch.arange(R, device=self.device)
        )
        out = torch.empty(R, T, 4, dtype=torch.float64, device=self.device)
        k = k0.to(self.device)
        prev = torch.stack([m.r_pu[k], m.r_se[k]], -1)
        best = torch.zeros(R, dtype=torch.float64, device=self.device)
        for step in range(T):
            p, t = k // T2, k % T2
            s = m.row[k]
            j = _choose_batched(q[tables, s], m.valid[p], u[:, step], self.epsilon)
            p2, t2 = m.next_cells[p, j].long(), m.next_tasks[t, j].long()
            k2 = p2 * T2 + t2
            r_pu, r_se = m.r_pu[k2], m.r_se[k2]
            if cfg.reward == "best_so_far":
                reward = best_so_far_reward(r_pu + r_se, best)
                best = torch.maximum(best, r_pu + r_se)
            else:
                reward = delta_reward(r_pu, r_se, prev[:, 0], prev[:, 1], cfg.beta1, cfg.beta2)
            prev = torch.stack([r_pu, r_se], -1)
            next_q = q[tables, m.row[k2]].masked_fill(~m.valid[p2], -math.inf).amax(-1)
            target = reward + self.gamma * next_q
            if self.shared_table:
                flat = s * A + j
                total = torch.zeros(q[0].numel(), dtype=torch.float64, device=self.device).index_add_(0, flat, target)
                count = torch.zeros(q[0].numel(), dtype=torch.float64, device=self.device).index_add_(
                    0, flat, torch.ones_like(target)
                )
                q0 = q[0].view(-1)
                q0[flat] = (1 - self.alpha) * q0[flat] + self.alpha * (total[flat] / count[flat])
            else:
                q[tables, s, j] = (1 - self.alpha) * q[tables, s, j] + self.alpha * target
            out[:, step, 0], out[:, step, 1] = r_pu, r_se
            out[:, step, 2], out[:, step, 3] = m.moves[p, j].double(), m.switches[t, j].double()
            k = k2
        self._configuration = k
        return out

    # checkpoints
    def state_dict(self) -> dict:
        return {
            "q": self.q.cpu(),
            "episode": self.episode,
            "configuration": None if self._configuration is None else self._configuration.cpu(),
        }

    def load_state_dict(self, state: dict):
        if state["q"].shape != self.q.shape:
            raise ValueError(
                f"checkpoint Q table has shape {tuple(state['q'].shape)}, this learner needs {tuple(self.q.shape)}: "
                "same env and agent settings are required"
            )
        self.q.copy_(state["q"])
        self.episode = int(state["episode"])
        self._configuration = None if state["configuration"] is None else state["configuration"].to(self.device)


def _nth_true_batched(mask: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
    return ((mask.cumsum(-1) == (n + 1).unsqueeze(-1)) & mask).int().argmax(-1)


def _choose_batched(q_rows, valid_rows, u, epsilon):
    """:func:`_choose` batched over worlds, same random numbers, same result."""
    explore = u < epsilon
    n_valid = valid_rows.sum(-1)
    random_pick = (
        _nth_true_batched(valid_rows, (u / epsilon * n_valid).long().clamp(max=valid_rows.shape[-1] - 1))
        if epsilon > 0
        else None
    )
    best = q_rows.masked_fill(~valid_rows, -math.inf).amax(-1, keepdim=True)
    ties = valid_rows & (q_rows == best)
    greedy = _nth_true_batched(ties, ((u - epsilon) / (1 - epsilon) * ties.sum(-1)).long().clamp(min=0))
    return greedy if random_pick is None else torch.where(explore, random_pick, greedy)


# ----------------------------------------------------------------------------- TorchRL policy
class TabularPolicy(TensorDictModuleBase):
    """Greedy valid joint action from a Q table ``[S, 6^N]``, as a TorchRL policy.

    Reads ``state_index`` and ``positions``; writes ``("agents", "action")``.
    Ties are broken uniformly at random (SPEC section 6) from the policy's own
    generator seeded ``seed``, so a rollout is reproducible.

    Example:
        >>> from uavrl.envs import UAVSpectrumEnv
        >>> env = UAVSpectrumEnv(batch_size=3, grid=(3, 3), num_uavs=2)
        >>> policy = TabularPolicy(torch.zeros(81, 36), env.cfg)
        >>> env.rollout(4, policy)["agents", "action"].shape
        torch.Size([3, 4, 2])
    """

    in_keys = ["state_index", "positions"]
    out_keys = [("agents", "action")]

    def __init__(self, q: torch.Tensor, cfg: ModelConfig, seed: int = 0):
        super().__init__()
        self.cfg = cfg
        env = UAVSpectrumEnv(batch_size=1, config=cfg, device=q.device)
        self.register_buffer("q", q)
        self.register_buffer("neighbours", env.neighbours)
        self.register_buffer("actions", decode_joint_actions(cfg.num_uavs, q.device))
        self.generator = torch.Generator(device=q.device).manual_seed(seed)

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        positions = td.get("positions").to(self.q.device)
        cells = positions[..., 1] * self.cfg.grid[0] + positions[..., 0]
        valid = joint_action_valid(cells, self.neighbours, self.cfg.num_uavs)
        values = self.q[td.get("state_index").to(self.q.device)].masked_fill(~valid, -math.inf)
        ties = values == values.amax(-1, keepdim=True)
        pick = (
            torch.rand(ties.shape, generator=self.generator, device=self.q.device).masked_fill(~ties, -1.0).argmax(-1)
        )
        td.set(("agents", "action"), self.actions[pick].to(td.device or self.q.device))
        return td


# ----------------------------------------------------------------------------- the uavrl agent
def exact_q_table(cfg: ModelConfig, gamma: float, device="cpu", memory_budget=DEFAULT_MEMORY_BUDGET) -> torch.Tensor:
    """The paper's "offline" table: exact ``Q*`` ``[S, 6^N]`` of the delta reward for the tabular state (SPEC section
    6).

    Solved on the configuration graph (:mod:`uavrl.envs.exact`, the environment's
    own dynamics and rates), infinite horizon, discount ``gamma``.  With
    ``state_includes_tasks`` a row is one configuration and holds ``Q*`` itself.
    The paper's location-only state hides the tasks, so no row can be exact for
    every task vector behind it: a row holds the mean of ``Q*`` over the task
    vectors an episode starts with (all ``2^N`` for ``init_tasks=random``, else
    the one), the value of acting from that location when the tasks are known
    only to come from the reset (QMDP).  Its greedy policy is the best such a
    table can express, not an optimal policy.  Invalid joint actions hold 0, as
    in a learned table (policies mask them).
    """
    if cfg.reward != "delta":
        raise ValueError(
            f"env.reward={cfg.reward!r} is invalid for agent.method=value_iteration: the best_so_far reward depends "
            "on the episode's past, not on the configuration; use env.reward=delta"
        )
    if cfg.layout == "random" or cfg.fading != "none":
        raise ValueError(
            "agent.method=value_iteration needs a fixed layout and deterministic channels (env.layout=line or "
            "reference_code, env.fading=none)"
        )
    need = cfg.num_states * cfg.num_joint_actions * 8
    if not cfg.has_state_index or need > memory_budget:
        raise ValueError(
            f"the exact Q table of {cfg.num_uavs} UAVs on {cfg.grid[0]}x{cfg.grid[1]} would need "
            f"{cfg.num_states * cfg.num_joint_actions * 8:,} bytes, over the memory budget of {int(memory_budget):,} "
            "bytes; raise agent.memory_budget or use agent=dqn"
        )
    N, C, A, dev = cfg.num_uavs, cfg.num_cells, cfg.num_joint_actions, torch.device(device)
    space = ConfigurationSpace(cfg.grid, N, dev)
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


class TabularAgent:
    """The tabular agent behind ``python -m uavrl.train agent=tabular`` (protocol in :mod:`uavrl.agents`).

    ``agent.method=q_learning`` (the paper's learner): one iteration is one
    episode of ``cfg.train.runs`` runs of ``cfg.train.steps_per_episode`` steps.
    ``agent.method=value_iteration``: one iteration solves :func:`exact_q_table`.
    """

    def __init__(self, env_cfg: ModelConfig, cfg, device, seed: int):
        a = cfg.agent
        self.method = a.get("method", "q_learning")
        if self.method not in METHODS:
            raise ValueError(
                f"agent.method={self.method!r} is invalid: allowed methods are {', '.join(map(repr, METHODS))}"
            )
        self.env_cfg, self.device = env_cfg, torch.device(device)
        if self.method == "value_iteration":
            if not 0 < float(a.gamma) <= 1:
                raise ValueError(f"agent.gamma={a.gamma} is invalid for value iteration: it must lie in (0, 1]")
            self.gamma, self.memory_budget = float(a.gamma), float(a.memory_budget)
            self.learner, self.q, self.num_iterations = None, None, 1
            return
        self.learner = TeamQLearner(
            env_cfg,
            runs=int(cfg.train.runs),
            seed=seed,
            alpha=a.alpha,
            gamma=a.gamma,
            epsilon=a.epsilon,
            shared_table=bool(a.shared_table),
            backend=a.backend,
            device=device,
            memory_budget=float(a.memory_budget),
        )
        self.num_iterations = int(cfg.train.episodes)
        self._u_star = torch.full((self.learner.runs,), self.learner.model.u_star, dtype=torch.float64)

    @property
    def env_steps(self) -> int:
        """Team steps per run so far (all runs advance together); value iteration takes none."""
        return 0 if self.learner is None else self.learner.episode * self.env_cfg.max_steps

    def train_iteration(self) -> dict[str, float]:
        if self.learner is None:
            started = time.perf_counter()
            self.q = exact_q_table(self.env_cfg, self.gamma, self.device, self.memory_budget)
            return {"train/solve_seconds": time.perf_counter() - started}
        steps = self.learner.run_episode()
        per_run = episode_metrics(
            steps["r_pu"], steps["r_se"], steps["task_switches"], steps["moves"], self._u_star.to(steps["r_pu"].device)
        )
        self.last_episode = per_run  # [R] each, for figures
        return {f"train/{k}": v.mean().item() for k, v in per_run.items()}

    def policies(self) -> list[TabularPolicy]:
        tables = self.learner.q if self.learner is not None else [self.q]
        return [TabularPolicy(q, self.env_cfg) for q in tables]

    def state_dict(self) -> dict:
        return (
            self.learner.state_dict() if self.learner is not None else {"q": None if self.q is None else self.q.cpu()}
        )

    def load_state_dict(self, state: dict):
        if self.learner is not None:
            self.learner.load_state_dict(state)
        else:
            self.q = None if state["q"] is None else state["q"].to(self.device)
