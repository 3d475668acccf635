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

The processes of a round run one after the other, rounds interleave them, and
each figure is the median (and the best) over rounds; the machine's load
average is printed beside them (other people's work shares its cores).
"""

from __future__ import annotations

import argparse
import os
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
    np.random.seed(seed)
    q = np.zeros((C * C, 36), np.float32)
    actions = np.zeros(36, np.int64)
    for _ in range(runs):
        q[:] = 0
        for _ in range(episodes):
            c0 = np.random.randint(C)
            c1 = (c0 + 1 + np.random.randint(C - 1)) % C
            k = (c0 * C + c1) * 4 + np.random.randint(4)
            for _ in range(steps):
                p, t = k >> 2, k & 3
                n = 0
                for j in range(36):
                    if valid[p, j]:
                        actions[n] = j
                        n += 1
                if np.random.random() < epsilon:
                    j = actions[np.random.randint(n)]
                else:
                    best, ties = -np.inf, 0
                    for i in range(n):
                        v = q[p, actions[i]]
                        if v > best:
                            best, ties, j = v, 1, actions[i]
                        elif v == best:
                            ties += 1
                            if np.random.randint(ties) == 0:
                                j = actions[i]
                a0, a1 = j % 6, j // 6
                t2 = t
                if a0 >= 4:
                    t2 = (t2 & 2) | (a0 - 4)
                if a1 >= 4:
                    t2 = (t2 & 1) | ((a1 - 4) << 1)
                k2 = next_cells[p, j] * 4 + t2
                reward = r_pu[k2] - r_pu[k] + r_se[k2] - r_se[k]
                p2, target = k2 >> 2, -np.inf
                for j2 in range(36):
                    if valid[p2, j2] and q[p2, j2] > target:
                        target = q[p2, j2]
                q[p, j] = (1 - alpha) * q[p, j] + alpha * (reward + gamma * target)
                k = k2
    return q


def plain(grids: list[int], runs: int, episodes: int) -> None:
    """The plain loop's process: tables in numpy, the whole protocol in one compiled call per grid."""
    from uavrl.envs.config import make_config  # the model's constants (standard library only)

    numba.set_num_threads(1)
    started = time.perf_counter()
    for side in grids:
        cfg = make_config("paper", grid=(side, side), num_uavs=2)
        L1, L2, h = side, side, cfg.height
        nodes = np.array([(0.0, L2 / 2, 0.0), (float(L1), L2 / 2, 0.0), (-L1 / 2, L2 / 2, h), (1.5 * L1, L2 / 2, h)])
        cells = np.array([(c % L1, c // L1, h) for c in range(L1 * L2)], float)
        gains = cfg.g0 * (np.linalg.norm(cells[:, None] - nodes[None], axis=-1) * cfg.cell_size) ** -cfg.alpha
        g1 = gains[:, [0, 2]] * np.array([cfg.p_pt, cfg.p_s]) / cfg.noise
        g2 = gains[:, [1, 3]] * cfg.p_u / cfg.noise
        contrib = g1 * g2 / (1 + g1 + g2)
        r_pu, r_se, valid, next_cells = tables(contrib, np.zeros(2), side, cfg.lease_rule)
        plain_protocol(r_pu, r_se, valid, next_cells, side * side, runs, episodes, TABLE2_STEPS[side], 0.1, 0.3, 0.1, 0)
    print(f"plain loop: {time.perf_counter() - started:.2f} s inside the process", file=sys.stderr)


def timed(command: list[str]) -> float:
    started = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - started


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--skip-table", action="store_true", help="only the 6x6 protocol")
    p.add_argument("--plain", nargs="+", type=int, help=argparse.SUPPRESS)  # the plain loop's process: its grids
    args = p.parse_args()
    if args.plain:
        plain(args.plain, runs=10, episodes=200)
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
        for _name, command in cases[:2]:
            timed(_command(command, out))
    print(f"# reproduction, whole processes; {args.rounds} interleaved rounds; {os.cpu_count()} CPUs")
    seconds = {name: [] for name, _ in cases}
    for round_ in range(args.rounds):
        for name, command in cases:
            with tempfile.TemporaryDirectory() as out:
                seconds[name].append(timed(_command(command, out)))
            print(f"round {round_ + 1}: {name:<15} {seconds[name][-1]:7.2f} s  (load {os.getloadavg()[0]:.2f})")
    print(f"{'process':<15} {'median s':>9} {'best s':>8}")
    for name, values in seconds.items():
        print(f"{name:<15} {statistics.median(values):>9.2f} {min(values):>8.2f}")
    for ours, baseline in (("ours 6x6", "plain 6x6"), ("ours Table II", "plain Table II")):
        if ours in seconds:
            ratio = statistics.median(seconds[ours]) / statistics.median(seconds[baseline])
            best = min(seconds[ours]) / min(seconds[baseline])
            print(f"{ours} / {baseline}: {ratio:.2f}x (medians), {best:.2f}x (bests)")


def _command(command: list[str], out_dir: str) -> list[str]:
    if command[0] != "reproduce":
        return command
    return [sys.executable, "-m", "uavrl.reproduce", "table2", *command[1:], "progress=false", f"out_dir={out_dir}"]


if __name__ == "__main__":
    main()
