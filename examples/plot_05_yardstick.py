"""
Scoring your own policy against exact optimal control
=====================================================

The final utility after a long horizon cannot tell policies apart (random actions already end at 0.6 of the
optimum ``U*`` with two UAVs).  :func:`uavrl.agents.evaluation.evaluate` measures any TorchRL policy against exact
optimal
control instead: from fixed, seeded starts it compares the discounted return with the exact best ``V*_H``
(backward induction on the whole configuration graph, :mod:`uavrl.envs.exact`), and the steps a policy takes to
0.999 ``U*`` with the fewest possible.

Here a hand-written rule, "every UAV climbs towards the cell where its own task contributes most", is scored beside
the uniform random policy and the oracle planner.  Raise ``NUM_STARTS`` (to the default 200) for a real score.
"""

# %%
# Your policy: any TorchRL module that writes ``("agents", "action")``
# --------------------------------------------------------------------
# Each UAV's observation starts with its own (x, y, task), then the contributions it would add relaying for the
# primary link and sensing for the secondary one, at its cell and at the four cells its moves reach (actions up,
# down, left, right; -1 off the grid).
import matplotlib.pyplot as plt
import torch
from tensordict.nn import TensorDictModule

from uavrl.agents.baselines import OraclePolicy, RandomPolicy
from uavrl.agents.evaluation import evaluate
from uavrl.envs import ACTION_NAMES, exact, make_config

NUM_STARTS = 64  # the evaluation's default is 200 starts
SENSE, RELAY = ACTION_NAMES.index("sense"), ACTION_NAMES.index("relay")


def climb_own_contribution(observation, action_mask):
    """Move to the neighbouring cell where the UAV's own task adds most; stay (keeping its task) at a local peak."""
    task = observation[..., 2].long()  # 0 sensing, 1 relaying
    contributions = observation[..., 3:13].unflatten(-1, (5, 2))  # [..., cell: own, up, down, left, right, 2]
    own_task = contributions.gather(-1, (1 - task)[..., None, None].expand(*task.shape, 5, 1)).squeeze(-1)
    best = own_task.argmax(-1)  # 0: here, 1-4: the move's cell
    stay = torch.where(task == 1, RELAY, SENSE)
    action = torch.where(best == 0, stay, best - 1)
    return torch.where(action_mask.gather(-1, action[..., None]).squeeze(-1), action, stay)


my_policy = TensorDictModule(
    climb_own_contribution,
    in_keys=[("agents", "observation"), ("agents", "action_mask")],
    out_keys=[("agents", "action")],
)

# %%
# The yardstick
# -------------
# ``evaluate`` builds the environment of ``cfg`` itself, with the same held-out starts for every policy, so the
# numbers compare with every agent's ``eval/...`` metrics.
cfg = make_config("paper", grid=(6, 6), num_uavs=2)
policies = {"random": RandomPolicy(seed=0), "climb own contribution": my_policy, "oracle planner": OraclePolicy(cfg)}
scores = {name: evaluate(policy, cfg, num_starts=NUM_STARTS) for name, policy in policies.items()}
for name, metrics in scores.items():
    print(
        f"{name:>24}: return ratio {metrics['eval/return_ratio']:.3f}, "
        f"reach 0.999 U* {metrics['eval/reach_999']:.2f}, final U/U* {metrics['eval/optimality']:.3f}"
    )

# %%
# The exact solver itself
# -----------------------
# ``evaluate`` reads its references from :mod:`uavrl.envs.exact`, which you can query directly: every
# configuration of 2 interchangeable UAVs on 6x6 (cells and tasks), its utility, the fewest steps from it to ``U*``
# (breadth-first search) and the best discounted return from it (value iteration).
space = exact.ConfigurationSpace(cfg.grid, cfg.num_uavs)
utility = space.utility(cfg, *exact.fixed_layout_tables(cfg))  # [1, K]
at_optimum = utility >= utility.max() * (1 - 1e-9)
fewest = exact.min_steps(space, at_optimum)
best_return = exact.optimal_values(space, utility, gamma=0.9)
print(
    f"{utility.shape[1]:,} configurations, {int(at_optimum.sum())} of them optimal; fewest steps to U*: "
    f"{fewest.float().mean():.2f} on average, {int(fewest.max())} at most; "
    f"best return {best_return.mean():.3f} on average"
)

# %%
# What the numbers say
# --------------------
# The return ratio is the policy's discounted return over the exact best one (1 is optimal control); "reach 0.999
# U*" the share of starts that get there within the horizon.  The rule reaches 0.999 ``U*`` from some starts, which
# random actions almost never do, yet its return is far from the best: each UAV keeps the task it was dealt, so from
# a start where both sense (or both relay) it climbs to the wrong configuration and stays there.
labels = {"eval/return_ratio": "return ratio", "eval/reach_999": "reach 0.999 U*", "eval/optimality": "final U / U*"}
figure, axis = plt.subplots(figsize=(8, 4), layout="constrained")
width = 0.8 / len(scores)
for i, (name, metrics) in enumerate(scores.items()):
    axis.bar([j + i * width for j in range(len(labels))], [metrics[key] for key in labels], width, label=name)
axis.set_xticks([j + width * (len(scores) - 1) / 2 for j in range(len(labels))], list(labels.values()))
axis.set_ylabel("score (1 = exact optimal control)")
axis.set_title(f"6x6 grid, 2 UAVs, {NUM_STARTS} held-out starts")
axis.legend(loc="upper left", bbox_to_anchor=(1, 1))
plt.show()
