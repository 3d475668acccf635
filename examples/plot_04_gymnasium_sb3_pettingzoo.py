"""
Gymnasium, Stable-Baselines3 and PettingZoo
===========================================

The same batched worlds (same physics, seeds and action masks) behind Gymnasium's and PettingZoo's APIs, so any
library written for them trains on the UAV task.  This example needs the ``[gym]`` extra
(``pip install -e ".[gym]"``: gymnasium, pettingzoo, stable-baselines3, sb3-contrib).

It trains sb3-contrib's ``MaskablePPO`` on the team env (one ``MultiDiscrete([6] * N)`` action per step), scores it
with the same yardstick as every agent, then plays a PettingZoo episode with one policy per UAV.  ``TIMESTEPS`` is
tiny here; raise it (to 50,000, say) for a real run.
"""

# %%
# Gymnasium: one env, or a vector of batched worlds
# -------------------------------------------------
import gymnasium as gym
import matplotlib.pyplot as plt
import numpy as np
from sb3_contrib import MaskablePPO

from uavrl.agents.baselines import RandomPolicy
from uavrl.agents.evaluation import evaluate
from uavrl.envs.gym_env import TeamActionPolicy, UAVSpectrumGymEnv  # importing it registers "uavrl/UAVSpectrum-v0"
from uavrl.envs.pettingzoo_env import UAVSpectrumParallelEnv

TIMESTEPS, NUM_STARTS = 4_096, 64  # the README's PPO run: 50,000 steps; the evaluation's default: 200 starts

env = gym.make("uavrl/UAVSpectrum-v0", grid=(6, 6), num_uavs=2, max_steps=30)
obs, info = env.reset(seed=0)
print("team observation", obs.shape, "action mask", info["action_mask"].shape, "action space", env.action_space)
envs = gym.make_vec("uavrl/UAVSpectrum-v0", num_envs=256, grid=(6, 6), num_uavs=2)  # one batched World
obs, infos = envs.reset(seed=0)
print("256 worlds:", obs.shape)

# %%
# Stable-Baselines3: MaskablePPO, scored by the yardstick
# -------------------------------------------------------
# ``env.action_masks()`` is the flat mask MaskablePPO reads; ``TeamActionPolicy`` turns the trained model into a
# TorchRL policy that :func:`uavrl.agents.evaluation.evaluate` measures on the same held-out starts as every agent.
team_env = UAVSpectrumGymEnv(grid=(6, 6), num_uavs=2, max_steps=30)
model = MaskablePPO("MlpPolicy", team_env, n_steps=1_024, batch_size=256, seed=0, verbose=0)
model.learn(total_timesteps=TIMESTEPS)


def act(observation, action_mask):
    """The model's deterministic team action for each world, with each world's flat mask."""
    masks = action_mask.reshape(len(observation), -1).astype(bool)
    return model.predict(observation, action_masks=masks, deterministic=True)[0]


scores = {
    "uniform random": evaluate(RandomPolicy(seed=0), team_env.cfg, num_starts=NUM_STARTS),
    f"MaskablePPO, {TIMESTEPS:,} steps": evaluate(TeamActionPolicy(act), team_env.cfg, num_starts=NUM_STARTS),
}
for name, metrics in scores.items():
    print(f"{name}: return ratio {metrics['eval/return_ratio']:.3f}, final U/U* {metrics['eval/optimality']:.3f}")

# %%
# PettingZoo: one policy per UAV
# ------------------------------
# The parallel env names the UAVs ``uav_0``, ``uav_1``, ...; each gets its observation and action mask and the team
# reward.  Here each draws a random allowed action; the episode's utility is in ``infos``.
pz_env = UAVSpectrumParallelEnv(grid=(6, 6), num_uavs=2, max_steps=30)
observations, infos = pz_env.reset(seed=0)
for i, agent in enumerate(pz_env.agents):
    pz_env.action_space(agent).seed(i)  # reproducible draws
utility = []
while pz_env.agents:
    actions = {a: pz_env.action_space(a).sample(observations[a]["action_mask"]) for a in pz_env.agents}
    observations, rewards, terminations, truncations, infos = pz_env.step(actions)
    utility.append(infos["uav_0"]["utility"])

figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
labels = {"eval/return_ratio": "return ratio", "eval/optimality": "final U / U*"}
for i, (name, metrics) in enumerate(scores.items()):
    left.bar(np.arange(len(labels)) + 0.4 * i, [metrics[key] for key in labels], 0.4, label=name)
left.set_xticks(np.arange(len(labels)) + 0.2, list(labels.values()))
left.set_ylabel("score (1 = exact optimal control)")
left.set_title(f"yardstick, {NUM_STARTS} held-out starts")
left.set_ylim(0, 1.25)
left.legend(loc="upper left")
right.plot(range(1, len(utility) + 1), utility)
right.set_xlabel("step")
right.set_ylabel("team utility U (bit/s/Hz)")
right.set_title("a PettingZoo episode, random actions")
plt.show()
