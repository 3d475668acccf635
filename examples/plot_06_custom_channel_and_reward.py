"""
Your own channel and reward as World parts
==========================================

A :class:`~uavrl.envs.World` is composed of parts, each behind a small contract and reached as
``world.parts[name]``: the layouts, the fading, the dynamics, the reward and, under an energy model, the energy.
This example writes two parts of its own and puts them in the world of an environment:

* a channel part: log-normal shadowing of every link, redrawn each step around the mean channel (the fading part's
  contract: ``table``, ``gains``, ``direct``, ``random``);
* a reward part: a proportional-fair team reward, the change of ``log2(1 + R_PU) + log2(1 + R_SE)``, which values
  the two networks' rates fairly rather than their sum (the reward part's contract: ``(reward, best)`` from the rates
  before and after a step).

Built-in channel models and rewards are options (``env.channel``, ``env.fading``, ``env.reward``); a new *mean*
channel model (a path loss) is added to the library itself, as ``docs/architecture.md`` (The World's parts) says,
since the exact optimum and the oracle read it too.
"""

# %%
# A channel part: log-normal shadowing
# ------------------------------------
# A random channel's per-layout table is the links' mean power gains (Rayleigh's, below, is the same), so a part
# that draws around the mean takes its place.  Its draws come from the world's own seeded streams
# (:mod:`uavrl.envs.streams`), so world ``i`` of a batch seeded ``s`` stays world 0 of one seeded ``s + i``.
import math

import matplotlib.pyplot as plt
import torch

from uavrl.agents.baselines import OraclePolicy
from uavrl.envs import UAVSpectrumEnv, make_config, streams
from uavrl.envs.fading import Fading


class LogNormalShadowing(Fading):
    """Every link's power gain times ``X = 10^(sigma_db N(0, 1) / 10)`` scaled to mean 1, drawn anew each step."""

    name, random = "lognormal", True

    def __init__(self, cfg, sigma_db: float):
        super().__init__(cfg)
        self.scale = sigma_db * math.log(10) / 10  # X = exp(scale N - scale^2 / 2): E[X] = 1

    def table(self, cell_xyz, nodes, mean_gains):
        return mean_gains

    def _draws(self, keys, counters, purpose, shape):
        u = streams.uniform(keys, counters, purpose, 2 * math.prod(shape[1:])).view(*shape, 2).double()
        normal = torch.sqrt(-2 * torch.log1p(-u[..., 0])) * torch.cos(2 * math.pi * u[..., 1])  # Box-Muller
        return torch.exp(self.scale * normal - self.scale**2 / 2)

    def gains(self, rows, keys, counters):
        return rows * self._draws(keys, counters, streams.FADING, rows.shape)

    def direct(self, snr, keys, counters):
        return snr * self._draws(keys, counters, streams.FADING_DIRECT, snr.shape)


# %%
# A reward part: proportional fairness
# ------------------------------------
# ``rates`` and ``prev_rates`` are ``[B, 2]`` (R_PU, R_SE) after and before the step; ``best`` is the memory of
# ``env.reward=best_so_far`` (kept as it is here), ``u_star`` each layout's optimum, ``mean_rates()`` the mean
# channel's rates for a reward that should not follow the draws.
class ProportionalFairReward:
    def __call__(self, rates, prev_rates, best, u_star, mean_rates):
        def fair(r):
            return torch.log2(1 + r).sum(-1)

        return fair(rates) - fair(prev_rates), best


# %%
# Put them in an environment's world
# ----------------------------------
# The environment is built with a random channel (``fading="rayleigh"``: its tables are the mean gains and its
# reward part knows the channel is random), then the world's parts are replaced.
cfg = make_config("paper", grid=(6, 6), num_uavs=2, max_steps=30, fading="rayleigh")
env = UAVSpectrumEnv(batch_size=256, config=cfg, seed=0)
env.world.fading = LogNormalShadowing(cfg, sigma_db=6.0)
env.world.reward = ProportionalFairReward()
print({name: type(part).__name__ for name, part in env.world.parts.items()})

mean_env = UAVSpectrumEnv(batch_size=256, grid=(6, 6), num_uavs=2, max_steps=30, seed=0)  # the mean channel
u_star = mean_env.optimum()[0]
with torch.no_grad():
    shadowed = env.rollout(30, OraclePolicy(cfg))
    mean = mean_env.rollout(30, OraclePolicy(mean_env.cfg))

# %%
# What the parts change
# ---------------------
# The oracle moves the UAVs to the mean channel's optimal configuration in a few steps; under shadowing the rates it
# gets there scatter from step to step, and on average they fall below the mean channel's (a rate is concave in the
# gains: Jensen's inequality) (left).  The proportional-fair reward of each step (right) sums,
# over an episode, to the fairness gained since the start.
steps = range(1, 31)
figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
for name, rollout in (("mean channel", mean), ("log-normal shadowing, 6 dB", shadowed)):
    rate = (rollout["next", "r_pu"] + rollout["next", "r_se"])[..., 0] / u_star[:, None]
    left.plot(steps, rate.mean(0), label=f"{name}: mean")
    if rollout is shadowed:
        low, high = rate.quantile(0.1, 0), rate.quantile(0.9, 0)
        left.fill_between(steps, low, high, alpha=0.25, label=f"{name}: 10-90% of worlds")
left.set_xlabel("step")
left.set_ylabel("(R_PU + R_SE) / U*  (the oracle)")
left.set_ylim(0.3, 1.05)
left.legend(loc="lower left")
right.plot(steps, shadowed["next", "reward"][..., 0].mean(0))
right.set_xlabel("step")
right.set_ylabel("proportional-fair reward (mean over worlds)")
plt.show()
