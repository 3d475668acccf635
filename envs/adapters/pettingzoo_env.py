"""The PettingZoo adapter of the model (``pip install -e ".[gym]"``): one world as a ``ParallelEnv``, one agent per UAV.

Agents ``uav_0 .. uav_{N-1}`` act at once, as in the model.  Each agent observes a dict, as PettingZoo's own
environments with action masks do: ``"observation"``, its row of the team observation of
:mod:`uavrl.envs.adapters.gym_env` (its observation followed by the four nodes' positions, ``[F + 12]`` float32), and
``"action_mask"`` ``[6]`` int8 (1 where the move stays on the grid).  Every agent receives the team reward;
every agent is truncated after ``max_steps`` (or, under an energy model, terminated when no UAV serves any more),
and then ``agents`` is empty until the next reset.  ``state()`` is the world's state ``[5 N + 12]``, ``[7 N + 12]``
under an energy model (``state_space``).  The infos hold the step's ``r_pu``, ``r_se``, ``utility``, ``moves``,
``task_switches`` (the team's, in every agent's info).

The physics is a :class:`~uavrl.envs.world.World` of one world: the same observations, masks, rewards and
seeds as :class:`~uavrl.envs.env.UAVSpectrumEnv` and :class:`~uavrl.envs.adapters.gym_env.UAVSpectrumGymEnv`
(``reset(seed=s)`` is the Gymnasium env's ``reset(seed=s)``; before the first seeded reset the world is seeded
0).  ``reset`` accepts PettingZoo's ``options`` and ignores them: the model defines none.  With
``render_mode="rgb_array"``, ``render()`` returns the world's ``[H, W, 3]`` uint8 frame, the picture
``UAVSpectrumEnv.render()`` draws (:mod:`uavrl.envs.render`).

Example:
    >>> env = UAVSpectrumParallelEnv(grid=(6, 6), num_uavs=2, max_steps=10)
    >>> observations, infos = env.reset(seed=0)
    >>> env.agents, observations["uav_0"]["observation"].shape, observations["uav_0"]["action_mask"].dtype
    (['uav_0', 'uav_1'], (28,), dtype('int8'))
    >>> actions = {agent: env.action_space(agent).sample(observations[agent]["action_mask"]) for agent in env.agents}
    >>> observations, rewards, terminations, truncations, infos = env.step(actions)
    >>> rewards["uav_0"] == rewards["uav_1"]
    True
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from ..config import ModelConfig
from ..errors import InvalidOption, InvalidType
from ..world import World, check_seed
from .gym_env import (
    RENDER_FPS,
    RENDER_MODES,
    NumpyWorlds,
    check_actions,
    check_render_mode,
    model_config,
    observation_bounds,
    render_frames,
    state_bounds,
    world_info,
)

__all__ = ["UAVSpectrumParallelEnv"]


class UAVSpectrumParallelEnv(ParallelEnv):
    """One world of the model as a PettingZoo ``ParallelEnv``: agent ``uav_i`` is UAV ``i``.

    Arguments as :class:`~uavrl.envs.adapters.gym_env.UAVSpectrumGymEnv`'s.

    Args:
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
        >>> env = UAVSpectrumParallelEnv(grid=(4, 4), num_uavs=2)
        >>> observations, infos = env.reset(seed=0)
        >>> sorted(observations)
        ['uav_0', 'uav_1']
        >>> actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        >>> observations, rewards, terminations, truncations, infos = env.step(actions)
        >>> rewards["uav_0"] == rewards["uav_1"]  # the team reward
        True
    """

    metadata = {
        "name": "uavrl_uav_spectrum_v0",
        "render_modes": RENDER_MODES,
        "render_fps": RENDER_FPS,
        "is_parallelizable": True,
    }

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
        self.possible_agents = [f"uav_{i}" for i in range(self.cfg.fleet_size)]
        self.agents: list[str] = []
        low, high = observation_bounds(self.cfg)
        # one space object per agent, so seeding one agent's space leaves the others' alone
        self.observation_spaces = {
            agent: spaces.Dict(
                {
                    "observation": spaces.Box(low[i], high[i], dtype=np.float32),
                    "action_mask": spaces.Box(0, 1, (self.cfg.num_actions,), dtype=np.int8),
                }
            )
            for i, agent in enumerate(self.possible_agents)
        }
        self.action_spaces = {agent: spaces.Discrete(self.cfg.num_actions) for agent in self.possible_agents}
        self.state_space = spaces.Box(*state_bounds(self.cfg), dtype=np.float32)
        self._state = None

    @property
    def world(self) -> World:
        """The wrapped physics."""
        return self._worlds.world

    def observation_space(self, agent: str) -> spaces.Dict:
        """The observation space of ``agent`` (a UAV's name): its observation and its action mask."""
        return self.observation_spaces[self._known(agent)]

    def action_space(self, agent: str) -> spaces.Discrete:
        """The action space of ``agent``: one of the model's actions (6, or 7 with recharging)."""
        return self.action_spaces[self._known(agent)]

    def _known(self, agent) -> str:
        if agent not in self.action_spaces:
            raise InvalidOption("agent", agent, f"the agents are {self.possible_agents}")
        return agent

    def reset(self, seed: int | None = None, options: dict | None = None):
        """PettingZoo's reset: ``(observations, infos)`` of every UAV, by name, for a new episode (``seed`` seeds it
        and those that follow; ``options`` is not read).

        ``options`` is read by no part of the model; unlike the Gymnasium adapters, which refuse any, it is accepted
        whatever it holds, as PettingZoo's ``parallel_api_test`` requires of a parallel env (it resets with
        ``options={"options": 1}``)."""
        out = self._worlds.reset(None if seed is None else check_seed(seed))
        self.agents = self.possible_agents[:]
        return self._observations(out), self._infos(out)

    def step(self, actions: dict):
        """PettingZoo's parallel step: ``actions``, an action for every live UAV by name, to ``(observations, rewards,
        terminations, truncations, infos)``; every UAV gets the team reward."""
        if not self.agents:
            raise RuntimeError("step() with no live agents: call reset() first (the episode ended or never began)")
        if not isinstance(actions, dict):
            message = f"actions is a {type(actions).__name__}: give a dict of one action per live agent, by name"
            raise InvalidType("actions", message=message)
        unknown = sorted(set(actions) - set(self.agents), key=str)
        if unknown:
            raise InvalidOption("actions", message=f"actions names {unknown[0]!r}: the agents are {self.agents}")
        missing = [agent for agent in self.agents if agent not in actions]
        if missing:
            message = f"actions has no action for {missing[0]!r}: every live agent acts each step"
            raise InvalidOption("actions", message=message)
        joint = check_actions(
            [actions[agent] for agent in self.possible_agents], (self.cfg.fleet_size,), "actions", self.cfg.num_actions
        )
        out, reward, truncated = self._worlds.step(joint[None])
        observations, infos = self._observations(out), self._infos(out)
        rewards = dict.fromkeys(self.agents, reward[0].item())
        terminated = bool(self._worlds.terminated()[0])
        terminations = dict.fromkeys(self.agents, terminated)
        truncations = dict.fromkeys(self.agents, bool(truncated[0]))
        if truncated[0] or terminated:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def render(self) -> np.ndarray | None:
        """The world now as an ``[H, W, 3]`` uint8 frame (``render_mode="rgb_array"``); None without a mode."""
        frames = render_frames(self.world, self.render_mode, range(1))
        return None if frames is None else frames[0]

    def state(self) -> np.ndarray:
        """The global state (the team's configuration and the nodes), as :class:`~uavrl.envs.UAVSpectrumEnv`'s."""
        if self._state is None:
            raise RuntimeError("state() before any reset: call reset() first")
        return self._state.copy()

    def _observations(self, out: dict[str, np.ndarray]) -> dict[str, dict[str, np.ndarray]]:
        self._state = out["state"][0]
        return {
            agent: {"observation": out["observation"][0, i], "action_mask": out["action_mask"][0, i]}
            for i, agent in enumerate(self.possible_agents)
        }

    def _infos(self, out: dict[str, np.ndarray]) -> dict[str, dict]:
        team = world_info(out, 0)
        del team["action_mask"]  # in each agent's observation
        return {agent: dict(team) for agent in self.possible_agents}
