"""The team reward and the episode metrics, written once for the torch loops (tensors) and the tabular learner's
compiled loops (numba scalars): both forms, and the batched episode_metrics of the DQN and the evaluation, against
computations written here."""

import numba
import numpy as np
import pytest
import torch

from uavrl.agents.episodes import EPISODE_METRICS, NINETY_PERCENT, episode_metrics, episode_start, episode_step
from uavrl.agents.tabular import kernels  # noqa: F401  (registers the written-once functions with numba)
from uavrl.envs.physics.rewards import episode_best, team_reward


@numba.njit
def _compiled_metrics(r_pu, r_se, task_switches, moves, u_star):
    """episode_step over each episode's steps in scalars, as the kernels sum them."""
    W, T = r_pu.shape
    out = np.empty((W, 6))
    for w in range(W):
        metrics = episode_start(0.0, T)
        for t in range(T):
            u90 = NINETY_PERCENT * u_star[w]
            metrics = episode_step(metrics, t + 1, r_pu[w, t], r_se[w, t], task_switches[w, t], moves[w, t], u90)
        for column in range(6):
            out[w, column] = metrics[column]
    return out


@numba.njit
def _compiled_rewards(r_pu, r_se, start, use_best_so_far, beta1, beta2):
    W, T = r_pu.shape
    rewards, bests = np.empty((W, T)), np.empty((W, T))
    for w in range(W):
        prev_pu, prev_se, best = start[w, 0], start[w, 1], 0.0
        for t in range(T):
            rewards[w, t], best = team_reward(
                r_pu[w, t], r_se[w, t], prev_pu, prev_se, best, use_best_so_far, beta1, beta2
            )
            bests[w, t], prev_pu, prev_se = best, r_pu[w, t], r_se[w, t]
    return rewards, bests


def plain_metrics(r_pu, r_se, task_switches, moves, u_star) -> dict[str, list[float]]:
    """docs/model.md, "What the numbers mean", one episode at a time in Python floats: the sums of R_PU, R_SE, U,
    task switches and moves added in step order, and the first step (from 1) whose U reaches 90% of U* (T if
    none)."""
    out = {key: [] for key in EPISODE_METRICS}
    steps = [x.tolist() for x in (r_pu, r_se, task_switches, moves)]
    for w, best in enumerate(u_star.tolist()):
        pu, se, switches, moved = (x[w] for x in steps)
        sums, first = [0.0] * 5, None
        for t in range(len(pu)):
            for i, value in enumerate((pu[t], se[t], pu[t] + se[t], switches[t], moved[t])):
                sums[i] += value
            if first is None and pu[t] + se[t] >= 0.9 * best:
                first = t + 1
        for key, value in zip(EPISODE_METRICS, [*sums, float(first or len(pu))], strict=True):
            out[key].append(value)
    return out


def steps_around_ninety_percent(T=50):
    """Steps of six episodes whose utility stays below 90% of U* except where planted: never (0), exactly at the
    level at step 1 (1), above it at the last step only (2), first at step 17 (3), a hair below it at 17 and
    above at 30 (4), and unplanted random rates above it now and then (5)."""
    g = torch.Generator().manual_seed(0)
    r_pu = torch.rand(6, T, generator=g, dtype=torch.float64)
    r_se = torch.rand(6, T, generator=g, dtype=torch.float64)
    u_star = torch.full((6,), 2.5 / 0.9, dtype=torch.float64)
    u_star[5] = 1.2 / 0.9
    u90 = NINETY_PERCENT * u_star
    for w, t, value in [(1, 0, u90[1]), (2, T - 1, u90[2] + 1), (3, 16, u90[3]), (3, 29, u90[3] + 1)]:
        r_pu[w, t], r_se[w, t] = value, 0.0
    r_pu[4, 16], r_se[4, 16] = torch.nextafter(u90[4], torch.tensor(0.0, dtype=torch.float64)), 0.0
    r_pu[4, 29], r_se[4, 29] = u90[4], 0.0
    task_switches = torch.randint(0, 3, (6, T), generator=g).to(torch.int8)
    moves = torch.randint(0, 3, (6, T), generator=g).to(torch.int8)
    return r_pu, r_se, task_switches, moves, u_star


def test_episode_step_and_episode_metrics_give_the_metrics_of_the_steps():
    r_pu, r_se, task_switches, moves, u_star = steps_around_ninety_percent()
    T = r_pu.shape[1]
    expected = plain_metrics(r_pu, r_se, task_switches, moves, u_star)
    assert expected["steps_to_90"] == [50.0, 1.0, 50.0, 17.0, 30.0, expected["steps_to_90"][5]]
    assert 1 < expected["steps_to_90"][5] < 50

    metrics = episode_start(torch.zeros(6, dtype=torch.float64), T)  # the torch loop's form: [W] tensors
    for t in range(T):
        step = (r_pu[:, t], r_se[:, t], task_switches[:, t].double(), moves[:, t].double())
        metrics = episode_step(metrics, t + 1, *step, NINETY_PERCENT * u_star)
    compiled = _compiled_metrics(r_pu.numpy(), r_se.numpy(), task_switches.numpy(), moves.numpy(), u_star.numpy())
    batched = episode_metrics(r_pu, r_se, task_switches, moves, u_star)
    assert list(batched) == list(EPISODE_METRICS)
    for column, key in enumerate(EPISODE_METRICS):
        want = torch.tensor(expected[key], dtype=torch.float64)
        assert torch.equal(metrics[column], want), key  # in step order: bit for bit
        assert torch.equal(torch.from_numpy(compiled[:, column]), want), key
        if key.startswith("sum_"):  # batched sums add pairwise: equal up to rounding
            torch.testing.assert_close(batched[key], want, rtol=1e-13, atol=0)
        else:
            assert torch.equal(batched[key], want), key


@pytest.mark.parametrize("use_best_so_far", [False, True])
def test_team_reward_is_the_reward_of_docs_model_on_tensors_and_compiled(use_best_so_far):
    """eq. 7 (delta), or 10 (S - M) above the episode's best M (0 before the first step) and S - M below it; the
    best is the larger one exactly, also where best + (total - best) rounds away from total."""
    g = torch.Generator().manual_seed(1)
    r_pu = torch.rand(4, 30, generator=g, dtype=torch.float64)
    r_se = torch.rand(4, 30, generator=g, dtype=torch.float64)
    r_pu[:, 7], r_se[:, 7] = r_pu[:, 5], r_se[:, 5]  # revisits: a level step and ties with the best
    r_pu[0, 2], r_se[0, 2] = 0.0014655124839901626, 0.0  # a best whose gap to the next rounds back
    r_pu[0, 3], r_se[0, 3] = 0.07451806700073295, 0.0
    r_pu[0, :2], r_se[0, :2] = 0.0, 0.0
    start = torch.rand(4, 2, generator=g, dtype=torch.float64)
    beta1, beta2 = 1.5, 0.5
    want_rewards, want_bests = [], []
    for w in range(4):
        prev, best, rewards, bests = start[w].tolist(), 0.0, [], []
        for pu, se in zip(r_pu[w].tolist(), r_se[w].tolist(), strict=True):
            if use_best_so_far:
                gain = pu + se - best
                rewards.append(10 * gain if gain > 0 else gain)
                best = max(best, pu + se)
            else:
                rewards.append(beta1 * (pu - prev[0]) + beta2 * (se - prev[1]))
            bests.append(best)
            prev = [pu, se]
        want_rewards.append(rewards)
        want_bests.append(bests)
    want_rewards, want_bests = (torch.tensor(x, dtype=torch.float64) for x in (want_rewards, want_bests))

    prev, best, rewards, bests = start.unbind(-1), torch.zeros(4, dtype=torch.float64), [], []
    for t in range(30):
        reward, best = team_reward(r_pu[:, t], r_se[:, t], *prev, best, use_best_so_far, beta1, beta2)
        rewards.append(reward)
        bests.append(best)
        prev = (r_pu[:, t], r_se[:, t])
    compiled = _compiled_rewards(r_pu.numpy(), r_se.numpy(), start.numpy(), use_best_so_far, beta1, beta2)
    assert torch.equal(torch.stack(rewards, -1), want_rewards)
    assert torch.equal(torch.from_numpy(compiled[0]), want_rewards)
    assert torch.equal(torch.stack(bests, -1), want_bests)
    assert torch.equal(torch.from_numpy(compiled[1]), want_bests)
    if use_best_so_far:
        assert (want_rewards == 0).any() and (want_rewards < 0).any() and (want_rewards > 0).any()
        best, total = 0.0014655124839901626, 0.07451806700073295
        assert best + (total - best) != total and episode_best(total, best) == total


def test_episode_best_is_the_larger_one_of_tensors_bit_for_bit():
    g = torch.Generator().manual_seed(2)
    total = torch.rand(10_000, generator=g, dtype=torch.float64) * 10.0 ** torch.randint(-5, 2, (10_000,), generator=g)
    best = torch.rand(10_000, generator=g, dtype=torch.float64) * 10.0 ** torch.randint(-5, 2, (10_000,), generator=g)
    best[:100] = total[:100]
    assert torch.equal(episode_best(total, best), torch.maximum(total, best))
