"""The energy-aware planner (``agent=planner``): the oracle's plan, with the batteries read (docs/model.md, The
energy-aware planner).

It is :class:`~uavrl.agents.baselines.OraclePolicy` (it drives the UAVs in service to an optimal configuration
``A`` by the bottleneck assignment, step by step, collision-free) with two rules on top, both read from the energy
model's numbers, never learnt:

1. **Move rather than hover, where that delivers more per joule.**  ``B`` is the configuration that moves every UAV
   of ``A`` to a neighbouring cell (at its level, with altitude levels), keeping its task (cells off ``A`` and
   distinct), of the largest utility ``U_B``.
   Once the team holds ``A`` it cycles ``A, B, A, ...`` (every UAV moves every step) when that delivers more per
   joule than hovering: ``(U_A + U_B) / 2 / e_move > U_A / e_stay``, i.e. ``U_B > (2 e_move / e_stay - 1) U_A``
   (``e_move``, ``e_stay``: a serving UAV's step that moves or not).  Under ``rotary_wing`` (132.8 J and 175.3 J
   with the defaults) that is ``U_B > 0.515 U_A``; under ``follow_up`` (1.5 and 0.5) never.  ``B`` is searched over
   every combination of neighbours up to :data:`MAX_CYCLE_UAVS` UAVs in service; beyond, the team hovers.
2. **Staggered returns, so that a charged spare always takes over** (``recharge_steps`` and ``num_spares > 0``).
   UAV ``i`` in service can serve ``s_i = floor((b_i - reserve(c_i)) / e)`` more steps (battery ``b_i``, the
   reserve of its cell, ``e`` its step in the chosen pattern).  Its departures, sorted, must keep two spacings:
   ``h`` steps between consecutive ones (``h``: the steps from the entry cell to the farthest pair of ``A``, plus
   one, so each handover ends before the next starts), and ``T = F + R + 1`` between departures ``S = num_spares``
   apart (``F`` the longest flight home, ``R = recharge_steps``: the UAV that left ``S`` departures earlier is then
   charged again, and a spare waits for every departure).  The latest such schedule is ``d_k = min(s_(k), d_(k+1)
   - h, d_(k+S) - T)``, from the UAV with the most steps left backwards; when ``d_1 <= 0``, all ``num_uavs``
   serve, a spare waits charged and the entry cell is free, the UAV with the fewest steps left returns now (action
   ``return``), and the spare that enters is assigned its pair by the oracle's assignment.  The oracle instead
   keeps every UAV in service to its reserve, so the team's UAVs, started alike, leave together.

The UAVs' batteries are read from the environment's ``state`` (each UAV's battery as a fraction of the capacity).

Example:
    >>> from uavrl.envs import UAVSpectrumEnv, make_config
    >>> cfg = make_config("paper", grid=(6, 6), num_uavs=2, energy="rotary_wing", base=(-1, 0), battery_wh=4.0)
    >>> env = UAVSpectrumEnv(batch_size=2, config=cfg.replace(max_steps=60))
    >>> planner = PlannerPolicy(cfg)
    >>> planner.cycles(0, None)  # rotary_wing: the team moves between A and B, cheaper than hovering
    True
    >>> td = env.rollout(60, planner, tensordict=env.reset(), auto_reset=False, break_when_any_done=False)
    >>> int(td["next", "moves"][:, 10:].min())  # after reaching A: both UAVs move every step
    2
"""

from __future__ import annotations

import itertools
import math

import torch
from tensordict import TensorDictBase

from uavrl.agents.baselines import SENSE, BaselineAgent, OraclePolicy
from uavrl.envs import ModelConfig
from uavrl.envs.config import RETURN
from uavrl.envs.physics.channel import rates
from uavrl.envs.physics.energy import Energy
from uavrl.envs.physics.grid import manhattan
from uavrl.envs.solvers.bounds import assignment_costs, best_assignment

MAX_CYCLE_UAVS = 7  # B is searched over 4^n neighbour combinations: 16,384 at 7 UAVs in service


class PlannerPolicy(OraclePolicy):
    """The energy-aware planner's policy (module doc); under ``energy="none"`` it is the oracle.

    Args:
        cfg: the model (:func:`~uavrl.envs.make_config`) it plans for, its energy model among it.
        env: an environment to check up front (as :meth:`~uavrl.agents.baselines.OraclePolicy.bind_env`); None:
            none.
    """

    def __init__(self, cfg: ModelConfig, env=None):
        super().__init__(cfg, env)
        self.energy = None if cfg.energy == "none" else Energy(cfg)
        if self.energy is not None:
            self.in_keys = [*self.in_keys, "state"]
            e = cfg.step_energies
            self.e_move, self.e_stay = e.move, e.stay
        self._cycle_partners: dict[tuple, tuple[torch.Tensor, bool]] = {}  # (world key, A) -> (B's cells, cycle?)

    def _partners(self, world: int, nodes, cells: torch.Tensor, tasks: torch.Tensor) -> tuple[torch.Tensor, bool]:
        """``(B's cells [n], whether to cycle)`` for the UAVs in service holding ``A`` = ``(cells, tasks)`` (rule 1)."""
        key = (None if nodes is None else world, tuple(cells.tolist()), tuple(tasks.tolist()))
        if key in self._cycle_partners:
            return self._cycle_partners[key]
        contributions, direct = self._world_tables(world, nodes)[:2]
        n = len(cells)
        found = (cells, False)
        if n <= MAX_CYCLE_UAVS:
            # B moves each UAV in the plane (a step of e_move; a climb or a descent costs otherwise)
            held = set(cells.tolist())
            options = [[c for c in self.neighbours[cell][:4] if c >= 0 and c not in held] for cell in cells]
            combos = torch.tensor([c for c in itertools.product(*options) if len(set(c)) == n], dtype=torch.long)
            if len(combos):
                here = sum(rates(contributions[cells][None], tasks[None], direct[None], self.cfg))[0]
                there = sum(rates(contributions[combos], tasks.expand_as(combos), direct[None], self.cfg))
                best = int(there.argmax())
                cycle = (here + there[best]) / 2 / self.e_move > here / self.e_stay
                found = (combos[best], bool(cycle))
        self._cycle_partners[key] = found
        return found

    def cycles(self, world: int, nodes) -> bool:
        """Whether the full team cycles between ``A`` (the first optimal configuration of the world) and ``B``;
        ``world`` is the world's index, ``nodes`` its node positions (None for a fixed layout)."""
        target_cells, target_tasks = self._optimal_sets(world, nodes)
        return self._partners(world, nodes, target_cells[0], target_tasks[0])[1]

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        if self.energy is None:
            return super().forward(td)
        self.run_env.check(td)
        positions, tasks = td.get("positions"), td.get("tasks")
        fleet = self.cfg.fleet_size
        cells, serving, tasks_of = self._serving(td)
        state = td.get("state").cpu().reshape(len(cells), -1)
        battery = state[:, 5 * fleet : 7 * fleet : 2].double() * self.energy.capacity  # the World's state layout
        nodes = self._nodes(td)
        actions = torch.full(cells.shape, SENSE, dtype=torch.long)
        for w in range(len(cells)):
            uavs = serving[w].nonzero().squeeze(-1)
            if len(uavs):
                actions[w, uavs] = self._act(w, cells[w], tasks_of[w], battery[w], uavs, nodes)
        td.set(("agents", "action"), actions.view(tasks.shape).to(positions.device))
        return td

    def _act(self, world, cells, tasks, battery, uavs, nodes) -> torch.Tensor:
        """The actions of the UAVs ``uavs`` in service of one world (rules 1 and 2)."""
        here, now = cells[uavs], tasks[uavs]
        target_cells, target_tasks = self._optimal_sets(world, nodes)
        steps = best_assignment(assignment_costs(here, now, target_cells, target_tasks, self.positions))[0]
        partners, cycle = self._partners(world, nodes, here, now) if steps == 0 else (here, False)
        if steps == 0 and cycle:  # at A: every UAV moves to its cell of B (free cells, so no move is cancelled)
            moves = zip(here.tolist(), partners.tolist(), strict=True)
            actions = torch.tensor([self.neighbours[cell].index(partner) for cell, partner in moves])
        else:  # on the way to A, or at B: the oracle's step towards A
            actions = self._plan(world, here, now, nodes)
        leaving = self._returning(cells, battery, uavs, here, target_cells, cycle or self.cycles(world, nodes))
        if leaving is not None:
            actions[leaving] = RETURN
        return actions

    def _returning(self, cells, battery, uavs, here, target_cells, cycle: bool) -> int | None:
        """Which of the UAVs in service returns now (its index in ``uavs``), or None (rule 2)."""
        cfg, energy = self.cfg, self.energy
        if cfg.recharge_steps is None or cfg.num_spares == 0 or len(uavs) < cfg.num_uavs:
            return None
        away = cells >= energy.away
        spare_ready = (away & (battery >= energy.capacity)).any()
        if not spare_ready or bool((here == energy.entry).any()):
            return None
        step = self.e_move if cycle else self.e_stay
        left = ((battery[uavs] - energy.reserve[here]) / step).floor()
        order = left.argsort()
        handover, turnaround = self._spacing(target_cells)
        deadlines = [math.inf] * len(order)
        for k in reversed(range(len(order))):  # the latest departures that keep both spacings
            after = deadlines[k + 1] - handover if k + 1 < len(order) else math.inf
            reuse = deadlines[k + cfg.num_spares] - turnaround if k + cfg.num_spares < len(order) else math.inf
            deadlines[k] = min(float(left[order[k]]), after, reuse)
        return int(order[0]) if deadlines[0] <= 0 else None

    def _spacing(self, target_cells: torch.Tensor) -> tuple[int, int]:
        """Rule 2's ``(h, T)``: the steps between consecutive departures, and between departures ``num_spares``
        apart."""
        cfg, energy = self.cfg, self.energy
        handover = int(manhattan(torch.tensor(energy.entry), target_cells, cfg.grid[0]).max()) + 1
        return handover, int(energy.steps_home[: energy.away].max()) + cfg.recharge_steps + 1


class PlannerAgent(BaselineAgent):
    """``agent=planner``: the energy-aware planner (module doc)."""

    name = "planner"

    def policies(self) -> list[PlannerPolicy]:
        return [PlannerPolicy(self.env_cfg)]
