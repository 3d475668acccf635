"""
A size-free checkpoint evaluated zero-shot at N = 50
====================================================

A size-free DQN (``agent.network=set``) reads each UAV's neighbourhood as a set, so one checkpoint acts in a team of
any size on any grid.  ``agent.sizes`` trains it over several teams at once; it is then evaluated on a team and grid
it never saw.

Here a tiny size-free run (teams of 2 and 4 UAVs, 20 iterations, a few seconds) is trained and evaluated zero-shot
with 50 UAVs on a 50x50 grid, beside the oracle planner and random actions.  A tiny run does not beat random actions
there: a real checkpoint comes from ``python -m uavrl.train agent=dqn scenario=size_free`` (teams of 2 to 16 UAVs,
about 20 minutes on one core), which reaches 0.999 ``U*`` from 97-100% of the starts of 50 UAVs on 50x50.  Point
``run_dir`` at such a run (``runs/dqn/size_free/<stamp>``) to evaluate it instead.

The run is written to ``runs/examples/size_free`` under the current directory.
"""

# %%
# Train a tiny size-free run
# --------------------------
# The command runs in a subprocess of this interpreter, exactly as on the command line; ``run_dir`` names its folder.
import shutil
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from uavrl import load_policy
from uavrl.agents.baselines import OraclePolicy, RandomPolicy
from uavrl.agents.evaluation import evaluate
from uavrl.envs import make_config

run_dir = Path("runs/examples/size_free")
shutil.rmtree(run_dir, ignore_errors=True)  # this example's own run of an earlier time
tiny = ["agent.iterations=20", "agent.sizes=[[2,6,6],[4,8,8]]", "agent.layouts=[line]", "agent.learning_starts=200"]
command = [sys.executable, "-m", "uavrl.train", "agent=dqn", "scenario=size_free", *tiny, "eval.num_starts=8"]
result = subprocess.run([*command, f"run_dir={run_dir}", "progress=false"], capture_output=True, text=True, check=True)
print(result.stdout)

# %%
# Zero-shot: 50 UAVs on a 50x50 grid
# ----------------------------------
# ``load_policy(run_dir, env_config=...)`` asks for the policy in another team size or grid of the run's model (any
# policy but a size-free one is refused there, in one line).  The exact solver does not fit 50 UAVs, so the fewest
# steps are the yardstick's lower bounds; ``U*`` itself is exact.
# ``python -m uavrl.evaluate checkpoint=<run_dir> env.grid=[50,50] env.num_uavs=50`` does the same from the shell.
NUM_STARTS = 16  # the evaluation's default: 200
cfg = make_config("paper", grid=(50, 50), num_uavs=50)
policy, cfg = load_policy(run_dir, env_config=cfg)
scores = {
    "size-free DQN (tiny run)": evaluate(policy, cfg, num_starts=NUM_STARTS),
    "oracle planner": evaluate(OraclePolicy(cfg), cfg, num_starts=NUM_STARTS),
    "uniform random": evaluate(RandomPolicy(seed=0), cfg, num_starts=NUM_STARTS),
}
for name, metrics in scores.items():
    print(f"{name}: final U/U* {metrics['eval/optimality']:.3f}, reach 0.999 U* {metrics['eval/reach_999']:.2f}")

figure, axis = plt.subplots(figsize=(8, 4), layout="constrained")
labels = {"eval/optimality": "final U / U*", "eval/reach_999": "starts reaching 0.999 U*"}
for i, (name, metrics) in enumerate(scores.items()):
    axis.bar(np.arange(len(labels)) + 0.27 * i, [metrics[key] for key in labels], 0.27, label=name)
axis.set_xticks(np.arange(len(labels)) + 0.27, list(labels.values()))
axis.set_ylim(0, 1.3)
axis.set_ylabel("score (1 = optimal)")
axis.set_title(f"zero-shot: 50 UAVs on 50x50, {NUM_STARTS} held-out starts")
axis.legend(loc="upper right")
plt.show()
