"""Stable-Baselines3's PPO trained on the Gymnasium adapter, measured by the yardstick beside random and the oracle.

A user's code: ``PPO("MlpPolicy", UAVSpectrumGymEnv(...))`` with SB3's defaults, ``learn(--timesteps)``, then the
deterministic policy evaluated through ``uavrl.agents.evaluation.evaluate`` (``TeamActionPolicy``), the evaluation of
every agent: ``--starts`` held-out starts, the default horizon (24 greedy steps on 6x6), ``eval.gamma`` 0.9.
The random policy (``agent=random``'s, seeded like the PPO run) and the oracle planner are evaluated on the same
starts.  Prints one BENCHMARKS.md row per policy and seed.

Usage::

    python benchmarks/sb3_yardstick.py                                # N = 2 on 6x6, 50,000 steps, seed 0
    python benchmarks/sb3_yardstick.py --timesteps 200000 --seeds 0 1 2 --reward log_gap
    python benchmarks/sb3_yardstick.py --save runs/sb3     # also keeps each model: runs/sb3/ppo_seed<k>.zip (.json:
                                                           # the arguments of its model)
    python benchmarks/sb3_yardstick.py --city urban --altitudes 30 60 100 200 300   # a city with altitude levels

A kept model is scored on a benchmark suite by ``python benchmarks/score_outside.py sb3 runs/sb3/ppo_seed0.zip``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--timesteps", type=int, default=50_000, help="PPO's environment steps")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--starts", type=int, default=200, help="held-out evaluation starts")
    p.add_argument("--grid", type=int, nargs=2, default=[6, 6])
    p.add_argument("--uavs", type=int, default=2)
    p.add_argument("--max-steps", type=int, default=30, help="training episode length (the DQN's on 6x6)")
    p.add_argument("--reward", default="delta", help="the model's reward option PPO trains on")
    p.add_argument("--save", help="a folder to keep each trained model in, as ppo_seed<k>.zip")
    p.add_argument(
        "--city", help="an ITU-R P.1410 city on env=a2g_urban's channel (suburban, urban, dense_urban, highrise)"
    )
    p.add_argument("--altitudes", type=float, nargs="+", help="altitude levels in m (env.altitudes_m)")
    return p.parse_args(argv)


MODEL_FLAGS = ("grid", "uavs", "max_steps", "city", "altitudes", "reward")  # the arguments that set the model


def model_flags(args) -> list[str]:
    """The command line's arguments that set the model (:data:`MODEL_FLAGS`), as this script takes them."""
    flags = []
    for name in MODEL_FLAGS:
        value = getattr(args, name)
        if value is not None:
            flags += [f"--{name.replace('_', '-')}", *map(str, value if isinstance(value, list) else [value])]
    return flags


def model_options(args) -> dict:
    """The model's options: the paper's, or with ``--city`` and ``--altitudes`` ``a2g_urban``'s channel in a city."""
    options = dict(grid=tuple(args.grid), num_uavs=args.uavs, max_steps=args.max_steps, reward=args.reward)
    if args.city or args.altitudes:
        options |= dict(preset="a2g_urban", altitudes_m=args.altitudes)
        options |= dict(city=args.city, environment=args.city) if args.city else {}
    return options


def row(name: str, seed, metrics: dict, train_seconds) -> str:
    def value(key, digits):
        return f"{metrics[key]:.{digits}f}" if key in metrics else "-"

    return (
        f"| {name} | {seed} | {value('eval/optimality', 4)} | {value('eval/return_ratio', 4)} | "
        f"{value('eval/reach_999', 2)} | {value('eval/steps_to_999', 2)} | {value('eval/min_steps_to_999', 2)} | "
        f"{value('eval/step_ratio_999', 3)} | {train_seconds} |"
    )


def main(argv=None):
    args = parse_args(argv)
    import torch
    from stable_baselines3 import PPO

    from uavrl.agents.baselines import OraclePolicy, RandomPolicy
    from uavrl.agents.evaluation import evaluate
    from uavrl.envs.adapters.gym_env import TeamActionPolicy, UAVSpectrumGymEnv

    torch.set_num_threads(1)
    print(
        f"# SB3 PPO on UAVSpectrumGymEnv: {time.strftime('%Y-%m-%d %H:%M')}, {args.uavs} UAVs on "
        f"{args.grid[0]}x{args.grid[1]}, city={args.city}, altitudes={args.altitudes}, reward={args.reward}, "
        f"{args.timesteps} steps of episodes of {args.max_steps}, {args.starts} held-out starts, one torch thread"
    )
    print(
        "| row | seed | final U/U\\* | return ratio | reach 0.999 U\\* | steps to 0.999 U\\* | fewest (exact) "
        "| step ratio 0.999 | train s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    cfg = None
    for seed in args.seeds:
        env = UAVSpectrumGymEnv(**model_options(args))
        env.reset(seed=seed)
        started = time.perf_counter()
        model = PPO("MlpPolicy", env, seed=seed, device="cpu")
        model.learn(total_timesteps=args.timesteps)
        seconds = time.perf_counter() - started
        if args.save:  # the model beside the flags of its model, which score_outside.py reads (JSON: nothing runs)
            model.save(f"{args.save}/ppo_seed{seed}.zip")
            Path(args.save, f"ppo_seed{seed}.json").write_text(json.dumps(model_flags(args)))
        cfg = env.cfg.replace(reward="delta")  # the yardstick reads utilities, not the training reward
        policy = TeamActionPolicy(lambda obs, mask, model=model: model.predict(obs, deterministic=True)[0])
        name = f"SB3 PPO, defaults, {args.timesteps:,} steps (`UAVSpectrumGymEnv`, reward={args.reward})"
        print(row(name, seed, evaluate(policy, cfg, num_starts=args.starts), f"{seconds:.0f}"))
        print(
            row("uniform random (`agent=random`)", seed, evaluate(RandomPolicy(seed), cfg, num_starts=args.starts), 0)
        )
    print(row("oracle planner (`agent=oracle`)", "-", evaluate(OraclePolicy(cfg), cfg, num_starts=args.starts), 0))


if __name__ == "__main__":
    main()
