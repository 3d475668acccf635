"""Gymnasium adapters of the model (``pip install -e ".[gym]"``): a team-level ``Env`` and a ``VectorEnv`` of B worlds.

Both wrap the batched physics, a :class:`~uavrl.envs.world.World`, as :class:`~uavrl.envs.env.UAVSpectrumEnv`
does, with no TorchRL on the way: the same observations, action masks, rewards and seeds.

- :class:`UAVSpectrumGymEnv`: one world; the team acts with one action per UAV, ``MultiDiscrete([A] * N)``.
- :class:`UAVSpectrumVectorEnv`: ``num_envs`` worlds stepped together as one ``World`` of that batch (a step
  costs a few tensor operations whatever the batch, no loop over worlds); next-step autoreset, as
  Gymnasium's own vector envs.
- :class:`TeamActionPolicy`: a function of these observations (a Stable-Baselines3 model's ``predict``) as a
  TorchRL policy of ``UAVSpectrumEnv``, so :func:`uavrl.agents.evaluation.evaluate` measures it on the yardstick
  from the same held-out starts as every agent.

Actions are ``MultiDiscrete([6] * N)`` rather than the joint action ``Discrete(6^N)``: the space grows as
``6 N`` where the joint one grows as ``6^N`` (46,656 at N = 6); the per-UAV masks apply to it as they are
(MaskablePPO reads the mask of a ``MultiDiscrete`` space as the per-dimension masks side by side); and every
one of its actions is legal, since a move off the grid leaves the UAV in place and clashing moves are
repaired (docs/model.md, "What a UAV can do in one step"). Stable-Baselines3's PPO, A2C and MaskablePPO
take it; its DQN takes ``Discrete`` spaces only.

The observation is, per UAV, its observation followed by the four nodes' positions
(:func:`~uavrl.envs.world.observation_with_nodes`, what the project's DQN reads): ``Box`` ``[N, F + 12]``
float32, whose bounds hold every layout the config allows.  The reward is the team reward (float32, as
``UAVSpectrumEnv``'s); an episode is truncated after ``max_steps``, and terminated only under an energy model, when
no UAV serves any more (docs/model.md, Energy and lifetime).  The info holds ``action_mask`` ``[N, A]`` int8
(A = 6, 7 with recharging, 8 with altitude levels; 1 where the move is possible) and the step's ``r_pu``, ``r_se``,
``utility``, ``moves``, ``task_switches``; :meth:`UAVSpectrumGymEnv.action_masks` is the mask flat, as
MaskablePPO asks for it.

Seeds: ``reset(seed=s)`` seeds the world's stream ``s``; the vector env seeds its world ``i`` with ``s + i``,
as ``gymnasium.vector.SyncVectorEnv`` seeds its ``i``-th env, so world ``i`` of the vector env is the single
env seeded ``s + i``.  Before the first seeded reset the worlds are seeded 0, ``UAVSpectrumEnv``'s default:
the same result run after run.  The physics draws from the worlds' own streams, never from ``np_random``.

Rendering: ``render_mode="rgb_array"`` (the one mode, ``metadata["render_modes"]``): ``render()`` returns the
``[H, W, 3]`` uint8 frame that ``UAVSpectrumEnv.render()`` draws of the same world (:mod:`uavrl.envs.render`);
the vector env returns a tuple of its worlds' frames, as ``gymnasium.vector.SyncVectorEnv`` does.  With
``render_mode=None`` nothing is drawn and ``render()`` returns None, as Gymnasium specifies.

Example:
    >>> env = UAVSpectrumGymEnv(grid=(6, 6), num_uavs=2, max_steps=10)
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["action_mask"].shape, env.action_space
    ((2, 28), (2, 6), MultiDiscrete([6 6]))
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    >>> vec = UAVSpectrumVectorEnv(num_envs=4, grid=(6, 6), num_uavs=2, max_steps=10)
    >>> obs, infos = vec.reset(seed=0)
    >>> obs.shape, vec.action_space.shape
    ((4, 2, 28), (4, 2))
"""

from __future__ import annotations

import gymnasium
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from ..config import ModelConfig, action_names, check_config_alone, make_config
from ..errors import InvalidOption, InvalidType
from ..limits import DEFAULT_MEMORY_BUDGET, VERTICAL_FEATURES
from ..physics.channel import fixed_layout
from ..render import RENDER_MODES as DRAWN_MODES
from ..render import render as render_world
from ..world import NODE_FEATURES, World, check_memory, check_seed, observation_with_nodes, resolve_device

__all__ = [
    "ENV_ID",
    "TeamActionPolicy",
    "UAVSpectrumGymEnv",
    "UAVSpectrumVectorEnv",
    "observation_bounds",
    "state_bounds",
]

ENV_ID = "uavrl/UAVSpectrum-v0"  # gymnasium.make(ENV_ID, ...) and gymnasium.make_vec(ENV_ID, num_envs=B, ...)
INFO_KEYS = ("r_pu", "r_se", "utility", "moves", "task_switches")  # the step's diagnostics, in every info
RENDER_MODES = list(DRAWN_MODES)  # the modes the adapters draw (metadata["render_modes"])
# a step has no duration in the model: videos play at the rate the project's own are written (eval.video_fps)
RENDER_FPS = 4


def model_config(config: ModelConfig | None, preset, grid, num_uavs, max_steps, overrides: dict) -> ModelConfig:
    """The model an adapter wraps, from a complete config or from ``UAVSpectrumEnv``'s arguments."""
    if config is not None and not isinstance(config, ModelConfig):
        raise InvalidType("config", config, "give a ModelConfig (uavrl.envs.make_config(...)) or None")
    check_config_alone(config, overrides, grid=grid, num_uavs=num_uavs, preset=preset, max_steps=max_steps)
    return config or make_config(preset, grid=grid, num_uavs=num_uavs, max_steps=max_steps, **overrides)


def check_no_options(options, note: str = "") -> None:
    """Every adapter's ``reset(options=...)``: None or ``{}``, as no part of the model reads reset options; anything
    else is refused in one line, so nothing given is ignored."""
    if options is None or (isinstance(options, dict) and not options):
        return
    kind = InvalidOption if isinstance(options, dict) else InvalidType
    raise kind("options", options, f"this env takes no reset options (give None or {{}}){note}")


def check_render_mode(render_mode) -> None:
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise InvalidOption("render_mode", render_mode, f"the render modes are {RENDER_MODES} or None")


def render_frames(world: World, render_mode: str | None, indices: range) -> list[np.ndarray] | None:
    """The frames of worlds ``indices`` in ``render_mode``; None, with Gymnasium's warning, when it is None."""
    if render_mode is None:
        gymnasium.logger.warn(
            "render() of an env made with render_mode=None draws nothing: give render_mode='rgb_array' to the "
            "constructor (or gymnasium.make)"
        )
        return None
    return [render_world(world, render_mode, i) for i in indices]


def _node_bounds(cfg: ModelConfig) -> tuple[np.ndarray, np.ndarray]:
    """``[12]`` bounds of the nodes' ``(x / L1, y / L2, z / h)``: a random layout's range (within half a grid of the
    grid, on the ground or at UAV altitude; docs/model.md, "Where the four nodes are"), widened to hold a fixed
    layout's nodes (the authors' absolute layout lies outside it on small grids)."""
    nodes = NODE_FEATURES // 3
    low, high = np.tile(np.float32([-0.5, -0.5, 0.0]), nodes), np.tile(np.float32([1.5, 1.5, 1.0]), nodes)
    layout = fixed_layout(cfg)
    if layout is not None:  # scaled exactly as World does it
        L1, L2 = cfg.grid
        scaled = (layout / torch.tensor([L1, L2, cfg.height], dtype=layout.dtype)).flatten().float().numpy()
        low, high = np.minimum(low, scaled), np.maximum(high, scaled)
    return low, high


def _position_bounds(cfg: ModelConfig) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of a UAV's (x, y, task): [0, 1]; under an energy model the base's scaled position too (a UAV out of
    service is shown there)."""
    if cfg.energy == "none":
        return np.zeros(3), np.ones(3)
    (L1, L2), (bx, by) = cfg.grid, cfg.base
    base = np.float32([bx / max(L1 - 1, 1), by / max(L2 - 1, 1), 0.0])
    return np.minimum(base, 0), np.maximum(base, 1)


def _vertical_bounds(cfg: ModelConfig) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Bounds of the observation's altitude part (none at one level): the own level scaled to [0, 1], the
    contributions at the positions a climb and a descent reach (``VERTICAL_FEATURES - 1``, -1 where the move is
    impossible), the others' levels in [0, 1]."""
    if cfg.num_levels == 1:
        return [], []
    contributions, others = VERTICAL_FEATURES - 1, cfg.fleet_size - 1
    low = [np.zeros(1), np.full(contributions, -1.0), np.zeros(others)]
    return low, [np.ones(1), np.ones(contributions), np.ones(others)]


def observation_bounds(cfg: ModelConfig) -> tuple[np.ndarray, np.ndarray]:
    """``[N, F + 12]`` bounds of the team observation: positions and tasks in [0, 1], the contributions at the own
    and the 4 next cells in [0, 1] (scaled by the best cell's), -1 where a move leaves the grid (or for a UAV out of
    service), the batteries and service flags of an energy model in [0, 1]; with altitude levels the own level in
    [0, 1], the contributions a climb and a descent reach (as the next cells') and the others' levels in [0, 1]; then
    the nodes.

    Args:
        cfg: the model.

    Returns:
        The lower and the upper bounds, ``[N, F + 12]`` float32 each.
    """
    N, (position_low, position_high) = cfg.fleet_size, _position_bounds(cfg)
    energy = 0 if cfg.energy == "none" else 2 * N
    node_low, node_high = _node_bounds(cfg)
    vertical_low, vertical_high = _vertical_bounds(cfg)
    low = [position_low, np.full(10, -1.0), np.tile(position_low, N - 1), np.zeros(energy), *vertical_low, node_low]
    high = [position_high, np.ones(10), np.tile(position_high, N - 1), np.ones(energy), *vertical_high, node_high]
    low, high = np.concatenate(low).astype(np.float32), np.concatenate(high).astype(np.float32)
    return np.tile(low, (N, 1)), np.tile(high, (N, 1))


def state_bounds(cfg: ModelConfig) -> tuple[np.ndarray, np.ndarray]:
    """``[5 N + 12]`` bounds of the state: per UAV (x, y, task) and its contributions at its cell, all in [0, 1],
    then the nodes; under an energy model ``[7 N + 12]``: a UAV out of service at the base with contributions -1,
    then each UAV's battery and service flag in [0, 1], then the nodes; with altitude levels each UAV's level in
    [0, 1] before the nodes (after the batteries under an energy model).

    Args:
        cfg: the model.

    Returns:
        The lower and the upper bounds, float32.
    """
    node_low, node_high = _node_bounds(cfg)
    levels = cfg.fleet_size * (cfg.num_levels > 1)
    if cfg.energy == "none":
        per_uav = 5 * cfg.fleet_size + levels
        return np.concatenate([np.zeros(per_uav, np.float32), node_low]), np.concatenate(
            [np.ones(per_uav, np.float32), node_high]
        )
    N, (position_low, position_high) = cfg.fleet_size, _position_bounds(cfg)
    low = [np.tile(np.concatenate([position_low, [-1.0, -1.0]]), N), np.zeros(2 * N + levels), node_low]
    high = [np.tile(np.concatenate([position_high, [1.0, 1.0]]), N), np.ones(2 * N + levels), node_high]
    return np.concatenate(low).astype(np.float32), np.concatenate(high).astype(np.float32)


def team_observation_space(cfg: ModelConfig) -> spaces.Box:
    low, high = observation_bounds(cfg)
    return spaces.Box(low, high, dtype=np.float32)


def check_actions(actions, shape: tuple[int, ...], name: str, num_actions: int) -> np.ndarray:
    """``actions`` as an int64 array of ``shape``, each below ``num_actions``; a one-line error naming ``name``
    otherwise."""
    if hasattr(actions, "device") and getattr(actions.device, "type", "cpu") != "cpu":  # a torch tensor elsewhere
        raise InvalidOption(name, message=f"{name} is on device {actions.device}: give a NumPy array or a CPU tensor")
    try:
        array = np.asarray(actions)
    except (TypeError, ValueError, RuntimeError) as err:  # ragged lists, objects NumPy cannot read
        reason = " ".join(str(err).split())[:120]
        raise InvalidType(name, message=f"{name} is no array of integers ({reason}): give {shape} integers") from None
    if array.shape != shape:
        raise InvalidOption(name, message=f"{name} has shape {array.shape}: expected {shape} (one action per UAV)")
    if not np.issubdtype(array.dtype, np.integer):
        message = f"{name} has dtype {array.dtype}: expected integers {action_names(num_actions)}"
        raise InvalidType(name, message=message)
    lo, hi = array.min(), array.max()
    if lo < 0 or hi >= num_actions:
        bad = lo if lo < 0 else hi
        raise InvalidOption(name, message=f"{name} holds {bad}: actions are {action_names(num_actions)}")
    return array.astype(np.int64, copy=False)


class NumpyWorlds:
    """A :class:`~uavrl.envs.world.World` of ``num_worlds`` worlds whose outputs come back as NumPy arrays: what
    the Gymnasium and PettingZoo adapters share.

    :meth:`reset` and :meth:`step` return ``observation`` ``[B, N, F + 12]`` float32 (the team observation),
    ``action_mask`` ``[B, N, A]`` int8, ``state`` ``[B, 5 N + 12]`` float32 and the :data:`INFO_KEYS` ``[B]``,
    every array new (Gymnasium's checker asks that no two calls share data).
    """

    def __init__(self, cfg: ModelConfig, num_worlds: int, device):
        if cfg.local:  # each UAV's observation here carries the world's nodes (observation_with_nodes)
            reason = (
                "the Gymnasium and PettingZoo adapters give each UAV the central observation and the nodes; act on "
                "local observations in UAVSpectrumEnv (TorchRL, BenchMARL)"
            )
            raise InvalidOption("observation", cfg.observation, reason)
        self.cfg = cfg
        self.world = World(cfg, num_worlds, resolve_device(device), seed=0)
        self.was_reset = False

    def _numpy(self, out: dict) -> dict[str, np.ndarray]:
        arrays = {key: out[key].numpy(force=True) for key in INFO_KEYS}
        arrays["observation"] = observation_with_nodes(out["observation"], out["state"]).numpy(force=True)
        arrays["action_mask"] = out["action_mask"].to(torch.int8).numpy(force=True)
        arrays["state"] = out["state"].numpy(force=True)
        return arrays

    def reset(self, seed: int | None, worlds: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Every world's outputs after a reset of all worlds, or of ``worlds`` (indices; the others are left as they
        are)."""
        if seed is not None:
            self.world.set_seed(check_seed(seed))
        self.was_reset = True
        return self._numpy(self.world.reset(None if worlds is None else torch.from_numpy(worlds)))

    def terminated(self) -> np.ndarray:
        """``[B]`` bool: which worlds' episodes the last step ended (only an energy model's can end)."""
        return self.world.terminated.numpy(force=True).copy()

    def step(self, actions: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
        """Every world takes ``actions`` ``[B, N]`` (checked); the outputs, the team reward ``[B]`` (float32 values,
        as ``UAVSpectrumEnv`` gives them, in float64) and truncation ``[B]``."""
        if not self.was_reset:
            raise RuntimeError("step() before any reset: call reset() first (the worlds have no UAV positions yet)")
        out, reward, truncated = self.world.step(torch.from_numpy(actions).to(self.world.device))
        return self._numpy(out), reward.float().double().numpy(force=True), truncated.numpy(force=True)


def world_info(arrays: dict[str, np.ndarray], world: int) -> dict:
    """The info of one world: its action mask and the step's diagnostics as Python numbers."""
    info = {key: arrays[key][world].item() for key in INFO_KEYS}
    info["action_mask"] = arrays["action_mask"][world]
    return info


class UAVSpectrumGymEnv(gymnasium.Env):
    """One world of the model as a Gymnasium env; the team's action is ``MultiDiscrete([6] * N)``.

    Args (as :class:`~uavrl.envs.env.UAVSpectrumEnv`'s): ``grid``, ``num_uavs``, ``preset``, ``max_steps``,
    ``device``, ``config`` (a complete :class:`~uavrl.envs.config.ModelConfig`) or ``**overrides`` (any model
    option); ``render_mode`` one of ``metadata["render_modes"]`` or None.  Seed with ``reset(seed=...)``.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": RENDER_FPS}

    def __init__(
        self,
        grid=(6, 6),
        num_uavs=2,
        preset="paper",
        max_steps=100,
        device="cpu",
        render_mode=None,
        *,
        config: ModelConfig | None = None,
        **overrides,
    ):
        check_render_mode(render_mode)
        self.render_mode = render_mode
        self.cfg = model_config(config, preset, grid, num_uavs, max_steps, overrides)
        self._worlds = NumpyWorlds(self.cfg, 1, device)
        self.observation_space = team_observation_space(self.cfg)
        self.action_space = spaces.MultiDiscrete([self.cfg.num_actions] * self.cfg.fleet_size)
        self._mask = None

    @property
    def world(self) -> World:
        """The wrapped physics (its ``utility``, ``optimum``, ``code``...)."""
        return self._worlds.world

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Gymnasium's reset: ``(observation, info)`` of a new episode (``seed`` seeds it and those that follow;
        ``options`` must be None or empty: the env takes none)."""
        super().reset(seed=None if seed is None else check_seed(seed))
        check_no_options(options)
        out = self._worlds.reset(seed)
        self._mask = out["action_mask"][0]
        return out["observation"][0], world_info(out, 0)

    def step(self, action):
        """Gymnasium's step: the team's ``action`` (one per UAV, checked) to ``(observation, reward, terminated,
        truncated, info)``."""
        actions = check_actions(action, (self.cfg.fleet_size,), "action", self.cfg.num_actions)
        out, reward, truncated = self._worlds.step(actions[None])
        self._mask = out["action_mask"][0]
        terminated = bool(self._worlds.terminated()[0])
        return out["observation"][0], reward[0].item(), terminated, bool(truncated[0]), world_info(out, 0)

    def action_masks(self) -> np.ndarray:
        """``[6 N]`` bool: each UAV's action mask, side by side (what sb3-contrib's MaskablePPO reads)."""
        if self._mask is None:
            raise RuntimeError("action_masks() before any reset: call reset() first")
        return self._mask.reshape(-1).astype(bool)

    def render(self) -> np.ndarray | None:
        """The world now as an ``[H, W, 3]`` uint8 frame (``render_mode="rgb_array"``); None without a mode."""
        frames = render_frames(self.world, self.render_mode, range(1))
        return None if frames is None else frames[0]


class UAVSpectrumVectorEnv(VectorEnv):
    """``num_envs`` worlds of the model as one Gymnasium ``VectorEnv``, stepped together as one ``World``.

    Observations ``[B, N, F + 12]``, actions ``[B, N]`` (``MultiDiscrete``), rewards, terminations and truncations
    ``[B]``; infos as Gymnasium's vector envs batch them (each key ``[B, ...]`` beside its ``_key`` mask).
    Autoreset is ``NEXT_STEP``: the step after an episode ends resets the worlds, ignores their actions and
    returns their first observation with reward 0.  ``reset(seed=s)`` seeds world ``i`` with ``s + i``.
    Arguments as :class:`UAVSpectrumGymEnv`'s, plus ``num_envs`` (the batch).

    Args:
        num_envs: the number of worlds ``B``.
        grid: ``(L1, L2)`` cells.
        num_uavs: ``N``, at most ``L1 * L2``.
        preset: ``"paper"``, ``"reference_code"`` or ``"a2g_urban"``; ``grid`` and ``num_uavs`` given here win over
            the preset's.
        max_steps: the episode length ``T`` in steps.
        device: the torch device of the world (observations come back as NumPy arrays).
        render_mode: ``"rgb_array"`` or None.
        config: a complete :class:`~uavrl.envs.config.ModelConfig`; replaces ``grid``, ``num_uavs``, ``preset``,
            ``max_steps`` and the overrides.
        **overrides: any model option (:class:`~uavrl.envs.config.ModelConfig`'s fields), e.g. ``channel="al_hourani"``.

    Example:
        >>> vector_env = UAVSpectrumVectorEnv(num_envs=4, grid=(4, 4), num_uavs=2)
        >>> observation, info = vector_env.reset(seed=0)
        >>> observation.shape
        (4, 2, 28)
        >>> observation, reward, terminated, truncated, info = vector_env.step(vector_env.action_space.sample())
        >>> reward.shape, truncated.shape
        ((4,), (4,))
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": RENDER_FPS, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs=1,
        grid=(6, 6),
        num_uavs=2,
        preset="paper",
        max_steps=100,
        device="cpu",
        render_mode=None,
        *,
        config: ModelConfig | None = None,
        **overrides,
    ):
        if not isinstance(num_envs, int) or isinstance(num_envs, bool) or num_envs < 1:
            raise (InvalidOption if isinstance(num_envs, int) else InvalidType)(
                "num_envs", num_envs, "give the number of worlds B >= 1"
            )
        check_render_mode(render_mode)
        self.render_mode = render_mode
        self.cfg = model_config(config, preset, grid, num_uavs, max_steps, overrides)
        self.num_envs = num_envs
        # the World's own check would name its batch_size, and a memory_budget this class does not take
        check_memory(self.cfg, num_envs, DEFAULT_MEMORY_BUDGET, batch="num_envs", budget=None)
        self._worlds = NumpyWorlds(self.cfg, num_envs, device)
        self.single_observation_space = team_observation_space(self.cfg)
        self.single_action_space = spaces.MultiDiscrete([self.cfg.num_actions] * self.cfg.fleet_size)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._autoreset = np.zeros(num_envs, dtype=bool)  # the worlds whose episode ended with the last step
        self._mask = None

    @property
    def world(self) -> World:
        """The wrapped physics: world ``i`` is sub-environment ``i``."""
        return self._worlds.world

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Gymnasium's vector reset: batched ``(observations, infos)`` of new episodes in every world.

        ``seed`` (an int) seeds world ``i`` with ``seed + i``, and the episodes that follow; ``options`` must be None
        or empty (every reset starts all worlds).
        """
        if seed is not None and not isinstance(seed, int):
            raise InvalidType("seed", seed, "give one int (world i is seeded seed + i) or None")
        super().reset(seed=None if seed is None else check_seed(seed))
        check_no_options(options, "; every reset starts all worlds, so there is no reset_mask")
        self._autoreset[:] = False
        out = self._worlds.reset(seed)
        return out["observation"], self._infos(out)

    def step(self, actions):
        """Gymnasium's vector step: ``actions`` ``[num_envs, N]`` to batched ``(observations, rewards, terminations,
        truncations, infos)``; a world whose episode ended resets on its next step (next-step autoreset)."""
        B = self.num_envs
        ended = self._autoreset  # next-step autoreset: the actions of worlds whose episode ended are ignored
        if ended.all():  # episodes of one length that nothing terminates end together
            out = self._worlds.reset(None)
            reward, terminated, truncated = np.zeros(B), np.zeros(B, dtype=bool), np.zeros(B, dtype=bool)
        else:
            out, reward, truncated = self._worlds.step(
                check_actions(actions, (B, self.cfg.fleet_size), "actions", self.cfg.num_actions)
            )
            terminated = self._worlds.terminated()
            if ended.any():  # an energy model's episodes terminate apart: those worlds restart, the others step
                first = self._worlds.reset(None, np.flatnonzero(ended))
                for key, values in out.items():
                    values[ended] = first[key][ended]
                reward[ended], terminated[ended], truncated[ended] = 0.0, False, False
        self._autoreset = terminated | truncated
        return out["observation"], reward, terminated, truncated, self._infos(out)

    def _infos(self, out: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        self._mask = out["action_mask"]
        infos = {}
        for key in (*INFO_KEYS, "action_mask"):
            infos[key], infos[f"_{key}"] = out[key], np.ones(self.num_envs, dtype=bool)
        for key in ("r_pu", "r_se", "utility"):  # Python floats in the single env's info, float64 when batched
            infos[key] = infos[key].astype(np.float64)
        return infos

    def action_masks(self) -> np.ndarray:
        """``[B, 6 N]`` bool: per world, each UAV's action mask side by side."""
        if self._mask is None:
            raise RuntimeError("action_masks() before any reset: call reset() first")
        return self._mask.reshape(self.num_envs, -1).astype(bool)

    def render(self) -> tuple[np.ndarray, ...] | None:
        """Every world's ``[H, W, 3]`` uint8 frame, world ``i`` at ``i`` (``render_mode="rgb_array"``; about 15 ms of
        CPU a world); None without a mode."""
        frames = render_frames(self.world, self.render_mode, range(self.num_envs))
        return None if frames is None else tuple(frames)


class TeamActionPolicy(TensorDictModuleBase):
    """A function of the Gymnasium team observation as a TorchRL policy of :class:`~uavrl.envs.env.UAVSpectrumEnv`.

    ``act(observation, action_mask)`` gets, for the env's worlds, the team observations ``[*, N, F + 12]``
    float32 and action masks ``[*, N, A]`` int8 exactly as :class:`UAVSpectrumVectorEnv` returns them, and
    returns ``[*, N]`` integer actions.  :func:`uavrl.agents.evaluation.evaluate` then measures it as it measures every
    agent (the same starts and yardstick).

    Example (a Stable-Baselines3 model trained on :class:`UAVSpectrumGymEnv`)::

        policy = TeamActionPolicy(lambda obs, mask: model.predict(obs, deterministic=True)[0])
        metrics = uavrl.agents.evaluation.evaluate(policy, env.cfg)
    """

    in_keys = [("agents", "observation"), ("agents", "action_mask"), "state"]
    out_keys = [("agents", "action")]

    def __init__(self, act):
        super().__init__()
        if not callable(act):
            raise TypeError(f"act={act!r} is not callable: give a function (observation, action_mask) -> actions")
        self.act = act

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        observation = observation_with_nodes(td.get(("agents", "observation")), td.get("state"))
        mask = td.get(("agents", "action_mask"))
        actions = self.act(observation.numpy(force=True), mask.to(torch.int8).numpy(force=True))
        actions = check_actions(actions, tuple(mask.shape[:-1]), "the policy's actions", mask.shape[-1])
        td.set(("agents", "action"), torch.from_numpy(actions).to(mask.device))
        return td


if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        ENV_ID, entry_point=f"{__name__}:UAVSpectrumGymEnv", vector_entry_point=f"{__name__}:UAVSpectrumVectorEnv"
    )
