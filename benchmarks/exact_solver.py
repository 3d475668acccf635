"""Time the exact solver (BENCHMARKS.md, "The yardstick"): Q* of the fixed layout, beside a dense baseline.

For each case it times, in this process with one torch thread, the solver of
``uavrl.envs.solvers.exact`` from nothing to the exact Q* of every configuration
(building the configuration graph, value iteration to the fixed point, Q* of
every configuration and joint action), and the same Q* by a dense baseline
written here that numbers *ordered* configurations (UAV i is UAV i, N! times
as many) and sweeps them the same way.  Both must agree.

Usage::

    python benchmarks/exact_solver.py                 # N = 2 on 10x10, N = 3 on 6x6; gamma 0.3 and 0.9
"""

from __future__ import annotations

import argparse
import time

import torch

from uavrl.envs import make_config
from uavrl.envs.physics.grid import grid_neighbours, joint_next_tasks, joint_targets, targets_valid
from uavrl.envs.solvers.exact import ConfigurationSpace, fixed_layout_tables, optimal_values

CASES = {"n2-10x10": ((10, 10), 2, 1.0), "n3-6x6": ((6, 6), 3, 30.0)}


def solver_q(cfg, gamma):
    space = ConfigurationSpace(cfg.grid, cfg.num_uavs)
    potential = space.utility(cfg, *fixed_layout_tables(cfg))
    values = optimal_values(space, potential, gamma)
    return space.q_values(potential, values, gamma, space.cells[None], space.tasks[None])[0], space


def dense_q(cfg, gamma, cells, tasks):
    """The baseline: value iteration over all ordered configurations, Q* at ``cells``/``tasks`` ``[K, N]``."""
    N, C = cfg.num_uavs, cfg.num_cells
    place, bits = C ** torch.arange(N), 2 ** torch.arange(N)
    every = torch.arange(C**N * 2**N)
    all_cells, all_tasks = ((every // 2**N)[:, None] // place) % C, ((every % 2**N)[:, None] // bits) % 2
    distinct = (all_cells.sort(-1).values.diff(dim=-1) != 0).all(-1)
    space = ConfigurationSpace(
        cfg.grid, N, memory_budget=2**40
    )  # only its rate helper: the utility of each ordered configuration
    utility = space.utility(cfg, *fixed_layout_tables(cfg))[0][
        space.index(all_cells.where(distinct[:, None], 0).clamp(min=0), all_tasks)
    ]
    utility = utility.where(distinct, -1e30)
    neighbours = grid_neighbours(cfg.grid)
    successors = torch.empty(len(every), 6**N, dtype=torch.long)
    for start in range(0, len(every), 1 << 14):
        rows = slice(start, start + (1 << 14))
        target = joint_targets(all_cells[rows], neighbours, N)
        nxt = (target.clamp(min=0) * place).sum(-1) * 2**N + (joint_next_tasks(all_tasks[rows], N) * bits).sum(-1)
        successors[rows] = nxt.where(targets_valid(target) & distinct[rows, None], len(every))
    values = torch.zeros(len(every), dtype=torch.float64)
    while True:
        padded = torch.cat([utility + gamma * values, torch.tensor([-torch.inf], dtype=torch.float64)])
        new = (padded[successors].amax(-1) - utility).where(distinct, 0.0)
        if (new - values).abs().max() <= 1e-12 * utility[distinct].abs().max():
            break
        values = new
    rows = (cells * place).sum(-1) * 2**N + (tasks * bits).sum(-1)
    padded = torch.cat([utility + gamma * new, torch.tensor([-torch.inf], dtype=torch.float64)])
    return padded[successors[rows]] - utility[rows, None]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", choices=sorted(CASES), default=list(CASES))
    parser.add_argument("--gammas", nargs="+", type=float, default=[0.3, 0.9])
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(
        "| case | configurations (solver / dense) | gamma | solver Q* s | target s | dense baseline s | max abs "
        "difference |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in args.cases:
        grid, N, target = CASES[name]
        cfg = make_config("paper", grid=grid, num_uavs=N)
        for gamma in args.gammas:
            started = time.perf_counter()
            q, space = solver_q(cfg, gamma)
            solver_s = time.perf_counter() - started
            started = time.perf_counter()
            dense = dense_q(cfg, gamma, space.cells, space.tasks)
            dense_s = time.perf_counter() - started
            finite = q > -torch.inf
            assert torch.equal(finite, dense > -torch.inf)
            diff = (q[finite] - dense[finite]).abs().max().item()
            ordered = cfg.num_cells**N * 2**N
            print(
                f"| {name} | {space.num_configurations:,} / {ordered:,} | {gamma} | {solver_s:.2f} | < {target:g} | "
                f"{dense_s:.2f} | {diff:.1e} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
