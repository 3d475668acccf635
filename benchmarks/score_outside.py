"""Policies trained outside uavrl's commands scored on a benchmark suite, by the routes of docs/leaderboard.md.

    python benchmarks/score_outside.py benchmarl RUN_DIR [RUN_DIR ...] [--suite paper] [--out DIR]
    python benchmarks/score_outside.py sb3 MODEL.zip [--suite paper] [--out DIR]

``benchmarl``: each ``RUN_DIR`` is a directory of ``python -m uavrl.benchmarl ... run_dir=RUN_DIR`` (needs the
``[benchmarl]`` extra); its experiment at its last checkpoint (``uavrl.experiment.benchmarl.load_experiment``) acts
with its deterministic policy where it can (the model it trained on), n/a elsewhere.  The budget is the experiment's
frames and its training CPU seconds (``metrics.json``).

``sb3``: a Stable-Baselines3 model trained on the Gymnasium adapter (``benchmarks/sb3_yardstick.py --save``), acting
through ``TeamActionPolicy`` on the model it trained on only (the model arguments ``sb3_yardstick.py`` keeps beside
it in ``ppo_seed<k>.json``; without that file the paper's 6x6 model).  The budget is its ``num_timesteps``.

A policy trained in a city acts in the suite's other cities of its model too (``uavrl.agents.schema.run_city``).

Each results file goes to ``DIR/<suite>-<name>.json`` (default ``benchmarks/results/leaderboard``) with its table
and figure beside it; ``python -m uavrl.bench leaderboard`` then puts it on the site's page.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

DEFAULT_OUT = Path("benchmarks/results/leaderboard")


def benchmarl_submission(run_dir: Path, suite: str) -> tuple[dict, str]:
    """The results of a BenchMARL run directory on ``suite``, and the file name they go under."""
    from omegaconf import OmegaConf
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from uavrl.agents.schema import run_city
    from uavrl.bench.run import NotApplicable, score_suite
    from uavrl.experiment.benchmarl import load_experiment

    saved = OmegaConf.load(run_dir / "config.yaml")
    metrics = json.loads((run_dir / "metrics.json").read_text())
    experiment = load_experiment(run_dir)
    trained_on = experiment.task.model_config

    def factory(env):
        if env.cfg.replace(max_steps=trained_on.max_steps, **run_city(env.cfg, trained_on)) != trained_on:
            raise NotApplicable("the experiment's networks act in its own model only")
        return experiment.policy

    algorithm = metrics["agent"].removeprefix("benchmarl_")
    frames = saved.experiment.max_n_frames
    heard, label, run = _local(trained_on)
    run = f"runs/benchmarl-{algorithm}{run}"
    train_command = (  # as benchmarks/benchmarl_comparison.py runs it: its evaluations draw on BenchMARL's seeds too
        f"python -m uavrl.benchmarl algorithm={algorithm} task={metrics['task']}{heard} seed={saved.seed} "
        f"experiment.max_n_frames={frames} experiment.evaluation_interval={saved.experiment.evaluation_interval} "
        f"eval.num_starts={saved.eval.num_starts} run_dir={run}"
    )
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        results = score_suite(
            suite,
            factory,
            name=f"BenchMARL {algorithm.upper()}{label or f', {frames:,} frames'}",
            budget={"env_steps": int(experiment.total_frames), "cpu_seconds": round(metrics["train_cpu_seconds"])},
            source=f"python benchmarks/score_outside.py benchmarl {run} --suite {suite}",
            train_command=train_command,
            progress=print,
        )
    return results, f"{suite}-{run.removeprefix('runs/')}"


def _local(model) -> tuple[str, str, str]:
    """What sets a model of local observations apart (``env.observation=local``): its overrides as typed, its label
    as the DQN's rows name theirs, and its run directory's suffix (``" env.observation=local env.comm_radius=4"``,
    ``" local (n6-r4)"``, ``"-local-r4"``; the radius, ``full`` where every UAV is heard, and ``-m<d>`` with
    messages); nothing for the central observation."""
    if not model.local:
        return "", "", ""
    radius = "" if model.comm_radius is None else f"{model.comm_radius:g}"
    overrides = " env.observation=local" + (f" env.comm_radius={radius}" if radius else "")
    overrides += f" env.message_size={model.message_size}" if model.message_size else ""
    heard = f"{'r' + radius if radius else 'full'}{'-m' + str(model.message_size) if model.message_size else ''}"
    return overrides, f" local (n{model.num_uavs}-{heard})", f"-local-{heard}"


def sb3_model(path: Path) -> list[str]:
    """The model arguments of ``sb3_yardstick.py`` an SB3 model trained with, as ``sb3_yardstick.py --save`` wrote
    them to ``path`` (JSON, read as data: a list of strings that the script's own parser checks); none (the paper's
    6x6 model) without the file."""
    from uavrl.experiment.io import read_small_text

    if not path.exists():
        return []
    flags = json.loads(read_small_text(path, within=path.parent))
    if not isinstance(flags, list) or not all(isinstance(flag, str) for flag in flags):
        raise SystemExit(f"{path}: not the model arguments sb3_yardstick.py writes (a list of strings)")
    return flags


def sb3_submission(path: Path, suite: str) -> tuple[dict, str]:
    """The results of an SB3 model on ``suite``, and the file name they go under."""
    from sb3_yardstick import model_options, parse_args
    from stable_baselines3 import PPO

    from uavrl.agents.schema import run_city
    from uavrl.bench.run import NotApplicable, score_suite
    from uavrl.envs import make_config
    from uavrl.envs.adapters.gym_env import TeamActionPolicy

    model = PPO.load(str(path), device="cpu")
    flags = sb3_model(path.with_suffix(".json"))
    trained_on = make_config(**model_options(parse_args(flags)))

    def factory(env):
        acting = env.cfg.replace(max_steps=trained_on.max_steps, reward=trained_on.reward)
        if acting.replace(**run_city(acting, trained_on)) != trained_on:
            raise NotApplicable(
                f"trained on a {trained_on.grid[0]}x{trained_on.grid[1]} grid, {trained_on.num_uavs} UAVs"
            )
        return TeamActionPolicy(lambda obs, mask: model.predict(obs, deterministic=True)[0])

    steps = int(model.num_timesteps)
    results = score_suite(
        suite,
        factory,
        name=f"SB3 PPO (Gymnasium adapter), {steps:,} steps",
        budget={"env_steps": steps},
        source=f"python benchmarks/score_outside.py sb3 runs/sb3/{path.name} --suite {suite}",
        train_command=" ".join(["python benchmarks/sb3_yardstick.py", *flags, f"--timesteps {steps} --save runs/sb3"]),
        progress=print,
    )
    return results, f"{suite}-sb3-ppo"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("kind", choices=("benchmarl", "sb3"))
    parser.add_argument("paths", nargs="+", type=Path, help="BenchMARL run directories, or SB3 model files")
    parser.add_argument("--suite", default="paper")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="the folder of the results files")
    args = parser.parse_args(argv)
    import torch

    from uavrl.bench.results import save

    torch.set_num_threads(1)
    for path in args.paths:
        submission = benchmarl_submission if args.kind == "benchmarl" else sb3_submission
        results, name = submission(path, args.suite)
        for written in save(results, args.out / f"{name}.json"):
            print(f"wrote {written}")


if __name__ == "__main__":
    main()
