"""The learner's episode loops: compiled (numba) over the model tables, and the same choice batched in torch.

``_episode_per_run`` runs ``R`` independent tables in parallel (``prange``),
``_episode_shared`` feeds one table from ``R`` worlds synchronously;
:func:`_choose_batched` is :func:`_choose` over a batch of worlds in torch, so
the torch backend of :class:`~uavrl.agents.tabular.TeamQLearner` makes the same
choices from the same random numbers.  Both backends reward a step with
:func:`uavrl.envs.physics.rewards.team_reward` and sum its metrics with
:func:`uavrl.agents.episodes.episode_step`, the same Python functions (numba
compiles them for scalars here).  Call :func:`use_workqueue_threads` before
the first parallel launch.

numba's cache of these kernels (``cache=True``) is keyed by this file alone, but
they also compile functions of other modules (:data:`COMPILED_ELSEWHERE`).
:data:`COMPILED_ELSEWHERE_DIGEST` is the digest of their source: a change there
fails ``tests/agents/test_tabular.py`` until the digest here is updated, and that edit of
this file is what makes numba compile the kernels anew.
"""

from __future__ import annotations

import hashlib
import inspect
import math
import os

import numba
import numpy as np
import torch
from numba.extending import register_jitable

from uavrl.agents.episodes import episode_start, episode_step
from uavrl.envs.physics import streams
from uavrl.envs.physics.rewards import best_so_far_reward, delta_reward, episode_best, team_reward

# the reward and the episode metrics are written once, in arithmetic that serves the torch loop's tensors and these
# loops' scalars: numba compiles that same Python source where a kernel calls them
COMPILED_ELSEWHERE = (delta_reward, best_so_far_reward, episode_best, team_reward, episode_start, episode_step)
for _written_once in COMPILED_ELSEWHERE:
    register_jitable(_written_once)
COMPILED_ELSEWHERE += (streams._mix32,)
COMPILED_ELSEWHERE_DIGEST = "1b7ce943780bd4f8"  # sources_digest(COMPILED_ELSEWHERE): see the module docstring


def sources_digest(functions) -> str:
    """SHA-256 (first 16 hex digits) of the functions' source text, in order."""
    text = "".join(inspect.getsource(function) for function in functions)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def use_workqueue_threads() -> None:
    """Run the parallel loops on numba's workqueue threading layer, unless ``NUMBA_THREADING_LAYER`` picks one.

    numba's OpenMP layer shares the process with torch's OpenMP runtime and
    costs ~15 ms a parallel call here (threads waking up); the workqueue layer
    costs microseconds.  numba reads the setting when it first launches its
    threads (the first parallel kernel, or ``numba.set_num_threads``), so this
    is called just before those; later calls change nothing.
    """
    if "NUMBA_THREADING_LAYER" not in os.environ and not numba.np.ufunc.parallel._is_initialized:
        numba.config.THREADING_LAYER = "workqueue"


_mix32 = numba.njit(streams._mix32)  # the random streams' mixer, compiled for ints: bit for bit the torch one


@numba.njit(cache=True, inline="always")
def _lane_uniform(head, lane):
    """Lane ``lane`` of the random stream with head ``head`` as a uniform: :func:`uavrl.envs.physics.streams.lane_bits`
    times ``UNIFORM_SCALE``, the numbers the torch loop draws."""
    return _mix32((head + lane * streams._GOLDEN) & streams._M32) * streams.UNIFORM_SCALE


@numba.njit(cache=True, inline="always")
def _scan(q, table, s, valid, p, n_valid):
    """Best value of row ``q[table, s]`` over the first ``n_valid`` valid joint actions ``valid[p]``, how many tie
    for it, and the first of them.  (Indices, not row views: a view costs an atomic reference count.)"""
    best, ties, best_j = -np.inf, 0, -1
    for i in range(n_valid):
        j = valid[p, i]
        value = q[table, s, j]
        if value > best:
            best, ties, best_j = value, 1, j
        elif value == best:
            ties += 1
    return best, ties, best_j


@numba.njit(cache=True, inline="always")
def _choose(q, table, s, valid, p, n_valid, u, epsilon, best, ties, best_j):
    """Epsilon-greedy action among the valid ``valid[p, :n_valid]`` (ascending) from one uniform ``u``, given the
    row's :func:`_scan`.

    ``u < epsilon`` explores, and then ``u / epsilon`` is a fresh uniform that
    picks the valid action; otherwise ``(u - epsilon) / (1 - epsilon)`` picks
    among the tied best ones.
    """
    if u < epsilon:
        return valid[p, int(u / epsilon * n_valid)]
    if ties == 1:
        return best_j
    n = int((u - epsilon) / (1 - epsilon) * ties)
    for i in range(n_valid):
        if q[table, s, valid[p, i]] == best:
            if n == 0:
                return valid[p, i]
            n -= 1
    return -1


@numba.njit(cache=True, inline="always")
def _log2(power_of_two):
    """``N`` of ``2^N``: configurations are ``k = p 2^N + t``, so ``p = k >> N`` and ``t = k & (2^N - 1)``."""
    n = 0
    while (1 << n) < power_of_two:
        n += 1
    return n


@numba.njit(cache=True, inline="always")
def _store(out, r, metrics):
    """Run ``r``'s episode metrics (:func:`~uavrl.agents.episodes.episode_step`) to ``out[r]``, the columns in their
    order (:data:`~uavrl.agents.episodes.EPISODE_METRICS`)."""
    for column in range(len(metrics)):
        out[r, column] = metrics[column]


@numba.njit(cache=True)
def _run_episode(q, r, k, heads, T, model, learning, out):
    """Run ``r``'s episode of ``T`` steps on table ``q[r]`` from configuration ``k``; returns the last configuration.

    Step ``t`` draws lane ``t`` of the random stream with head ``heads[r]``
    (:func:`uavrl.envs.physics.streams.stream_heads`).  The episode's metrics
    (:func:`~uavrl.agents.episodes.episode_step`) go to ``out[r]``.

    ``model`` holds the tables of :attr:`TabularModel.kernel_tables`, ``learning`` the constants
    ``(alpha, gamma, epsilon, beta1, beta2, use_best_so_far, 0.9 U*)``.  The scan of the next state's row that
    gives the target's max is also the next step's greedy choice, so each step scans one row (two when it stays
    in the row it just updated).  The run's state lives in locals, not in arrays shared with the other runs'
    threads.
    """
    rates, row_t, valid, n_valid, next_cells, next_tasks, moves_t, switches_t = model
    alpha, gamma, epsilon, beta1, beta2, use_best, u90 = learning
    T2, head = next_tasks.shape[0], heads[r]
    shift, task_mask = _log2(T2), T2 - 1
    prev_pu, prev_se, best = rates[k, 0], rates[k, 1], 0.0
    metrics = episode_start(0.0, T)
    p = k >> shift
    v_best, ties, best_j = _scan(q, r, row_t[k], valid, p, n_valid[p])
    for step in range(T):
        s, p, t = row_t[k], k >> shift, k & task_mask
        u = _lane_uniform(head, step)
        j = _choose(q, r, s, valid, p, n_valid[p], u, epsilon, v_best, ties, best_j)
        k2 = (next_cells[p, j] << shift) + next_tasks[t, j]
        r_pu, r_se = rates[k2, 0], rates[k2, 1]
        reward, best = team_reward(r_pu, r_se, prev_pu, prev_se, best, use_best, beta1, beta2)
        prev_pu, prev_se = r_pu, r_se
        s2, p2 = row_t[k2], k2 >> shift
        v_best, ties, best_j = _scan(q, r, s2, valid, p2, n_valid[p2])
        q[r, s, j] = (1 - alpha) * q[r, s, j] + alpha * (reward + gamma * v_best)
        if s2 == s:
            v_best, ties, best_j = _scan(q, r, s2, valid, p2, n_valid[p2])
        metrics = episode_step(metrics, step + 1, r_pu, r_se, switches_t[t, j], moves_t[p, j], u90)
        k = k2
    _store(out, r, metrics)
    return k


@numba.njit(cache=True, parallel=True)
def _episode_per_run(q, k0, heads, T, model, learning, out):
    """One episode of ``R`` independent runs in parallel, run ``r`` on table ``q[r]`` (:func:`_run_episode`)."""
    for r in numba.prange(len(heads)):
        k0[r] = _run_episode(q, r, k0[r], heads, T, model, learning, out)


@numba.njit(cache=True)
def _episode_shared(q, k0, heads, T, model, learning, out):
    """One episode of ``R`` worlds feeding the single table ``q[0]`` synchronously (see module doc); arguments as
    :func:`_run_episode`'s."""
    rates, row_t, valid, n_valid, next_cells, next_tasks, moves_t, switches_t = model
    alpha, gamma, epsilon, beta1, beta2, use_best, u90 = learning
    R, T2 = len(heads), next_tasks.shape[0]
    shift, task_mask = _log2(T2), T2 - 1
    A = q.shape[2]
    prev = np.empty((R, 2))
    best = np.zeros(R)
    metrics = [episode_start(0.0, T)] * R
    s_w = np.empty(R, np.int64)
    j_w = np.empty(R, np.int64)
    target_w = np.empty(R)
    total = np.zeros(q.shape[1] * A)
    count = np.zeros(q.shape[1] * A, np.int64)
    for w in range(R):
        prev[w, 0], prev[w, 1] = rates[k0[w], 0], rates[k0[w], 1]
    for step in range(T):
        for w in range(R):
            k = k0[w]
            s, p, t = row_t[k], k >> shift, k & task_mask
            v_best, ties, best_j = _scan(q, 0, s, valid, p, n_valid[p])
            u = _lane_uniform(heads[w], step)
            j = _choose(q, 0, s, valid, p, n_valid[p], u, epsilon, v_best, ties, best_j)
            k2 = (next_cells[p, j] << shift) + next_tasks[t, j]
            r_pu, r_se = rates[k2, 0], rates[k2, 1]
            reward, best[w] = team_reward(r_pu, r_se, prev[w, 0], prev[w, 1], best[w], use_best, beta1, beta2)
            prev[w, 0], prev[w, 1] = r_pu, r_se
            s_w[w], j_w[w], k0[w] = s, j, k2
            p2 = k2 >> shift
            target_w[w] = reward + gamma * _scan(q, 0, row_t[k2], valid, p2, n_valid[p2])[0]
            metrics[w] = episode_step(metrics[w], step + 1, r_pu, r_se, switches_t[t, j], moves_t[p, j], u90)
        for w in range(R):
            f = s_w[w] * A + j_w[w]
            total[f] += target_w[w]
            count[f] += 1
        for w in range(R):
            f = s_w[w] * A + j_w[w]
            if count[f] > 0:
                q[0, s_w[w], j_w[w]] = (1 - alpha) * q[0, s_w[w], j_w[w]] + alpha * (total[f] / count[f])
                total[f] = 0.0
                count[f] = 0
    for w in range(R):
        _store(out, w, metrics[w])


# ----------------------------------------------------------------------------- the same choice in torch
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
