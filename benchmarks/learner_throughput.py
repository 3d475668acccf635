"""Team Q-learning throughput: the compiled loop beside a plain Python loop, same run, same tables.

    python benchmarks/learner_throughput.py            # learner steps/s
    python benchmarks/learner_throughput.py --table2   # also the whole Table II protocol, wall time

The plain loop is the learner written the direct way (one Python iteration per
step over the same lookup tables, like the authors' code): the baseline the
compiled loop is compared with.  The batched torch loop is the device-agnostic
path (CUDA on a GPU), shown for reference.
"""

from __future__ import annotations

import argparse
import math
import time

import numba
import torch

from uavrl.agents.tabular import TeamQLearner
from uavrl.agents.tabular.kernels import use_workqueue_threads
from uavrl.envs import make_config


def plain_python_episode(learner: TeamQLearner, steps: int) -> None:
    """The same update as the compiled loop, one Python step at a time (run 0, delta reward)."""
    m, q = learner.model, learner.q[0].numpy()
    valid, next_cells, next_tasks = m.valid.numpy(), m.next_cells.numpy(), m.next_tasks.numpy()
    r_pu, r_se, row = m.r_pu.numpy(), m.r_se.numpy(), m.row.numpy()
    T2, eps, alpha, gamma = m.num_task_codes, learner.epsilon, learner.alpha, learner.gamma
    g = torch.Generator().manual_seed(0)
    uniforms = torch.rand(steps, generator=g, dtype=torch.float64).tolist()
    k = 0
    prev = r_pu[k] + r_se[k]
    for u in uniforms:
        p, t = divmod(k, T2)
        s = row[k]
        actions = [j for j in range(valid.shape[1]) if valid[p, j]]
        if u < eps:
            j = actions[int(u / eps * len(actions))]
        else:
            best = max(q[s, a] for a in actions)
            ties = [a for a in actions if q[s, a] == best]
            j = ties[int((u - eps) / (1 - eps) * len(ties))]
        k2 = next_cells[p, j] * T2 + next_tasks[t, j]
        total = r_pu[k2] + r_se[k2]
        target = total - prev + gamma * max(q[row[k2], a] for a in range(valid.shape[1]) if valid[k2 // T2, a])
        q[s, j] = (1 - alpha) * q[s, j] + alpha * target
        prev, k = total, k2


def rate(fn, steps: int, repeat: int = 3) -> float:
    best = math.inf
    for _ in range(repeat):
        started = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - started)
    return steps / best


def training_rate(cfg, runs: int, episodes: int) -> float:
    """Team steps/s of a whole training run from an empty table (early episodes, full of ties, included)."""
    learner = TeamQLearner(cfg, runs=runs, seed=0)
    started = time.perf_counter()
    for _ in range(episodes):
        learner.run_episode()
    return runs * episodes * cfg.max_steps / (time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=6)
    parser.add_argument("--steps", type=int, default=12000, help="steps per episode (Table II: 12,000 on 6x6)")
    parser.add_argument("--episodes", type=int, default=200, help="episodes of the timed training runs (Table II: 200)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--table2", action="store_true", help="also time the whole Table II protocol")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    use_workqueue_threads()  # as the learner does, before numba.get_num_threads() launches the threads
    cfg = make_config("paper", grid=(args.grid, args.grid), num_uavs=2, max_steps=args.steps)
    print(
        f"team Q-learning, N=2, {args.grid}x{args.grid}, {args.steps} steps/episode, torch threads {args.threads}, "
        f"numba threads {numba.get_num_threads()} ({numba.config.THREADING_LAYER} layer)"
    )

    TeamQLearner(cfg, runs=1, seed=0).run_episode()  # compile
    fast_one = training_rate(cfg, 1, args.episodes)
    fast_ten = training_rate(cfg, 10, args.episodes)
    one = TeamQLearner(cfg, runs=1, seed=0)
    plain_steps = 20000
    plain = rate(lambda: plain_python_episode(one, plain_steps), plain_steps, repeat=1)
    short = cfg.replace(max_steps=500)
    torch_one = TeamQLearner(short, runs=1, seed=0, backend="torch")
    torch_ten = TeamQLearner(short, runs=10, seed=0, backend="torch")
    batched_one = rate(torch_one.run_episode, 500, repeat=1)
    batched_ten = rate(torch_ten.run_episode, 5000, repeat=1)
    print(f"{'loop':44s} {'team steps/s':>14s} {'vs plain':>9s}")
    for name, value in [
        ("plain Python loop (baseline), 1 run", plain),
        (f"compiled loop (numba), 1 run x {args.episodes} episodes", fast_one),
        (f"compiled loop (numba), 10 runs x {args.episodes} episodes", fast_ten),
        ("batched torch loop, 1 run", batched_one),
        ("batched torch loop, 10 runs", batched_ten),
    ]:
        print(f"{name:44s} {value:14,.0f} {value / plain:8.0f}x")
    print(f"target: >= 5,000,000 team steps/s for one run: {'met' if fast_one >= 5e6 else 'NOT met'}")

    if args.table2:
        from omegaconf import OmegaConf

        from uavrl.experiment.reproducing import table2

        cfg2 = OmegaConf.load(__file__.replace("benchmarks/learner_throughput.py", "configs/reproduce.yaml"))
        cfg2.progress, cfg2.out_dir = False, "/tmp/uavrl-bench-table2"
        started = time.perf_counter()
        table2(cfg2)
        wall = time.perf_counter() - started
        print(
            f"Table II protocol (7 grids x 10 runs x 200 episodes, with evaluation): {wall:.1f} s wall; target <= 30 "
            f"s: {'met' if wall <= 30 else 'NOT met'}"
        )


if __name__ == "__main__":
    main()
