"""World-steps per second of UAVSpectrumEnv, beside a trivial TorchRL env measured the same way.

For every batch size B and UAV count N this prints, in world-steps per second
(B times the number of steps, over the wall time):

* ``rollout``: ``env.rollout(T, policy, break_when_any_done=False)`` with a
  masked uniform random policy (valid per-UAV actions only); ``max_steps`` is
  larger than T, so no world resets during the run.  This includes TorchRL's
  per-step bookkeeping and its final ``torch.stack`` of every key along the
  time dimension.
* ``rollout, no stack``: the loop of ``env.rollout`` (policy, then
  ``step_and_maybe_reset``, every step's TensorDict kept) without the final
  stack.  (``return_contiguous=False`` is no way around the stack: TorchRL
  0.14's ``maybe_dense_stack`` stacks densely whenever it can.)
* ``step loop``: ``policy(td); td = step_mdp(env.step(td))``, outputs not kept.
* ``env._step``: the environment's own code (action check, dynamics, rates,
  reward, observation), outputs kept as a rollout keeps them.
* ``policy``: the masked random policy alone, for reference.
* ``stub rollout``: a stub env with exactly the same keys, shapes and dtypes
  that only copies one output (zeros, every action allowed): what ``env.rollout``
  costs for this output volume.
* ``trivial rollout``: a minimal EnvBase (one float observation, one action)
  with a random policy: TorchRL's floor.

Each figure is the median (and the best) of ``--repeats`` timed runs after
``--warmup`` runs; ``us/step`` is the median time of one step of all B worlds.

Usage::

    python benchmarks/env_throughput.py                  # 1 thread
    python benchmarks/env_throughput.py --threads 2
    python benchmarks/env_throughput.py --malloc-hugetlb # re-runs itself with GLIBC_TUNABLES=glibc.malloc.hugetlb=1
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time

HUGETLB = "glibc.malloc.hugetlb=1"


def timed(fn, repeats: int, warmup: int) -> tuple[float, float]:
    """(median, best) seconds of ``repeats`` runs of ``fn`` after ``warmup`` runs."""
    times = []
    for i in range(warmup + repeats):
        start = time.perf_counter()
        fn()
        if i >= warmup:
            times.append(time.perf_counter() - start)
    return statistics.median(times), min(times)


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--threads", type=int, default=1, help="torch.set_num_threads (default 1)")
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[1, 64, 4096])
    p.add_argument("--uavs", type=int, nargs="+", default=[2, 6])
    p.add_argument("--grid", type=int, nargs=2, default=[6, 6])
    p.add_argument(
        "--world-steps",
        type=int,
        default=400_000,
        help="world-steps per timed run (T = this / B, clipped to [100, 2000])",
    )
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument(
        "--malloc-hugetlb",
        action="store_true",
        help=f"re-run with GLIBC_TUNABLES={HUGETLB} (transparent huge pages for malloc)",
    )
    return p.parse_args(argv)


def stub_env(**kwargs):
    """A ``UAVSpectrumEnv(**kwargs)`` whose every step returns a fresh copy of one output (zeros, every action
    allowed): the same specs, keys, shapes and dtypes with no physics, so its rollout costs what TorchRL's machinery
    costs for our output volume (also used by ``env_vs_vmas.py --stub``)."""
    from uavrl.envs import UAVSpectrumEnv

    class StubEnv(UAVSpectrumEnv):
        def _step(self, td):
            if not hasattr(self, "_output"):
                self._output = (
                    self.full_observation_spec.zero()
                    .update(self.full_reward_spec.zero())
                    .update(self.full_done_spec.zero())
                )
                self._output["agents", "action_mask"].fill_(True)
            return self._output.clone()

    return StubEnv(**kwargs)


def main(argv=None):
    args = parse_args(argv)
    if args.malloc_hugetlb and HUGETLB not in os.environ.get("GLIBC_TUNABLES", ""):
        env = dict(os.environ, GLIBC_TUNABLES=":".join(filter(None, [os.environ.get("GLIBC_TUNABLES"), HUGETLB])))
        os.execve(sys.executable, [sys.executable, *sys.argv], env)

    import torch
    from tensordict import TensorDict
    from torchrl.data import Categorical, Composite, Unbounded
    from torchrl.envs import EnvBase
    from torchrl.envs.utils import step_mdp

    from uavrl.envs import UAVSpectrumEnv

    torch.set_num_threads(args.threads)

    class TrivialEnv(EnvBase):
        """One float observation, six actions, zero reward, never done."""

        def __init__(self, batch_size):
            super().__init__(batch_size=torch.Size([batch_size]))
            self.observation_spec = Composite(observation=Unbounded((batch_size, 1)), shape=(batch_size,))
            self.action_spec = Categorical(6, (batch_size, 1))
            self.reward_spec = Unbounded((batch_size, 1))

        def _reset(self, td):
            B = self.batch_size[0]
            return TensorDict(
                {
                    "observation": torch.zeros(B, 1),
                    "done": torch.zeros(B, 1, dtype=torch.bool),
                    "terminated": torch.zeros(B, 1, dtype=torch.bool),
                },
                self.batch_size,
            )

        def _step(self, td):
            B = self.batch_size[0]
            return TensorDict(
                {
                    "observation": torch.zeros(B, 1),
                    "reward": torch.zeros(B, 1),
                    "done": torch.zeros(B, 1, dtype=torch.bool),
                    "terminated": torch.zeros(B, 1, dtype=torch.bool),
                },
                self.batch_size,
            )

        def _set_seed(self, seed):
            return seed

    gen = torch.Generator().manual_seed(0)

    def masked_random(td):
        mask = td.get(("agents", "action_mask"))
        td.set(("agents", "action"), torch.rand(mask.shape, generator=gen).masked_fill_(~mask, -1.0).argmax(-1))
        return td

    def random_action(td):
        td.set("action", torch.randint(0, 6, td.batch_size + (1,), generator=gen))
        return td

    print(
        f"# uavrl env throughput: {time.strftime('%Y-%m-%d')}, torch {torch.__version__}, threads "
        f"{torch.get_num_threads()}, "
        f"{os.cpu_count()} CPUs ({platform.processor() or platform.machine()}), "
        f"GLIBC_TUNABLES={os.environ.get('GLIBC_TUNABLES', '')!r}"
    )
    print(
        f"# grid {args.grid[0]}x{args.grid[1]}, max_steps > T (no resets), {args.repeats} runs after {args.warmup} "
        f"warm-up runs; load average {os.getloadavg()[0]:.2f}"
    )
    print(f"{'B':>5} {'N':>2} {'T':>5}  {'method':<17} {'world-steps/s':>14} {'best':>14} {'us/step':>9}")
    for N in args.uavs:
        for B in args.batch_sizes:
            T = max(100, min(2000, args.world_steps // B))
            env = UAVSpectrumEnv(batch_size=B, grid=tuple(args.grid), num_uavs=N, max_steps=10**9)
            stub = stub_env(batch_size=B, grid=tuple(args.grid), num_uavs=N, max_steps=10**9)
            trivial = TrivialEnv(B)
            start = env.reset()
            actions = torch.stack([masked_random(start.clone())[("agents", "action")] for _ in range(T)])

            def rollout_unstacked(env=env, T=T):  # what env.rollout does per step, without its final torch.stack
                td, kept = env.reset(), []
                for _ in range(T):
                    td.update(masked_random(td))
                    out, td = env.step_and_maybe_reset(td)
                    kept.append(out)

            def step_loop(env=env, T=T):
                td = env.reset()
                for _ in range(T):
                    td = step_mdp(env.step(masked_random(td)))

            def own_step(env=env, T=T, start=start, actions=actions):
                td = start.clone()
                kept = []
                for t in range(T):
                    td.set(("agents", "action"), actions[t])
                    kept.append(env._step(td))

            def policy_only(T=T, start=start):
                td = start.clone()
                for _ in range(T):
                    masked_random(td)

            rows = [
                ("rollout", lambda env=env, T=T: env.rollout(T, masked_random, break_when_any_done=False)),
                ("rollout, no stack", rollout_unstacked),
                ("step loop", step_loop),
                ("env._step", own_step),
                ("policy", policy_only),
                ("stub rollout", lambda stub=stub, T=T: stub.rollout(T, masked_random, break_when_any_done=False)),
                (
                    "trivial rollout",
                    lambda trivial=trivial, T=T: trivial.rollout(T, random_action, break_when_any_done=False),
                ),
            ]
            for name, fn in rows:
                median, best = timed(fn, args.repeats, args.warmup)
                print(
                    f"{B:>5} {N:>2} {T:>5}  {name:<17} {B * T / median:>14,.0f} {B * T / best:>14,.0f} "
                    f"{median / T * 1e6:>9.1f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
