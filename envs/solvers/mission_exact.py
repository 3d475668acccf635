"""Exact optimal control of a mission under an energy model: the most data a mission can deliver (docs/model.md,
The exact mission solver).

:func:`optimal_mission` takes a reset :class:`~uavrl.envs.world.World` (its state now is each world's start: cells,
tasks, batteries, statuses) and finds, by backward induction over the states reachable in ``horizon`` steps, the
most data ``sum_t (R_PU + R_SE) slot_s`` (bit/Hz) any policy delivers from each start, as the evaluation counts it
(:func:`uavrl.agents.evaluation.mission_metrics`).  The transition function is the World's own step
(:meth:`~uavrl.envs.world.World.successors`: the dynamics part, then the energy part, then the rates), called on
every reachable state with every joint action the environment's masks allow; nothing of the physics is written
here.  What the solver adds is the state space:

- a UAV out of service (flying home or at the base) never serves again without recharging and adds nothing to the
  rates nor blocks a cell, so all of them are one state (``OUT`` at the away cell);
- UAVs are interchangeable: a state lists its UAVs in a canonical order;
- a battery is its float64 value rounded to a multiple of ``q``, a power of two near ``2^-30`` of the largest
  battery.  From one start a UAV's battery after ``t`` steps is ``b0 - m move - (t - m) stay`` for the ``m`` moves
  it made (with altitude levels, less each climb and descent it made), so the reachable batteries are finitely
  many, but the float64 running sum depends on the order of the steps in its last bits (hundreds of distinct floats
  per ``(t, m)`` on a 2 Wh battery); those differ by about ``1e-15`` of the battery and fall into one bucket.  The
  solver is exact as long as no leaving test (``battery <= reserve``) is decided within the rounding this can
  cause: it checks every battery it reaches against every position's reserve and refuses (one line) if one falls
  within ``(t + 1) (q / 2 + ulp)``.  Where every energy and start battery is a multiple of ``q`` (the follow-up's
  units) the arithmetic is exact and no check is needed.

Sizes: the states of a step are about ``(2 C n_t)^N / N!`` for ``C`` positions and ``n_t`` battery levels a UAV
can have after ``t`` steps (up to ``t + 1``; with altitude levels, whose climbs and descents cost more kinds of
step, up to the moves, stays and round trips between levels a battery can pay for), each with ``A^N`` joint actions
(``A`` 6, 8 with levels); :func:`mission_size` estimates them and :func:`optimal_mission` refuses, in one line
before any work, what would take more than ``memory_budget``.
BENCHMARKS.md times it (``benchmarks/mission_exact.py``).

Example:
    >>> from uavrl.envs import make_config
    >>> from uavrl.envs.world import World
    >>> cfg = make_config("paper", grid=(2, 2), num_uavs=1, energy="rotary_wing", base=(-1, 0), battery_wh=0.35)
    >>> world = World(cfg, 2, seed=0)
    >>> _ = world.reset()
    >>> best = optimal_mission(world, horizon=10)
    >>> best.value.shape, bool((best.value > 0).all())
    (torch.Size([2]), True)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import torch

from ..config import SENSING
from ..limits import gib
from ..physics.energy import OUT, SERVING
from ..physics.grid import decode_joint_actions

MAX_UAVS = 2
MEMORY_BUDGET = 2**31  # bytes of the solver's tables (every step's next-state table) unless raised
QUANTUM_BITS = 30  # a battery's bucket: 2^-30 of the largest battery (rounded to a power of two)
_CHUNK = 1 << 18  # (state, joint action) rows stepped at once: ~100 MB of temporaries
_TABLE_BYTES = 4  # a next-state index (int32) per state and joint action
_STATE_BYTES = 48  # per state: its cells, best action, next state, value, and the step's working tensors
_CANDIDATE_BYTES = 48  # per (state, joint action) of the largest step while it is deduplicated


class MissionTooLarge(ValueError):
    """The solver would need more than its memory budget (the message says how much, and why)."""


class NotCovered(ValueError):
    """A model or a state the solver does not cover (the message says which): an energy-free or random channel,
    recharging, more than 2 UAVs, or a leaving test decided within float64 rounding."""


@dataclass
class MissionOptimum:
    """The exact optimum of the missions of a World's starts (:func:`optimal_mission`).

    ``value`` ``[B]`` float64: the most data (bit/Hz) a mission of ``horizon`` steps delivers from each start;
    ``first_action`` ``[B, N]``: an optimal joint action there (the UAVs in the World's order); ``states``,
    ``transitions``: how many states and (state, joint action) pairs were solved; ``seconds``: the time it took.
    :meth:`actions` plays the optimal policy step by step.  ``start_index`` ``[B]``: each start's state among the
    first step's; ``num_actions``: a UAV's actions within a joint action (6, 8 with altitude levels).  The fields
    ``_cells``, ``_best`` and ``_next`` are the solver's per-step tables that
    :meth:`actions` reads (the solver fills them; not for users).
    """

    value: torch.Tensor
    first_action: torch.Tensor
    horizon: int
    states: int
    transitions: int
    seconds: float
    start_index: torch.Tensor  # [B] each start's state among the first step's
    num_actions: int  # a UAV's actions within a joint action: 6, 8 with altitude levels
    _cells: list = field(repr=False)  # per step [S_t, N] the canonical cells of its states
    _best: list = field(repr=False)  # per step [S_t] an optimal joint action (canonical UAV order)
    _next: list = field(repr=False)  # per step [S_t] the state it leads to

    def actions(self, step: int, index: torch.Tensor, cells: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """An optimal joint action ``[B, N]`` (the World's UAV order) at ``step`` from the states ``index`` ``[B]``
        whose UAVs are on ``cells`` ``[B, N]`` (the World's), and the states it leads to."""
        canonical = self._cells[step][index]  # [B, N]
        joint = decode_joint_actions(canonical.shape[1], index.device, self.num_actions)[self._best[step][index].long()]
        same = cells.unsqueeze(-1) == canonical.unsqueeze(-2)  # [B, N world, N canonical]
        which = same.long().argmax(-1)  # the canonical UAV on each world UAV's cell (one out of service: any)
        return joint.gather(1, which), self._next[step][index].long()


def check_world(world) -> None:
    """One-line refusals of what the solver does not cover, before any work.

    Args:
        world: the :class:`~uavrl.envs.World` whose starts would be solved, reset.

    Raises:
        NotCovered: no energy model, a random channel, recharging or more than 2 UAVs.
    """
    cfg = world.cfg
    if world.energy is None:
        raise NotCovered("the exact mission solver needs an energy model: env.energy is 'none' (use envs.exact)")
    if world.fading.random:
        raise NotCovered(f"the exact mission solver reads deterministic channels: fading={cfg.fading!r} is random")
    if cfg.recharge_steps is not None:
        raise NotCovered(
            f"the exact mission solver has no recharging: recharge_steps={cfg.recharge_steps} (a UAV out of service "
            "never serves again is what keeps its states few)"
        )
    if world.num_uavs > MAX_UAVS:
        raise NotCovered(f"num_uavs={world.num_uavs} is invalid for the exact mission solver: it takes 1 or 2 UAVs")
    if not bool(world.state.started.all()):
        raise RuntimeError("the exact mission solver starts from the World's state: call world.reset() first")


def _layout_rows(world) -> torch.Tensor:
    """``[B]`` the row of each world's layout tables (0 for all under a fixed layout)."""
    B, dev = world.num_worlds, world.device
    return torch.arange(B, device=dev) if world.layouts.fixed is None else torch.zeros(B, dtype=torch.long, device=dev)


def _levels(battery: float, horizon: int, move: float, stay: float, least_reserve: float) -> torch.Tensor:
    """``[H + 1]`` after each step ``t``, how many move counts ``m`` in ``0..t`` leave ``battery - m move - (t - m)
    stay`` above ``least_reserve`` (the battery levels a serving UAV can have then)."""
    t = torch.arange(horizon + 1, dtype=torch.float64)
    slope, need = stay - move, least_reserve - battery + t * stay  # serving after t steps: m slope > need
    if slope == 0:
        return torch.where(need < 0, t + 1, 0.0).long()
    if slope > 0:
        fewest = (torch.floor(need / slope) + 1).clamp(min=0)
        return (t + 1 - fewest).clamp(min=0).long()
    most = torch.minimum(torch.ceil(need / slope) - 1, t)
    return (most + 1).clamp(min=0).long()


def _vertical_levels(battery: float, horizon: int, energies, least_reserve: float, num_levels: int) -> torch.Tensor:
    """``[H + 1]`` an upper bound on the battery levels a serving UAV can have after each step ``t`` with altitude
    levels, whose climbs and descents (``energies``: :class:`~uavrl.envs.physics.power.StepEnergies`) cost what a
    move and a stay do not.  A path that ends ``d`` levels from where it began crossed each gap between levels up and
    down equally often but for ``d`` of them, so its battery is set by its moves ``m``, stays ``s`` and round trips
    ``k_g`` per gap ``g`` with ``m + s + 2 sum k = t - d`` (at most two ends lie ``d`` levels away); only those whose
    cheapest cost leaves the battery above ``least_reserve`` count.  Float64, as :func:`mission_size` multiplies
    them past int64's range."""
    gaps, spare = num_levels - 1, battery - least_reserve
    planar = min(energies.move, energies.stay)
    round_trip = min(c + d for c, d in zip(energies.climb, energies.descend, strict=True))
    crossing = min(*energies.climb, *energies.descend)
    # every (t, d, j): t steps, d levels between the path's ends, j = sum k round trips over the gaps
    t = torch.arange(horizon + 1, dtype=torch.float64)[:, None, None]
    d = torch.arange(gaps + 1, dtype=torch.float64)[None, :, None]
    j = torch.arange(horizon // 2 + 1, dtype=torch.float64)[None, None, :]
    rest = t - d - 2 * j  # the moves and stays
    ways = torch.tensor([math.comb(k + gaps - 1, gaps - 1) for k in range(horizon // 2 + 1)], dtype=torch.float64)
    ways = ways * (rest + 1) * torch.where(d == 0, 1.0, 2.0)  # the round trips over the gaps, m + s = rest, two ends
    affordable = (rest >= 0) & (rest * planar + j * round_trip + d * crossing < spare)
    return (ways * affordable).sum((1, 2))


def mission_size(world, horizon: int) -> tuple[int, int, int]:
    """``(states, transitions, bytes)`` the solver would need for ``world``'s starts over ``horizon`` steps: an
    estimate from the battery levels each UAV can reach (every position, task and level combined; an upper bound on
    the states reachable but for the rounding of batteries), per distinct start (layout and batteries)."""
    energy, cfg, N = world.energy, world.cfg, world.num_uavs
    C, A = energy.away, cfg.joint_action_base**N
    move, stay = float(energy.move), float(energy.stay)
    least_reserve = float(energy.reserve[:C].min())
    keys = torch.cat([_layout_rows(world)[:, None].double(), world.battery.sort(-1).values], -1).unique(dim=0)
    vertical = len({move, stay, *energy.energies.climb, *energy.energies.descend}) > 2  # the follow-up's: a move
    states = largest = 0
    for key in keys.tolist():
        if vertical:
            levels = [_vertical_levels(b, horizon, energy.energies, least_reserve, cfg.num_levels) for b in key[1:]]
        else:
            levels = [_levels(b, horizon, move, stay, least_reserve) for b in key[1:]]
        levels = [count.double() for count in levels]  # with levels, products past int64's range
        if N == 1:
            per_step = 2 * C * levels[0] + 1
        else:
            both = 2 * C * 2 * (C - 1) * levels[0] * levels[1] // (2 if key[1] == key[2] else 1)
            per_step = both + 2 * C * (levels[0] + levels[1]) + 1
        states += int(per_step.sum())
        largest = max(largest, int(per_step.max()))
    transitions = states * A
    need = transitions * _TABLE_BYTES + states * _STATE_BYTES + largest * A * _CANDIDATE_BYTES * len(keys)
    return states, transitions, need


def _quantum(world) -> float:
    """The bucket width of a battery: a power of two near ``2^-QUANTUM_BITS`` of the largest battery."""
    largest = max(float(world.battery.max()), float(world.energy.capacity))
    return 2.0 ** (math.floor(math.log2(largest)) - QUANTUM_BITS)


def _exact_arithmetic(world, quantum: float) -> bool:
    """Whether every battery the solver reaches is exact in float64: the start batteries, the step's energies and
    the reserves all multiples of ``quantum`` (then every difference of them is, and no rounding happens)."""
    e = world.energy
    vertical = torch.tensor([*e.energies.climb, *e.energies.descend], dtype=torch.float64, device=e.move.device)
    values = torch.cat(
        [world.battery.flatten(), torch.stack([e.move, e.stay, e.fly, e.fly_and_arrive]), vertical, e.reserve[: e.away]]
    )
    scaled = values / quantum
    return bool((scaled == scaled.round()).all() and (scaled.abs() < 2.0**50).all())


def _canonical(state: dict, quantum: float, away: int) -> tuple[dict, torch.Tensor]:
    """The canonical form of ``[W, N]`` states: UAVs out of service as one (``OUT`` at ``away``), batteries rounded
    to their bucket, UAVs sorted by ``(bucket, code)`` (out of service first).  Returns it and each UAV's key
    ``[W, N]`` int64 (-1 out of service, else ``bucket (2 away + 2) + code``)."""
    serving = state["status"] == SERVING
    bucket = torch.round(state["battery"] / quantum).long()
    code = torch.add(state["task"], state["cell"], alpha=2)
    key = torch.where(serving, bucket * (2 * away + 2) + code, -1)
    key, order = key.sort(-1)
    serving = serving.gather(1, order)
    out = {
        "cell": torch.where(serving, state["cell"].gather(1, order), away),
        "task": torch.where(serving, state["task"].gather(1, order), SENSING),
        "battery": torch.where(serving, bucket.gather(1, order).double() * quantum, 0.0),
        "status": torch.where(serving, SERVING, OUT),
    }
    return out, key


def _pack(key: torch.Tensor, rows: torch.Tensor, levels: torch.Tensor, codes: int) -> torch.Tensor:
    """``[W]`` one int64 per canonical state: its layout row and its UAVs' keys, each as ``level * codes + code``
    with ``level`` its bucket's index in ``levels`` (sorted buckets of the step), ``0`` out of service."""
    levels = levels if len(levels) else levels.new_zeros(1)
    out = rows.clone()
    serving = key >= 0
    bucket, code = key.div(codes, rounding_mode="floor"), key.remainder(codes)
    level = torch.searchsorted(levels, bucket)
    digit = torch.where(serving, (level * codes + code) + 1, 0)
    base = (len(levels) * codes) + 1
    for i in range(key.shape[1]):
        out = out * base + digit[:, i]
    return out


def _unpack(packed: torch.Tensor, num_uavs: int, levels: torch.Tensor, codes: int, quantum: float, away: int):
    """The canonical states ``[S, N]`` (and layout rows ``[S]``) of :func:`_pack`'s numbers."""
    levels = levels if len(levels) else levels.new_zeros(1)  # every UAV out of service: no level read
    base = (len(levels) * codes) + 1
    digits = []
    rest = packed
    for _ in range(num_uavs):
        digits.append(rest.remainder(base))
        rest = rest.div(base, rounding_mode="floor")
    digit = torch.stack(digits[::-1], -1)
    serving = digit > 0
    level, code = (digit - 1).clamp(min=0).div(codes, rounding_mode="floor"), (digit - 1).clamp(min=0) % codes
    state = {
        "cell": torch.where(serving, code >> 1, away),
        "task": torch.where(serving, code & 1, SENSING),
        "battery": torch.where(serving, levels[level].double() * quantum, 0.0),
        "status": torch.where(serving, SERVING, OUT),
    }
    return state, rest


def _check_margin(world, battery: torch.Tensor, tolerance: float) -> None:
    """Refuse where a leaving test from the batteries ``battery`` ``[S, N]`` (of serving UAVs; 0 out of service)
    is decided within ``tolerance`` of a reserve: rounding could then decide it otherwise."""
    e = world.energy
    values = battery[battery > 0].unique()
    if not len(values):
        return
    costs = [e.move, e.stay, *e.energies.climb, *e.energies.descend]
    after = torch.stack([values - cost for cost in costs], -1)  # what the energy part computes
    gap = (after[..., None] - e.reserve[None, None, : e.away]).abs().min()
    if gap <= tolerance:
        raise NotCovered(
            f"a battery the mission reaches lies {gap.item():.3g} J from a reserve, within the float64 rounding "
            f"({tolerance:.3g}) the exact mission solver allows: change battery_wh slightly"
        )


def _step_layer(world, state, rows, per_world, joint, quantum, away, codes):
    """Every valid (state, joint action) of a step ``[P, 2]``, and their canonical successors: packed as one number
    each (:func:`_pack`, with the step's battery levels, also returned) and their rates ``[P]`` (bit/Hz)."""
    S, N = state["cell"].shape
    masks = world.dynamics.masks(state["cell"])  # [S, N, A]: the environment's per-UAV masks
    valid = masks[:, 0, joint[:, 0]]
    for i in range(1, N):
        valid = valid & masks[:, i, joint[:, i]]
    pairs = valid.nonzero().int()  # [P, 2]
    keys, rates = [], []
    for begin in range(0, len(pairs), _CHUNK):
        s, a = pairs[begin : begin + _CHUNK].long().unbind(-1)
        before = {name: value[s] for name, value in state.items()}
        before["timer"] = torch.zeros_like(before["status"])
        after, r = world.successors(before, joint[a], rows[s] if per_world else None)
        keys.append(_canonical(after, quantum, away)[1])
        rates.append((r[:, 0] + r[:, 1]) * world.cfg.slot_s)
    buckets = [key[key >= 0].div(codes, rounding_mode="floor").unique() for key in keys]
    levels = torch.cat(buckets).unique() if buckets else rows.new_zeros(0)
    packed = torch.empty(len(pairs), dtype=torch.long, device=rows.device)
    for i, key in enumerate(keys):  # chunk by chunk: a chunk's temporaries, not the step's
        begin = i * _CHUNK
        packed[begin : begin + len(key)] = _pack(key, rows[pairs[begin : begin + len(key), 0].long()], levels, codes)
        keys[i] = None
    return pairs, packed, torch.cat(rates), levels


@torch.no_grad()
def optimal_mission(world, horizon: int, memory_budget: int = MEMORY_BUDGET) -> MissionOptimum:
    """The exact optimum of the missions of ``world``'s starts over ``horizon`` steps (the module's docstring).

    ``world``: a reset :class:`~uavrl.envs.world.World` under an energy model without recharging, deterministic
    channels, 1 or 2 UAVs; its state now is the start of every world.  Refused in one line, before any work, where
    :func:`mission_size` exceeds ``memory_budget`` bytes.
    """
    check_world(world)
    if not isinstance(horizon, int) or isinstance(horizon, bool) or horizon < 1:
        raise ValueError(f"horizon={horizon!r} is invalid: give the mission's steps, a whole number >= 1")
    states_guess, _, need = mission_size(world, horizon)
    if need > memory_budget:
        cfg = world.cfg
        raise MissionTooLarge(
            f"the exact mission solver for {world.num_uavs} UAVs on {cfg.grid[0]}x{cfg.grid[1]} over {horizon} "
            f"steps needs about {gib(need)} for ~{states_guess:,} states x {cfg.num_joint_actions} joint actions, over "
            f"its budget of {int(memory_budget):,} bytes: the evaluation uses the bound there"
        )
    began = time.perf_counter()
    dev, N = world.device, world.num_uavs
    away, codes = world.energy.away, 2 * (world.energy.away + 1)
    quantum = _quantum(world)
    exact_arithmetic = _exact_arithmetic(world, quantum)
    rounding = 0.0 if exact_arithmetic else 2.0**-52 * max(float(world.battery.max()), world.energy.capacity)
    per_world = world.layouts.fixed is None
    joint = decode_joint_actions(N, dev, world.cfg.joint_action_base)
    s = world.state
    _, start_key = _canonical({"cell": s.cell, "task": s.task, "battery": s.battery, "status": s.status}, quantum, away)
    levels = start_key[start_key >= 0].div(codes, rounding_mode="floor").unique()
    packed, start_index = _pack(start_key, _layout_rows(world), levels, codes).unique(return_inverse=True)
    state, rows = _unpack(packed, N, levels, codes, quantum, away)
    cells, tables, rates = [state["cell"]], [], []
    num_states = transitions = 0
    for t in range(horizon):
        num_states += len(rows)
        if not exact_arithmetic:
            _check_margin(world, state["battery"], (t + 1) * (quantum / 2 + rounding) + rounding)
        pairs, packed, rate, levels = _step_layer(world, state, rows, per_world, joint, quantum, away, codes)
        transitions += len(pairs)
        packed, successor = packed.unique(return_inverse=True)
        table = torch.full((len(rows), len(joint)), -1, dtype=torch.int32, device=dev)
        table[pairs[:, 0].long(), pairs[:, 1].long()] = successor.int()
        del pairs
        step_rate = torch.empty(len(packed), dtype=torch.float64, device=dev)
        step_rate[successor] = rate  # every pair reaching a state has its rates (the same codes)
        tables.append(table)
        rates.append(step_rate)
        state, rows = _unpack(packed, N, levels, codes, quantum, away)
        cells.append(state["cell"])
    values = torch.zeros(len(rows), dtype=torch.float64, device=dev)
    best, following = [None] * horizon, [None] * horizon
    for t in range(horizon - 1, -1, -1):  # V_t(s) = max over valid a of rate(s') + V_{t+1}(s')
        worth, table = rates[t] + values, tables[t]
        values = torch.empty(len(table), dtype=torch.float64, device=dev)
        choice = torch.empty(len(table), dtype=torch.long, device=dev)
        for begin in range(0, len(table), _CHUNK // len(joint)):  # chunks of rows: [rows, A^N] temporaries
            rows_table = table[begin : begin + _CHUNK // len(joint)]
            q = worth[rows_table.clamp(min=0).long()].masked_fill(rows_table < 0, -math.inf)
            values[begin : begin + len(q)], choice[begin : begin + len(q)] = q.max(-1)
        best[t], following[t] = choice.to(torch.int16), table.gather(1, choice[:, None]).squeeze(1)
        tables[t] = None  # freed as the induction goes back
    optimum = MissionOptimum(
        num_actions=world.cfg.joint_action_base,
        value=values[start_index],
        first_action=torch.empty(0),
        horizon=horizon,
        states=num_states,
        transitions=transitions,
        seconds=0.0,
        start_index=start_index,
        _cells=cells,
        _best=best,
        _next=following,
    )
    optimum.first_action = optimum.actions(0, start_index, s.cell)[0]
    optimum.seconds = time.perf_counter() - began
    return optimum
