"""The factored DQN's targets (BENCHMARKS.md, "Factored DQN"): train, evaluate, compare with random.

Each target runs the training command as a user would, timed from the shell's
point of view (Python start-up, training and the final evaluation), reads the
run's ``metrics.json``, evaluates the saved agent again on ``--starts`` held-out
starts (``uavrl.evaluate``, the same shared evaluation) and the uniform random
policy on the same starts, and prints one markdown row per target and seed.

- ``n2``: ``python -m uavrl.train agent=dqn`` (N = 2 on 6x6, paper preset)
- ``n6``: ``python -m uavrl.train agent=dqn env.grid=[10,10] env.num_uavs=6``
- ``random``: ``python -m uavrl.train agent=dqn env.layout=random`` (a new
  layout per world and episode; the evaluation's layouts come from the eval
  seed, so none was seen in training)
- ``n2-joint``: ``python -m uavrl.train agent=dqn agent.head=joint``
- beyond the targets: ``n6-qmix`` (``agent.mixer=qmix``) and ``n6-random``
  (random layouts with N = 6 on 10x10)

Usage::

    python benchmarks/dqn_targets.py                         # every target, seed 0
    python benchmarks/dqn_targets.py --targets n6 --seeds 0 1 2
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir

from uavrl.config import config_dir, model_config
from uavrl.evaluate import load_agent
from uavrl.agents.baselines import RandomPolicy
from uavrl.evaluation import evaluate, evaluate_agent

TARGETS = {
    "n2": [],
    "n6": ["env.grid=[10,10]", "env.num_uavs=6"],
    "random": ["env.layout=random"],
    "n2-joint": ["agent.head=joint"],
    "n6-qmix": ["env.grid=[10,10]", "env.num_uavs=6", "agent.mixer=qmix"],
    "n6-random": ["env.grid=[10,10]", "env.num_uavs=6", "env.layout=random"],
}


def run_target(name: str, seed: int, starts: int, out: Path) -> dict:
    overrides = ["agent=dqn", *TARGETS[name], f"seed={seed}"]
    run_dir = out / f"{name}-seed{seed}"
    started = time.perf_counter()
    subprocess.run([sys.executable, "-m", "uavrl.train", *overrides, f"run_dir={run_dir}", "progress=false"], check=True, capture_output=True)
    wall = time.perf_counter() - started
    metrics = json.loads((run_dir / "metrics.json").read_text())
    agent, _ = load_agent(run_dir)
    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        env_cfg = model_config(compose("config", overrides=overrides))
    held_out = evaluate_agent(agent, env_cfg, num_starts=starts)
    random = evaluate(RandomPolicy(seed), env_cfg, num_starts=starts)
    return {"target": name, "seed": seed, "command": "python -m uavrl.train " + " ".join(overrides), "wall_seconds": wall, "train_seconds": metrics["train_seconds"], "run": metrics, "held_out": held_out, "random": random}


def row(r: dict) -> str:
    h, rnd = r["held_out"], r["random"]
    return (
        f"| {r['target']} | {r['seed']} | {h['eval/optimality']:.4f} | {h['eval/optimality_min']:.3f} | {h['eval/optimal_fraction']:.2f} "
        f"| {rnd['eval/optimality']:.4f} | {rnd['eval/optimal_fraction']:.2f} | {r['train_seconds']:.0f} | {r['wall_seconds']:.0f} |"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", nargs="+", choices=sorted(TARGETS), default=["n2", "n6", "random", "n2-joint"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--starts", type=int, default=100, help="held-out evaluation starts (and layouts)")
    parser.add_argument("--out", type=Path, default=None, help="where the runs go (default: a temporary directory)")
    parser.add_argument("--json", type=Path, default=None, help="also write every result here")
    args = parser.parse_args()
    torch.set_num_threads(1)
    out = args.out or Path(tempfile.mkdtemp(prefix="dqn_targets_"))
    print("| target | seed | optimality | min | optimal fraction | random optimality | random optimal fraction | train s | wall s |")
    print("|---|---|---|---|---|---|---|---|---|")
    results = []
    for name in args.targets:
        for seed in args.seeds:
            results.append(run_target(name, seed, args.starts, out))
            print(row(results[-1]), flush=True)
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
