"""Baselines every agent is reported beside: the uniform random policy and an oracle planner.

Both are TorchRL policies (read the environment's keys, write
``("agents", "action")``) and both are agents of the registry with nothing to
train (``python -m uavrl.train agent=random`` or ``agent=oracle`` evaluates
them and saves a run directory like any agent's, so ``load_policy`` and the
reports treat them alike).

The **oracle** knows the model.  Each step it lists every optimal
configuration of each world (:func:`uavrl.envs.solvers.bounds.optimal_configurations`),
assigns the UAVs to the (position, task) pairs of one of them by the bottleneck
assignment (:func:`uavrl.envs.solvers.bounds.best_assignment`: the fewest steps for
the slowest UAV, then the fewest UAVs on long paths) and moves every UAV one
step along it: the UAV with the most steps left chooses first, a task change
comes first, then a move that shortens its path along the axis (x, y, or the
altitude level) with the most left, then the others, else it stays.  Steps are
counted along the model's positions (:class:`PathLengths`: around buildings in a
city).  A move is taken only into a position that no UAV still to choose holds
and no UAV that chose targets, so every joint action is valid (no cancelled
move, no collision).

Example:
    >>> from uavrl.envs import UAVSpectrumEnv
    >>> env = UAVSpectrumEnv(batch_size=4, grid=(6, 6), num_uavs=3, max_steps=12)
    >>> td = env.rollout(12, OraclePolicy(env.cfg))
    >>> u_star = env.optimum()[0]
    >>> bool(((td["next", "utility"][:, -1, 0].double() - u_star).abs() <= 1e-6 * u_star).all())
    True
"""

from __future__ import annotations

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from uavrl.agents.base import Agent
from uavrl.agents.env_check import CheckedPolicy, RunEnvironment
from uavrl.agents.generators import PolicyGenerator
from uavrl.agents.schema import AGENTS
from uavrl.envs import ModelConfig
from uavrl.envs.config import CLIMB, DESCEND
from uavrl.envs.physics.channel import direct_terms, link_gains, relay_contributions
from uavrl.envs.physics.grid import cells_or_away
from uavrl.envs.physics.positions import Positions, model_positions
from uavrl.envs.solvers.bounds import (
    assignment_costs,
    best_assignment,
    grid_coordinates,
    moves_apart,
    optimal_configurations,
)
from uavrl.envs.solvers.exact import fixed_layout_tables
from uavrl.envs.solvers.optimum import optimum

UP, DOWN, LEFT, RIGHT, SENSE = range(5)
MOVES = (UP, DOWN, LEFT, RIGHT, CLIMB, DESCEND)  # the action of each column of Positions.neighbours
AXIS = {UP: 1, DOWN: 1, LEFT: 0, RIGHT: 0, CLIMB: 2, DESCEND: 2}  # the coordinate (x, y, level) each move changes


class PathLengths:
    """The fewest moves between a model's positions: called on position indices ``here`` and ``there`` (broadcast),
    or :meth:`between` two of them.

    Where no position is inside a building the positions form a box and the fewest moves are
    :func:`~uavrl.envs.solvers.bounds.moves_apart` (``|dx| + |dy| + |dlevel|``); in a city with blocked positions, a
    breadth-first search over the positions' moves to each ``there`` (kept: the graph is the model's), and
    ``len(positions)`` (more than any path) where no path leads.

    Example:
        >>> from uavrl.envs import make_config
        >>> lengths = PathLengths(model_positions(make_config("paper", grid=(3, 3), num_uavs=2)))
        >>> lengths(torch.tensor([0, 4]), torch.tensor(8)).tolist(), lengths.between(2, 6)
        ([4, 2], 4)
    """

    def __init__(self, positions: Positions):
        self.positions = positions
        self.coordinates = grid_coordinates(positions).tolist()
        self.graph = None
        if len(positions) < len(positions.number):  # some positions blocked: paths go around them
            from scipy.sparse import csr_matrix  # scipy (~0.7 s to import) only in a city

            rows, columns = (positions.neighbours >= 0).nonzero(as_tuple=True)
            moves = (np.ones(len(rows)), (rows.cpu().numpy(), positions.neighbours[rows, columns].cpu().numpy()))
            self.graph = csr_matrix(moves, shape=(len(positions), len(positions)))
        self._to: dict[int, np.ndarray] = {}  # there -> [P] the fewest moves from every position to it

    def __call__(self, here: torch.Tensor, there: torch.Tensor) -> torch.Tensor:
        if self.graph is None:
            return moves_apart(self.positions, here, there)
        here, there = torch.broadcast_tensors(here, there)
        out = torch.empty_like(here)
        for t in there.unique().tolist():
            at = there == t
            out[at] = torch.from_numpy(self._lengths_to(t))[here[at]]
        return out

    def between(self, here: int, there: int) -> int:
        """The fewest moves from position ``here`` to position ``there``."""
        if self.graph is None:
            return sum(abs(a - b) for a, b in zip(self.coordinates[here], self.coordinates[there], strict=True))
        return int(self._lengths_to(there)[here])

    def _lengths_to(self, there: int) -> np.ndarray:
        if there not in self._to:
            from scipy.sparse.csgraph import shortest_path

            # every move has its reverse (a building blocks both ways): the lengths to ``there`` are those from it
            lengths = shortest_path(self.graph, unweighted=True, indices=there)
            self._to[there] = np.where(np.isinf(lengths), len(self.positions), lengths).astype(np.int64)
        return self._to[there]


class RandomPolicy(TensorDictModuleBase):
    """Uniform random per-UAV actions among those the ``action_mask`` allows, from its own seeded generator.

    It acts in any environment; ``RandomAgent.policies`` wraps it in a
    :class:`~uavrl.agents.env_check.CheckedPolicy`, as every policy of a run.

    Args:
        seed: seeds its generator.

    Example:
        >>> from uavrl.envs import UAVSpectrumEnv
        >>> env = UAVSpectrumEnv(batch_size=2, grid=(3, 3), num_uavs=2)
        >>> env.rollout(5, RandomPolicy(seed=0))["agents", "action"].shape
        torch.Size([2, 5, 2])
    """

    in_keys = [("agents", "action_mask")]
    out_keys = [("agents", "action")]

    def __init__(self, seed: int = 0):
        super().__init__()
        self.generator = PolicyGenerator(seed)

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        mask = td.get(("agents", "action_mask"))
        scores = torch.rand(mask.shape, generator=self.generator).to(mask.device).masked_fill(~mask, -1.0)
        td.set(("agents", "action"), scores.argmax(-1))
        return td


class OraclePolicy(TensorDictModuleBase):
    """Drives each world's team to an optimal configuration along a valid, collision-free plan (module doc).

    Fixed layouts need only ``cfg``.  With ``layout="random"`` the oracle reads
    each world's layout from the tensordict it gets: the node positions
    ``nodes`` that :class:`~uavrl.envs.UAVSpectrumEnv` publishes for random
    layouts, from which it computes the world's tables as the environment does
    (:mod:`uavrl.envs.physics.channel`).  So it needs no environment and acts alike in
    a plain env, a ``SerialEnv``, a ``ParallelEnv`` and a collector's workers,
    and a pickled copy too.  Leading batch dimensions are planned world by
    world, as one batch.  It acts only in environments of ``cfg``'s grid,
    number of UAVs and layout (:mod:`uavrl.agents.env_check`): ``env=`` or
    ``bind_env`` checks one up front.
    """

    out_keys = [("agents", "action")]

    def __init__(self, cfg: ModelConfig, env=None):
        super().__init__()
        self.cfg, self.run_env = cfg, RunEnvironment(cfg)
        self.in_keys = ["positions", "tasks"] + (["levels"] if cfg.num_levels > 1 else [])
        self.in_keys += ["nodes"] if cfg.layout == "random" else []
        self.bind_env(env)
        self.positions = model_positions(cfg)
        self.neighbours = self.positions.neighbours.tolist()
        self.path_lengths = PathLengths(self.positions)
        self._targets: dict[int, tuple] = {}  # world -> (its nodes, contributions, direct, optimal cells, tasks)
        self._fixed = None if cfg.layout == "random" else fixed_layout_tables(cfg)

    def bind_env(self, env) -> OraclePolicy:
        """Check that ``env`` (None: nothing to check) has ``cfg``'s grid, number of UAVs and layout, else a one-line
        ValueError; the evaluation calls this.  The oracle keeps no reference to it."""
        self.run_env.check_env(env)
        return self

    def _nodes(self, td: TensorDictBase) -> torch.Tensor | None:
        """Every world's ``[W, 4, 3]`` node positions for a random layout, None for a fixed one."""
        if self._fixed is not None:
            return None
        nodes = td.get("nodes", None)
        if nodes is None:
            raise ValueError(
                "OraclePolicy with layout='random' reads each world's layout from the key 'nodes' [..., 4, 3] that "
                "UAVSpectrumEnv(layout='random') writes: this tensordict has none (keep 'nodes' through transforms)"
            )
        return nodes.reshape(-1, 4, 3)

    def _world_tables(self, world: int, nodes) -> tuple[torch.Tensor, ...]:
        """One world's ``(contributions [P, 2], direct [2], optimal positions, optimal tasks)``, kept per layout."""
        if nodes is None:
            cached = self._targets.get(0)
            if cached is None:
                contributions, direct = self._fixed[0][0], self._fixed[1][0]
                optimal = self._optimal_configurations(contributions, direct)
                cached = self._targets[0] = (None, contributions, direct, *optimal)
            return cached[1:]
        at = nodes[world]
        cached = self._targets.get(world)
        if cached is None or not torch.equal(cached[0], at):
            # the World's own functions on the same float64 nodes (World._set_layout): the same tables, bit for bit
            xyz = self.positions.xyz.to(at.device)
            contributions = relay_contributions(link_gains(xyz, at[None], self.cfg), self.cfg)[0]
            direct = direct_terms(at[None], self.cfg)[0]
            optimal = self._optimal_configurations(contributions, direct)
            cached = self._targets[world] = (at.clone(), contributions, direct, *optimal)
        return cached[1:]

    def _optimal_sets(self, world: int, nodes) -> tuple[torch.Tensor, torch.Tensor]:
        return self._world_tables(world, nodes)[2:]

    def _optimal_configurations(self, contributions: torch.Tensor, direct: torch.Tensor):
        """Every optimal configuration ``(positions, tasks)`` of one world's tables ``[P, 2]``, ``[2]``."""
        u_star = float(optimum(contributions[None], direct[None], self.cfg)[0][0])
        return optimal_configurations(contributions, direct, self.cfg, u_star)

    def _serving(self, td: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(positions, serving, tasks)`` ``[W, N]`` of the UAVs of ``td``'s worlds (on the CPU): each UAV's position
        index (its cell with one level; past the model's positions out of service), whether it serves, its task."""
        fleet = self.cfg.fleet_size
        cells = cells_or_away(td.get("positions").cpu(), self.cfg.grid).reshape(-1, fleet)  # L1 L2: out of service
        serving, tasks = cells < self.cfg.num_cells, td.get("tasks").cpu().reshape(-1, fleet)
        if self.cfg.num_levels > 1:  # the position of (cell, level)
            levels = td.get("levels").cpu().reshape(-1, fleet)
            number = self.positions.number[cells.clamp(max=self.cfg.num_cells - 1) + self.cfg.num_cells * levels]
            cells = torch.where(serving, number, len(self.positions))
        return cells, serving, tasks

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        self.run_env.check(td)
        positions, tasks = td.get("positions"), td.get("tasks")
        cells, serving, tasks_of = self._serving(td)
        nodes = self._nodes(td)
        # a UAV out of service has only the no-op; the oracle plans for those in service and never sends one home
        actions = torch.full(cells.shape, SENSE, dtype=torch.long)
        for w in range(len(cells)):
            uavs = serving[w].nonzero().squeeze(-1)
            if len(uavs) == len(cells[w]):
                actions[w] = self._plan(w, cells[w], tasks_of[w], nodes)
            elif len(uavs):
                actions[w, uavs] = self._plan(w, cells[w, uavs], tasks_of[w, uavs], nodes)
        td.set(("agents", "action"), actions.view(tasks.shape).to(positions.device))
        return td

    def _plan(self, world: int, cells: torch.Tensor, tasks: torch.Tensor, nodes) -> torch.Tensor:
        """One valid joint action ``[n]`` of the ``n <= N`` UAVs of one world in service (an assignment of them to
        pairs of an optimal configuration)."""
        target_cells, target_tasks = self._optimal_sets(world, nodes)
        costs = assignment_costs(cells, tasks, target_cells, target_tasks, self.positions, self.path_lengths)
        _, s, pair = best_assignment(costs)
        goal = list(zip(target_cells[s][pair].tolist(), target_tasks[s][pair].tolist(), strict=True))
        cells, tasks = cells.tolist(), tasks.tolist()
        lengths, where = self.path_lengths.between, self.path_lengths.coordinates

        def steps_to(i: int, cell_task: tuple[int, int]) -> int:
            return lengths(cells[i], cell_task[0]) + (cell_task[1] != tasks[i])

        def preferences(i: int) -> list[int]:
            """A task change first, then moves that shorten the path (along the axis with the most left first), then
            staying."""
            here, (there, task) = cells[i], goal[i]
            left = lengths(here, there)
            moves = [
                (abs(where[there][AXIS[move]] - where[here][AXIS[move]]), move)
                for move, reached in zip(MOVES, self.neighbours[here], strict=False)  # 4 moves without levels
                if reached >= 0 and lengths(reached, there) < left
            ]
            change = [SENSE + task] if task != tasks[i] else []
            return change + [move for _, move in sorted(moves, reverse=True)] + [SENSE + tasks[i]]

        def target(i: int, action: int) -> int:
            return self.neighbours[cells[i]][MOVES.index(action)] if action in MOVES else cells[i]

        holder = {cell: i for i, cell in enumerate(cells)}
        waiting, claimed, actions = set(cells), set(), [0] * len(cells)
        for i in sorted(range(len(cells)), key=lambda i: -steps_to(i, goal[i])):
            waiting.discard(cells[i])
            options = preferences(i)
            if all(target(i, a) in waiting for a in options[:-1] if a in MOVES) and any(a in MOVES for a in options):
                # every shortening move runs into a UAV still to choose: hand it this UAV's goal and take its
                # place (it lies on this UAV's path), when that makes neither of the two slower
                j = holder[target(i, next(a for a in options if a in MOVES))]
                if max(steps_to(i, goal[j]), steps_to(j, goal[i])) <= max(steps_to(i, goal[i]), steps_to(j, goal[j])):
                    goal[i], goal[j] = goal[j], goal[i]
                    options = preferences(i)
            actions[i] = next(
                a
                for a in options
                if a not in MOVES and target(i, a) == cells[i] or target(i, a) not in waiting | claimed
            )
            claimed.add(target(i, actions[i]))
        return torch.tensor(actions)


class BaselineAgent(Agent):
    """An agent with nothing to learn (contract: :class:`~uavrl.agents.base.Agent`): no iteration, no checkpoint.

    Args:
        env_cfg: the run's :class:`~uavrl.envs.ModelConfig`, the environments its policy acts in.
        cfg: the full Hydra config (a baseline's settings, ``agent.memory_budget``, are the evaluation's), or
            ``None``.
        device: unused: a baseline's policy acts on the device of the tensordict it gets.
        seed: seeds the random baseline's generator.
    """

    num_iterations = 0
    env_steps = 0
    name: str  # its name in uavrl.agents.AGENTS

    def __init__(self, env_cfg: ModelConfig, cfg, device, seed: int):
        if cfg is not None and cfg.get("agent") is not None:
            AGENTS[self.name].validate(env_cfg, cfg.agent)
        self.env_cfg, self.seed = env_cfg, int(seed)

    def train_iteration(self) -> dict[str, float]:
        raise RuntimeError(f"{type(self).__name__} has nothing to train")

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, state: dict):
        pass


class RandomAgent(BaselineAgent):
    """``agent=random``: the uniform random policy over allowed per-UAV actions, seeded by ``seed``."""

    name = "random"

    def policies(self) -> list[CheckedPolicy]:
        return [CheckedPolicy(RandomPolicy(self.seed), self.env_cfg)]


class OracleAgent(BaselineAgent):
    """``agent=oracle``: the oracle planner (module doc)."""

    name = "oracle"

    def policies(self) -> list[OraclePolicy]:
        return [OraclePolicy(self.env_cfg)]
