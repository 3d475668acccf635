"""The environments a trained policy may act in: those of its run's grid, number of UAVs, layout, altitude levels,
city and observations (central, or local with its messages; any communication radius).

A table or network learned on a 6x6 grid reads the positions and observations
of a 5x5 grid without any error (same shapes), and acts on a model it never
saw.  So the policies of a run (``uavrl.load_policy``, ``Agent.policies``)
check what they act in, at no per-step cost beyond a shape comparison:

- ``bind_env(env)`` compares the environment's grid, number of UAVs, layout,
  altitude levels (``altitudes_m``), city and observations (``observation``, ``message_size``) with the run's (the
  evaluation binds every policy it measures);
- every tensordict: its number of UAVs;
- the first tensordicts of each batch shape, until one has a UAV off the
  first column and one off the first row (at most :data:`FULL_CHECKS`): its
  positions lie on the run's grid, the observed (x, y) are those positions
  scaled to the run's grid, the moves that leave the grid are the run's (blocked, among others, where
  buildings stand in the way of UAVs at altitude levels), and
  for a fixed layout the nodes in ``state`` are the run's.

A mismatch is a ValueError in one line.  :class:`RunEnvironment` holds plain
numbers and small CPU tensors, so a policy that carries one stays picklable.

Example:
    >>> from uavrl.envs import UAVSpectrumEnv, make_config
    >>> run = RunEnvironment(make_config("paper", grid=(6, 6)))
    >>> run.check(UAVSpectrumEnv(batch_size=2, grid=(6, 6)).reset())
    >>> try:
    ...     run.check(UAVSpectrumEnv(batch_size=3, grid=(5, 5)).reset())
    ... except ValueError as err:
    ...     print(str(err).split("; ")[1].split(": ")[0])
    the tensordict's observed positions are scaled for another grid
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from uavrl.envs import config
from uavrl.envs.config import InvalidOption, ModelConfig
from uavrl.envs.limits import NODE_FEATURES, OWN_FEATURES, model_observation_size
from uavrl.envs.physics.channel import fixed_layout
from uavrl.envs.physics.grid import on_grid

ADVICE = (
    "act in an environment of the run's env_config (UAVSpectrumEnv(config=env_config), env_config from "
    "uavrl.load_policy)"
)
FULL_CHECKS = (
    8  # tensordicts of one batch shape checked in full at most, while all UAVs stay in the first row or column
)


CITY_OPTIONS = ("city", *config.CITY_OPTIONS)  # what places the buildings and decides line of sight


class RunEnvironment:
    """The grid, number of UAVs, layout, altitude levels and city of a run, and the checks that an environment or
    tensordict has them."""

    def __init__(self, cfg: ModelConfig):
        self.grid, self.num_uavs, self.layout = tuple(cfg.grid), int(cfg.fleet_size), cfg.layout  # spares act too
        self.altitudes_m, self.city = cfg.altitudes_m, _city(cfg)
        L1, L2 = self.grid
        self.xy_scale = torch.tensor([max(L1 - 1, 1), max(L2 - 1, 1)], dtype=torch.float64)
        self.layout_nodes = fixed_layout(cfg)  # [4, 3], None for layout="random"
        scale = torch.tensor([L1, L2, cfg.height], dtype=torch.float64)
        # as the env's state holds them
        self.nodes = None if self.layout_nodes is None else (self.layout_nodes / scale).flatten().float()
        # under an energy model a UAV out of service is shown at the base, off the grid, and every observation ends
        # with the UAVs' batteries and service flags
        self.base = None if cfg.energy == "none" else torch.tensor(cfg.base)
        self.observation_size = model_observation_size(cfg)
        # what a UAV observes: central, or local with messages of that size (any radius: the same features)
        self.observation = (cfg.observation, cfg.message_size)
        self._checked_shape = None  # the batch shape whose tensordicts were checked in full
        self._pending = (None, 0)  # a batch shape being checked in full, and how many of its tensordicts were

    def __str__(self) -> str:
        shown = f"a {self.grid[0]}x{self.grid[1]} grid, {self.num_uavs} UAVs, layout {self.layout!r}"
        return shown + "".join(_extras(self.altitudes_m, self.city)) + _observed(*self.observation)

    def _refuse(self, what: str) -> ValueError:
        return InvalidOption("env", message=f"this policy acts in its run's environment ({self}); {what}: {ADVICE}")

    def check_env(self, env) -> None:
        """A one-line ValueError unless ``env`` (or every worker of a ``SerialEnv``/``ParallelEnv``) has the run's
        grid, number of UAVs, layout, altitude levels and city; ``None`` (no environment) leaves every tensordict to its
        own check."""
        if env is None:
            self._checked_shape = None
            return
        if getattr(env, "is_closed", False) and hasattr(env, "start"):  # a batched env not started has no workers
            env.start()
        configs = env.model_config()
        for cfg in configs if isinstance(configs, list) else [configs]:
            self._check_config(cfg)
        self._checked_shape = tuple(env.batch_size)

    def _check_config(self, cfg: ModelConfig) -> None:
        differ = []
        if tuple(cfg.grid) != self.grid:
            differ.append(f"a {cfg.grid[0]}x{cfg.grid[1]} grid")
        if cfg.fleet_size != self.num_uavs:
            differ.append(f"{cfg.fleet_size} UAVs")
        nodes = fixed_layout(cfg)
        if cfg.layout != self.layout:
            differ.append(f"layout {cfg.layout!r}")
        elif nodes is not None and tuple(cfg.grid) == self.grid and not torch.equal(nodes, self.layout_nodes):
            differ.append(f"layout {cfg.layout!r} with its nodes elsewhere (another altitude)")
        if cfg.altitudes_m != self.altitudes_m or _city(cfg) != self.city:
            differ.append("".join(_extras(cfg.altitudes_m, _city(cfg))).removeprefix(", ") or "one altitude, no city")
        if (cfg.observation, cfg.message_size) != self.observation:
            differ.append(_observed(cfg.observation, cfg.message_size).removeprefix(", ") or "central observations")
        if differ:
            raise self._refuse(f"the environment has {', '.join(differ)}")

    def check(self, td: TensorDictBase) -> None:
        """A one-line ValueError unless ``td`` comes from an environment of the run (module doc: what is checked)."""
        positions = td.get("positions")
        if positions.shape[-2:] != (self.num_uavs, 2):
            shape = f"[..., {self.num_uavs}, 2]"
            raise self._refuse(f"the tensordict holds positions of shape {list(positions.shape)}, not {shape}")
        shape = positions.shape[:-2]
        if shape == self._checked_shape:
            return
        told_apart = self._check_content(td, positions.cpu())
        calls = self._pending[1] + 1 if self._pending[0] == shape else 1
        if told_apart or calls >= FULL_CHECKS:
            self._checked_shape = shape
        self._pending = (shape, calls)

    def _check_content(self, td: TensorDictBase, positions: torch.Tensor) -> bool:
        """Checks ``td`` (module doc); whether its positions tell the run's grid from others of the same cells in the
        first row and column (a UAV off each, where the grid has more than one)."""
        L1, L2 = self.grid
        x, y = positions[..., 0], positions[..., 1]
        serving = on_grid(positions, self.grid)
        at_base = torch.zeros_like(serving) if self.base is None else (positions == self.base).all(-1)
        if not bool((serving | at_base).all()):
            raise self._refuse(
                "the tensordict's positions leave that grid" + ("" if self.base is None else " and base")
            )
        observation = td.get(("agents", "observation"), None)
        if observation is not None:
            observation = observation.cpu()
            if observation.shape[-1] != self.observation_size:
                raise self._refuse(
                    f"its observations have {observation.shape[-1]} features, not {self.observation_size}"
                )
            expected = (positions.double() / self.xy_scale).to(observation.dtype)
            if not torch.allclose(observation[..., :2], expected, atol=1e-5):
                raise self._refuse("the tensordict's observed positions are scaled for another grid")
            leaves = observation[..., 5:OWN_FEATURES:2] == -1.0  # per neighbour: -1 where the move leaves the grid
            # the moves up, down, left, right that leave the grid, from the positions (no per-cell table)
            edges = torch.stack([y == 0, y == L2 - 1, x == 0, x == L1 - 1], -1)
            blocked = self.city is not None and self.altitudes_m is not None  # buildings block moves too
            if not torch.equal(edges[serving] & leaves[serving] if blocked else leaves[serving], edges[serving]):
                raise self._refuse("the tensordict's observations mark the grid's edges elsewhere")
        state = td.get("state", None)
        if state is not None and self.nodes is not None:
            nodes = state[..., -NODE_FEATURES:].cpu()
            if not torch.allclose(nodes, self.nodes.expand_as(nodes), atol=1e-5):
                raise self._refuse("the nodes in the tensordict's state are those of another layout")
        return bool((L1 == 1 or (x > 0).any()) and (L2 == 1 or (y > 0).any()))


def _city(cfg: ModelConfig) -> tuple | None:
    """The options that place a model's buildings, None without a city."""
    return None if cfg.city == "none" else tuple(getattr(cfg, name) for name in CITY_OPTIONS)


def _observed(observation: str, message_size: int) -> str:
    """How a run's observations are named where they are not central: ``, local observations (messages of 2)``."""
    if observation == "central":
        return ""
    return ", local observations" + (f" (messages of {message_size})" if message_size else "")


def _extras(altitudes_m, city) -> list[str]:
    """How a run's altitude levels and city are named: ``, altitudes_m=[30, 100]``, ``, city 'urban' (city_seed=0,
    los=geometric)``."""
    shown = [f", altitudes_m=[{', '.join(f'{h:g}' for h in altitudes_m)}]"] if altitudes_m else []
    if city is not None:
        options = ", ".join(f"{k}={v}" for k, v in zip(CITY_OPTIONS[1:], city[1:], strict=True) if v is not None)
        shown.append(f", city {city[0]!r} ({options})")
    return shown


class CheckedPolicy(TensorDictModuleBase):
    """A TorchRL policy that acts only in environments of its run (:class:`RunEnvironment`)."""

    def __init__(self, policy: TensorDictModuleBase, cfg: ModelConfig):
        super().__init__()
        self.policy, self.run_env = policy, RunEnvironment(cfg)
        self.in_keys, self.out_keys = list(policy.in_keys), list(policy.out_keys)

    def bind_env(self, env) -> CheckedPolicy:
        """Act in ``env``: a one-line ValueError unless it has the run's model (:class:`RunEnvironment`); the
        policy's own random draws (a module's ``restart()``: the local DQN's coins) start again, so an evaluation
        plays the same whatever the policy played before, and a module that reads the environment is bound to it
        (``bind(env)``: whether the local DQN's team is common knowledge there)."""
        self.run_env.check_env(env)
        for module in self.policy.modules():
            if hasattr(module, "restart"):
                module.restart()
            if hasattr(module, "bind"):  # what a module reads of the environment (the local DQN's common knowledge)
                module.bind(env)
        return self

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        self.run_env.check(td)
        return self.policy(td)
