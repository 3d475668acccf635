"""
Reproducing Table II and Figs. 3-5
==================================

``python -m uavrl.reproduce`` runs the paper's protocol (team Q-learning with two UAVs, alpha 0.1, gamma 0.3,
epsilon 0.1) on its grids and writes Table II (the run time per episode against the paper's, the greedy policies'
final ``U / U*`` and the yardstick) and Figs. 3-5 (sum throughput per episode, task switches and moves, steps to
90% of ``U*``).  The whole table at full size takes about ten seconds; here it runs on two grids with 3 runs of 30
episodes.  Drop ``grids``, ``runs`` and ``episodes`` (the paper's: 7 grids, 10 runs, 200 episodes) for the real one.

The outputs go to ``reproduction/example/`` under the current directory.
"""

# %%
# Table II
# --------
# The command runs in a subprocess of this interpreter, exactly as on the command line.
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt

out_dir = Path("reproduction/example").resolve()
settings = ["grids=[3,6]", "runs=3", "episodes=30", "figure_grid=6", "progress=false"]
common = [*settings, f"out_dir={out_dir}", "overwrite=true"]
table = subprocess.run(
    [sys.executable, "-m", "uavrl.reproduce", "table2", *common], capture_output=True, text=True, check=True
)
print(table.stdout)

# %%
# Figs. 3-5
# ---------
# ``figures`` draws them for ``figure_grid`` from the episode histories ``table2`` saved (PNG and TensorBoard).
subprocess.run(
    [sys.executable, "-m", "uavrl.reproduce", "figures", *common], capture_output=True, text=True, check=True
)
for name in ("fig3_sum_utility.png", "fig4_switches_moves.png", "fig5_steps_to_90.png"):
    figure, axis = plt.subplots(figsize=(8, 5), layout="constrained")
    axis.imshow(plt.imread(out_dir / name))
    axis.set_axis_off()
plt.show()
