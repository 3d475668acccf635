"""
A guided tour of uavrl
======================

``uavrl`` is a batched TorchRL environment for UAV spectrum sharing: N UAVs on a grid of cells each either *relay*
for a primary network (PT to PR) or *sense* for a secondary one (S to E), and the team is paid the sum of the two
networks' rates, ``U = R_PU + R_SE``.  Beside the environment it ships agents (tabular team Q-learning, a factored
DQN, baselines), the exact optimum ``U*`` and an exact solver of optimal control to score any policy against.

This tour takes ten minutes to read and under a minute to run: the environment, a picture of it, the optimum, a
trained agent and its score.  Every other page of the gallery goes deeper into one of these steps.  The tour is also
a notebook: the gallery offers it for download, and ``.ci/notebook`` converts and runs it in CI.
"""

# %%
# The environment
# ---------------
# ``B`` independent worlds step in one tensor program.  The keys follow TorchRL's multi-agent convention: the group
# ``"agents"`` holds each UAV's ``observation``, ``action`` and ``action_mask``; the root holds the team ``reward``,
# the done keys, a global ``state`` and the step's rates.
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import torch

from uavrl import load_policy
from uavrl.agents.evaluation import evaluate
from uavrl.envs import ACTION_NAMES, UAVSpectrumEnv

env = UAVSpectrumEnv(batch_size=512, grid=(6, 6), num_uavs=2, max_steps=40, seed=0)
print("actions:", ACTION_NAMES)
td = env.rollout(40)  # random actions
print(td)

# %%
# The optimum
# -----------
# ``env.optimum()`` gives each world's exact best utility ``U*`` and the configurations that reach it.  Random
# actions end far from it:
u_star, positions, tasks = env.optimum()
final = td["next", "utility"][:, -1, 0] / u_star
print(f"U* = {u_star[0]:.3f} bit/s/Hz; random actions end at {final.mean():.3f} of it on average")
print("an optimal configuration: cells (x, y)", positions[0].tolist(), "tasks (1 = relay)", tasks[0].tolist())

# %%
# A picture of a world
# --------------------
# ``env.render()`` draws one world: the nodes, the UAVs coloured by task with the links they serve, and the step's
# utility against ``U*``.
plt.figure(figsize=(8, 6))
plt.imshow(env.render(env_index=0))
plt.axis("off")
plt.show()

# %%
# Train an agent
# --------------
# ``python -m uavrl.train`` trains any agent and writes a run directory (config, checkpoint, metrics, TensorBoard).
# Here the factored DQN for 40 iterations, about fifteen seconds (its default is 500); the command runs in a
# subprocess of this interpreter, exactly as in a shell, and writes ``runs/tour/dqn`` under the current directory.
run_dir = Path("runs/tour/dqn")
if not (run_dir / "metrics.json").exists():
    command = [sys.executable, "-m", "uavrl.train", "agent=dqn", "agent.iterations=40", "eval.num_starts=32"]
    result = subprocess.run([*command, f"run_dir={run_dir}", "progress=false"], capture_output=True, text=True)
    print(result.stdout or result.stderr)
    result.check_returncode()

# %%
# Load it back and score it
# -------------------------
# ``load_policy`` returns the run's greedy TorchRL policy and its environment's settings; ``evaluate`` measures any
# policy against exact optimal control on fixed, seeded starts: the discounted return over the best possible one,
# and the share of starts that reach 0.999 ``U*``.
policy, env_config = load_policy(run_dir)
metrics = evaluate(policy, env_config, num_starts=64)
print(
    f"return ratio {metrics['eval/return_ratio']:.3f}, reach 0.999 U* {metrics['eval/reach_999']:.2f}, "
    f"final U/U* {metrics['eval/optimality']:.3f}"
)

# %%
# Watch it act
# ------------
# The trained policy from the same start as a random one: the utility per step over ``U*``.
env = UAVSpectrumEnv(batch_size=64, config=env_config, seed=1)
u_star = env.optimum()[0]
with torch.no_grad():
    trained = env.rollout(20, policy)
env.set_seed(1)
random_actions = env.rollout(20)
figure, axis = plt.subplots(figsize=(7, 4), layout="constrained")
for name, rollout in (("trained DQN", trained), ("random actions", random_actions)):
    axis.plot(range(1, 21), (rollout["next", "utility"][..., 0] / u_star[:, None]).mean(0), label=name)
axis.set_xlabel("step")
axis.set_ylabel("U / U*  (mean over 64 worlds)")
axis.set_title("6x6 grid, 2 UAVs")
axis.legend()
plt.show()

# %%
# Where next
# ----------
# The gallery's other examples: the environment in your own TorchRL loop; TorchRL's MAPPO and QMIX/VDN scripts;
# Gymnasium, Stable-Baselines3 and PettingZoo; your own policy against exact optimal control; your own channel and
# reward; an energy mission; a size-free policy at 50 UAVs; the paper's Table II and figures; a study on Ray.
