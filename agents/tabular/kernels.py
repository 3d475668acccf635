"""The learner's episode loops: compiled (numba) over the model tables, and the same choice batched in torch.

``_episode_per_run`` runs ``R`` independent tables in parallel (``prange``),
``_episode_shared`` feeds one table from ``R`` worlds synchronously;
:func:`_choose_batched` is :func:`_choose` over a batch of worlds in torch, so
the torch backend of :class:`~uavrl.agents.tabular.TeamQLearner` makes the same
choices from the same random numbers.  Call :func:`use_workqueue_threads`
before the first parallel launch.
"""

from __future__ import annotations

import math
import os

import numba
import numpy as np
import torch

from uavrl.envs.channel import best_so_far_reward, delta_reward


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
