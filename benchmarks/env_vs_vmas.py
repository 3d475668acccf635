"""World-steps per second of UAVSpectrumEnv beside VMAS on the same TorchRL paths, interleaved in one process.

VMAS (``pip install vmas``) runs through ``torchrl.envs.libs.vmas.VmasEnv``
with discrete actions (``continuous_actions=False``, 5 categorical actions
per agent), ``num_envs=B``, ``n_agents=N`` and no episode limit; ours is
``UAVSpectrumEnv(batch_size=B, grid=..., num_uavs=N)`` with ``max_steps``
larger than T.  Neither resets a world during a timed run.  Paths:

* ``rollout+mask``: ours is ``TransformedEnv(env, ActionMask(("agents",
  "action"), ("agents", "action_mask"))).rollout(T)``, TorchRL's random
  policy drawing valid actions only (the way TorchRL users get them); VMAS has
  no action mask, so its figure is its plain ``env.rollout(T)`` (the same as
  the next row).
* ``rollout``: ``env.rollout(T)`` with TorchRL's random policy (ours draws any
  of its 6 actions; a move off the grid stays).
* ``step loop``: ``td = env.reset()``, then ``T`` times ``td =
  env.step_mdp(env.step(env.rand_action(td)))``, outputs dropped.

``--lean`` adds a column for ours with ``diagnostics=False`` (the keys an
agent acts and learns from, as BenchMARL's task builds it).  ``--stub`` adds
a column for a stub of ours: the same specs and keys, every step a copy of
one output with no physics at all (every action allowed), so its figures are
the most any environment with our keys can get from TorchRL's machinery on
these paths.

A world-step is one step of one world (all its N agents): figures are
``B * T / wall time``.  Each timed run measures ours and every VMAS scenario
one after the other (the order rotates between runs), so load from other jobs
hits all of them alike; each figure is the median of ``--repeats`` runs after
``--warmup`` runs, printed beside VMAS's and their ratio (ours / VMAS).

Usage::

    python benchmarks/env_vs_vmas.py                      # B = 4096, T = 50, N = 2 and 6, 1 thread
    python benchmarks/env_vs_vmas.py --uavs 2 --repeats 3
    git archive <rev> envs | tar -x -C /tmp/before && python benchmarks/env_vs_vmas.py --before /tmp/before/envs
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import statistics
import sys
import time

PATHS = ("rollout+mask", "rollout", "step loop")


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch-size", type=int, default=4096, help="worlds B (default 4096)")
    p.add_argument("--steps", type=int, default=50, help="steps T per timed run (default 50)")
    p.add_argument("--uavs", type=int, nargs="+", default=[2, 6], help="agents N (default 2 6)")
    p.add_argument("--grid", type=int, nargs=2, default=[6, 6], help="our grid (default 6 6)")
    p.add_argument(
        "--scenarios", nargs="*", default=["simple_spread", "navigation"], help="VMAS scenarios (none: ours only)"
    )
    p.add_argument("--paths", nargs="+", default=list(PATHS), choices=PATHS)
    p.add_argument(
        "--before",
        metavar="ENVS_DIR",
        help="also time the envs/ folder of another uavrl version (e.g. from git archive) in the same runs",
    )
    p.add_argument("--lean", action="store_true", help="also time ours with diagnostics=False")
    p.add_argument("--stub", action="store_true", help="also time a stub with our keys and no physics")
    p.add_argument("--repeats", type=int, default=5, help="timed runs per figure (default 5)")
    p.add_argument("--warmup", type=int, default=1, help="untimed runs first (default 1)")
    p.add_argument("--threads", type=int, default=1, help="torch.set_num_threads (default 1)")
    return p.parse_args(argv)


def main(argv=None):
    args = parse_args(argv)
    import torch
    import torchrl

    try:
        import vmas
    except ImportError:
        sys.exit("benchmarks/env_vs_vmas.py needs VMAS: pip install vmas (--dry-run first: it must keep your torch)")
    from env_throughput import stub_env  # this folder is on sys.path when run as a script
    from torchrl.envs import ActionMask, TransformedEnv
    from torchrl.envs.libs.vmas import VmasEnv

    from uavrl.envs import UAVSpectrumEnv

    def load_before(envs_dir):
        """``UAVSpectrumEnv`` of another version's ``envs/`` folder (relative imports only), as package ``before``."""
        spec = importlib.util.spec_from_file_location("before", os.path.join(envs_dir, "__init__.py"))
        package = importlib.util.module_from_spec(spec)
        sys.modules["before"] = package
        spec.loader.exec_module(package)
        return importlib.import_module("before.env").UAVSpectrumEnv

    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    B, T = args.batch_size, args.steps

    def run(env, path):
        if path == "step loop":
            td = env.reset()
            for _ in range(T):
                td = env.step_mdp(env.step(env.rand_action(td)))
        else:
            env.rollout(T)

    print(
        f"# uavrl env vs VMAS {vmas.__version__}: {time.strftime('%Y-%m-%d %H:%M')}, torch {torch.__version__}, "
        f"torchrl {torchrl.__version__}, threads {torch.get_num_threads()}, {os.cpu_count()} CPUs "
        f"({platform.processor() or platform.machine()}); before: {args.before}"
    )
    print(
        f"# B = {B}, T = {T}, our grid {args.grid[0]}x{args.grid[1]}, VMAS discrete actions; medians of "
        f"{args.repeats} interleaved runs after {args.warmup}; world-steps/s; load average at start "
        f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}"
    )
    Before = load_before(args.before) if args.before else None
    extra = ["before"] * bool(Before) + ["lean"] * args.lean + ["stub"] * args.stub
    columns = extra + args.scenarios
    width = max(len(s) for s in columns + ["uavrl"])
    print(
        f"{'N':>2}  {'path':<13} {'uavrl':>{width + 2}}  "
        + "  ".join(f"{s:>{width + 2}} {'ratio':>6}" for s in columns)
    )
    makers = {"uavrl": UAVSpectrumEnv, "before": Before, "lean": UAVSpectrumEnv, "stub": stub_env}
    for N in args.uavs:
        kwargs = dict(batch_size=B, grid=tuple(args.grid), num_uavs=N, max_steps=10**9)
        ours = {
            name: makers[name](**kwargs, **({"diagnostics": False} if name == "lean" else {}))
            for name in ["uavrl", *extra]
        }
        masked = {
            name: TransformedEnv(env, ActionMask(("agents", "action"), ("agents", "action_mask")))
            for name, env in ours.items()
        }
        peers = {
            s: VmasEnv(s, num_envs=B, n_agents=N, continuous_actions=False, device="cpu", seed=0)
            for s in args.scenarios
        }
        for path in args.paths:
            contenders = {**(masked if path == "rollout+mask" else ours), **peers}
            names = list(contenders)
            times = {name: [] for name in names}
            for i in range(args.warmup + args.repeats):
                shift = i % len(names)
                for name in names[shift:] + names[:shift]:
                    start = time.perf_counter()
                    run(contenders[name], path)
                    if i >= args.warmup:
                        times[name].append(time.perf_counter() - start)
            rate = {name: B * T / statistics.median(t) for name, t in times.items()}
            cells = "  ".join(f"{rate[s] / 1e6:>{width}.3f} M {rate['uavrl'] / rate[s]:>5.2f}x" for s in columns)
            print(f"{N:>2}  {path:<13} {rate['uavrl'] / 1e6:>{width}.3f} M  {cells}", flush=True)
    print(f"# load average at end {' '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
