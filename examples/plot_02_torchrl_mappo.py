"""
TorchRL's MAPPO / IPPO script on the UAV task
=============================================

TorchRL's ``sota-implementations/multiagent/mappo_ippo.py`` trains MAPPO (a centralised critic) or IPPO on a VMAS
scenario.  This is that script with only the lines that build the environment changed (``VmasEnv`` becomes
:class:`~uavrl.envs.UAVSpectrumEnv` with ``agent_rewards=True``) and, since our actions are discrete, the actor's
last layer made categorical (logits and ``Categorical`` instead of ``TanhNormal``).  Its Hydra config is the dict
``cfg`` below and its logger is replaced by a print and a figure of the training curve.

The budget is shrunk to run in seconds; TorchRL's defaults are in the comments (``n_iters``, ``frames_per_batch``,
``num_epochs``, ``num_cells``): raise them for a real run.
"""

# %%
# The configuration (TorchRL's ``mappo_ippo.yaml``, shrunk)
# ---------------------------------------------------------
import time

import matplotlib.pyplot as plt
import torch
from omegaconf import OmegaConf
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import TensorDictReplayBuffer
from torchrl.data.replay_buffers.samplers import SamplerWithoutReplacement
from torchrl.data.replay_buffers.storages import LazyTensorStorage
from torchrl.envs import RewardSum, Transform, TransformedEnv
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import ProbabilisticActor, ValueOperator
from torchrl.modules.models.multiagent import MultiAgentMLP
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from uavrl.envs import UAVSpectrumEnv

cfg = OmegaConf.create(
    {
        "seed": 0,
        "env": {"max_steps": 20, "grid": [6, 6], "num_uavs": 2, "device": "cpu"},
        "model": {"shared_parameters": True, "centralised_critic": True},  # False: IPPO
        "collector": {"frames_per_batch": 1_280, "n_iters": 10},  # TorchRL: 60_000 frames x 500 iterations
        "buffer": {},
        "loss": {"gamma": 0.9, "lmbda": 0.9, "entropy_eps": 1e-4, "clip_epsilon": 0.2},
        "train": {"num_epochs": 3, "minibatch_size": 320, "lr": 5e-4, "max_grad_norm": 1.0, "device": "cpu"},
        "eval": {"evaluation_episodes": 16},
        "num_cells": 64,  # TorchRL: 256
    }
)


class DoneTransform(Transform):
    """TorchRL's ``utils/utils.py``: the root's done keys expanded to the per-agent reward's shape."""

    def __init__(self, reward_key, done_keys):
        super().__init__()
        self.reward_key, self.done_keys = reward_key, done_keys

    def forward(self, tensordict):
        for done_key in self.done_keys:
            new_name = ("agents",) + ((done_key,) if isinstance(done_key, str) else done_key)
            tensordict.set(
                ("next", *new_name),
                tensordict.get(("next", done_key))
                .unsqueeze(-1)
                .expand(tensordict.get(("next", self.reward_key)).shape),
            )
        return tensordict


# %%
# The training function (TorchRL's ``train``; the environment lines changed)
# --------------------------------------------------------------------------
def train(cfg):
    torch.manual_seed(cfg.seed)
    cfg.env.num_worlds = cfg.collector.frames_per_batch // cfg.env.max_steps
    cfg.collector.total_frames = cfg.collector.frames_per_batch * cfg.collector.n_iters
    cfg.buffer.memory_size = cfg.collector.frames_per_batch

    # Create env and env_test: the lines changed (VmasEnv -> UAVSpectrumEnv)
    env = UAVSpectrumEnv(
        batch_size=cfg.env.num_worlds,
        grid=tuple(cfg.env.grid),
        num_uavs=cfg.env.num_uavs,
        max_steps=cfg.env.max_steps,
        device=cfg.env.device,
        seed=cfg.seed,
        agent_rewards=True,
    )
    env = TransformedEnv(env, RewardSum(in_keys=[env.reward_key], out_keys=[("agents", "episode_reward")]))
    env_test = UAVSpectrumEnv(
        batch_size=cfg.eval.evaluation_episodes,
        grid=tuple(cfg.env.grid),
        num_uavs=cfg.env.num_uavs,
        max_steps=cfg.env.max_steps,
        device=cfg.env.device,
        seed=cfg.seed + 10_000,
        agent_rewards=True,
    )

    # Policy: a categorical actor (the script's TanhNormal is for VMAS's continuous actions)
    actor_net = MultiAgentMLP(
        n_agent_inputs=env.observation_spec["agents", "observation"].shape[-1],
        n_agent_outputs=env.full_action_spec_unbatched[env.action_key].space.n,
        n_agents=env.n_agents,
        centralized=False,
        share_params=cfg.model.shared_parameters,
        device=cfg.train.device,
        depth=2,
        num_cells=cfg.num_cells,
        activation_class=nn.Tanh,
    )
    policy_module = TensorDictModule(actor_net, in_keys=[("agents", "observation")], out_keys=[("agents", "logits")])
    policy = ProbabilisticActor(
        module=policy_module,
        spec=env.full_action_spec_unbatched,
        in_keys=[("agents", "logits")],
        out_keys=[env.action_key],
        distribution_class=torch.distributions.Categorical,
        return_log_prob=True,
    )

    # Critic
    module = MultiAgentMLP(
        n_agent_inputs=env.observation_spec["agents", "observation"].shape[-1],
        n_agent_outputs=1,
        n_agents=env.n_agents,
        centralized=cfg.model.centralised_critic,
        share_params=cfg.model.shared_parameters,
        device=cfg.train.device,
        depth=2,
        num_cells=cfg.num_cells,
        activation_class=nn.Tanh,
    )
    value_module = ValueOperator(module=module, in_keys=[("agents", "observation")])

    collector = Collector(
        env,
        policy,
        device=cfg.env.device,
        storing_device=cfg.train.device,
        frames_per_batch=cfg.collector.frames_per_batch,
        total_frames=cfg.collector.total_frames,
        postproc=DoneTransform(reward_key=env.reward_key, done_keys=env.done_keys),
    )
    replay_buffer = TensorDictReplayBuffer(
        storage=LazyTensorStorage(cfg.buffer.memory_size, device=cfg.train.device),
        sampler=SamplerWithoutReplacement(),
        batch_size=cfg.train.minibatch_size,
    )

    # Loss
    loss_module = ClipPPOLoss(
        actor_network=policy,
        critic_network=value_module,
        clip_epsilon=cfg.loss.clip_epsilon,
        entropy_coeff=cfg.loss.entropy_eps,
        normalize_advantage=False,
    )
    loss_module.set_keys(
        reward=env.reward_key,
        action=env.action_key,
        done=("agents", "done"),
        terminated=("agents", "terminated"),
    )
    loss_module.make_value_estimator(ValueEstimators.GAE, gamma=cfg.loss.gamma, lmbda=cfg.loss.lmbda)
    optim = torch.optim.Adam(loss_module.parameters(), cfg.train.lr)

    history = {"iteration": [], "train": [], "eval": []}
    start = time.time()
    for i, tensordict_data in enumerate(collector):
        with torch.no_grad():
            loss_module.value_estimator(
                tensordict_data,
                params=loss_module.critic_network_params,
                target_params=loss_module.target_critic_network_params,
            )
        replay_buffer.extend(tensordict_data.reshape(-1))
        for _ in range(cfg.train.num_epochs):
            for _ in range(cfg.collector.frames_per_batch // cfg.train.minibatch_size):
                loss_vals = loss_module(replay_buffer.sample())
                loss_value = loss_vals["loss_objective"] + loss_vals["loss_critic"] + loss_vals["loss_entropy"]
                loss_value.backward()
                torch.nn.utils.clip_grad_norm_(loss_module.parameters(), cfg.train.max_grad_norm)
                optim.step()
                optim.zero_grad()
        collector.update_policy_weights_()

        # the script's log_training and log_evaluation: the mean episode reward of the finished episodes
        done = tensordict_data.get(("next", "agents", "done"))
        episode_reward = tensordict_data.get(("next", "agents", "episode_reward"))[done].mean().item()
        env_test.set_seed(cfg.seed + 10_000)  # the same evaluation starts every time
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            rollouts = env_test.rollout(max_steps=cfg.env.max_steps, policy=policy, break_when_any_done=False)
        eval_optimality = (rollouts.get(("next", "utility"))[:, -1, 0] / env_test.optimum()[0]).mean().item()
        history["iteration"].append(i)
        history["train"].append(episode_reward)
        history["eval"].append(eval_optimality)
        print(f"iteration {i}: episode reward {episode_reward:.3f}, evaluation: final U / U* {eval_optimality:.3f}")
    print(f"trained in {time.time() - start:.1f} s")
    collector.shutdown()
    return history


# %%
# Run it
# ------
# The team reward is the change of the utility each step (``env.reward=delta``), so an episode's return is how much
# the team improved on its start: it is noisy.  The evaluation plays the deterministic policy from the same 16 starts
# each iteration and reports its final utility over the exact optimum ``U*``.
history = train(cfg)
figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
left.plot(history["iteration"], history["train"])
left.set_xlabel("iteration")
left.set_ylabel("episode return (team reward)")
left.set_title("training episodes (sampled actions)")
right.plot(history["iteration"], history["eval"])
right.set_xlabel("iteration")
right.set_ylabel("final U / U*  (mean over starts)")
right.set_title("evaluation (deterministic actions)")
figure.suptitle("MAPPO on the UAV task, 6x6 grid, 2 UAVs")
plt.show()
