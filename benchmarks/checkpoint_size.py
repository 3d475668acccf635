"""Size of a DQN checkpoint with full replay buffers (N = 6 on 10x10, N = 10 on 20x20, a size-free network over N = 2
on 6x6 and N = 6 on 10x10) beside an earlier commit's.

Each measurement is a whole process: the scenario's agent collects until its
replay buffers (``agent.buffer_size`` transitions each) are full, with one gradient
step an iteration (``agent.updates=1``: the optimizer's state is there, and
the networks are the same size as with the scenario's updates), then its
``state_dict`` is saved as ``python -m uavrl.train`` saves a checkpoint
(``torch.save``); the bytes written are the figure.
``--baseline REV`` measures REV the same way in a temporary git worktree.

Usage::

    python benchmarks/checkpoint_size.py --baseline 36027f6
    python benchmarks/checkpoint_size.py --baseline e6fad62 --scenarios set_6_10
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from dqn_iteration import _installed_names, checkouts_beside

MEASURE = """
import io, math, torch
torch.set_num_threads(1)
from hydra import compose, initialize_config_dir
from uavrl.config import config_dir, model_config
from uavrl.agents.dqn import DQNAgent
with initialize_config_dir(config_dir=config_dir(), version_base=None):
    cfg = compose("config", overrides=["agent=dqn", *sys.argv[1:], "agent.updates=1"])
agent = DQNAgent(model_config(cfg), cfg, torch.device("cpu"), seed=0)
frames = int(cfg.agent.worlds) * cfg.env.max_steps
for _ in range(math.ceil(int(cfg.agent.buffer_size) / frames)):
    agent.train_iteration()
saved = io.BytesIO()
torch.save(agent.state_dict(), saved)
print(sum(len(group.buffer) for group in getattr(agent, "groups", [agent])), saved.tell())
"""

SIZE_FREE = [
    *("agent.network=set", "agent.mixer=mean", "agent.sizes=[[2,6,6],[6,10,10]]", "agent.worlds=8"),
    *("env.max_steps=40", "agent.buffer_size=2000", "agent.hidden=64", "agent.heads=4"),
]
SCENARIOS = {  # name: (what it is, its overrides)
    "n6_10x10": ("N = 6 on 10x10", ["scenario=n6_10x10"]),
    "large_20x20": ("N = 10 on 20x20", ["scenario=large_20x20"]),
    "set_6_10": ("size-free 2+6", SIZE_FREE),
}


def measure(checkout: Path, scenario: str) -> tuple[int, int]:
    """(transitions in the buffer, checkpoint bytes) of the code in ``checkout``."""
    code = "import sys\n" + _installed_names(checkout) + MEASURE
    done = subprocess.run([sys.executable, "-c", code, *SCENARIOS[scenario][1]], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"measuring {checkout} failed:\n{done.stderr}")
    transitions, size = map(int, done.stdout.split()[-2:])
    return transitions, size


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", help="a git revision to measure beside this checkout")
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=list(SCENARIOS))
    args = parser.parse_args()
    with checkouts_beside(args.baseline) as checkouts:
        for scenario in args.scenarios:
            sizes = {}
            for name, checkout in checkouts.items():
                transitions, sizes[name] = measure(checkout, scenario)
                per = sizes[name] / transitions
                print(
                    f"{SCENARIOS[scenario][0]:<16} {name:<22} {sizes[name] / 1e6:8.1f} MB ({transitions} transitions, "
                    f"{per:.0f} bytes each)",
                    flush=True,
                )
            if args.baseline:
                ratio = sizes["this checkout"] / sizes[f"baseline {args.baseline}"]
                print(f"{SCENARIOS[scenario][0]:<16} this checkout / baseline: {ratio:.3f}", flush=True)


if __name__ == "__main__":
    main()
