"""Missions under an energy model: random, the energy-unaware oracle, the energy-aware planner and the DQN
on the scenarios ``energy_4x4`` (where the exact optimum fits), ``energy_6x6`` and ``persistent_10x10``, as the user
types them, and what each of the planner's rules buys.

Each row is whole commands ``python -m uavrl.train agent=<a> scenario=<s> seed=<k> progress=false`` (one torch
thread), timed from outside; the figures are each run's ``metrics.json``, measured by the shared evaluation from
its 64 held-out starts (``eval.seed``, far from every training seed).  The oracle and the planner are deterministic
and read no seed: one run each.  ``eval/delivered_optimality`` (the exact optimum of delivered data, where it fits)
is shown where the evaluation reports it.  Then the planner with one rule switched off, evaluated in this process
on the same starts.  Prints Markdown tables (BENCHMARKS.md, Missions under an energy model)::

    python benchmarks/energy_missions.py                        # every scenario and agent, 3 seeds
    python benchmarks/energy_missions.py --scenarios energy_6x6 --agents planner oracle --seeds 0
    python benchmarks/energy_missions.py --extra agent.iterations=5   # a smoke run
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SCENARIOS = ("energy_4x4", "energy_6x6", "persistent_10x10")
AGENTS = ("random", "oracle", "planner", "dqn")
DETERMINISTIC = ("oracle", "planner")  # no seed changes what they do: one run
COLUMNS = {  # metric: header
    "eval/delivered_bit_per_hz": "delivered (bit/Hz)",
    "eval/delivered_bound": "bound",
    "eval/delivered_ratio": "delivered / bound",
    "eval/delivered_optimality": "delivered / optimum",
    "eval/first_leave_steps": "first UAV leaves (step)",
    "eval/service_lost_steps": "service lost (step)",
    "eval/service_steps_per_uav": "steps in service per UAV",
}


def run(agent: str, scenario: str, seed: int, workdir: Path, extra: list[str]) -> tuple[dict, float, float]:
    """One whole command's metrics, its wall seconds and its CPU seconds (user + system: on a shared machine the
    wall time grows with the load, the CPU time much less)."""
    run_dir = workdir / f"{scenario}-{agent}-{seed}"
    argv = [sys.executable, "-m", "uavrl.train", f"agent={agent}", f"scenario={scenario}", f"seed={seed}"]
    argv += ["progress=false", f"run_dir={run_dir}", *extra]
    started, before = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    result = subprocess.run(argv, capture_output=True, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    seconds, after = time.perf_counter() - started, resource.getrusage(resource.RUSAGE_CHILDREN)
    if result.returncode:
        raise SystemExit(f"{' '.join(argv[1:])} failed:\n{result.stderr[-2000:]}")
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return json.loads((run_dir / "metrics.json").read_text()), seconds, cpu


def cell(values: list[float]) -> str:
    """The mean, and the range over seeds where there are several."""
    if not values:
        return "-"
    mean = statistics.fmean(values)
    digits = 3 if abs(mean) < 10 else 1
    spread = f" ({min(values):.{digits}f}-{max(values):.{digits}f})" if len(values) > 1 else ""
    return f"{mean:.{digits}f}{spread}"


def table(scenario: str, agents, seeds, workdir: Path, extra: list[str]) -> None:
    print(f"\n### {scenario}\n")
    print("| agent | runs | " + " | ".join(COLUMNS.values()) + " | wall per run (s) | CPU per run (s) |")
    print("|---|---|" + "---|" * (len(COLUMNS) + 2))
    for agent in agents:
        results = [
            run(agent, scenario, seed, workdir, extra) for seed in (seeds[:1] if agent in DETERMINISTIC else seeds)
        ]
        metrics = [m for m, _, _ in results]
        row = [cell([m[key] for m in metrics if key in m]) for key in COLUMNS]
        row += [cell([wall for _, wall, _ in results]), cell([cpu for _, _, cpu in results])]
        print(f"| {agent} | {len(results)} | " + " | ".join(row) + " |", flush=True)


def rule_ablation(scenario: str) -> None:
    """The planner with each rule switched off, on the scenario's model and the evaluation's own starts."""
    import torch
    from hydra import compose, initialize_config_dir

    from uavrl.agents.baselines import OraclePolicy
    from uavrl.agents.evaluation import evaluate
    from uavrl.agents.planner import PlannerPolicy
    from uavrl.config import config_dir, model_config

    class HoveringPlanner(PlannerPolicy):  # rule 1 off: the team hovers on A
        def _partners(self, world, nodes, cells, tasks):
            return cells, False

    class UnstaggeredPlanner(PlannerPolicy):  # rule 2 off: every UAV serves to its reserve
        def _returning(self, *args):
            return None

    torch.set_num_threads(1)
    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        cfg = compose("config", overrides=["agent=planner", f"scenario={scenario}"])
    model, horizon = model_config(cfg), cfg.eval.horizon
    print(f"\n{scenario}, what each rule buys (64 held-out starts):\n")
    print("| policy | delivered (bit/Hz) | delivered / bound | first UAV leaves (step) | wall (s) |")
    print("|---|---|---|---|---|")
    variants = {
        "oracle (neither rule)": OraclePolicy,
        "planner without rule 1 (hovers)": HoveringPlanner,
        "planner without rule 2 (no early return)": UnstaggeredPlanner,
        "planner": PlannerPolicy,
    }
    for name, policy in variants.items():
        started = time.perf_counter()
        m = evaluate(policy(model), model, horizon=horizon)
        seconds = time.perf_counter() - started
        print(
            f"| {name} | {m['eval/delivered_bit_per_hz']:.1f} | {m['eval/delivered_ratio']:.3f} | "
            f"{m['eval/first_leave_steps']:.1f} | {seconds:.1f} |",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", nargs="+", default=SCENARIOS, choices=SCENARIOS)
    parser.add_argument("--agents", nargs="+", default=AGENTS, choices=AGENTS)
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--extra", nargs="*", default=[], help="more overrides for every command")
    parser.add_argument("--workdir", type=Path, default=None, help="where the runs go (default: a temporary folder)")
    parser.add_argument("--no-ablation", action="store_true", help="skip the planner's rules one at a time")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as temporary:
        workdir = args.workdir or Path(temporary)
        for scenario in args.scenarios:
            table(scenario, args.agents, args.seeds, workdir, args.extra)
            if not args.no_ablation:
                rule_ablation(scenario)


if __name__ == "__main__":
    main()
