"""The reproduction as whole processes, beside a plain compiled loop of the same protocol.

    python benchmarks/reproduction.py                 # 3 interleaved rounds of the four processes below
    python benchmarks/reproduction.py --rounds 5 --skip-table

Each round runs, as separate processes timed from outside (imports, table
building and compilation included, as a user meets them):

* ``plain 6x6``: :func:`plain_protocol`, the paper's learner written as one
  plain numba loop in this file: N = 2 on 6x6, 10 runs x 200 episodes x
  12,000 steps, a float32 table, epsilon-greedy over the valid joint actions
  with random tie-breaking, one thread, no metrics, no evaluation, no files;
* ``ours 6x6``: ``python -m uavrl.reproduce table2 grids=[6] runs=10 episodes=200``;
* ``plain Table II`` and ``ours Table II``: the same over all of Table II's
  grids (``python -m uavrl.reproduce table2``).

``--kernel`` instead times the learning loops alone, in one process, one
thread each: the plain loop against ours (``TeamQLearner``'s compiled kernel
with one numba thread, its episode metrics included), the same protocol per
grid, alternating, best of ``--rounds``: team steps per second per thread.

The processes of a round run one after the other, rounds interleave them, and
each figure is the median (and the best) over rounds, as wall time and as CPU
time (user + system: less moved by other work on the machine, but it counts
both cores' work when ours runs its learners in parallel); the load average
is printed beside them (other people's work shares the cores).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numba
import numpy as np

TABLE2_STEPS = {2: 120, 3: 800, 4: 2000, 5: 5000, 6: 12000, 8: 20000, 10: 30000}


@numba.njit(cache=True)
def tables(contrib, direct, side, lease):
    """Two UAVs: per configuration k = (c0 C + c1) 4 + tasks the rates; per cell pair and joint action the
    valid flag and the next cells."""
    C = side * side
    r_pu, r_se = np.zeros(C * C * 4), np.zeros(C * C * 4)
    valid = np.zeros((C * C, 36), np.bool_)
    next_cells = np.zeros((C * C, 36), np.int64)
    moves = ((0, -1), (0, 1), (-1, 0), (1, 0), (0, 0), (0, 0))
    for c0 in range(C):
        for c1 in range(C):
            p = c0 * C + c1
            for t in range(4):
                relay0, relay1 = t & 1, t >> 1
                pu = direct[0] + relay0 * contrib[c0, 0] + relay1 * contrib[c1, 0]
                se = direct[1] + (1 - relay0) * contrib[c0, 1] + (1 - relay1) * contrib[c1, 1]
                r_pu[p * 4 + t] = 0.5 * np.log2(1 + pu)
                r_se[p * 4 + t] = 0.0 if lease and relay0 + relay1 == 0 else 0.5 * np.log2(1 + se)
            for j in range(36):
                a0, a1 = j % 6, j // 6
                x0, y0 = c0 % side + moves[a0][0], c0 // side + moves[a0][1]
                x1, y1 = c1 % side + moves[a1][0], c1 // side + moves[a1][1]
                on = 0 <= x0 < side and 0 <= y0 < side and 0 <= x1 < side and 0 <= y1 < side
                if on and (x0, y0) != (x1, y1) and c0 != c1:
                    valid[p, j] = True
                    next_cells[p, j] = (y0 * side + x0) * C + y1 * side + x1
    return r_pu, r_se, valid, next_cells


@numba.njit(cache=True)
def plain_protocol(r_pu, r_se, valid, next_cells, C, runs, episodes, steps, alpha, gamma, epsilon, seed):
    """The learner the direct way: one uniform per step explores or breaks the greedy ties among the valid joint
    actions (listed once per cell pair), a float32 table, the delta reward, the target's max by a second scan."""
    np.random.seed(seed)
    q = np.zeros((C * C, 36), np.float32)
    actions, n_valid = np.zeros((C * C, 36), np.int64), valid.sum(1)
    for p in range(C * C):
        actions[p, : n_valid[p]] = np.nonzero(valid[p])[0]
    for _ in range(runs):
        q[:] = 0
        for _ in range(episodes):
            c0 = np.random.randint(C)
            c1 = (c0 + 1 + np.random.randint(C - 1)) % C
            k = (c0 * C + c1) * 4 + np.random.randint(4)
            for _ in range(steps):
                p, t, n, u = k >> 2, k & 3, n_valid[k >> 2], np.random.random()
                if u < epsilon:
                    j = actions[p, int(u / epsilon * n)]
                else:
                    best, ties = -np.inf, 0
                    for i in range(n):
                        v = q[p, actions[p, i]]
                        if v > best:
                            best, ties, j = v, 1, actions[p, i]
                        elif v == best:
                            ties += 1
                    if ties > 1:  # the m-th of the tied actions
                        m = int((u - epsilon) / (1 - epsilon) * ties)
                        for i in range(n):
                            if q[p, actions[p, i]] == best:
                                if m == 0:
                                    j = actions[p, i]
                                    break
                                m -= 1
                a0, a1 = j % 6, j // 6
                t2 = t
                if a0 >= 4:
                    t2 = (t2 & 2) | (a0 - 4)
                if a1 >= 4:
                    t2 = (t2 & 1) | ((a1 - 4) << 1)
                k2 = next_cells[p, j] * 4 + t2
                reward = r_pu[k2] - r_pu[k] + r_se[k2] - r_se[k]
                p2, target = k2 >> 2, -np.inf
                for i in range(n_valid[p2]):
                    target = max(target, q[p2, actions[p2, i]])
                q[p, j] = (1 - alpha) * q[p, j] + alpha * (reward + gamma * target)
                k = k2
    return q


def plain_tables(side: int) -> tuple:
    """The plain loop's tables for N = 2 on ``side x side``, in numpy."""
    from uavrl.envs.config import make_config  # the model's constants (standard library only)

    cfg = make_config("paper", grid=(side, side), num_uavs=2)
    L1, L2, h = side, side, cfg.height
    nodes = np.array([(0.0, L2 / 2, 0.0), (float(L1), L2 / 2, 0.0), (-L1 / 2, L2 / 2, h), (1.5 * L1, L2 / 2, h)])
    cells = np.array([(c % L1, c // L1, h) for c in range(L1 * L2)], float)
    gains = cfg.g0 * (np.linalg.norm(cells[:, None] - nodes[None], axis=-1) * cfg.cell_size) ** -cfg.alpha
    g1 = gains[:, [0, 2]] * np.array([cfg.p_pt, cfg.p_s]) / cfg.noise
    g2 = gains[:, [1, 3]] * cfg.p_u / cfg.noise
    contrib = g1 * g2 / (1 + g1 + g2)
    return tables(contrib, np.zeros(2), side, cfg.lease_rule)


def plain(grids: list[int], runs: int, episodes: int) -> None:
    """The plain loop's process: tables in numpy, the whole protocol in one compiled call per grid."""
    numba.set_num_threads(1)
    started = time.perf_counter()
    for side in grids:
        r_pu, r_se, valid, next_cells = plain_tables(side)
        plain_protocol(r_pu, r_se, valid, next_cells, side * side, runs, episodes, TABLE2_STEPS[side], 0.1, 0.3, 0.1, 0)
    print(f"plain loop: {time.perf_counter() - started:.2f} s inside the process", file=sys.stderr)


def kernels(grids: list[int], rounds: int, episodes: int = 20) -> None:
    """Team steps/s per thread of the plain loop and of ours, one process, alternating, best of ``rounds``."""
    import torch

    from uavrl.agents.tabular import TeamQLearner
    from uavrl.agents.tabular.kernels import use_workqueue_threads
    from uavrl.envs.config import make_config

    torch.set_num_threads(1)
    use_workqueue_threads()
    numba.set_num_threads(1)
    print(f"# learning loops, one thread each, 10 runs x {episodes} episodes per grid; best of {rounds} rounds")
    for side in grids:
        steps, tables_ = TABLE2_STEPS[side], plain_tables(side)
        learner = TeamQLearner(make_config("paper", grid=(side, side), num_uavs=2, max_steps=steps), runs=10, seed=0)
        plain_protocol(*tables_, side * side, 1, 1, 10, 0.1, 0.3, 0.1, 0)  # compiled (or loaded) before timing
        learner.run_episode()
        best = {"plain": 0.0, "ours": 0.0}
        for _ in range(rounds):
            started = time.perf_counter()
            plain_protocol(*tables_, side * side, 10, episodes, steps, 0.1, 0.3, 0.1, 0)
            best["plain"] = max(best["plain"], 10 * episodes * steps / (time.perf_counter() - started))
            started = time.perf_counter()
            for _ in range(episodes):
                learner.run_episode()
            best["ours"] = max(best["ours"], 10 * episodes * steps / (time.perf_counter() - started))
        print(
            f"{side}x{side}: plain {best['plain'] / 1e6:.2f} M team steps/s, ours {best['ours'] / 1e6:.2f} M "
            f"({best['ours'] / best['plain']:.2f}x)  (load {_load()})"
        )


def timed(command: list[str]) -> tuple[float, float]:
    """Wall seconds and CPU seconds (user + system) of one whole process."""
    before, started = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall, after = time.perf_counter() - started, resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--skip-table", action="store_true", help="only the 6x6 protocol")
    p.add_argument("--kernel", action="store_true", help="time the learning loops alone, one thread each")
    p.add_argument("--plain", nargs="+", type=int, help=argparse.SUPPRESS)  # the plain loop's process: its grids
    args = p.parse_args()
    if args.plain:
        plain(args.plain, runs=10, episodes=200)
        return
    if args.kernel:
        kernels(sorted(TABLE2_STEPS), args.rounds)
        return
    grids = sorted(TABLE2_STEPS)
    cases = [
        ("plain 6x6", [sys.executable, __file__, "--plain", "6"]),
        ("ours 6x6", ["reproduce", "grids=[6]"]),
    ]
    if not args.skip_table:
        cases += [
            ("plain Table II", [sys.executable, __file__, "--plain", *map(str, grids)]),
            ("ours Table II", ["reproduce"]),
        ]
    # compile and fill the numba caches once, untimed: the figures are of a user's second run
    with tempfile.TemporaryDirectory() as out:
        for _, command in cases[:2]:
            timed(_command(command, out))
    print(f"# reproduction, whole processes; {args.rounds} interleaved rounds; {os.cpu_count()} CPUs")
    wall, cpu = {name: [] for name, _ in cases}, {name: [] for name, _ in cases}
    for round_ in range(args.rounds):
        for name, command in cases:
            with tempfile.TemporaryDirectory() as out:
                seconds = timed(_command(command, out))
            wall[name].append(seconds[0])
            cpu[name].append(seconds[1])
            print(f"round {round_ + 1}: {name:<15} wall {seconds[0]:7.2f} s  cpu {seconds[1]:7.2f} s  (load {_load()})")
    print(f"{'process':<15} {'wall median':>12} {'wall best':>10} {'cpu median':>11} {'cpu best':>9}")
    for name in wall:
        figures = (statistics.median(wall[name]), min(wall[name]), statistics.median(cpu[name]), min(cpu[name]))
        print(f"{name:<15} {figures[0]:>12.2f} {figures[1]:>10.2f} {figures[2]:>11.2f} {figures[3]:>9.2f}")
    for ours, baseline in (("ours 6x6", "plain 6x6"), ("ours Table II", "plain Table II")):
        if ours in wall:
            ratio = [f(by[ours]) / f(by[baseline]) for by in (wall, cpu) for f in (statistics.median, min)]
            print(
                f"{ours} / {baseline}: wall {ratio[0]:.2f}x (medians) {ratio[1]:.2f}x (bests), "
                f"cpu {ratio[2]:.2f}x (medians) {ratio[3]:.2f}x (bests)"
            )


def _load() -> str:
    return f"{os.getloadavg()[0]:.2f}"


def _command(command: list[str], out_dir: str) -> list[str]:
    if command[0] != "reproduce":
        return command
    return [sys.executable, "-m", "uavrl.reproduce", "table2", *command[1:], "progress=false", f"out_dir={out_dir}"]


if __name__ == "__main__":
    main()
