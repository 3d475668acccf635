"""
TorchRL's QMIX / VDN script on the UAV task
===========================================

TorchRL's ``sota-implementations/multiagent/qmix_vdn.py`` trains a shared Q-network per agent with a QMIX or VDN
mixer on a VMAS scenario.  This is that script with only the lines that build the environment changed (``VmasEnv``
becomes :class:`~uavrl.envs.UAVSpectrumEnv` with ``agent_rewards=True``); its Hydra config is the dict ``cfg``
below, and its logger a print and a figure.  As in the script, the per-agent reward is averaged back to the team's
(every UAV holds a copy of it, so the mean is exactly the team reward).

The budget is shrunk to run in seconds; TorchRL's defaults are in the comments: raise ``n_iters``,
``frames_per_batch``, ``num_epochs`` and ``num_cells`` for a real run.
"""

# %%
# The configuration (TorchRL's ``qmix_vdn.yaml``, shrunk)
# -------------------------------------------------------
import time

import matplotlib.pyplot as plt
import torch
from omegaconf import OmegaConf
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import TensorDictReplayBuffer
from torchrl.data.replay_buffers.samplers import SamplerWithoutReplacement
from torchrl.data.replay_buffers.storages import LazyTensorStorage
from torchrl.envs import RewardSum, TransformedEnv
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import EGreedyModule, QValueModule, SafeSequential
from torchrl.modules.models.multiagent import MultiAgentMLP, QMixer, VDNMixer
from torchrl.objectives import SoftUpdate, ValueEstimators
from torchrl.objectives.multiagent.qmixer import QMixerLoss

from uavrl.envs import UAVSpectrumEnv

cfg = OmegaConf.create(
    {
        "seed": 0,
        "env": {"max_steps": 20, "grid": [6, 6], "num_uavs": 2, "device": "cpu"},
        "model": {"shared_parameters": True},
        "collector": {"frames_per_batch": 1_280, "n_iters": 30},  # TorchRL: 60_000 frames x 500 iterations
        "buffer": {},
        "loss": {"mixer_type": "qmix", "gamma": 0.9, "tau": 0.005},  # mixer_type: qmix or vdn
        "train": {"num_epochs": 2, "minibatch_size": 256, "lr": 5e-4, "max_grad_norm": 40.0, "device": "cpu"},
        "eval": {"evaluation_episodes": 16},
        "num_cells": 64,  # TorchRL: 256
    }
)


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

    # Policy
    net = MultiAgentMLP(
        n_agent_inputs=env.observation_spec["agents", "observation"].shape[-1],
        n_agent_outputs=env.full_action_spec["agents", "action"].space.n,
        n_agents=env.n_agents,
        centralized=False,
        share_params=cfg.model.shared_parameters,
        device=cfg.train.device,
        depth=2,
        num_cells=cfg.num_cells,
        activation_class=nn.Tanh,
    )
    module = TensorDictModule(net, in_keys=[("agents", "observation")], out_keys=[("agents", "action_value")])
    value_module = QValueModule(
        action_value_key=("agents", "action_value"),
        out_keys=[env.action_key, ("agents", "action_value"), ("agents", "chosen_action_value")],
        spec=env.full_action_spec_unbatched,
        action_space=None,
    )
    qnet = SafeSequential(module, value_module)
    qnet_explore = TensorDictSequential(
        qnet,
        EGreedyModule(
            eps_init=0.3,
            eps_end=0,
            annealing_num_steps=int(cfg.collector.total_frames * (1 / 2)),
            action_key=env.action_key,
            spec=env.full_action_spec_unbatched,
        ),
    )

    if cfg.loss.mixer_type == "qmix":
        mixer = TensorDictModule(
            module=QMixer(
                state_shape=env.observation_spec_unbatched["agents", "observation"].shape,
                mixing_embed_dim=32,
                n_agents=env.n_agents,
                device=cfg.train.device,
            ),
            in_keys=[("agents", "chosen_action_value"), ("agents", "observation")],
            out_keys=["chosen_action_value"],
        )
    elif cfg.loss.mixer_type == "vdn":
        mixer = TensorDictModule(
            module=VDNMixer(n_agents=env.n_agents, device=cfg.train.device),
            in_keys=[("agents", "chosen_action_value")],
            out_keys=["chosen_action_value"],
        )
    else:
        raise ValueError("Mixer type not in the example")

    collector = Collector(
        env,
        qnet_explore,
        device=cfg.env.device,
        storing_device=cfg.train.device,
        frames_per_batch=cfg.collector.frames_per_batch,
        total_frames=cfg.collector.total_frames,
    )
    replay_buffer = TensorDictReplayBuffer(
        storage=LazyTensorStorage(cfg.buffer.memory_size, device=cfg.train.device),
        sampler=SamplerWithoutReplacement(),
        batch_size=cfg.train.minibatch_size,
    )

    loss_module = QMixerLoss(qnet, mixer, delay_value=True)
    loss_module.set_keys(
        action_value=("agents", "action_value"),
        local_value=("agents", "chosen_action_value"),
        global_value="chosen_action_value",
        action=env.action_key,
    )
    loss_module.make_value_estimator(ValueEstimators.TD0, gamma=cfg.loss.gamma)
    target_net_updater = SoftUpdate(loss_module, eps=1 - cfg.loss.tau)
    optim = torch.optim.Adam(loss_module.parameters(), cfg.train.lr)

    history = {"iteration": [], "train": [], "eval": []}
    start = time.time()
    for i, tensordict_data in enumerate(collector):
        # Remove agent dimension from reward (since it is shared in QMIX/VDN)
        tensordict_data.set(("next", "reward"), tensordict_data.get(("next", env.reward_key)).mean(-2))
        del tensordict_data["next", env.reward_key]
        tensordict_data.set(
            ("next", "episode_reward"), tensordict_data.get(("next", "agents", "episode_reward")).mean(-2)
        )
        del tensordict_data["next", "agents", "episode_reward"]

        current_frames = tensordict_data.numel()
        replay_buffer.extend(tensordict_data.reshape(-1))
        for _ in range(cfg.train.num_epochs):
            for _ in range(cfg.collector.frames_per_batch // cfg.train.minibatch_size):
                loss_vals = loss_module(replay_buffer.sample())
                loss_vals["loss"].backward()
                torch.nn.utils.clip_grad_norm_(loss_module.parameters(), cfg.train.max_grad_norm)
                optim.step()
                optim.zero_grad()
                target_net_updater.step()
        qnet_explore[1].step(frames=current_frames)  # Update exploration annealing
        collector.update_policy_weights_()

        # the script's log_training and log_evaluation: the finished episodes' reward, the greedy policy's result
        done = tensordict_data.get(("next", "done"))
        episode_reward = tensordict_data.get(("next", "episode_reward"))[done].mean().item()
        env_test.set_seed(cfg.seed + 10_000)  # the same evaluation starts every time
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            rollouts = env_test.rollout(max_steps=cfg.env.max_steps, policy=qnet, break_when_any_done=False)
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
# The evaluation plays the greedy policy from the same 16 starts each iteration and reports its final utility over
# the exact optimum ``U*``.  Set ``cfg.loss.mixer_type = "vdn"`` for VDN.
history = train(cfg)
figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
left.plot(history["iteration"], history["train"])
left.set_xlabel("iteration")
left.set_ylabel("episode return (team reward)")
left.set_title("training episodes (epsilon-greedy)")
right.plot(history["iteration"], history["eval"])
right.set_xlabel("iteration")
right.set_ylabel("final U / U*  (mean over starts)")
right.set_title("evaluation (greedy)")
figure.suptitle(f"{cfg.loss.mixer_type.upper()} on the UAV task, 6x6 grid, 2 UAVs")
plt.show()
