"""Baselines every agent is reported beside: the uniform random policy and an oracle planner.

Both are TorchRL policies (read the environment's keys, write
``("agents", "action")``) and both are agents of the registry with nothing to
train (``python -m uavrl.train agent=random`` or ``agent=oracle`` evaluates
them and saves a run directory like any agent's, so ``load_policy`` and the
reports treat them alike).

The **oracle** knows the model.  Each step it lists every optimal
configuration of each world (:func:`uavrl.envs.bounds.optimal_configurations`),
assigns the UAVs to the (cell, task) pairs of one of them by the bottleneck
assignment (:func:`uavrl.envs.bounds.best_assignment`: the fewest steps for
the slowest UAV, then the fewest UAVs on long paths) and moves every UAV one
step along it: the UAV with the most steps left chooses first, a task change
comes first, then a move that shortens its path along the longer axis, then
the other axis, else it stays.  A move is taken only into a cell that no UAV
still to choose holds and no UAV that chose targets, so every joint action is
valid (no cancelled move, no collision).

Example:
    >>> from uavrl.envs import UAVSpectrumEnv
    >>> env = UAVSpectrumEnv(batch_size=4, grid=(6, 6), num_uavs=3, max_steps=12)
    >>> td = env.rollout(12, OraclePolicy(env.cfg))
    >>> u_star = env.optimum()[0]
    >>> bool(((td["next", "utility"][:, -1, 0].double() - u_star).abs() <= 1e-6 * u_star).all())
    True
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from uavrl.agents.base import Agent
from uavrl.agents.env_check import CheckedPolicy, RunEnvironment
from uavrl.agents.generators import PolicyGenerator
from uavrl.envs import ModelConfig
from uavrl.envs.bounds import assignment_costs, best_assignment, optimal_configurations
from uavrl.envs.exact import fixed_layout_tables
from uavrl.envs.grid import cells_of, grid_neighbours
from uavrl.envs.optimum import optimum

UP, DOWN, LEFT, RIGHT, SENSE = range(5)


class RandomPolicy(TensorDictModuleBase):
    """Uniform random per-UAV actions among those the ``action_mask`` allows, from its own seeded generator.

    It acts in any environment; ``RandomAgent.policies`` wraps it in a
    :class:`~uavrl.agents.env_check.CheckedPolicy`, as every policy of a run.
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
    each world's layout from the environment it acts in: give ``env=`` (or
    call ``bind_env``) before the rollout; a ``SerialEnv`` or ``ParallelEnv``
    of :class:`~uavrl.envs.UAVSpectrumEnv` works too (its workers' worlds in
    order).  Leading batch dimensions are planned world by world, as one batch.
    The bound env stays in its process: a pickled copy carries none.  It acts
    only in environments of ``cfg``'s grid, number of UAVs and layout
    (:mod:`uavrl.agents.env_check`).
    """

    in_keys = ["positions", "tasks"]
    out_keys = [("agents", "action")]

    def __init__(self, cfg: ModelConfig, env=None):
        super().__init__()
        self.cfg, self.run_env = cfg, RunEnvironment(cfg)
        self.bind_env(env)
        self.neighbours = grid_neighbours(cfg.grid).tolist()
        self._targets: dict[int, tuple] = {}  # world -> (its contributions, optimal cells, optimal tasks)
        self._fixed = None if cfg.layout == "random" else fixed_layout_tables(cfg)

    def bind_env(self, env) -> OraclePolicy:
        """Act in ``env`` (the evaluation calls this; with ``layout="random"`` the layouts come from it); a one-line
        ValueError unless it has ``cfg``'s grid, number of UAVs and layout."""
        if env is not None:
            self.run_env.check_env(env)
        # kept out of the nn.Module's registry: an env is no part of the policy's parameters or state
        self.__dict__["env"] = env
        return self

    def __getstate__(self):
        state = super().__getstate__()
        state["env"] = None  # an env (a ParallelEnv's workers) belongs to its process
        return state

    def _layouts(self) -> tuple[torch.Tensor, torch.Tensor] | None:
        """Every world's ``(contributions [W, C, 2], direct [W, 2])`` for a random layout, None for a fixed one."""
        if self._fixed is not None:
            return None
        if self.env is None:
            raise ValueError(
                "OraclePolicy with layout='random' needs the environment it acts in: OraclePolicy(cfg, env=env)"
            )
        tables = self.env.layout_tables()
        if isinstance(tables, list):  # a SerialEnv or ParallelEnv: one pair per worker, in the order of its batch
            return torch.cat([c for c, _ in tables]), torch.cat([d for _, d in tables])
        return tables

    def _optimal_sets(self, world: int, layouts) -> tuple[torch.Tensor, torch.Tensor]:
        if layouts is None:
            contributions, direct = self._fixed[0][0], self._fixed[1][0]
        else:
            contributions, direct = layouts[0][world], layouts[1][world]
        key = 0 if self._fixed is not None else world
        cached = self._targets.get(key)
        if cached is None or not torch.equal(cached[0], contributions):
            u_star = float(optimum(contributions[None], direct[None], self.cfg)[0][0])
            cached = (contributions, *optimal_configurations(contributions, direct, self.cfg, u_star))
            self._targets[key] = cached
        return cached[1], cached[2]

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        self.run_env.check(td)
        positions, tasks = td.get("positions"), td.get("tasks")
        N = self.cfg.num_uavs
        cells = cells_of(positions, self.cfg.grid[0]).cpu().reshape(-1, N)
        tasks_of = tasks.cpu().reshape(-1, N)
        layouts = self._layouts()
        actions = torch.stack([self._plan(w, cells[w], tasks_of[w], layouts) for w in range(len(cells))])
        td.set(("agents", "action"), actions.view(tasks.shape).to(positions.device))
        return td

    def _plan(self, world: int, cells: torch.Tensor, tasks: torch.Tensor, layouts) -> torch.Tensor:
        """One valid joint action of one world, ``[N]``."""
        target_cells, target_tasks = self._optimal_sets(world, layouts)
        costs = assignment_costs(cells, tasks, target_cells, target_tasks, self.cfg.grid)
        _, s, pair = best_assignment(costs)
        width = self.cfg.grid[0]
        goal = list(zip(target_cells[s][pair].tolist(), target_tasks[s][pair].tolist(), strict=True))
        cells, tasks = cells.tolist(), tasks.tolist()

        def steps_to(i: int, cell_task: tuple[int, int]) -> int:
            (y, x), (gy, gx) = divmod(cells[i], width), divmod(cell_task[0], width)
            return abs(gx - x) + abs(gy - y) + (cell_task[1] != tasks[i])

        def preferences(i: int) -> list[int]:
            """A task change first, then moves that shorten the path (longer axis first), then staying."""
            (y, x), (gy, gx) = divmod(cells[i], width), divmod(goal[i][0], width)
            moves = sorted(
                [(abs(gx - x), RIGHT if gx > x else LEFT), (abs(gy - y), DOWN if gy > y else UP)], reverse=True
            )
            change = [SENSE + goal[i][1]] if goal[i][1] != tasks[i] else []
            return change + [move for distance, move in moves if distance > 0] + [SENSE + tasks[i]]

        def target(i: int, action: int) -> int:
            return cells[i] if action >= SENSE else self.neighbours[cells[i]][action]

        holder = {cell: i for i, cell in enumerate(cells)}
        waiting, claimed, actions = set(cells), set(), [0] * len(cells)
        for i in sorted(range(len(cells)), key=lambda i: -steps_to(i, goal[i])):
            waiting.discard(cells[i])
            options = preferences(i)
            if all(target(i, a) in waiting for a in options[:-1] if a < SENSE) and any(a < SENSE for a in options):
                # every shortening move runs into a UAV still to choose: hand it this UAV's goal and take its
                # place (it lies on this UAV's path), when that makes neither of the two slower
                j = holder[target(i, next(a for a in options if a < SENSE))]
                if max(steps_to(i, goal[j]), steps_to(j, goal[i])) <= max(steps_to(i, goal[i]), steps_to(j, goal[j])):
                    goal[i], goal[j] = goal[j], goal[i]
                    options = preferences(i)
            actions[i] = next(
                a for a in options if a >= SENSE and target(i, a) == cells[i] or target(i, a) not in waiting | claimed
            )
            claimed.add(target(i, actions[i]))
        return torch.tensor(actions)


class BaselineAgent(Agent):
    """An agent with nothing to learn (contract: :class:`~uavrl.agents.base.Agent`): no iteration, no checkpoint."""

    num_iterations = 0
    env_steps = 0

    def __init__(self, env_cfg: ModelConfig, cfg, device, seed: int):
        self.env_cfg, self.seed = env_cfg, int(seed)

    def train_iteration(self) -> dict[str, float]:
        raise RuntimeError(f"{type(self).__name__} has nothing to train")

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, state: dict):
        pass


class RandomAgent(BaselineAgent):
    """``agent=random``: the uniform random policy over allowed per-UAV actions, seeded by ``seed``."""

    def policies(self) -> list[CheckedPolicy]:
        return [CheckedPolicy(RandomPolicy(self.seed), self.env_cfg)]


class OracleAgent(BaselineAgent):
    """``agent=oracle``: the oracle planner (module doc)."""

    def policies(self) -> list[OraclePolicy]:
        return [OraclePolicy(self.env_cfg)]
