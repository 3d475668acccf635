"""The physics of the UAV spectrum-sharing model for ``B`` worlds at once, with no TorchRL.

:class:`World` composes the model's parts (docs/architecture.md, The World's parts), VMAS's scenario hooks written
for this model, and holds what they share: every world's layout and the tables computed from it, the UAVs' state and
the per-world random streams.  The parts are

- ``layouts`` (:mod:`uavrl.envs.physics.layouts`): where the four nodes are, fixed or drawn at each reset;
- the channel and the rate model (:mod:`uavrl.envs.physics.channel`): the mean gain of every link and the AF rates,
  turned into per-cell and per-code tables once per layout;
- ``fading`` (:mod:`uavrl.envs.physics.fading`): the links' random power gains drawn each step, and whether the
  channel is random;
- ``dynamics`` (:mod:`uavrl.envs.physics.dynamics`): the per-UAV state variables, their start, their step, the masks,
  termination;
- ``reward`` (:class:`uavrl.envs.physics.rewards.TeamReward`): ``env.reward`` from the rates;
- ``energy`` (:mod:`uavrl.envs.physics.energy`, under ``env.energy`` other than ``none``): the batteries, who serves,
  termination.
- ``city`` (:mod:`uavrl.envs.physics.buildings`, under ``env.city`` other than ``none``): the ITU-R P.1410 city the
  channel decides line of sight in, the roofs PT and PR stand on, where S and E may fly.

A step is their pipeline: dynamics, rates, reward, termination, observation.  :meth:`World.reset` and
:meth:`World.step` return plain tensors (observations, masks, rates, rewards);
:class:`~uavrl.envs.env.UAVSpectrumEnv` is the thin TorchRL ``EnvBase`` on top (specs, keys, seeding); the tabular
learner and the tabular evaluation use a ``World`` directly, so they never import TorchRL.

A step is a fixed handful of tensor operations whatever ``B`` is, on CPU or CUDA.  A UAV's cell and task index the
per-code tables as one code ``2 cell + task``, so rates and observations are lookups in small tables built once per
layout (see BENCHMARKS.md for timings).

The package's modules, one responsibility each (every name is importable from here):

- :mod:`.checks`: the one-line refusals of a device, a seed, a number of worlds, a memory budget;
- :mod:`.tables`: the grid's and each layout's tables, and the cache the Worlds of one model share them in;
- :mod:`.observations`: each UAV's observation and each world's state, assembled from those tables;
- :mod:`.queries`: the solvers' and evaluations' questions (rates of any configuration, ``U*``, valid joint actions);
- :mod:`.core`: :class:`World`, its parts and state, and the pipeline of a reset and a step.

Example:
    >>> import torch
    >>> from uavrl.envs import make_config
    >>> world = World(make_config("paper", grid=(6, 6), num_uavs=2, max_steps=10), batch_size=4)
    >>> first = world.reset()
    >>> out, reward, truncated = world.step(torch.full((4, 2), 5))
    >>> out["utility"].shape, reward.shape, first["observation"].shape, world.terminated.tolist()
    (torch.Size([4]), torch.Size([4]), torch.Size([4, 2, 16]), [False, False, False, False])
"""

from .checks import SEED_LIMIT, check_batch_size, check_memory, check_seed, resolve_device
from .core import World, WorldsState
from .observations import DIAGNOSTICS, NODE_FEATURES, Observations, observation_with_nodes
from .queries import SolverQueries
from .tables import LayoutTables

__all__ = [
    "DIAGNOSTICS",
    "NODE_FEATURES",
    "SEED_LIMIT",
    "LayoutTables",
    "Observations",
    "SolverQueries",
    "World",
    "WorldsState",
    "check_batch_size",
    "check_memory",
    "check_seed",
    "observation_with_nodes",
    "resolve_device",
]
