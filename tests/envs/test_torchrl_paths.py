"""The TorchRL paths that TorchRL's own multi-agent examples take, on :class:`~uavrl.envs.UAVSpectrumEnv`.

TorchRL's ``sota-implementations/multiagent`` scripts (``iql.py``, ``qmix_vdn.py``, ``mappo_ippo.py``) and its
``multiagent_ppo`` tutorial run on this env with only the lines that build the env changed (``agent_rewards=True``);
CI cannot fetch them, so these tests take the same steps: ``RewardSum`` on the group's reward, ``DQNLoss`` and
``QMixerLoss`` with per-agent rewards and dones, ``ClipPPOLoss`` with GAE on per-agent values, ``CatTensors`` of the
per-world scalars with ``state``; then every policy ``uavrl.load_policy`` returns over TorchRL's batched envs and
collectors.
"""

import functools
import pickle

import numpy as np
import pytest
import torch
from tensordict import unravel_key
from tensordict.nn import TensorDictModule, TensorDictSequential
from torchrl.collectors import MultiSyncCollector
from torchrl.envs import CatTensors, ParallelEnv, RewardSum, SerialEnv, TransformedEnv
from torchrl.envs.utils import check_env_specs
from torchrl.modules import (
    EGreedyModule,
    MultiAgentMLP,
    ProbabilisticActor,
    QValueModule,
    SafeSequential,
    VDNMixer,
)
from torchrl.objectives import ClipPPOLoss, DQNLoss, QMixerLoss, ValueEstimators
from torchrl.record import PixelRenderTransform
from torchrl.record.loggers import CSVLogger

from uavrl.agents import agent_class
from uavrl.config import model_config
from uavrl.envs import UAVSpectrumEnv
from uavrl.envs.compat import make_collector

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

TINY = functools.partial(UAVSpectrumEnv, batch_size=4, grid=(3, 3), num_uavs=2, max_steps=5, seed=1)


def per_agent_dones(batch, reward_key=("agents", "reward")):
    """What the examples' ``DoneTransform`` does: the root done keys expanded to the group reward's shape."""
    shape = batch.get(("next", reward_key)).shape
    for key in ("done", "terminated"):
        batch.set(("next", "agents", key), batch.get(("next", key)).unsqueeze(-1).expand(shape))
    return batch


def test_multi_agent_names_follow_vmas():
    env = TINY(agent_rewards=True)
    assert env.n_agents == 2 and env.agent_names == ["agent_0", "agent_1"]
    assert env.group_map == {"agents": ["agent_0", "agent_1"]}
    assert env.reward_key == ("agents", "reward") and env.action_key == ("agents", "action")
    assert env.done_keys == ["done", "terminated", "truncated"]  # at the root only, as VMAS's
    check_env_specs(env)
    check_env_specs(TINY())
    with pytest.raises(ValueError, match="agent_rewards='yes' is invalid"):
        TINY(agent_rewards="yes")


def test_group_reward_is_the_team_reward_for_every_uav():
    team, group = TINY(), TINY(agent_rewards=True)
    actions = torch.randint(0, 6, (12, 4, 2), generator=torch.Generator().manual_seed(0))
    for env in (team, group):
        env.set_seed(5)
    td_team, td_group = team.reset(), group.reset()
    for action in actions:
        td_team["agents", "action"], td_group["agents", "action"] = action, action.clone()
        out_team, td_team = team.step_and_maybe_reset(td_team)
        out_group, td_group = group.step_and_maybe_reset(td_group)
        reward = out_group["next", "agents", "reward"]
        assert reward.shape == (4, 2, 1)
        assert torch.equal(reward, out_team["next", "reward"].unsqueeze(1).expand(4, 2, 1))
        assert "reward" not in out_group["next"].keys()
        assert torch.equal(out_group["next", "utility"], out_team["next", "utility"])


def test_reward_sum_on_the_groups_keys():
    env = TransformedEnv(
        TINY(agent_rewards=True), RewardSum(in_keys=[("agents", "reward")], out_keys=[("agents", "episode_reward")])
    )
    check_env_specs(env)
    td = env.rollout(12, break_when_any_done=False)  # episodes of 5 steps: two end, a third begins
    reward, total = td["next", "agents", "reward"], td["next", "agents", "episode_reward"]
    assert total.shape == reward.shape == (4, 12, 2, 1)
    torch.testing.assert_close(total[:, 4], reward[:, :5].sum(1))
    torch.testing.assert_close(total[:, 9], reward[:, 5:10].sum(1))  # restarted after the first episode's end
    torch.testing.assert_close(total[:, 11], reward[:, 10:].sum(1))


def test_cat_tensors_joins_the_per_world_scalars_with_the_state():
    keys = ["state", "r_pu", "r_se", "utility", "moves", "task_switches", "state_index"]
    base = TINY()
    env = TransformedEnv(base, CatTensors(in_keys=keys, out_key="features", del_keys=False, sort=False))
    check_env_specs(env)
    td = env.rollout(3)
    assert td["next", "features"].shape == (4, 3, base.state_size + 6)
    torch.testing.assert_close(td["next", "features"][..., base.state_size + 2], td["next", "utility"][..., 0])


def q_network(env):
    net = MultiAgentMLP(
        n_agent_inputs=env.observation_spec["agents", "observation"].shape[-1],
        n_agent_outputs=env.full_action_spec["agents", "action"].space.n,
        n_agents=env.n_agents,
        centralized=False,
        share_params=True,
        depth=1,
        num_cells=16,
    )
    values = TensorDictModule(net, in_keys=[("agents", "observation")], out_keys=[("agents", "action_value")])
    greedy = QValueModule(
        action_value_key=("agents", "action_value"),
        out_keys=[env.action_key, ("agents", "action_value"), ("agents", "chosen_action_value")],
        spec=env.full_action_spec_unbatched,
        action_space=None,
    )
    qnet = SafeSequential(values, greedy)
    explore = TensorDictSequential(qnet, EGreedyModule(eps_init=0.5, action_key=env.action_key, spec=env.action_spec))
    return qnet, explore


def one_batch(env, policy, frames=40):
    collector = make_collector(env, policy, frames_per_batch=frames, total_frames=frames)
    batch = next(iter(collector))
    collector.shutdown()
    return batch


def assert_trains(loss_module, batch):
    losses = loss_module(batch)
    total = sum(v for k, v in losses.items() if k.startswith("loss"))
    assert torch.isfinite(total)
    total.backward()
    grads = [p.grad for p in loss_module.parameters() if p.grad is not None]
    assert grads and any(bool(g.abs().sum() > 0) for g in grads)


def test_dqn_loss_with_per_agent_rewards_and_dones():  # iql.py
    env = TINY(agent_rewards=True)
    qnet, explore = q_network(env)
    batch = per_agent_dones(one_batch(env, explore).reshape(-1))
    loss = DQNLoss(qnet, delay_value=True)
    loss.set_keys(
        action_value=("agents", "action_value"),
        action=env.action_key,
        value=("agents", "chosen_action_value"),
        reward=env.reward_key,
        done=("agents", "done"),
        terminated=("agents", "terminated"),
    )
    loss.make_value_estimator(ValueEstimators.TD0, gamma=0.9)
    assert_trains(loss, batch)


def test_qmixer_loss_on_the_mean_of_the_per_agent_rewards():  # qmix_vdn.py
    env = TINY(agent_rewards=True)
    qnet, explore = q_network(env)
    batch = one_batch(env, explore).reshape(-1)
    team = batch.get(("next", env.reward_key)).mean(-2)  # the script's reduction: exactly the team reward
    torch.testing.assert_close(team, batch.get(("next", env.reward_key))[..., 0, :])
    batch.set(("next", "reward"), team)
    del batch["next", env.reward_key]
    mixer = TensorDictModule(
        VDNMixer(n_agents=env.n_agents, device="cpu"),
        in_keys=[("agents", "chosen_action_value")],
        out_keys=["chosen_action_value"],
    )
    loss = QMixerLoss(qnet, mixer, delay_value=True)
    loss.set_keys(
        action_value=("agents", "action_value"),
        local_value=("agents", "chosen_action_value"),
        global_value="chosen_action_value",
        action=env.action_key,
    )
    loss.make_value_estimator(ValueEstimators.TD0, gamma=0.9)
    assert_trains(loss, batch)


def test_clip_ppo_loss_with_gae_on_per_agent_values_and_rewards():  # mappo_ippo.py, the multiagent_ppo tutorial
    env = TINY(agent_rewards=True)
    n_obs, n_actions = (
        env.observation_spec["agents", "observation"].shape[-1],
        env.full_action_spec[env.action_key].space.n,
    )
    logits = MultiAgentMLP(n_obs, n_actions, env.n_agents, centralized=False, share_params=True, depth=1, num_cells=16)
    actor = ProbabilisticActor(
        TensorDictModule(logits, in_keys=[("agents", "observation")], out_keys=[("agents", "logits")]),
        spec=env.full_action_spec_unbatched,
        in_keys=[("agents", "logits")],
        out_keys=[env.action_key],
        distribution_class=torch.distributions.Categorical,
        return_log_prob=True,
    )
    critic = TensorDictModule(  # the tutorial's critic (mappo_ippo.py's ValueOperator writes the same per UAV)
        MultiAgentMLP(n_obs, 1, env.n_agents, centralized=True, share_params=True, depth=1, num_cells=16),
        in_keys=[("agents", "observation")],
        out_keys=[("agents", "state_value")],
    )
    batch = per_agent_dones(one_batch(env, actor))
    loss = ClipPPOLoss(actor, critic, clip_epsilon=0.2, entropy_coeff=1e-4, normalize_advantage=False)
    loss.set_keys(
        reward=env.reward_key,
        action=env.action_key,
        value=("agents", "state_value"),
        done=("agents", "done"),
        terminated=("agents", "terminated"),
    )
    loss.make_value_estimator(ValueEstimators.GAE, gamma=0.9, lmbda=0.9)
    with torch.no_grad():
        loss.value_estimator(batch, params=loss.critic_network_params, target_params=loss.target_critic_network_params)
    assert batch["advantage"].shape == (4, 10, 2, 1)  # per UAV and step
    assert_trains(loss, batch.reshape(-1))


def test_the_examples_evaluation_logs_a_video(tmp_path):  # iql.py, qmix_vdn.py, mappo_ippo.py with a logger on
    """Their evaluation: a rollout whose callback keeps ``env.render(mode="rgb_array", agent_index_focus=None)``
    in ``env.frames``, then the frames as a ``[1, T, 3, H, W]`` uint8 video to the logger."""
    env = TINY(agent_rewards=True)
    env.frames = []

    def rendering_callback(env, td):
        env.frames.append(env.render(mode="rgb_array", agent_index_focus=None))

    torch.manual_seed(0)  # the rollout's random actions
    with torch.no_grad():
        rollouts = env.rollout(max_steps=5, callback=rendering_callback, break_when_any_done=False)
    assert rollouts.batch_size == (4, 5) and len(env.frames) == 4  # TorchRL calls back after every step but the last
    video = torch.tensor(np.transpose(np.stack(env.frames), (0, 3, 1, 2)), dtype=torch.uint8).unsqueeze(0)
    logger = CSVLogger("eval", log_dir=str(tmp_path), video_format="pt")  # "mp4" needs torchcodec
    logger.log_video("eval_video", video, step=0)
    saved = torch.load(tmp_path / "eval" / "videos" / "eval_video_0.pt")
    assert saved.shape == (1, 4, 3, 360, 480) and not torch.equal(saved[0, 0], saved[0, -1])


# ----------------------------------------------------------------- devices, batched envs, collectors
def world_tensors(world):
    tensors = {name: v for name, v in vars(world).items() if isinstance(v, torch.Tensor)}
    for part_name, part in world.parts.items():
        tensors.update({f"{part_name}.{name}": v for name, v in vars(part).items() if isinstance(v, torch.Tensor)})
    tensors.update({f"_s.{n}": getattr(world._s, n) for n in type(world._s).__slots__})
    return {name: v for name, v in tensors.items() if isinstance(v, torch.Tensor)}


DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA"))]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("options", [{}, {"layout": "random", "fading": "rayleigh"}])
def test_to_moves_every_tensor_of_the_worlds(device, options):
    moved, kept = TINY(**options), TINY(**options)
    moved.reset(), kept.reset()
    assert moved.to(device) is moved
    target = torch.device(device)
    assert moved.device.type == target.type and moved.world.device == moved.device
    assert len(world_tensors(moved.world)) > 20
    for name, tensor in world_tensors(moved.world).items():
        assert tensor.device.type == target.type, name
    actions = torch.tensor([[0, 5], [3, 4], [1, 1], [2, 5]])
    td_moved, td_kept = moved.reset(), kept.reset()
    for _ in range(3):  # the same worlds, the same steps, wherever they live
        td_moved["agents", "action"], td_kept["agents", "action"] = actions.to(moved.device), actions
        out_moved, td_moved = moved.step_and_maybe_reset(td_moved)
        out_kept, td_kept = kept.step_and_maybe_reset(td_kept)
        assert out_moved.device.type == target.type
        for key in ("positions", "tasks", "state_index"):
            assert torch.equal(out_moved["next", key].cpu(), out_kept["next", key])
        torch.testing.assert_close(out_moved["next", "utility"].cpu(), out_kept["next", "utility"])


@pytest.mark.parametrize("device", DEVICES)
def test_to_keeps_drawing_the_same_worlds(device):
    """The frames of worlds moved (after a frame was drawn, so the renderer predates the move) are the frames of the
    same worlds kept where they were, step after step."""
    moved, kept = TINY(layout="random"), TINY(layout="random")
    td_moved, td_kept = moved.reset(), kept.reset()
    worlds = [0, 3]
    before = moved.render(env_index=worlds)
    moved.to(device)
    assert np.array_equal(moved.render(env_index=worlds), before)
    actions = torch.tensor([[0, 5], [3, 4], [1, 1], [2, 5]])
    for _ in range(2):
        td_moved["agents", "action"], td_kept["agents", "action"] = actions.to(moved.device), actions
        td_moved, td_kept = moved.step(td_moved)["next"], kept.step(td_kept)["next"]
        assert np.array_equal(moved.render(env_index=worlds), kept.render(env_index=worlds))
    assert not np.array_equal(moved.render(env_index=worlds), before)


def test_to_a_missing_device_is_one_line():
    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    with pytest.raises(ValueError, match="device='cuda' is not available"):
        TINY().to("cuda")


@pytest.fixture(scope="module")
def policies():
    """The policy of every agent, as ``uavrl.load_policy`` returns them (untrained: the paths matter here)."""
    import hydra

    from tests.agents.test_agents import COMMON
    from tests.agents.test_agents import TINY as TINY_SETTINGS
    from uavrl.config import config_dir

    out = {}
    with hydra.initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        for name in ("tabular", "dqn", "random", "oracle"):
            cfg = hydra.compose("config", overrides=[f"agent={name}", *COMMON, *TINY_SETTINGS[name]])
            env_cfg = model_config(cfg)
            out[name] = (agent_class(name)(env_cfg, cfg, torch.device("cpu"), 0).policies()[0], env_cfg)
    return out


NAMES = ["tabular", "dqn", "random", "oracle"]


def make_env(env_cfg, batch_size=3):
    return UAVSpectrumEnv(batch_size=batch_size, config=env_cfg.replace(max_steps=4), seed=2)


def assert_valid_actions(td, env_cfg):
    action = td["agents", "action"]
    assert action.shape[-1] == env_cfg.num_uavs and action.dtype == torch.long
    assert bool(((action >= 0) & (action < 6)).all())


@pytest.mark.parametrize("name", NAMES)
def test_policy_is_picklable_and_acts_with_extra_batch_dims(name, policies):
    policy, env_cfg = policies[name]
    copy = pickle.loads(pickle.dumps(policy))
    env = make_env(env_cfg)
    td = env.reset()
    first, again = policy(td.clone()), copy(td.clone())
    assert torch.equal(first["agents", "action"], again["agents", "action"])  # the copy draws what the original draws
    stacked = torch.stack([td, td.clone()]).unsqueeze(0)  # [1, 2, B]
    acted = policy(stacked)
    assert acted["agents", "action"].shape == (1, 2, 3, env_cfg.num_uavs)
    assert_valid_actions(acted, env_cfg)


@pytest.mark.parametrize("name", NAMES)
def test_policy_in_a_rollout_with_pixels(name, policies):
    """What the examples' evaluation with a logger does: the policy acts in a ``PixelRenderTransform`` env, and
    every step's frame is world 0's picture then."""
    policy, env_cfg = policies[name]
    env = TransformedEnv(make_env(env_cfg), PixelRenderTransform())
    td = env.rollout(4, policy)
    assert td.batch_size == (3, 4)
    assert_valid_actions(td, env_cfg)
    frames = [np.asarray(td[0, t]["next", "pixels"]) for t in range(4)]
    assert all(frame.shape == (360, 480, 3) and frame.dtype == np.uint8 for frame in frames)
    assert np.array_equal(frames[-1], env.base_env.render())


@pytest.mark.parametrize("name", NAMES)
def test_policy_over_a_serial_env(name, policies):
    policy, env_cfg = policies[name]
    env = SerialEnv(2, functools.partial(make_env, env_cfg))
    td = env.rollout(6, policy, break_when_any_done=False)
    assert td["agents", "action"].shape == (2, 3, 6, env_cfg.num_uavs)
    assert_valid_actions(td, env_cfg)
    env.close()


def random_layout_oracle(policies, max_steps):
    """The oracle and the model options of a random-layout run, and its actions in one plain env of 4 worlds
    seeded 4 (auto-resets draw new layouts): what it must do wherever the worlds are."""
    from uavrl.agents.baselines import OraclePolicy

    cfg = policies["oracle"][1].replace(layout="random", max_steps=max_steps)
    alone = UAVSpectrumEnv(batch_size=4, config=cfg, seed=4)
    single = alone.rollout(2 * max_steps, OraclePolicy(cfg), break_when_any_done=False)
    return OraclePolicy(cfg), cfg, single


def test_random_layout_oracle_over_a_serial_env_acts_as_in_one_env(policies):
    """No env bound: the workers' worlds (seeded 4 and 5, then 6 and 7) carry their layouts in 'nodes'; a pickled
    copy, used or not, acts the same."""
    oracle, cfg, single = random_layout_oracle(policies, max_steps=6)
    worker = functools.partial(UAVSpectrumEnv, batch_size=2, config=cfg)
    unused = pickle.loads(pickle.dumps(random_layout_oracle(policies, max_steps=6)[0]))
    for policy in (oracle, pickle.loads(pickle.dumps(oracle)), unused):  # the second carries the first's cache
        batched = SerialEnv(2, [functools.partial(worker, seed=4), functools.partial(worker, seed=6)])
        over = batched.rollout(12, policy, break_when_any_done=False)
        batched.close()
        assert torch.equal(over["agents", "action"].flatten(0, 1), single["agents", "action"])


def test_random_layout_oracle_refuses_a_tensordict_without_nodes(policies):
    oracle, cfg, _ = random_layout_oracle(policies, max_steps=2)
    td = UAVSpectrumEnv(batch_size=2, config=cfg).reset().exclude("nodes")
    with pytest.raises(ValueError, match=r"^OraclePolicy with layout='random' reads .* 'nodes' .* has none[^\n]*$"):
        oracle(td)


@pytest.mark.slow
def test_random_layout_oracle_in_a_multi_sync_collector_acts_as_in_one_env(policies):
    """Each worker process gets a pickled oracle and no env: the layouts come with the tensordicts."""
    oracle, cfg, single = random_layout_oracle(policies, max_steps=5)
    worker = functools.partial(UAVSpectrumEnv, batch_size=2, config=cfg)
    makers = [functools.partial(worker, seed=4), functools.partial(worker, seed=6)]
    collector = MultiSyncCollector(makers, oracle, frames_per_batch=40, total_frames=40)
    (batch,) = list(collector)
    collector.shutdown()
    assert batch["agents", "action"].shape == (2, 2, 10, cfg.num_uavs)  # [workers, worlds, steps, UAVs]
    assert torch.equal(batch["agents", "action"].flatten(0, 1), single["agents", "action"])


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_policy_over_a_parallel_env_and_a_multi_sync_collector(name, policies):
    policy, env_cfg = policies[name]
    make = functools.partial(make_env, env_cfg)
    env = ParallelEnv(2, make)
    if hasattr(policy, "bind_env"):
        policy.bind_env(env)
    td = env.rollout(4, policy, break_when_any_done=False)
    assert td["agents", "action"].shape == (2, 3, 4, env_cfg.num_uavs)
    env.close()
    collector = MultiSyncCollector([make, make], policy, frames_per_batch=24, total_frames=48)
    batches = list(collector)
    collector.shutdown()
    assert len(batches) == 2 and all(b.numel() == 24 for b in batches)
    assert_valid_actions(batches[0], env_cfg)


@pytest.mark.parametrize("name", NAMES)
def test_policy_in_a_collector(name, policies):
    policy, env_cfg = policies[name]
    batch = one_batch(make_env(env_cfg), policy, frames=24)
    assert batch.numel() == 24 and unravel_key(("agents", "action")) in batch.keys(True)
    assert_valid_actions(batch, env_cfg)


@pytest.mark.slow
def test_random_layout_oracle_over_a_parallel_env_acts_as_in_one_env(policies):
    oracle, cfg, single = random_layout_oracle(policies, max_steps=4)
    worker = functools.partial(UAVSpectrumEnv, batch_size=2, config=cfg)
    env = ParallelEnv(2, [functools.partial(worker, seed=4), functools.partial(worker, seed=6)])  # worlds 4, 5, 6, 7
    over = env.rollout(8, oracle, break_when_any_done=False)
    env.close()
    assert torch.equal(over["agents", "action"].flatten(0, 1), single["agents", "action"])
