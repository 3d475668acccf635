"""The energy models' constants, their sources and the energy of one step (docs/model.md, Energy and lifetime).

Standard library only, like :mod:`.radio`: an energy model's rules (:func:`check_energy_options`,
:func:`check_battery_reach`, :func:`check_step_energies`), which :class:`~uavrl.envs.config.ModelConfig` applies before
torch is imported, and :mod:`.energy` (the World's part) builds its tables from the same numbers.

- ``rotary_wing``: Zeng, Xu, Zhang, "Energy Minimization for Wireless Communication with Rotary-Wing UAV", IEEE
  TWC 18(4):2329-2345, 2019, eq. (12) with their Table I; joules.  A climb or a descent between altitude levels:
  Zeng, Wu, Zhang, "Accessing From the Sky: A Tutorial on UAV Communications for 5G and Beyond", Proc. IEEE
  107(12):2327-2375, 2019, Section II-C's approximation for 3D flight (level-flight power at the speed flown, plus
  the change of potential energy ``W dh``), a descent never below the blades' profile power (ours).
- ``follow_up``: the accounting of Shamsoshoara et al., "An Autonomous Spectrum Management Scheme for Unmanned
  Aerial Vehicle Networks in Disaster Relief Operations", IEEE Access 8:58064-58079, 2020 (their code's
  ``config.py``, ``Config_Power``, and ``energy.py``); the follow-up's own units.

Example:
    >>> round(propulsion_power(0.0), 1), round(propulsion_power(10.0), 1)  # hover, and 10 m/s (Zeng et al.)
    (168.5, 126.0)
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from ..errors import InvalidOption, is_pair, is_whole

ENERGIES = ("none", "follow_up", "rotary_wing")  # uavrl.envs.physics.energy: one part each, none for "none"
BATTERY_INITS = ("full", "uniform")

# Zeng, Xu, Zhang 2019, Table I: a rotary-wing UAV of weight W = 20 N
WEIGHT_N = 20.0  # W, aircraft weight (N)
AIR_DENSITY = 1.225  # rho (kg/m^3)
ROTOR_RADIUS_M = 0.4  # R (m)
ROTOR_DISC_AREA_M2 = 0.503  # A = pi R^2 (m^2)
BLADE_ANGULAR_VELOCITY = 300.0  # Omega (rad/s)
TIP_SPEED = 120.0  # U_tip = Omega R (m/s)
ROTOR_SOLIDITY = 0.05  # s
FUSELAGE_DRAG_RATIO = 0.6  # d0
INDUCED_POWER_CORRECTION = 0.1  # k
PROFILE_DRAG_COEFFICIENT = 0.012  # delta

# Zeng et al. eq. (12): blade profile power P0 and induced power Pi in hover, mean rotor induced velocity v0 in hover
BLADE_PROFILE_POWER = (
    PROFILE_DRAG_COEFFICIENT
    / 8
    * AIR_DENSITY
    * ROTOR_SOLIDITY
    * ROTOR_DISC_AREA_M2
    * BLADE_ANGULAR_VELOCITY**3
    * ROTOR_RADIUS_M**3
)
INDUCED_POWER = (1 + INDUCED_POWER_CORRECTION) * WEIGHT_N**1.5 / math.sqrt(2 * AIR_DENSITY * ROTOR_DISC_AREA_M2)
HOVER_INDUCED_VELOCITY = math.sqrt(WEIGHT_N / (2 * AIR_DENSITY * ROTOR_DISC_AREA_M2))

# env.battery_wh's default: the DJI Phantom 4 Pro's Intelligent Flight Battery (5870 mAh at 15.2 V, 89.2 Wh), a
# quadrotor of about the weight Zeng et al. model (1.39 kg; their W = 20 N is 2.04 kg)
BATTERY_WH = 89.2
# env.circuit_power_w's default: the static power of a pico cell in EARTH's power model (Auer et al., "How much
# energy is needed to run a wireless network?", IEEE Wireless Communications 18(5):40-49, 2011, its table of base
# station power models: P0 = 6.8 W at P_max = 0.13 W), a radio of about a UAV relay's transmit power
CIRCUIT_POWER_W = 6.8
SLOT_S = 1.0  # env.slot_s's default: one step is a second
# battery_init=uniform draws U[lo, 1] x capacity: lo = 4000 / 5000, the follow-up's U[4000, 5000] of its 5000
UNIFORM_LOW = 0.8

# the follow-up's Config_Power (units of its own): MaxEnergy, mob_consump_intra, mob_consump_inter, trans_consump
FOLLOW_UP_CAPACITY = 5000.0
FOLLOW_UP_MOVE = 1.0  # per move inside a region (charged per move action, as its update_energy_movement does)
# mob_consump_inter: their code pays it per cell of inter-region flight (basestation.py); here once, on reaching
# the base (docs/model.md, The authors' follow-up)
FOLLOW_UP_REGION_FLIGHT = 10.0
FOLLOW_UP_TRANSMISSION = 0.5  # per step of transmission, whatever the task


def vertical_propulsion(rise_m: float, slot_s: float) -> float:
    """The propulsion energy in J of a climb (``rise_m > 0``) or a descent (``< 0``) of ``|rise_m|`` m in one step of
    ``slot_s`` s: Zeng, Wu, Zhang's approximation for 3D flight, ``P(|dh| / slot_s) slot_s + W dh``; a descent at
    least the blades' profile power over the step, ``P0 slot_s`` (the rotors keep turning: a battery never gains
    from a descent; ours).

    Example:
        >>> round(vertical_propulsion(10.0, 1.0), 1), round(vertical_propulsion(-10.0, 1.0), 1)  # 10 m up, down
        (326.0, 79.9)
        >>> round(vertical_propulsion(-60.0, 1.0), 1)  # 60 m down in a second: level flight at 60 m/s less W dh
        942.1
    """
    energy = propulsion_power(abs(rise_m) / slot_s) * slot_s + WEIGHT_N * rise_m
    return energy if rise_m > 0 else max(energy, BLADE_PROFILE_POWER * slot_s)


def propulsion_power(speed: float) -> float:
    """Zeng et al.'s eq. (12): the propulsion power in W of level flight at ``speed`` m/s (hover at 0)."""
    v2 = speed * speed
    v0_2 = HOVER_INDUCED_VELOCITY**2
    blade = BLADE_PROFILE_POWER * (1 + 3 * v2 / TIP_SPEED**2)
    induced = INDUCED_POWER * math.sqrt(math.sqrt(1 + v2 * v2 / (4 * v0_2 * v0_2)) - v2 / (2 * v0_2))
    parasite = 0.5 * FUSELAGE_DRAG_RATIO * AIR_DENSITY * ROTOR_SOLIDITY * ROTOR_DISC_AREA_M2 * speed**3
    return blade + induced + parasite


@dataclass(frozen=True)
class StepEnergies:
    """What one step costs a UAV under an energy model (docs/model.md, Energy and lifetime).

    ``move`` and ``stay``: a serving UAV's step that moves or not (hovering, a task switch, a cancelled move);
    ``fly``: each step of the flight to the base; ``arrive``: once, on the step the flight reaches the base;
    ``capacity``: a full battery; ``moves_by_action``: a move is charged by the action (the follow-up's code), not by
    the cell changing; with altitude levels ``climb[l]`` and ``descend[l]``: a serving UAV's step from level ``l`` up
    to ``l + 1``, and from ``l + 1`` down to ``l`` (empty at one level).
    """

    move: float
    stay: float
    fly: float
    arrive: float
    capacity: float
    moves_by_action: bool
    climb: tuple[float, ...] = ()
    descend: tuple[float, ...] = ()

    @property
    def dearest(self) -> float:
        """A serving UAV's dearest step: a move, a stay, or any climb or descent."""
        return max(self.move, self.stay, *self.climb, *self.descend)

    @property
    def cheapest(self) -> float:
        """A serving UAV's cheapest step."""
        return min(self.move, self.stay, *self.climb, *self.descend)

    def flight(self, steps: int) -> float:
        """The energy of the flight to a base ``steps`` steps away."""
        return steps * self.fly + (self.arrive if steps > 0 else 0.0)

    def reserve(self, steps: int) -> float:
        """The largest reserve at a cell ``steps`` from the base, where no neighbour lies farther (the farthest
        cell): one more step, the dearest, then the flight."""
        return self.dearest + self.flight(steps)


def step_energies(
    energy: str,
    cell_size: float,
    slot_s: float,
    comm_power_w: float,
    circuit_power_w: float,
    battery_wh: float,
    altitudes_m: tuple[float, ...] | None = None,
) -> StepEnergies:
    """The :class:`StepEnergies` of ``energy`` (``follow_up`` or ``rotary_wing``): a move flies one cell at
    ``cell_size / slot_s`` m/s, a climb or descent the gap between two levels in a step (:func:`vertical_propulsion`;
    the follow-up, which has no altitude, charges it as a move); a serving UAV also transmits at ``comm_power_w``
    and runs its radio's circuit.

    Args:
        energy: ``"follow_up"`` (the follow-up paper's fixed costs; the other arguments unused) or ``"rotary_wing"``.
        cell_size: a cell's side in m.
        slot_s: a step's duration in s.
        comm_power_w: a serving UAV's transmit power in W.
        circuit_power_w: its radio circuit's power in W.
        battery_wh: a full battery in Wh.
        altitudes_m: the altitude levels' heights in m, ascending (``None``: one height, no climb).

    Returns:
        The energies: ``rotary_wing``'s in J (a full battery is ``battery_wh`` times 3600 J), ``follow_up``'s in
        the follow-up's own units (a full battery is 5000).
    """
    rises = [high - low for low, high in itertools.pairwise(altitudes_m)] if altitudes_m else []
    if energy == "follow_up":
        move = FOLLOW_UP_MOVE + FOLLOW_UP_TRANSMISSION
        return StepEnergies(
            move=move,
            stay=FOLLOW_UP_TRANSMISSION,
            fly=0.0,
            arrive=FOLLOW_UP_REGION_FLIGHT,
            capacity=FOLLOW_UP_CAPACITY,
            moves_by_action=True,
            climb=(move,) * len(rises),
            descend=(move,) * len(rises),
        )
    radio = comm_power_w + circuit_power_w
    flying = propulsion_power(cell_size / slot_s)
    return StepEnergies(
        move=(flying + radio) * slot_s,
        stay=(propulsion_power(0.0) + radio) * slot_s,
        fly=flying * slot_s,
        arrive=0.0,
        capacity=battery_wh * 3600.0,
        moves_by_action=False,
        climb=tuple(vertical_propulsion(rise, slot_s) + radio * slot_s for rise in rises),
        descend=tuple(vertical_propulsion(-rise, slot_s) + radio * slot_s for rise in rises),
    )


# the options a battery's reach depends on, in the order a refusal blames them, and how each would let it reach
BATTERY_ADVICE = {
    "circuit_power_w": "give a smaller circuit power, a larger battery or a nearer base",
    "slot_s": "give a shorter slot, a larger battery or a nearer base",
    "cell_size": "give smaller cells, a larger battery or a nearer base",
    "base": "give a nearer base or a larger battery",
    "grid": "give a smaller grid, a nearer base or a larger battery",
    "battery_wh": "give a larger battery or a nearer base",
    "battery_init": "start full, or give a larger battery or a nearer base",
}


def lowest_start_and_largest_reserve(cfg, **changes) -> tuple[float, float, int]:
    """The lowest battery a UAV of the model ``cfg`` may start with, the largest reserve of a cell (the farthest from
    the base's), and that cell's steps from the base, under an energy model (with the options ``changes`` in place
    of these)."""
    v = {name: changes.get(name, getattr(cfg, name)) for name in BATTERY_ADVICE}
    (L1, L2), (bx, by) = v["grid"], v["base"]
    farthest = max(abs(x - bx) for x in (0, L1 - 1)) + max(abs(y - by) for y in (0, L2 - 1))
    energies = step_energies(cfg.energy, v["cell_size"], v["slot_s"], cfg.powers_w[2], v["circuit_power_w"],
                             v["battery_wh"], cfg.altitudes_m)  # fmt: skip
    lowest = energies.capacity * (UNIFORM_LOW if v["battery_init"] == "uniform" else 1.0)
    return lowest, energies.reserve(farthest), farthest


def battery_blamed(cfg, preset: dict) -> str:
    """The option to name when a battery of the model ``cfg`` cannot reach the base: the first one set away from its
    ``preset`` value whose preset value would let it, else the battery (the base under follow_up)."""
    for name in BATTERY_ADVICE:
        value = getattr(cfg, name)
        if value == preset[name] or (name == "base" and abs(value[0]) + abs(value[1]) <= 1):
            continue
        try:
            lowest, need, _ = lowest_start_and_largest_reserve(cfg, **{name: preset[name]})
        except (OverflowError, ValueError):
            continue
        if lowest > need:
            return name
    return "battery_wh" if cfg.energy == "rotary_wing" else "base"


def steps_before_reserve(cfg) -> int:
    """The most steps after which no battery of the model ``cfg`` (an energy model) can have reached its cell's
    reserve, however the UAVs act: every step at the dearest from the lowest start."""
    lowest, need, _ = lowest_start_and_largest_reserve(cfg)
    return math.ceil((lowest - need) / cfg.step_energies.dearest) - 1


def check_step_energies(cfg, default_slot_s: float) -> None:
    """rotary_wing's step energies are finite numbers: a slot so short that a move flies faster than a float's
    range (its propulsion power overflows) is refused naming ``slot_s``, and a battery beyond a float's range in
    joules naming ``battery_wh``."""
    try:
        energies = cfg.step_energies
        moving = (energies.move, energies.stay, energies.fly, *energies.climb, *energies.descend)
    except OverflowError:
        moving = (math.inf,)
    if not all(math.isfinite(value) for value in moving):
        speed = cfg.cell_size / cfg.slot_s
        reason = (
            f"a move of one cell (cell_size={cfg.cell_size!r} m) in it flies at {speed:.3g} m/s, whose propulsion "
            f"power overflows: give a slot of a realistic length (the default is {default_slot_s!r} s)"
        )
        raise InvalidOption("slot_s", cfg.slot_s, reason)
    if not math.isfinite(energies.capacity):
        raise InvalidOption("battery_wh", cfg.battery_wh, "in joules it overflows a float: give a smaller battery")


def check_energy_options(cfg, default_slot_s: float) -> tuple[int, ...]:
    """An energy model's options (``cfg.energy`` not ``none``) that go with it, each refused in one line: finite step
    energies, recharging (a whole number of steps; not with altitude levels), spares (only with recharging), a base
    off the grid, the AF rate model, random positions at a reset.  Returns the base as a pair of ints."""
    if cfg.energy == "rotary_wing":
        check_step_energies(cfg, default_slot_s)
    if cfg.recharge_steps is not None and not (is_whole(cfg.recharge_steps) and cfg.recharge_steps >= 1):
        reason = "give the whole number of steps >= 1 a battery takes to charge, or null for no recharging"
        raise InvalidOption("recharge_steps", cfg.recharge_steps, reason)
    if cfg.recharge_steps is not None and cfg.num_levels > 1:
        reason = "recharging with altitude levels is not modelled (return and climb would share action 6): give null"
        raise InvalidOption("recharge_steps", cfg.recharge_steps, reason)
    if not is_whole(cfg.num_spares) or cfg.num_spares < 0:
        raise InvalidOption("num_spares", cfg.num_spares, "give the whole number >= 0 of UAVs waiting at the base")
    if cfg.num_spares > 0 and cfg.recharge_steps is None:
        reason = "a spare enters when a UAV leaves for the base and recharges there: give recharge_steps too"
        raise InvalidOption("num_spares", cfg.num_spares, reason)
    if cfg.base is None:
        reason = "a UAV leaves service for its base: give base=[x, y], a cell off the grid"
        raise InvalidOption("energy", cfg.energy, reason)
    if not is_pair(cfg.base):
        raise InvalidOption("base", cfg.base, "give two integers x, y (cells; off the grid too), e.g. [-1, 0]")
    base = tuple(int(b) for b in cfg.base)
    L1, L2 = cfg.grid
    if 0 <= base[0] < L1 and 0 <= base[1] < L2:  # a UAV shown at the base is then never one serving there
        reason = f"a UAV out of service is shown at the base, off the grid: give a cell off the {L1}x{L2} grid"
        raise InvalidOption("base", list(base), reason)
    if cfg.rate_model == "reference_code":
        reason = "the authors' both-tasks rule counts every UAV, in service or not: use rate_model='af'"
        raise InvalidOption("energy", cfg.energy, reason)
    if cfg.reset_positions == "keep":
        reason = "a UAV that left service has no cell to keep: use reset_positions='random'"
        raise InvalidOption("energy", cfg.energy, reason)
    return base


def check_battery_reach(cfg, preset: dict) -> None:
    """A battery of the model ``cfg`` (its options checked) that starts above the largest reserve, else one line
    naming the option to change (:func:`battery_blamed` against ``preset``'s values) and, where a climb is the dearest
    step, the climb."""
    lowest, need, farthest = lowest_start_and_largest_reserve(cfg)
    if lowest > need:
        return
    name = battery_blamed(cfg, preset)
    unit, scale = ("Wh", 3600.0) if cfg.energy == "rotary_wing" else ("units", 1.0)
    climbs, step = cfg.step_energies.climb, "one step"
    if climbs and max(climbs) == cfg.step_energies.dearest:  # a climb decides it: say which
        k = climbs.index(max(climbs))
        step = f"its dearest step (a climb of {cfg.altitudes_m[k + 1] - cfg.altitudes_m[k]:g} m)"
    reason = (
        f"a UAV may start with {lowest / scale:.4g} {unit} ({cfg.battery_init}) at the cell farthest from the base "
        f"{list(cfg.base)}, {farthest} steps away, where {step} and the flight to the base take {need / scale:.4g} "
        f"{unit}: {BATTERY_ADVICE[name]}"
    )
    raise InvalidOption(name, list(cfg.base) if name == "base" else getattr(cfg, name), reason)
