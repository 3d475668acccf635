"""
A study on Ray and its report
=============================

A study is many runs: agents x scenarios x seeds.  ``python -m uavrl.train -m`` sweeps every combination of the
comma-separated values through one of Hydra's launchers; with ``hydra/launcher=ray`` each job runs on a Ray worker
(here a local Ray instance of 2 CPUs started by the sweep; on a cluster, ``hydra.launcher.ray.init.address=``).
``python -m uavrl.report`` then turns the run directories into a table with bootstrap confidence intervals and two
figures per setting.

This example needs the ``[ray]`` extra (``pip install -e ".[ray]"``: Ray, Hydra's Ray and joblib launchers).  It
sweeps the tabular learner at a tiny budget over three seeds and the two baselines beside it, all on the
``paper_6x6`` scenario; drop ``agent.episodes``, ``agent.runs`` and ``env.max_steps`` for the scenario's real
budget, and add seeds.  The study goes to ``runs/examples/study`` under the current directory.
"""

# %%
# Two sweeps into one study
# -------------------------
# An override that belongs to one agent (``agent.episodes``) cannot go into a sweep over agents that lack it, so the
# learner and the baselines are swept separately into the same ``sweep_dir``.
import shutil
import subprocess
import sys
from pathlib import Path

import hydra_plugins.hydra_ray_launcher  # noqa: F401  (the [ray] extra: Hydra's Ray launcher)
import matplotlib.pyplot as plt

sweep_dir = Path("runs/examples/study")
shutil.rmtree(sweep_dir, ignore_errors=True)  # this example's own study of an earlier time
ray = ["hydra/launcher=ray", "+hydra.launcher.ray.init.num_cpus=2"]
common = [f"sweep_dir={sweep_dir}", "scenario=paper_6x6", "eval.num_starts=16", "seed=0,1,2", "progress=false"]
sweeps = {
    "tabular": ["agent=tabular", "agent.episodes=20", "agent.runs=2", "env.max_steps=300"],
    "baselines": ["agent=random,oracle"],
}
for overrides in sweeps.values():
    command = [sys.executable, "-m", "uavrl.train", "-m", *ray, *common, *overrides]
    subprocess.run(command, capture_output=True, text=True, check=True)
for run in sorted(sweep_dir.rglob("metrics.json")):
    print(run.parent.relative_to(sweep_dir))

# %%
# The report
# ----------
# ``report.md`` holds, per setting and agent, the mean over seeds of the yardstick with a 95% bootstrap interval;
# the figures show the same metrics per agent and the learning curves, with the baselines as reference lines.
report = subprocess.run(
    [sys.executable, "-m", "uavrl.report", str(sweep_dir)], capture_output=True, text=True, check=True
)
print(report.stdout)
print((sweep_dir / "report.md").read_text())
for name in ("paper_6x6_metrics.png", "paper_6x6_curves.png"):
    figure, axis = plt.subplots(figsize=(10, 6), layout="constrained")
    axis.imshow(plt.imread(sweep_dir / name))
    axis.set_axis_off()
plt.show()
