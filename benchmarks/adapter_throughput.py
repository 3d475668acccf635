"""World-steps per second of the Gymnasium vector env (uavrl.envs.adapters.gym_env) beside UAVSpectrumEnv.step, in one
run.

Both step ``B`` worlds with the same pre-drawn uniform actions (drawing them is not timed), episodes longer
than the run (no resets), and every step's outputs kept alive only until the next step:

* ``UAVSpectrumEnv.step``: ``td = step_mdp(env.step(td.set(("agents", "action"), a)))``, TorchRL's loop.
* ``UAVSpectrumVectorEnv.step``: ``env.step(a)`` on NumPy actions, returning NumPy observations (the nodes
  appended), masks, rewards, dones and the batched infos, as a Gymnasium user's loop does.
* ``UAVSpectrumVectorEnv.step, autoreset``: the same with ``max_steps`` 100, so a next-step autoreset every
  101 steps (each counts as a world-step: it is what a training loop pays).
* ``UAVSpectrumGymEnv.step`` (B = 1 only): the single env, for reference.

Each figure is the median (and the best) of ``--repeats`` whole-loop timings after ``--warmup`` loops; the
ratio is the vector env's median over ``UAVSpectrumEnv.step``'s (the target: >= 0.5 at B = 1024).

Usage::

    python benchmarks/adapter_throughput.py                       # B = 1024, N = 2 on 6x6 and N = 6 on 10x10
    python benchmarks/adapter_throughput.py --batch-sizes 1 1024 4096 --threads 2
"""

from __future__ import annotations

import argparse
import os
import platform
import time


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[1024])
    p.add_argument("--models", nargs="+", default=["2x6", "6x10"], help="N x L: N UAVs on an L x L grid")
    p.add_argument("--steps", type=int, default=500, help="steps per timed loop")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--warmup", type=int, default=1)
    p.add_argument("--threads", type=int, default=1, help="torch.set_num_threads (default 1)")
    return p.parse_args(argv)


def loops(B: int, N: int, L: int, T: int) -> dict:
    """The timed loops of ``B`` worlds of ``N`` UAVs on an ``L x L`` grid, ``T`` steps each, by row name."""
    import torch
    from torchrl.envs.utils import step_mdp

    from uavrl.envs import UAVSpectrumEnv
    from uavrl.envs.adapters.gym_env import UAVSpectrumGymEnv, UAVSpectrumVectorEnv

    options = {"grid": (L, L), "num_uavs": N}
    actions = torch.randint(0, 6, (T, B, N), generator=torch.Generator().manual_seed(0))
    numpy_actions = actions.numpy()
    torchrl_env = UAVSpectrumEnv(batch_size=B, max_steps=10**9, **options)

    def torchrl_loop():
        td = torchrl_env.reset()
        for t in range(T):
            td = step_mdp(torchrl_env.step(td.set(("agents", "action"), actions[t])))

    def vector_loop(env):
        env.reset(seed=0)
        for t in range(T):
            env.step(numpy_actions[t])

    vector_env = UAVSpectrumVectorEnv(num_envs=B, max_steps=10**9, **options)
    resetting_env = UAVSpectrumVectorEnv(num_envs=B, max_steps=100, **options)
    rows = {
        "UAVSpectrumEnv.step": torchrl_loop,
        "UAVSpectrumVectorEnv.step": lambda: vector_loop(vector_env),
        "UAVSpectrumVectorEnv.step, autoreset": lambda: vector_loop(resetting_env),
    }
    if B == 1:
        single = UAVSpectrumGymEnv(max_steps=10**9, **options)

        def single_loop():
            single.reset(seed=0)
            for t in range(T):
                single.step(numpy_actions[t, 0])

        rows["UAVSpectrumGymEnv.step"] = single_loop
    return rows


def main(argv=None):
    args = parse_args(argv)
    import torch
    from env_throughput import timed  # this folder is on sys.path when run as a script

    torch.set_num_threads(args.threads)
    print(
        f"# adapter throughput: {time.strftime('%Y-%m-%d %H:%M')}, torch {torch.__version__}, threads "
        f"{torch.get_num_threads()}, {os.cpu_count()} CPUs ({platform.processor() or platform.machine()}), "
        f"load average {os.getloadavg()[0]:.2f}; {args.steps} steps a loop, median of {args.repeats} after "
        f"{args.warmup} warm-up"
    )
    print(f"{'B':>5} {'N':>2} {'grid':>5}  {'method':<38} {'world-steps/s':>14} {'best':>14} {'us/step':>9}")
    T = args.steps
    for model in args.models:
        N, L = (int(x) for x in model.split("x"))
        for B in args.batch_sizes:
            medians = {}
            for name, loop in loops(B, N, L, T).items():
                median, best = timed(loop, args.repeats, args.warmup)
                medians[name] = median
                print(
                    f"{B:>5} {N:>2} {L:>2}x{L:<2}  {name:<38} {B * T / median:>14,.0f} {B * T / best:>14,.0f} "
                    f"{1e6 * median / T:>9.1f}"
                )
            ratio = medians["UAVSpectrumEnv.step"] / medians["UAVSpectrumVectorEnv.step"]
            print(f"{B:>5} {N:>2} {L:>2}x{L:<2}  vector env / UAVSpectrumEnv.step: {ratio:.2f}x")


if __name__ == "__main__":
    main()
