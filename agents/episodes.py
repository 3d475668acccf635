"""The per-episode metrics every learner records while it trains (``train/...``; docs/model.md, "What the numbers
mean"), and the clock that leaves its evaluations out of its training time.

The metrics are written once for the torch loops (:func:`episode_metrics`, tensors ``[W, T]``) and, step by step, for
the tabular learner's loops (:func:`episode_start`, :func:`episode_step`: arithmetic only, compiled by numba too).
"""

from __future__ import annotations

import contextlib
import time

import torch

NINETY_PERCENT = 0.9
# the per-episode metrics of every agent's training (docs/model.md, "What the numbers mean"; train/<name>), in the
# order of episode_metrics and of the running metrics of episode_start / episode_step
EPISODE_METRICS = ("sum_r_pu", "sum_r_se", "sum_utility", "task_switches", "moves", "steps_to_90")


def episode_metrics(r_pu, r_se, task_switches, moves, u_star, utility=None) -> dict[str, torch.Tensor]:
    """The per-episode metrics of docs/model.md ("What the numbers mean").  Inputs ``[W, T]`` for ``W`` episodes of
    ``T`` steps, ``u_star`` ``[W]``.

    Returns ``[W]`` tensors: the sums over steps of R_PU, R_SE and U (Fig. 3), of
    task switches and moves (Fig. 4), and the number of steps until U first
    reaches 90% of U* (Fig. 5; T if never).  ``utility`` ``[W, T]``, the
    mean-channel utility, decides that under fading (default: R_PU + R_SE).

    Args:
        r_pu: each step's primary rate R_PU ``[W, T]`` (bit/s/Hz).
        r_se: each step's emergency rate R_SE ``[W, T]`` (bit/s/Hz).
        task_switches: each step's task switches ``[W, T]``.
        moves: each step's moves ``[W, T]``.
        u_star: each episode's best utility U* ``[W]``.
        utility: the mean-channel utility ``[W, T]``, or None.

    Example:
        >>> rates = torch.tensor([[0.5, 1.0, 1.0]])
        >>> metrics = episode_metrics(rates, rates, torch.zeros(1, 3), torch.ones(1, 3), torch.tensor([2.0]))
        >>> metrics["sum_utility"], metrics["moves"], metrics["steps_to_90"]
        (tensor([5.], dtype=torch.float64), tensor([3.], dtype=torch.float64), tensor([2.], dtype=torch.float64))
    """
    sum_utility = (r_pu + r_se).double()
    reach_utility = sum_utility if utility is None else utility.double()
    T = sum_utility.shape[-1]
    reached = reach_utility >= NINETY_PERCENT * u_star.double().unsqueeze(-1)
    first = torch.where(reached.any(-1), reached.double().argmax(-1) + 1, torch.full_like(u_star.double(), T))
    return {  # the order of EPISODE_METRICS
        "sum_r_pu": r_pu.double().sum(-1),
        "sum_r_se": r_se.double().sum(-1),
        "sum_utility": sum_utility.sum(-1),
        "task_switches": task_switches.double().sum(-1),
        "moves": moves.double().sum(-1),
        "steps_to_90": first.double(),
    }


def episode_start(zero, num_steps):
    """The running metrics of an episode of ``num_steps`` steps before its first step: a tuple in the order of
    :data:`EPISODE_METRICS`, each ``zero`` (``0.0``, or a tensor of zeros ``[W]`` for ``W`` episodes) plus its start
    value.  ``steps_to_90`` starts at ``num_steps``, what it stays at if 90% of U* is never reached."""
    return zero, zero, zero, zero, zero, zero + num_steps


def episode_step(metrics, step, r_pu, r_se, task_switches, moves, u90):
    """The running metrics ``metrics`` (:func:`episode_start`) after step number ``step`` (from 1) of the episode,
    to rates ``(r_pu, r_se)`` with ``task_switches`` and ``moves``; ``u90`` is 90% of U*.

    The metrics of :func:`episode_metrics`, one step at a time: the sums add the steps in order; ``steps_to_90``
    becomes the first step whose utility reaches ``u90``.  Arithmetic only, so it serves the tabular learner's
    torch loop (tensors ``[W]``) and, compiled by numba, its scalar loops: both add the same numbers in the same
    order, bit for bit.
    """
    sum_r_pu, sum_r_se, sum_utility, sum_switches, sum_moves, steps_to_90 = metrics
    utility = r_pu + r_se
    first = (utility >= u90) * (step < steps_to_90)
    return (
        sum_r_pu + r_pu,
        sum_r_se + r_se,
        sum_utility + utility,
        sum_switches + task_switches,
        sum_moves + moves,
        steps_to_90 + (step - steps_to_90) * first,
    )


class TrainingClock:
    """Seconds spent training so far in this process, wall and CPU, with the evaluations taken along the way left
    out (run them inside :meth:`paused`): a learning curve against time (``time/train_seconds`` and
    ``time/train_cpu_seconds`` beside each evaluation's ``eval/...``) then shows what the training itself cost,
    however often it was measured, for every agent (BenchMARL's too)."""

    def __init__(self):
        self.started, self.started_cpu = time.perf_counter(), time.process_time()
        self.paused_seconds = self.paused_cpu_seconds = 0.0

    @contextlib.contextmanager
    def paused(self):
        began, began_cpu = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self.paused_seconds += time.perf_counter() - began
            self.paused_cpu_seconds += time.process_time() - began_cpu

    def read(self) -> dict[str, float]:
        return {
            "time/train_seconds": time.perf_counter() - self.started - self.paused_seconds,
            "time/train_cpu_seconds": time.process_time() - self.started_cpu - self.paused_cpu_seconds,
        }
