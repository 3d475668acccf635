"""
The environment in your own TorchRL loop
========================================

:class:`~uavrl.envs.UAVSpectrumEnv` is a batched TorchRL ``EnvBase``: ``B`` independent worlds step in one tensor
program, with the per-UAV keys in the group ``"agents"`` as on VMAS.  This example rolls it out with random actions,
then trains a small shared Q-network with TorchRL's ``DQNLoss`` in a loop of a few lines, and compares the trained
greedy policy with the random one on the exact optimum ``U*`` of each world.

For a real run raise ``ITERATIONS`` (to about 300) and ``WORLDS``.
"""

# %%
# A rollout with random actions
# -----------------------------
# ``ActionMask`` makes ``env.rollout`` draw only the actions each UAV may take (no move off the grid).
import matplotlib.pyplot as plt
import torch
from tensordict.nn import TensorDictModule, TensorDictSequential
from torchrl.envs import ActionMask, TransformedEnv
from torchrl.modules import EGreedyModule, MultiAgentMLP, QValueModule, SafeSequential
from torchrl.objectives import DQNLoss, SoftUpdate, ValueEstimators

from uavrl.envs import UAVSpectrumEnv

torch.manual_seed(0)
WORLDS, STEPS, ITERATIONS = 64, 20, 25  # raise ITERATIONS to ~300 for a policy close to U*

base = UAVSpectrumEnv(batch_size=WORLDS, grid=(6, 6), num_uavs=2, max_steps=STEPS, agent_rewards=True, seed=0)
env = TransformedEnv(base, ActionMask(("agents", "action"), ("agents", "action_mask")))
td = env.rollout(STEPS)
u_star = base.optimum()[0]  # the exact best utility of each world's layout, [B]
print(td)
print("random policy, final U / U*:", (td["next", "utility"][:, -1, 0] / u_star).mean().item())

# %%
# A shared Q-network and TorchRL's DQN loss
# -----------------------------------------
# The team reward is copied to every UAV (``agent_rewards=True``), the done keys stay at the root: the loss reads
# them expanded to the reward's shape, as TorchRL's ``iql.py`` does.  ``QValueModule`` and ``EGreedyModule`` read the
# action mask so the policy never picks a forbidden action.
observation_size = base.observation_spec["agents", "observation"].shape[-1]
net = MultiAgentMLP(
    observation_size, 6, n_agents=base.n_agents, centralized=False, share_params=True, depth=2, num_cells=64
)
qnet = SafeSequential(
    TensorDictModule(net, in_keys=[("agents", "observation")], out_keys=[("agents", "action_value")]),
    QValueModule(
        action_value_key=("agents", "action_value"),
        out_keys=[base.action_key, ("agents", "action_value"), ("agents", "chosen_action_value")],
        action_mask_key=("agents", "action_mask"),
        spec=base.full_action_spec_unbatched,
        action_space=None,
    ),
)
explore = TensorDictSequential(
    qnet,
    EGreedyModule(
        eps_init=1.0,
        eps_end=0.05,
        annealing_num_steps=ITERATIONS // 2,
        action_key=base.action_key,
        action_mask_key=("agents", "action_mask"),
        spec=base.full_action_spec_unbatched,
    ),
)
loss = DQNLoss(qnet, delay_value=True)
loss.set_keys(
    action_value=("agents", "action_value"),
    action=base.action_key,
    value=("agents", "chosen_action_value"),
    reward=base.reward_key,
    done=("agents", "done"),
    terminated=("agents", "terminated"),
)
loss.make_value_estimator(ValueEstimators.TD0, gamma=0.9)
target_update = SoftUpdate(loss, eps=0.95)
optimizer = torch.optim.Adam(loss.parameters(), lr=1e-3)

# %%
# The training loop
# -----------------
# Each iteration plays one episode in every world, then takes a few gradient steps on it.
returns = []
for _ in range(ITERATIONS):
    with torch.no_grad():
        batch = base.rollout(STEPS, explore).reshape(-1)
    for key in ("done", "terminated"):  # the root's done keys, one per UAV
        batch["next", "agents", key] = batch["next", key].unsqueeze(-1).expand_as(batch["next", base.reward_key])
    for _ in range(4):
        minibatch = batch[torch.randint(batch.numel(), (512,))]
        loss(minibatch)["loss"].backward()
        optimizer.step()
        optimizer.zero_grad()
        target_update.step()
    explore[1].step()
    returns.append(batch["next", base.reward_key][..., 0, 0].sum().item() / WORLDS)

# %%
# The greedy policy against random actions
# ----------------------------------------
# Both are rolled out from the same seeded starts; each curve is the utility per step over ``U*``, mean over worlds.
base.set_seed(1)
with torch.no_grad():
    greedy = base.rollout(STEPS, qnet)
base.set_seed(1)
random_rollout = env.rollout(STEPS)
figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
left.plot(returns)
left.set_xlabel("iteration")
left.set_ylabel("return per episode (team reward)")
left.set_title("training")
for name, rollout in (("greedy Q-network", greedy), ("random", random_rollout)):
    right.plot(range(1, STEPS + 1), (rollout["next", "utility"][..., 0] / u_star[:, None]).mean(0), label=name)
right.set_xlabel("step")
right.set_ylabel("U / U*  (mean over worlds)")
right.set_title("after training")
right.legend()
plt.show()
