"""The energy part: the UAVs' batteries and their service (docs/model.md, Energy and lifetime).

``env.energy`` names the model: ``none`` (the paper: no part, nothing allocated, no work in a step), ``follow_up``
or ``rotary_wing``, whose per-step energies come from :mod:`.power`.  :class:`Energy` adds the per-UAV variables
:data:`ENERGY_STATE` to the World's state and gives

- ``start(keys, counters)``: full batteries, or ``U[lo, 1]`` of the capacity from each world's stream
  (``battery_init=uniform``), every UAV serving;
- ``step(state, cell_before, action)``: after the dynamics part moved the UAVs, what the step cost each battery (a
  move, a stay, or with altitude levels a climb or a descent), and who leaves service: a serving UAV whose battery is
  at or below the reserve of its position (its dearest next step, then the flight to the base, flown at its level)
  flies to the base over ``|x - bx| + |y - by|`` steps (``RETURNING``, ``timer`` the steps
  left), then is ``OUT``; with ``recharge_steps`` it also leaves on ``return`` (:data:`~.config.RETURN`), is
  ``CHARGING`` at the base for that many steps, then ``WAITING`` charged, and the first waiting UAV enters at
  :attr:`Energy.entry` while fewer than ``num_uavs`` serve (spares start waiting).  A UAV out of service sits on
  :attr:`Energy.away`, a cell index past the grid's whose per-code rows add nothing to the rates, clash with no
  UAV on the grid and allow only :data:`NO_OP`;
- ``features(state)``: ``[B, N, 2]`` what the observation and the state show of each UAV, its battery (a fraction
  of the capacity) and its service flag;
- ``terminated(state)``: ``[B]`` no UAV serves any more (``None`` with recharging: missions are truncated).

Example:
    >>> import torch
    >>> from uavrl.envs import make_config
    >>> from uavrl.envs.physics import streams
    >>> part = Energy(make_config("paper", grid=(3, 3), energy="follow_up", base=(-1, 0)))
    >>> part.steps_home.tolist()  # steps from each cell to the base, then the away cell's
    [1, 2, 3, 2, 3, 4, 3, 4, 5, 0]
    >>> start = part.start(streams.world_keys(0, 2), torch.ones(2, dtype=torch.long))
    >>> start["battery"].tolist(), start["status"].tolist()
    ([[5000.0, 5000.0], [5000.0, 5000.0]], [[0, 0], [0, 0]])
"""

from __future__ import annotations

import torch

from ..config import NUM_ACTIONS, RETURN, SENSING, ModelConfig
from . import streams
from .dynamics import NO_OP
from .positions import model_positions
from .power import UNIFORM_LOW

ENERGY_STATE = ("battery", "status", "timer")  # per-UAV variables the part adds to the World's state, [B, N] each
SERVING, RETURNING, OUT, CHARGING, WAITING = 0, 1, 2, 3, 4  # a UAV's status; the last two with recharge_steps


class Energy:
    """The batteries and service of the UAVs of the model ``cfg`` (``energy`` not ``none``; the module's
    docstring).

    Args:
        cfg: the model (its energy model, ``base``, ``recharge_steps`` and step energies).
        device: the torch device of its tables.
    """

    def __init__(self, cfg: ModelConfig, device="cpu"):
        self.cfg = cfg
        self.energies = energies = cfg.step_energies
        self.capacity = energies.capacity
        positions, (L1, _), (bx, by) = model_positions(cfg, device), cfg.grid, cfg.base
        C = len(positions)
        self.away = C  # the position of a UAV out of service
        self.num_serving, self.recharge_steps = cfg.num_uavs, cfg.recharge_steps
        # the flight home is flown at the UAV's level (docs/model.md, Energy and lifetime)
        steps = (positions.cell % L1 - bx).abs() + (positions.cell // L1 - by).abs()
        self.entry = int(steps.argmin())  # where a charged UAV enters: the position nearest the base, the first of ties
        flight = steps.double() * energies.fly + (steps > 0).double() * energies.arrive  # [C]
        # the reserve of a position: enough for its worst next step (stay, move to a neighbour, climb or descend),
        # then the flight home
        planar = positions.neighbours[:, :4]
        position = torch.arange(C, device=device)
        reach = torch.cat([position[:, None], planar.where(planar >= 0, position[:, None])], -1)
        reserve = torch.maximum(energies.stay + flight, energies.move + flight[reach].amax(-1))
        # a step's costs as float64 scalars (where() of Python floats would give float32)
        self.move, self.stay, self.fly, self.fly_and_arrive, self.nothing = torch.tensor(
            [energies.move, energies.stay, energies.fly, energies.fly + energies.arrive, 0.0],
            dtype=torch.float64,
            device=device,
        ).unbind()
        self.level = None  # with altitude levels: [C + 1] each position's level, the climb and descent from each
        if cfg.num_levels > 1:
            self.level = torch.cat([positions.level, positions.level.new_zeros(1)])
            climb = torch.tensor([*energies.climb, 0.0], dtype=torch.float64, device=device)  # [L]: from level l
            descend = torch.tensor([0.0, *energies.descend], dtype=torch.float64, device=device)
            self.climb, self.descend = climb, descend
            up, down = positions.neighbours[:, 4] >= 0, positions.neighbours[:, 5] >= 0
            vertical = torch.maximum(climb[positions.level].where(up, 0.0), descend[positions.level].where(down, 0.0))
            reserve = torch.maximum(reserve, vertical + flight)  # a climb or descent keeps the cell: the same flight
        self.steps_home = torch.cat([steps, steps.new_zeros(1)])  # [C + 1]
        self.reserve = torch.cat([reserve, reserve.new_full((1,), float("inf"))])  # [C + 1]: no one serves away

    def start(self, keys: torch.Tensor, counters: torch.Tensor) -> dict[str, torch.Tensor]:
        """The batteries and status of ``k`` worlds at a reset (``keys``, ``counters`` ``[k]``: their streams)."""
        shape, spares = (len(keys), self.cfg.num_uavs), self.cfg.num_spares
        if self.cfg.battery_init == "uniform":
            low = UNIFORM_LOW
            battery = (low + (1 - low) * streams.uniform(keys, counters, streams.BATTERY, shape[1])) * self.capacity
        else:
            battery = torch.full(shape, self.capacity, dtype=torch.float64, device=keys.device)
        status = torch.full(shape, SERVING, dtype=torch.long, device=keys.device)
        if spares:  # the spares wait charged at the base
            battery = torch.cat([battery, battery.new_full((len(keys), spares), self.capacity)], -1)
            status = torch.cat([status, status.new_full((len(keys), spares), WAITING)], -1)
        return {"battery": battery, "status": status, "timer": torch.zeros_like(status)}

    def step(self, state, cell_before: torch.Tensor, action: torch.Tensor) -> dict[str, torch.Tensor]:
        """The per-UAV variables after a step, from ``state`` (its ``cell`` and ``task`` the dynamics part's after the
        step, the rest before), the cells before it ``cell_before`` ``[B, N]`` and the joint actions ``action``
        ``[B, N]``."""
        e = self.energies
        status, timer = state.status, state.timer
        serving, returning = status == SERVING, status == RETURNING
        moved = self._moves_asked(action) if e.moves_by_action else state.cell != cell_before
        arriving = returning & (timer == 1)
        cost = torch.where(
            serving,
            torch.where(moved, self._moving(cell_before, state.cell), self.stay),
            torch.where(returning, torch.where(arriving, self.fly_and_arrive, self.fly), self.nothing),
        )
        battery = state.battery - cost
        if self.recharge_steps is not None:
            return self._step_recharging(state, battery, arriving, action)
        timer = timer - returning.long()
        status = torch.where(arriving, OUT, status)
        leaving = serving & (battery <= self.reserve.index_select(0, state.cell.view(-1)).view_as(battery))
        steps = self.steps_home.index_select(0, state.cell.view(-1)).view_as(timer)
        return {
            "battery": battery,
            "status": torch.where(leaving, torch.where(steps > 0, RETURNING, OUT), status),
            "timer": torch.where(leaving, steps, timer),
            "cell": torch.where(leaving, self.away, state.cell),
            "task": torch.where(leaving, SENSING, state.task),
        }

    def _moves_asked(self, action: torch.Tensor) -> torch.Tensor:
        """Which actions ask for a move: up, down, left, right, and with levels climb and descend (a follow-up's
        move is charged by its action)."""
        return (action < NO_OP) | (action >= NUM_ACTIONS) if self.level is not None else action < NO_OP

    def _moving(self, before: torch.Tensor, after: torch.Tensor) -> torch.Tensor:
        """What a serving UAV's move from the positions ``before`` to ``after`` ``[B, N]`` costs: a move in the plane,
        or with levels the climb or the descent from its level.  A cancelled move keeps the position: it is charged
        as a move, and only where a move is charged by its action (the follow-up's, whose climb is a move too)."""
        if self.level is None:
            return self.move
        start, end = self.level.index_select(0, before.view(-1)), self.level.index_select(0, after.view(-1))
        vertical = torch.where(end > start, self.climb[start], self.descend[start])  # from the level it left
        return torch.where(end == start, self.move, vertical).view_as(before)

    def _step_recharging(self, state, battery, arriving, action) -> dict[str, torch.Tensor]:
        """:meth:`step` with ``recharge_steps``: an arriving UAV charges for ``recharge_steps`` steps, then waits
        charged; a serving UAV also leaves on ``return``; then, while fewer than ``num_uavs`` serve and no UAV holds
        the entry cell, the first waiting UAV enters there (one a step)."""
        status, cell = state.status, state.cell
        serving, charging = status == SERVING, status == CHARGING
        timer = state.timer - ((status == RETURNING) | charging).long()
        charged = charging & (timer == 0)
        battery = torch.where(charged, self.capacity, battery)
        status = torch.where(arriving, CHARGING, torch.where(charged, WAITING, status))
        timer = torch.where(arriving, self.recharge_steps, timer)
        reserve = self.reserve.index_select(0, cell.view(-1)).view_as(battery)
        leaving = serving & ((battery <= reserve) | (action == RETURN))  # the base is off the grid: >= 1 step home
        status = torch.where(leaving, RETURNING, status)
        timer = torch.where(leaving, self.steps_home.index_select(0, cell.view(-1)).view_as(timer), timer)
        cell = torch.where(leaving, self.away, cell)
        waiting = status == WAITING
        room = ((status == SERVING).sum(-1) < self.num_serving) & (cell != self.entry).all(-1)
        entering = waiting & (waiting.cumsum(-1) == 1) & room.unsqueeze(-1)
        return {
            "battery": battery,
            "status": torch.where(entering, SERVING, status),
            "timer": timer,
            "cell": torch.where(entering, self.entry, cell),
            "task": torch.where(leaving | entering, SENSING, state.task),  # a UAV enters sensing
        }

    def features(self, state) -> torch.Tensor:
        """``[B, N, 2]`` float32 what the UAVs' observation and the state show: the battery as a fraction of the
        capacity, and 1 for a UAV in service (0 out)."""
        return torch.stack([(state.battery / self.capacity).float(), (state.status == SERVING).float()], -1)

    def terminated(self, state) -> torch.Tensor | None:
        """``[B]`` whether no UAV of a world serves any more in ``state``; ``None`` with ``recharge_steps``, where
        every UAV serves again once charged (the mission is truncated after ``max_steps``)."""
        return None if self.recharge_steps is not None else (state.status != SERVING).all(-1)


def energy_part(cfg: ModelConfig, device="cpu") -> Energy | None:
    """The energy part of ``cfg.energy``; ``None`` for ``none`` (the World then does no energy work at all).

    Args:
        cfg: the model.
        device: the torch device of the part's tables.
    """
    return None if cfg.energy == "none" else Energy(cfg, device)
