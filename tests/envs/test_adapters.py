"""The Gymnasium and PettingZoo adapters (uavrl.envs.adapters.gym_env, uavrl.envs.adapters.pettingzoo_env): their
official checkers, the same physics and seeds as UAVSpectrumEnv, Stable-Baselines3 training on them and the yardstick
measuring it.

Skipped where the [gym] extra is not installed (pip install -e ".[gym]"; CI: .ci/leg-gym).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

pytestmark = pytest.mark.gym  # .ci/leg-gym runs them (-m gym), where a skip fails
gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("pettingzoo")

from gymnasium.utils.env_checker import check_env, data_equivalence  # noqa: E402
from gymnasium.utils.passive_env_checker import data_shares_objects  # noqa: E402
from gymnasium.vector import AutoresetMode, SyncVectorEnv  # noqa: E402
from gymnasium.vector.utils import batch_space  # noqa: E402
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, render_test, state_test  # noqa: E402
from pettingzoo.utils.conversions import parallel_to_aec  # noqa: E402

from uavrl.agents.evaluation import EVAL_SEED, evaluate  # noqa: E402
from uavrl.envs import UAVSpectrumEnv, make_config, observation_with_nodes  # noqa: E402
from uavrl.envs.adapters.gym_env import ENV_ID, TeamActionPolicy, UAVSpectrumGymEnv, UAVSpectrumVectorEnv  # noqa: E402
from uavrl.envs.adapters.pettingzoo_env import UAVSpectrumParallelEnv  # noqa: E402
from uavrl.envs.limits import NODE_FEATURES, OWN_FEATURES, observation_size  # noqa: E402

# the paper's preset, a team of 3 on random layouts with fading (per-world layouts and fading draws), the
# authors' absolute layout (its nodes lie outside the grid's span on a 6x6 grid), three altitude levels over a city
# (8 actions; buildings block some climbs, descents and moves)
LEVELS_IN_A_CITY = {"preset": "a2g_urban", "altitudes_m": [20, 100, 300], "city": "highrise", "environment": "highrise"}
MODELS = [
    {"grid": (6, 6), "num_uavs": 2},
    {"grid": (4, 4), "num_uavs": 3, "layout": "random", "fading": "rayleigh"},
    {"grid": (6, 6), "num_uavs": 2, "preset": "reference_code"},
    {"grid": (3, 3), "num_uavs": 3, **LEVELS_IN_A_CITY},
]
MODEL_IDS = ["paper", "random-rayleigh", "reference_code", "levels-city"]


@pytest.fixture(autouse=True)
def _one_thread(one_thread):
    """Small tensors: one torch thread."""


# ----------------------------------------------------------------------------- Gymnasium, one world
@pytest.mark.parametrize("render_mode", [None, "rgb_array"])
@pytest.mark.parametrize("options", MODELS, ids=MODEL_IDS)
def test_gym_env_passes_check_env(options, render_mode):
    """Made through ``gymnasium.make``, so the checker also renders a new env in every declared mode."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # check_env's warnings (bounds, dtypes, determinism, render) fail the test too
        check_env(gymnasium.make(ENV_ID, max_steps=8, render_mode=render_mode, **options).unwrapped)


def test_make_builds_the_adapters():
    env = gymnasium.make(ENV_ID, grid=(4, 4), num_uavs=3)
    assert isinstance(env.unwrapped, UAVSpectrumGymEnv) and env.unwrapped.cfg.num_uavs == 3
    vec = gymnasium.make_vec(ENV_ID, num_envs=5, grid=(4, 4), num_uavs=3)
    assert isinstance(vec, UAVSpectrumVectorEnv) and vec.num_envs == 5 and vec.action_space.shape == (5, 3)


def test_gym_env_info_and_action_masks():
    env = UAVSpectrumGymEnv(grid=(3, 3), num_uavs=2, max_steps=4)
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs) and info["action_mask"].dtype == np.int8
    assert np.array_equal(env.action_masks(), info["action_mask"].reshape(-1).astype(bool))
    # on a 3x3 grid every UAV has an edge, so some move leaves the grid; tasks are always allowed
    assert not env.action_masks().all() and info["action_mask"][:, 4:].all()
    for t in range(4):
        obs, reward, terminated, truncated, info = env.step(np.array([5, 5]))
        assert terminated is False and truncated is (t == 3)
        assert set(info) == {"action_mask", "r_pu", "r_se", "utility", "moves", "task_switches"}


# ----------------------------------------------------------------------------- Gymnasium, B worlds
def check_vector_env(env: UAVSpectrumVectorEnv, steps: int, seed: int = 123):
    """Gymnasium's vector-env contract (Gymnasium 1.4 ships no checker for it): what ``check_env`` checks of an
    env, for a batch: spaces batched from the single ones, autoreset metadata, reset and step types, shapes and
    dtypes, observations within the space, seeded determinism, and no data shared between calls."""
    B = env.num_envs
    assert env.observation_space == batch_space(env.single_observation_space, B)
    assert env.action_space == batch_space(env.single_action_space, B)
    assert isinstance(env.metadata["autoreset_mode"], AutoresetMode)
    obs, infos = env.reset(seed=seed)
    assert env.np_random_seed == seed and env.observation_space.contains(obs) and isinstance(infos, dict)
    for key, value in infos.items():
        assert len(value) == B, key
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    calls = [(obs, infos)]
    for a in actions:
        obs, reward, terminated, truncated, infos = env.step(a)
        assert env.observation_space.contains(obs)
        assert reward.shape == terminated.shape == truncated.shape == (B,)
        assert reward.dtype == np.float64 and terminated.dtype == truncated.dtype == np.bool_
        calls.append((obs, infos))
    for i, (obs_i, info_i) in enumerate(calls):
        for obs_j, info_j in calls[i + 1 :]:
            assert not data_shares_objects(obs_i, obs_j) and not data_shares_objects(info_i, info_j)
    again = [env.reset(seed=seed)]
    again += [env.step(a) for a in actions]
    for first, second in zip(calls, [(o[0], o[-1]) for o in again], strict=True):
        assert data_equivalence(first, second, exact=True)
    other = env.reset(seed=seed + 1)[0]
    assert not np.array_equal(other, calls[0][0])


@pytest.mark.parametrize("options", MODELS, ids=MODEL_IDS)
def test_vector_env_passes_the_vector_contract(options):
    check_vector_env(UAVSpectrumVectorEnv(num_envs=4, max_steps=3, **options), steps=8)


@pytest.mark.parametrize("options", MODELS, ids=MODEL_IDS)
def test_vector_env_is_gymnasiums_sync_vector_env_of_single_envs(options):
    """World i of a batch seeded s is the single env seeded s + i, episode after episode, through next-step
    autoresets: step for step what Gymnasium's reference vectorisation of the single env returns."""
    B, seed = 3, 11
    ours = UAVSpectrumVectorEnv(num_envs=B, max_steps=3, **options)
    reference = SyncVectorEnv([lambda: UAVSpectrumGymEnv(max_steps=3, **options)] * B)
    assert ours.metadata["autoreset_mode"] == reference.metadata["autoreset_mode"]
    assert ours.observation_space == reference.observation_space and ours.action_space == reference.action_space
    assert data_equivalence(ours.reset(seed=seed), reference.reset(seed=seed), exact=True)
    ours.action_space.seed(0)
    for _ in range(9):  # two episodes ended and autoreset, a third under way
        actions = ours.action_space.sample()
        assert data_equivalence(ours.step(actions), reference.step(actions), exact=True)


def test_vector_env_is_uavspectrumenv():
    """The same observations (with the nodes appended), masks and rewards as the TorchRL env of the same seed."""
    B, seed, N = 4, 5, 3
    ours = UAVSpectrumVectorEnv(num_envs=B, grid=(4, 4), num_uavs=N, layout="random", max_steps=50)
    torchrl_env = UAVSpectrumEnv(batch_size=B, grid=(4, 4), num_uavs=N, layout="random", seed=seed, max_steps=50)
    obs, infos = ours.reset(seed=seed)
    td = torchrl_env.reset()
    generator = torch.Generator().manual_seed(0)
    for _ in range(6):
        assert np.array_equal(obs, observation_with_nodes(td["agents", "observation"], td["state"]).numpy())
        assert np.array_equal(infos["action_mask"], td["agents", "action_mask"].to(torch.int8).numpy())
        actions = torch.randint(0, 6, (B, N), generator=generator)
        obs, reward, _, _, infos = ours.step(actions.numpy())
        td = torchrl_env.step(td.set(("agents", "action"), actions))["next"]
        assert np.array_equal(reward, td["reward"].squeeze(-1).double().numpy())
        assert np.array_equal(infos["utility"], td["utility"].squeeze(-1).double().numpy())


def test_gymnasiums_vector_wrappers_run_on_the_vector_env():
    """Gymnasium's vector wrappers read the autoreset mode (``NormalizeObservation`` refuses all but next-step and
    disabled) and the episode ends: the episode statistics are each world's return over its ``max_steps`` steps."""
    from gymnasium.wrappers.vector import NormalizeObservation, RecordEpisodeStatistics

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = RecordEpisodeStatistics(NormalizeObservation(UAVSpectrumVectorEnv(num_envs=3, max_steps=4)))
        env.reset(seed=0)
        env.action_space.seed(0)
        returns = np.zeros(3)
        for _ in range(4):
            _, reward, _, truncated, infos = env.step(env.action_space.sample())
            returns += reward
    assert truncated.all() and infos["_episode"].all()
    assert np.array_equal(infos["episode"]["l"], [4, 4, 4]) and np.allclose(infos["episode"]["r"], returns)


def test_vector_env_autoresets_the_next_step():
    env = UAVSpectrumVectorEnv(num_envs=2, grid=(3, 3), max_steps=2)
    env.reset(seed=0)
    relay = np.full((2, 2), 5)
    env.step(relay)
    truncated = env.step(relay)[3]
    obs, reward, terminated, truncated_after, _ = env.step(relay)
    assert truncated.all() and not truncated_after.any() and not terminated.any() and (reward == 0).all()
    assert np.array_equal(env.world._s.steps.numpy(), [0, 0])  # a fresh episode, its actions ignored


# ----------------------------------------------------------------------------- PettingZoo
def test_parallel_env_passes_pettingzoos_tests():
    parallel_api_test(UAVSpectrumParallelEnv(grid=(4, 4), num_uavs=3, max_steps=20), num_cycles=40)
    parallel_seed_test(lambda: UAVSpectrumParallelEnv(grid=(4, 4), num_uavs=3, max_steps=20), num_cycles=40)
    with warnings.catch_warnings():
        # PettingZoo's AEC test warns of every dict observation (its own masked environments' layout, which
        # PettingZoo documents for action masks)
        warnings.filterwarnings("ignore", "Observation is not a NumPy array")
        warnings.filterwarnings("ignore", "Observation space for each agent probably should be")
        api_test(parallel_to_aec(UAVSpectrumParallelEnv(grid=(4, 4), num_uavs=3, max_steps=20)), num_cycles=40)
    state_test(parallel_to_aec(UAVSpectrumParallelEnv(max_steps=20)), UAVSpectrumParallelEnv(max_steps=20))


def test_parallel_env_passes_pettingzoos_tests_at_levels_in_a_city():
    options = dict(grid=(3, 3), num_uavs=3, max_steps=20, **LEVELS_IN_A_CITY)
    parallel_api_test(UAVSpectrumParallelEnv(**options), num_cycles=40)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Observation is not a NumPy array")
        warnings.filterwarnings("ignore", "Observation space for each agent probably should be")
        api_test(parallel_to_aec(UAVSpectrumParallelEnv(**options)), num_cycles=40)
    state_test(parallel_to_aec(UAVSpectrumParallelEnv(**options)), UAVSpectrumParallelEnv(**options))


def test_the_adapters_spaces_hold_every_observation_at_levels_in_a_city():
    """8 actions a UAV; the observation's and the state's bounds hold what a long random walk sees (a UAV at every
    level, climbs and descents blocked by the buildings: their contributions -1)."""
    options = dict(grid=(3, 3), num_uavs=3, max_steps=200, **LEVELS_IN_A_CITY)
    gym_env, zoo = UAVSpectrumGymEnv(**options), UAVSpectrumParallelEnv(**options)
    assert gym_env.action_space == gymnasium.spaces.MultiDiscrete([8, 8, 8])
    assert all(zoo.action_space(agent).n == 8 for agent in zoo.possible_agents)
    observation, info = gym_env.reset(seed=1)
    own_level = OWN_FEATURES + 3 * 2  # after the own part and the others' (x, y, task)
    assert observation.shape == (3, observation_size(3, False, levels=True) + NODE_FEATURES) == (3, 38)
    seen, blocked, rng = [observation], False, np.random.default_rng(0)
    for _ in range(200):
        observation, *_, info = gym_env.step(rng.integers(0, 8, 3))
        seen.append(observation)
        blocked |= bool((info["action_mask"][:, 6:] == 0).any())
    assert all(gym_env.observation_space.contains(o) for o in seen) and blocked
    levels = np.stack(seen)[:, :, own_level]  # 0 to 1
    assert set(np.round(levels.ravel() * 2).astype(int)) == {0, 1, 2}
    zoo.reset(seed=1)
    state = zoo.state()
    assert zoo.state_space.contains(state) and state.shape == (6 * 3 + 12,)


def test_parallel_env_is_the_gym_env():
    """One agent per UAV: its row of the team observation and mask, the team reward for every agent."""
    options = {"grid": (4, 4), "num_uavs": 3, "layout": "random", "fading": "rayleigh", "max_steps": 4}
    zoo, gym_env = UAVSpectrumParallelEnv(**options), UAVSpectrumGymEnv(**options)
    observations, _ = zoo.reset(seed=9)
    obs, info = gym_env.reset(seed=9)
    rng = np.random.default_rng(0)
    for _ in range(4):
        for i, agent in enumerate(zoo.possible_agents):
            assert np.array_equal(observations[agent]["observation"], obs[i])
            assert np.array_equal(observations[agent]["action_mask"], info["action_mask"][i])
            assert zoo.observation_space(agent).contains(observations[agent])
        assert zoo.state_space.contains(zoo.state())
        actions = rng.integers(0, 6, 3)
        observations, rewards, terminations, truncations, infos = zoo.step(dict(zip(zoo.agents, actions, strict=True)))
        obs, reward, _, truncated, info = gym_env.step(actions)
        assert set(rewards.values()) == {reward} and not any(terminations.values())
        assert set(truncations.values()) == {truncated} and infos["uav_2"]["utility"] == info["utility"]
    assert zoo.agents == []


# ----------------------------------------------------------------------------- rendering
def test_the_adapters_render_the_frames_uavspectrumenv_draws():
    """``render_mode="rgb_array"``: the Gymnasium env, the vector env (a frame per world) and the PettingZoo env draw
    the picture ``UAVSpectrumEnv.render()`` draws of the same world, step for step."""
    B, seed, options = 3, 4, {"grid": (4, 4), "num_uavs": 2, "layout": "random", "max_steps": 6}
    single = UAVSpectrumGymEnv(render_mode="rgb_array", **options)
    vector = UAVSpectrumVectorEnv(num_envs=B, render_mode="rgb_array", **options)
    zoo = UAVSpectrumParallelEnv(render_mode="rgb_array", **options)
    torchrl_one, torchrl_batch = (UAVSpectrumEnv(batch_size=b, seed=seed, **options) for b in (1, B))
    for env in (single, vector, zoo):
        env.reset(seed=seed)
    td_one, td_batch = torchrl_one.reset(), torchrl_batch.reset()
    generator = torch.Generator().manual_seed(0)
    for step in range(3):
        expected = torchrl_one.render()
        assert expected.shape == (360, 480, 3) and expected.dtype == np.uint8
        assert np.array_equal(single.render(), expected) and np.array_equal(zoo.render(), expected)
        frames = vector.render()
        assert isinstance(frames, tuple) and len(frames) == B
        for i, frame in enumerate(frames):
            assert np.array_equal(frame, torchrl_batch.render(env_index=i)), (step, i)
        actions = torch.randint(0, 6, (B, 2), generator=generator)
        single.step(actions[0].numpy())
        vector.step(actions.numpy())
        zoo.step(dict(zip(zoo.agents, actions[0].tolist(), strict=True)))
        td_one = torchrl_one.step(td_one.set(("agents", "action"), actions[:1]))["next"]
        td_batch = torchrl_batch.step(td_batch.set(("agents", "action"), actions))["next"]
    assert not np.array_equal(single.render(), expected)  # the frame follows the steps


@pytest.mark.parametrize(
    "make", [UAVSpectrumGymEnv, lambda: UAVSpectrumVectorEnv(2), UAVSpectrumParallelEnv], ids=["gym", "vector", "zoo"]
)
def test_render_without_a_render_mode_draws_nothing(make):
    env = make()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode=None draws nothing: give render_mode='rgb_array'"):
        assert env.render() is None


def test_parallel_env_passes_pettingzoos_render_test():
    def make(render_mode=None):
        # render_test builds its first env with render_mode="human" only to read the metadata's modes: this env
        # opens no window and refuses "human", so that one is made without a mode
        mode = None if render_mode == "human" else render_mode
        return parallel_to_aec(UAVSpectrumParallelEnv(grid=(4, 4), num_uavs=3, max_steps=20, render_mode=mode))

    assert make().metadata["render_modes"] == ["rgb_array"]
    render_test(make, custom_tests={"rgb_array": lambda frame: frame.shape == (360, 480, 3)})


# ----------------------------------------------------------------------------- evaluation and SB3
def test_team_action_policy_is_measured_on_the_vector_envs_worlds():
    """``evaluate(TeamActionPolicy(act))`` plays ``act`` on the vector env's observations: its final utility over
    U* is what playing ``act`` on the vector env seeded like the evaluation gives."""
    cfg, starts, horizon = make_config("paper", grid=(6, 6), num_uavs=2), 8, 6
    weights = np.random.default_rng(1).normal(size=(28, 6)).astype(np.float32)

    def act(observation, action_mask):  # a fixed, deterministic masked linear policy
        return np.where(action_mask == 1, observation @ weights, -np.inf).argmax(-1)

    metrics = evaluate(TeamActionPolicy(act), cfg, num_starts=starts, horizon=horizon)
    env = UAVSpectrumVectorEnv(num_envs=starts, config=cfg.replace(max_steps=horizon))
    obs, infos = env.reset(seed=EVAL_SEED)
    for _ in range(horizon):
        obs, _, _, _, infos = env.step(act(obs, infos["action_mask"]))
    u_star = env.world.optimum()[0].numpy()
    assert metrics["eval/optimality"] == pytest.approx((infos["utility"] / u_star).mean(), rel=1e-6)


def test_stable_baselines3_ppo_trains_and_the_yardstick_measures_it():
    sb3 = pytest.importorskip("stable_baselines3")
    env = UAVSpectrumGymEnv(grid=(6, 6), num_uavs=2, max_steps=24)
    model = sb3.PPO("MlpPolicy", env, n_steps=512, batch_size=128, n_epochs=2, seed=0, device="cpu")
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(total_timesteps=2048)
    assert model.num_timesteps == 2048
    assert any(not torch.equal(b, p) for b, p in zip(before, model.policy.parameters(), strict=True))
    policy = TeamActionPolicy(lambda obs, mask: model.predict(obs, deterministic=True)[0])
    metrics = evaluate(policy, env.cfg, num_starts=16)
    assert 0 < metrics["eval/optimality"] <= 1 and 0 <= metrics["eval/reach_999"] <= 1


def test_maskable_ppo_reads_the_action_masks():
    contrib = pytest.importorskip("sb3_contrib")
    env = UAVSpectrumGymEnv(grid=(3, 3), num_uavs=2, max_steps=10)
    model = contrib.MaskablePPO("MlpPolicy", env, n_steps=128, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=128)
    obs, _ = env.reset(seed=0)
    for _ in range(20):  # never a move off the grid, which only the mask rules out
        action, _ = model.predict(obs, action_masks=env.action_masks(), deterministic=False)
        assert env.action_masks().reshape(2, 6)[np.arange(2), action].all()
        obs, *_ = env.step(action)


# ----------------------------------------------------------------------------- bad input: one line each
@pytest.mark.parametrize(
    ("call", "error", "message"),
    [
        (lambda: UAVSpectrumGymEnv().step([1, 2]), RuntimeError, "call reset"),
        (lambda: _reset(UAVSpectrumGymEnv()).step([1, 2, 3]), ValueError, r"action has shape \(3,\): expected \(2,\)"),
        (lambda: _reset(UAVSpectrumGymEnv()).step([0, 6]), ValueError, "action holds 6: actions are 0..5"),
        (lambda: _reset(UAVSpectrumGymEnv()).step([0.5, 1.0]), TypeError, "action has dtype float64"),
        (lambda: UAVSpectrumGymEnv().reset(seed=-1), ValueError, r"seed=-1 is invalid"),
        (lambda: UAVSpectrumGymEnv().reset(options={"x": 1}), ValueError, "takes no reset options"),
        (
            lambda: UAVSpectrumGymEnv(render_mode="human"),
            ValueError,
            r"render_mode='human' is invalid: .*\['rgb_array'\]",
        ),
        (lambda: UAVSpectrumParallelEnv(render_mode="ansi"), ValueError, "render_mode='ansi' is invalid"),
        (lambda: UAVSpectrumGymEnv(render_mode="rgb_array").render(), RuntimeError, r"render\(\) before any reset"),
        (lambda: UAVSpectrumGymEnv(grid=(0, 6)), ValueError, "grid"),
        (lambda: UAVSpectrumVectorEnv(num_envs=0), ValueError, "num_envs=0 is invalid"),
        (lambda: UAVSpectrumVectorEnv(2).reset(options={"reset_mask": [1, 0]}), ValueError, "no reset_mask"),
        (lambda: UAVSpectrumVectorEnv(2).reset(seed=[1, 2]), ValueError, "give one int"),
        (lambda: _reset(UAVSpectrumVectorEnv(2)).step(np.zeros(2, int)), ValueError, r"expected \(2, 2\)"),
        (lambda: UAVSpectrumParallelEnv().step({"uav_0": 1}), RuntimeError, "no live agents"),
        (lambda: _reset(UAVSpectrumParallelEnv()).step({"uav_0": 1}), ValueError, "no action for 'uav_1'"),
        (lambda: _reset(UAVSpectrumParallelEnv()).step({"uav_7": 1}), ValueError, "names 'uav_7'"),
        (lambda: TeamActionPolicy(3), TypeError, "not callable"),
    ],
)
def test_bad_input_is_one_line(call, error, message):
    with pytest.raises(error, match=message) as caught:
        call()
    assert "\n" not in str(caught.value)


def _reset(env):
    env.reset(seed=0)
    return env


@pytest.mark.parametrize("adapter", [UAVSpectrumGymEnv, UAVSpectrumParallelEnv])
def test_local_observations_are_refused_in_one_line(adapter):
    """The adapters hand each UAV the central observation and the nodes: local observations are the TorchRL env's."""
    with pytest.raises(ValueError, match="observation='local' is invalid: the Gymnasium and PettingZoo adapters"):
        adapter(grid=(4, 4), num_uavs=2, observation="local")
