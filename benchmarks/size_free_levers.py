"""The size-free DQN's sample-efficiency levers, each against pure RL: one table for BENCHMARKS.md.

    python benchmarks/size_free_levers.py --out <dir> [--iterations 420] [--seeds 0 1 2] [--starts 200] [--jobs 2]
        [--lookahead 1] [--width 8] [--scenario size_free] [--teams N:L1xL2[:layout] ...] [--levers NAME ...]
        [-- <train overrides>]

Trains ``python -m uavrl.train agent=dqn scenario=<scenario>`` (``agent.iterations=<iterations>``) per seed and
combination of ``--levers`` (default all four: pure RL, ``agent.demonstrations=oracle``, ``agent.curriculum=loss``,
and both), at most ``--jobs`` at a time; then evaluates every checkpoint zero-shot on the same held-out starts
(``eval.seed``'s default) of every team, beside the oracle and the random policy, and every checkpoint also with
``eval.lookahead=<lookahead>`` (``eval.lookahead_width=<width>``).  Per team: the return ratio (N = 2 on 6x6) or
the share of starts reaching 0.999 U* and the quotient of the policy's and the oracle's mean steps over the fewest
("x oracle", each over its own reaching starts); means over the seeds.  Train CPU s: the run's training clock
(``train_cpu_seconds`` of its ``metrics.json``: the oracle's demonstrations, collection and updates), in brackets the
whole ``uavrl.train`` process where the benchmark ran it (start-up and its 8-start evaluation too).  Last, each
learned policy's own CPU seconds per world and step at the largest team (the greedy policy's, or the lookahead's
search).  Runs and evaluations already in ``--out`` are reused, so an interrupted benchmark continues.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

DEFAULT_TEAMS = ["2:6x6", "6:10x10", "10:20x20", "20:30x30", "50:50x50", "6:10x10:random", "20:30x30:random"]
TRAINED = {  # each lever on or off whatever the scenario's default (the oracle's knowledge: demonstrations need U*)
    "pure RL": ["agent.demonstrations=none", "agent.curriculum=none"],
    "+demonstrations": ["agent.demonstrations=oracle", "agent.curriculum=none"],
    "+curriculum": ["agent.demonstrations=none", "agent.curriculum=loss"],
    "+demonstrations +curriculum": ["agent.demonstrations=oracle", "agent.curriculum=loss"],
}
LOOKAHEAD_OF = {  # the checkpoints also evaluated with eval.lookahead
    "pure RL": "pure RL +lookahead",
    "+demonstrations": "+demonstrations +lookahead",
    "+curriculum": "+curriculum +lookahead",
    "+demonstrations +curriculum": "all three",
}
USES_ORACLE = {
    "oracle": "is the oracle",
    "random": "no",
    "pure RL": "no",
    "+demonstrations": "U*'s configurations (training)",
    "+curriculum": "no",
    "+demonstrations +curriculum": "U*'s configurations (training)",
    "pure RL +lookahead": "the model (evaluation)",
    "+demonstrations +lookahead": "both",
    "+curriculum +lookahead": "the model (evaluation)",
    "all three": "both",
}


def run_name(policy: str, seed: int) -> str:
    return policy.replace("+", "").replace(" ", "_").lower() + f"-seed{seed}"


def train(out: Path, policy: str, seed: int, args) -> dict:
    """Train one checkpoint (skipped when its metrics exist); its process's CPU and wall seconds."""
    run_dir = out / run_name(policy, seed)
    record = run_dir / "benchmark_train.json"
    if record.exists():
        return json.loads(record.read_text())
    if (run_dir / "metrics.json").exists():  # trained outside this benchmark: its training clock only
        metrics = json.loads((run_dir / "metrics.json").read_text())
        return {"wall_s": None, "cpu_s": None, "train_cpu_s": metrics.get("train_cpu_seconds")}
    command = [
        sys.executable,
        "-m",
        "uavrl.train",
        "agent=dqn",
        f"scenario={args.scenario}",
        f"seed={seed}",
        f"run_dir={run_dir}",
        f"agent.iterations={args.iterations}",
        "eval.num_starts=8",
        "progress=false",
        *TRAINED[policy],
        *args.overrides,
    ]
    began = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(process.pid, 0)
    if status:
        raise RuntimeError(f"{' '.join(command)} failed ({status})")
    metrics = json.loads((run_dir / "metrics.json").read_text())
    result = {
        "wall_s": time.perf_counter() - began,
        "cpu_s": usage.ru_utime + usage.ru_stime,
        "train_cpu_s": metrics.get("train_cpu_seconds"),
    }
    record.write_text(json.dumps(result))
    return result


class TimedPolicy:
    """A policy's CPU seconds and the world-steps it chose (``bind_env`` passed on)."""

    def __init__(self, policy):
        self.policy, self.seconds, self.world_steps = policy, 0.0, 0

    def bind_env(self, env):
        self.policy.bind_env(env)
        return self

    def __call__(self, td):
        began = time.process_time()
        out = self.policy(td)
        self.seconds += time.process_time() - began
        self.world_steps += td.batch_size.numel()
        return out


def evaluate_team(out: Path, team: str, runs: dict, args) -> dict:
    """Every policy's metrics on one team (cached in ``out``), from the same held-out starts."""
    import torch

    from uavrl.agents.baselines import OraclePolicy, RandomPolicy
    from uavrl.agents.evaluation import evaluate, evaluate_with_lookahead
    from uavrl.config import model_config
    from uavrl.experiment.saved import load_agent

    torch.set_num_threads(1)
    path = out / f"eval-{team.replace(':', '_')}.json"
    done = json.loads(path.read_text()) if path.exists() else {}
    n, grid, *layout = team.split(":")
    l1, l2 = grid.split("x")
    for policy, run_dirs in runs.items():
        for seed, run_dir in run_dirs:
            key = f"{policy}|{seed}"
            if key in done:
                continue
            began = time.process_time()
            if policy in ("oracle", "random"):
                agent, saved, _ = load_agent(runs[args.levers[0]][0][1])  # the runs' model
            else:
                agent, saved, _ = load_agent(run_dir)
            cfg = model_config(saved).replace(
                num_uavs=int(n), grid=(int(l1), int(l2)), layout=layout[0] if layout else model_config(saved).layout
            )
            if policy == "oracle":
                metrics = evaluate(OraclePolicy(cfg), cfg, num_starts=args.starts)
            elif policy == "random":
                metrics = evaluate(RandomPolicy(seed=0), cfg, num_starts=args.starts)
            elif policy in LOOKAHEAD_OF.values():
                metrics = evaluate_with_lookahead(agent, cfg, args.lookahead, args.width, num_starts=args.starts)
            else:  # agent.evaluate's evaluation, with the greedy policy's own CPU time
                timed = TimedPolicy(agent.policy_for(cfg))
                metrics = evaluate(timed, cfg, num_starts=args.starts)
                metrics["eval/policy_cpu_s_per_step"] = timed.seconds / max(1, timed.world_steps)
            metrics["cpu_s"] = time.process_time() - began
            done[key] = metrics
            path.write_text(json.dumps(done, indent=1))
            print(f"{team} {key}: {metrics['cpu_s']:.0f} CPU s", flush=True)
    return done


def train_cost(costs: list[dict]) -> str:
    """Mean training CPU s (its clock: the oracle's demonstrations, collection and updates), and of the whole
    process where the benchmark ran it."""
    if not costs:
        return "-"
    text = f"{sum(c['train_cpu_s'] for c in costs) / len(costs):.0f}"
    if all(c["cpu_s"] is not None for c in costs):
        text += f" ({sum(c['cpu_s'] for c in costs) / len(costs):.0f})"
    return text


def cell(team: str, results: list[dict], oracle: list[dict]) -> str:
    def mean(key, rows):
        values = [r[key] for r in rows if key in r]
        return sum(values) / len(values) if values else None

    if team.startswith("2:"):
        ratio = mean("eval/return_ratio", results)
        return "-" if ratio is None else f"{ratio:.3f}"
    reach, steps, best = mean("eval/reach_999", results), mean("eval/step_ratio_999", results), None
    best = mean("eval/step_ratio_999", oracle)
    times = f", {steps / best:.2f}x" if steps is not None and best else ""
    return f"{reach:.3f}{times}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--iterations", type=int, default=420)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--starts", type=int, default=200)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--lookahead", type=int, default=1)
    parser.add_argument("--width", type=int, default=8)
    parser.add_argument("--scenario", default="size_free")
    parser.add_argument("--teams", nargs="+", default=DEFAULT_TEAMS)
    parser.add_argument("--levers", nargs="+", default=list(TRAINED), choices=list(TRAINED), help="combinations")
    parser.add_argument("overrides", nargs="*", help="more uavrl.train overrides, after --")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    jobs = [(policy, seed) for seed in args.seeds for policy in args.levers]
    with ProcessPoolExecutor(args.jobs) as pool:
        done = [pool.submit(train, args.out, policy, seed, args) for policy, seed in jobs]
        costs = {job: future.result() for job, future in zip(jobs, done, strict=True)}
    runs = {"oracle": [(0, None)], "random": [(0, None)]}
    for policy in args.levers:
        runs[policy] = [(seed, args.out / run_name(policy, seed)) for seed in args.seeds]
        if policy in LOOKAHEAD_OF:
            runs[LOOKAHEAD_OF[policy]] = runs[policy]
    with ProcessPoolExecutor(args.jobs) as pool:
        done = {team: pool.submit(evaluate_team, args.out, team, runs, args) for team in args.teams}
        per_team = {team: future.result() for team, future in done.items()}
    largest = max(args.teams, key=lambda t: int(t.split(":")[0]))
    header = ["policy", "oracle's knowledge", "train CPU s (process)"]
    header += [
        f"N = {t.split(':')[0]}, {t.split(':')[1]}{' random' if t.endswith('random') else ''}" for t in args.teams
    ]
    header.append(f"policy CPU s / world-step, N = {largest.split(':')[0]}")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for policy, seeds in runs.items():
        trained = next((p for p, la in LOOKAHEAD_OF.items() if la == policy), policy)
        cost = [costs[(trained, s)] for s, _ in seeds] if trained in TRAINED else []
        row = [policy, USES_ORACLE[policy], train_cost(cost)]
        for team in args.teams:
            results = [per_team[team][f"{policy}|{s}"] for s, _ in seeds]
            row.append(cell(team, results, [per_team[team]["oracle|0"]]))
        step_cost = [
            per_team[largest][f"{policy}|{s}"].get(
                "eval/lookahead_cpu_s_per_step", per_team[largest][f"{policy}|{s}"].get("eval/policy_cpu_s_per_step")
            )
            for s, _ in seeds
        ]
        row.append(f"{sum(step_cost) / len(step_cost):.4f}" if None not in step_cost else "-")
        print("| " + " | ".join(row) + " |", flush=True)


if __name__ == "__main__":
    main()
