"""
An energy mission and its battery plot
======================================

Under an energy model (``env.energy=rotary_wing``) every UAV carries a battery: hovering, moving and the way home
cost energy, a UAV at its reserve flies back to the base, and with spares and recharging a charged UAV takes its
place.  One start is then one *mission*, scored by the data it delivers against an upper bound.

This example plays a persistent mission (three UAVs in service, one spare, recharging at the base) with the
energy-aware planner and with the oracle that ignores energy, scores both with :func:`uavrl.agents.evaluation.evaluate`,
and draws the planner's batteries with :func:`uavrl.experiment.missions.battery_figure`.  ``scenario=persistent_10x10``
is the same kind of mission at full size; raise ``HORIZON`` and ``NUM_STARTS`` for a real run.
"""

# %%
# A persistent mission
# --------------------
import matplotlib.pyplot as plt

from uavrl.agents.baselines import OraclePolicy
from uavrl.agents.evaluation import evaluate
from uavrl.agents.planner import PlannerPolicy
from uavrl.envs import make_config
from uavrl.experiment.missions import battery_figure, mission_history

HORIZON, NUM_STARTS = 240, 16  # scenario=persistent_10x10: 500 steps, 200 starts
cfg = make_config(
    "paper",
    grid=(6, 6),
    num_uavs=3,
    num_spares=1,
    energy="rotary_wing",
    battery_wh=3.0,
    base=(-1, 0),
    recharge_steps=30,
)
print(f"{cfg.fleet_size} UAVs, a full battery holds {cfg.step_energies.capacity:.0f} J")

# %%
# Delivered data against its bound
# --------------------------------
# ``eval/delivered_ratio`` is the data delivered over an upper bound no policy can beat (at every step, the exact
# optimum of the UAVs whose batteries can still serve); ``eval/service_steps_per_uav`` the steps each UAV served.
for name, policy in (("planner", PlannerPolicy(cfg)), ("oracle", OraclePolicy(cfg))):
    metrics = evaluate(policy, cfg, num_starts=NUM_STARTS, horizon=HORIZON)
    print(
        f"{name:>8}: delivered {metrics['eval/delivered_bit_per_hz']:.0f} bit/Hz, "
        f"{metrics['eval/delivered_ratio']:.3f} of the bound, "
        f"first UAV leaves at step {metrics['eval/first_leave_steps']:.0f}"
    )

# %%
# The batteries of one mission
# ----------------------------
# The top row counts the UAVs in service (three at most); below, each UAV's battery, shaded while it is away or
# charging, with markers where it leaves, comes back and enters service.
battery, status = mission_history(PlannerPolicy(cfg), cfg, horizon=HORIZON, seed=0)
figure = battery_figure(
    battery,
    status,
    cfg.step_energies.capacity,
    num_serving=cfg.num_uavs,
    title="energy-aware planner, 6x6, 3 serving + 1 spare, recharged in 30 steps",
)
figure.tight_layout()  # as uavrl.experiment.plots.save_figure does before it writes the PNG
plt.show()
