"""The model's options (docs/model.md), their presets and their validation.

A :class:`ModelConfig` is an immutable description of one UAV spectrum-sharing
model: the grid, the UAVs, the channel, the rate formulas, the reward and the
episode rules.  Every part of uavrl (environment, optimum, learners) reads its
numbers from here.

Example:
    >>> cfg = make_config("paper", grid=(6, 6), num_uavs=2)
    >>> cfg.num_cells, cfg.height  # h = L1 cells unless env.altitude is set
    (36, 6.0)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from .errors import InvalidOption, is_pair, is_whole
from .limits import PHYSICAL, allowed_range, is_number, physics_problem, radio_problem
from .physics import power, radio, sensing

ACTION_NAMES = ("up", "down", "left", "right", "sense", "relay")
NUM_ACTIONS = len(ACTION_NAMES)  # the paper's actions; altitude levels add CLIMB, DESCEND, recharging RETURN
RETURN = NUM_ACTIONS  # "return": fly home to recharge (docs/model.md, Energy and lifetime)
CLIMB, DESCEND = NUM_ACTIONS, NUM_ACTIONS + 1  # one level up or down (docs/model.md, Altitude as a decision)
VERTICAL_NAMES = ("climb", "descend")
MAX_LEVELS = 64  # altitude levels: more would not be a decision between heights but a continuum
SENSING, RELAYING = 0, 1

LAYOUTS = ("line", "random", "reference_code")
FADINGS = ("none", "rayleigh", "los_nlos", "rician")  # uavrl.envs.physics.fading: one part each
REWARDS = ("delta", "best_so_far", "log_gap", "delivered")
RATE_MODELS = ("af", "reference_code")
INIT_TASKS = ("random", "sensing", "relaying")
RESET_POSITIONS = ("random", "keep")
ENERGIES = power.ENERGIES
BATTERY_INITS = power.BATTERY_INITS
# the options only an energy model reads, and those only rotary_wing reads (docs/model.md, Energy and lifetime)
ENERGY_OPTIONS = ("base", "battery_init", "recharge_steps", "num_spares")
ROTARY_WING_OPTIONS = ("battery_wh", "slot_s", "circuit_power_w")
CHANNELS = radio.CHANNELS
ENVIRONMENTS = radio.ENVIRONMENTS
CITIES = ("none", *radio.P1410)  # docs/model.md, Cities of buildings: ITU-R P.1410's four environments
LOS_MODELS = ("geometric", "statistical")
# the options only a city reads (docs/model.md, Cities of buildings)
CITY_OPTIONS = ("city_alpha", "city_beta", "city_gamma", "city_seed", "los")
CITY_SEED_LIMIT = 2**63  # a city's seed is an int64, as a world's is
HELD_OUT_CITY_SEEDS = 2**62  # city seeds from here name the benchmark's held-out cities: no training run lays one out
PRESETS = ("paper", "reference_code", "a2g_urban")
# the options only the power laws read, and those only the physical channels read (docs/model.md, Channel models)
POWER_LAW_OPTIONS = ("alpha", "g0", "p_pt", "p_s", "p_u", "noise")
PHYSICAL_OPTIONS = ("environment", "carrier_ghz", "bandwidth_mhz", "noise_figure_db", "p_pt_dbm", "p_s_dbm", "p_u_dbm")


def action_names(num_actions: int) -> str:
    """A UAV's ``num_actions`` actions in words for a one-line error: ``0..5 (up, down, left, right, sense, relay)``,
    and ``return`` (6) with recharging, or ``climb`` (6) and ``descend`` (7) with altitude levels (the two never
    together)."""
    names = ACTION_NAMES + {NUM_ACTIONS + 1: ("return",), NUM_ACTIONS + 2: VERTICAL_NAMES}.get(num_actions, ())
    return f"0..{len(names) - 1} ({', '.join(names)})"


# the model's arguments of UAVSpectrumEnv and the adapters besides config=, and their defaults
MODEL_ARGUMENTS = {"grid": (6, 6), "num_uavs": 2, "preset": "paper", "max_steps": 100}


def check_config_alone(config, overrides: dict, **arguments) -> None:
    """With ``config=`` (a complete model) nothing else may describe the model: a model option, or one of
    :data:`MODEL_ARGUMENTS` changed from its default, is refused naming it (it would be ignored)."""
    if config is None:
        return
    given = sorted(overrides) + [name for name, value in arguments.items() if value != MODEL_ARGUMENTS[name]]
    if given:
        message = f"give either config= or model options, not both (got {given})"
        raise InvalidOption(given[0], message=message)


@dataclass(frozen=True)
class ModelConfig:
    """One model of docs/model.md.  Lengths are in cells unless the name says metres.

    ``altitude`` of ``None`` means the paper's ``h = L1`` cells (``altitude_m`` gives it in metres instead).
    ``channel`` picks the mean gain of a link (docs/model.md, Channel models): the power laws ``paper`` and
    ``reference_code`` read ``g0``, ``alpha`` (``None``: the channel's own, 1 and 2 or 2 and 4), powers and noise
    in W; the physical models (``al_hourani``, ``tr36777_uma``, ``tr36777_umi``, ``tr36777_rma``) read
    ``carrier_ghz``, ``bandwidth_mhz``, ``noise_figure_db`` and powers in dBm.  ``rate_model``
    ``"af"`` is the normalised amplify-and-forward form of docs/model.md (How good a configuration is);
    ``"reference_code"`` is the authors' published formula (docs/model.md, the authors' code),
    where ``reference_gain`` replaces the power products.  ``fading`` draws every link's power gain anew each step
    (:mod:`uavrl.envs.physics.fading`); ``rician_k_db`` is the K-factor of ``fading="rician"`` in dB.  ``energy`` gives
    the UAVs batteries (:mod:`uavrl.envs.physics.energy`): a UAV leaves service for the ``base`` when its battery
    reaches the reserve the flight there needs (or, given ``recharge_steps``, when the controller sends it home), and
    either stays out or recharges there for ``recharge_steps`` steps; ``num_spares`` more UAVs wait charged at the base
    to keep ``num_uavs`` in service; ``battery_wh``, ``slot_s`` and ``circuit_power_w`` are ``rotary_wing``'s.
    Build one with :func:`make_config` (a preset plus overrides); every option is checked here, a bad one raises
    :class:`InvalidOption` in one line.

    Args:
        grid: ``(L1, L2)`` cells.
        num_uavs: ``N``, the UAVs in service, 1 to ``L1 L2``.
        max_steps: the episode length ``T`` in steps.
        layout: where PT, PR, S and E are: ``"line"`` (on a line through the grid's middle), ``"random"`` (drawn
            per world at each reset) or ``"reference_code"`` (the authors' code's fixed positions).
        cell_size: a cell's side in m.
        altitude: the UAVs' (and S's and E's) height in cells; None: ``L1`` (or ``altitude_m``).
        altitude_m: the same height in m; give at most one of the two.
        altitudes_m: the UAVs' altitude levels in m, ascending (None: one level, the height above); the UAVs climb
            and descend one level a step, and S and E fly at the height above.
        channel: the mean gain of a link: ``"paper"``, ``"reference_code"`` (power laws), ``"al_hourani"``,
            ``"tr36777_uma"``, ``"tr36777_umi"`` or ``"tr36777_rma"`` (physical models).
        alpha: the power law's path-loss exponent; None: the channel's own (2 for ``paper``, 4 for
            ``reference_code``).
        g0: the power law's gain at unit distance; None: the channel's own (1 or 2).
        fading: ``"none"``, ``"rayleigh"``, ``"los_nlos"`` or ``"rician"``: each link's power gain drawn anew each step.
        rician_k_db: the K-factor of ``fading="rician"`` in dB.
        p_pt: PT's transmit power in W (power laws).
        p_s: S's transmit power in W (power laws).
        p_u: a UAV's transmit power in W (power laws).
        noise: the noise power in W (power laws).
        environment: the Al-Hourani environment of ``channel="al_hourani"``: ``"suburban"``, ``"urban"``,
            ``"dense_urban"`` or ``"highrise"``.
        carrier_ghz: the carrier frequency in GHz (physical models).
        bandwidth_mhz: the bandwidth in MHz, which sets the noise power (physical models).
        noise_figure_db: the receivers' noise figure in dB (physical models).
        p_pt_dbm: PT's transmit power in dBm (physical models).
        p_s_dbm: S's transmit power in dBm (physical models).
        p_u_dbm: a UAV's transmit power in dBm (physical models).
        city: a city of buildings over the area (a physical channel): ``"none"``, or the ITU-R P.1410 environment
            ``"suburban"``, ``"urban"``, ``"dense_urban"`` or ``"highrise"`` whose (alpha, beta, gamma) it has.
        city_alpha: the city's ratio of land covered by buildings, in (0, 1); None: the environment's.
        city_beta: its buildings per km^2; None: the environment's.
        city_gamma: the Rayleigh scale of its building heights in m; None: the environment's.
        city_seed: which city of those parameters (an integer >= 0): the seed that lays it out.
        los: whether a link of a city is in line of sight: ``"geometric"`` (its segment clears every building) or
            ``"statistical"`` (the channel's probability of the elevation angle, as without a city).
        direct_links: add the direct links PT to PR and S to E inside the rates' logarithms.
        lease_rule: the emergency network gets no rate unless some UAV relays for the primary one (docs/model.md,
            The picture).
        rate_model: ``"af"`` or ``"reference_code"`` (above).
        reference_gain: the power products' replacement in ``rate_model="reference_code"``.
        reward: ``"delta"`` (the paper's), ``"best_so_far"`` (the authors' code's), ``"log_gap"`` or ``"delivered"``
            (docs/model.md, Rewards and episodes).
        beta1: the weight of R_PU in the reward.
        beta2: the weight of R_SE in the reward.
        init_tasks: the UAVs' tasks at a reset: ``"random"``, ``"sensing"`` or ``"relaying"`` (all alike).
        reset_positions: ``"random"`` (distinct random cells at each reset) or ``"keep"`` (continue from where the
            last episode ended).
        state_includes_tasks: the tabular state also holds the UAVs' tasks (the paper's holds their cells only).
        energy: ``"none"``, ``"follow_up"`` or ``"rotary_wing"``: the UAVs' batteries and what a step costs.
        base: the base's cell ``(x, y)``, on the grid or off it; an energy model needs one.
        battery_wh: a full battery in Wh.
        battery_init: the batteries at a reset: ``"full"``, or ``"uniform"`` (each drawn uniformly from 80% to 100%
            of full).
        recharge_steps: the steps a UAV recharges at the base; None: a UAV that left service stays out.
        num_spares: UAVs beyond ``num_uavs`` waiting charged at the base (needs ``recharge_steps``).
        slot_s: a step's duration in s.
        circuit_power_w: a serving UAV's radio circuit power in W.
        observation: what a UAV observes: ``"central"`` (every UAV and node) or ``"local"`` (its own state and what
            lies within ``comm_radius``: :mod:`uavrl.envs.physics.sensing`).
        comm_radius: how far a UAV hears (cells, or m under a physical channel); None: every UAV and node.
        message_size: the numbers each UAV sends a step, read by those within range at the next step (0: none).
        preset: the preset the options came from (:func:`make_config` sets it; one-line errors name its values);
            not compared between configurations.

    Example:
        >>> cfg = make_config("paper", grid=(4, 4), num_uavs=3)
        >>> cfg.grid, cfg.num_uavs, cfg.layout
        ((4, 4), 3, 'line')
        >>> cfg.replace(num_uavs=20)
        Traceback (most recent call last):
        ...
        uavrl.envs.errors.InvalidOption: num_uavs=20 is invalid: a 4x4 grid holds 1 to 16 UAVs (one per cell)
    """

    grid: tuple[int, int] = (6, 6)
    num_uavs: int = 2
    max_steps: int = 100
    layout: str = "line"
    cell_size: float = 10.0
    altitude: float | None = None
    altitude_m: float | None = None
    altitudes_m: tuple[float, ...] | None = None
    channel: str = "paper"
    alpha: float | None = None
    g0: float | None = None
    fading: str = "none"
    rician_k_db: float = 9.0  # fading=rician's K-factor: TR 38.901's mean LoS K of UMa (docs/model.md, Channel models)
    p_pt: float = 0.01
    p_s: float = 0.02
    p_u: float = 0.02
    noise: float = 1e-9
    # the physical channels' defaults: the a2g_urban preset's (docs/model.md, Channel models, for their sources)
    environment: str = "urban"
    carrier_ghz: float = 2.0
    bandwidth_mhz: float = 10.0
    noise_figure_db: float = 9.0
    p_pt_dbm: float = 46.0
    p_s_dbm: float = 23.0
    p_u_dbm: float = 23.0
    city: str = "none"
    city_alpha: float | None = None
    city_beta: float | None = None
    city_gamma: float | None = None
    city_seed: int = 0
    los: str = "geometric"
    direct_links: bool = False
    lease_rule: bool = True
    rate_model: str = "af"
    reference_gain: float = 200.0
    reward: str = "delta"
    beta1: float = 1.0
    beta2: float = 1.0
    init_tasks: str = "random"
    reset_positions: str = "random"
    state_includes_tasks: bool = False
    energy: str = "none"
    base: tuple[int, int] | None = None  # the base's cell (x, y), on the grid or off it; an energy model needs one
    battery_wh: float = power.BATTERY_WH
    battery_init: str = "full"
    recharge_steps: int | None = None  # steps a UAV at the base recharges; None: a UAV that left stays out
    num_spares: int = 0  # UAVs beyond num_uavs waiting charged at the base (recharge_steps needed)
    slot_s: float = power.SLOT_S
    circuit_power_w: float = power.CIRCUIT_POWER_W
    observation: str = "central"
    comm_radius: float | None = None
    message_size: int = 0
    preset: str = field(default="paper", compare=False)

    def __post_init__(self):
        grid = tuple(int(g) for g in self.grid) if is_pair(self.grid) else None
        if grid is None or min(grid) < 1:
            raise InvalidOption("grid", self.grid, "give two integers L1, L2 >= 1, e.g. grid=(6, 6)")
        object.__setattr__(self, "grid", grid)
        cells = grid[0] * grid[1]
        if not is_whole(self.num_uavs) or not 1 <= self.num_uavs <= cells:
            reason = f"a {grid[0]}x{grid[1]} grid holds 1 to {cells} UAVs (one per cell)"
            if is_whole(self.num_uavs) and self.num_uavs == _DEFAULTS["num_uavs"] and grid != _DEFAULTS["grid"]:
                # the team left as it was: the grid is what was changed
                raise InvalidOption("grid", self.grid, f"{reason}, and num_uavs is {self.num_uavs}")
            raise InvalidOption("num_uavs", self.num_uavs, reason)
        if not is_whole(self.max_steps) or self.max_steps < 1:
            raise InvalidOption("max_steps", self.max_steps, "an episode needs a whole number of steps >= 1")
        object.__setattr__(self, "num_uavs", int(self.num_uavs))
        object.__setattr__(self, "max_steps", int(self.max_steps))
        _choice("layout", self.layout, LAYOUTS)
        _choice("channel", self.channel, CHANNELS)
        self._resolve_channel()
        _choice("fading", self.fading, FADINGS)
        _choice("reward", self.reward, REWARDS)
        _choice("rate_model", self.rate_model, RATE_MODELS)
        _choice("init_tasks", self.init_tasks, INIT_TASKS)
        _choice("reset_positions", self.reset_positions, RESET_POSITIONS)
        for name in ("p_pt", "p_s", "p_u", "noise", "cell_size", "g0", "alpha", "reference_gain"):
            value = getattr(self, name)
            if value is None and name in POWER_LAW_OPTIONS:  # a physical channel has no g0 and alpha
                continue
            if not (is_number(value) and value > 0):
                raise InvalidOption(name, value, "it must be a finite positive number")
        for name in ("beta1", "beta2", "rician_k_db"):
            value = getattr(self, name)
            if not is_number(value):
                raise InvalidOption(name, value, "it must be a finite number")
        if self.fading != "rician" and self.rician_k_db != _DEFAULTS["rician_k_db"]:
            reason = f"only fading='rician' reads it, not fading={self.fading!r}"
            raise InvalidOption("rician_k_db", self.rician_k_db, reason)
        if self.direct_links and self.rate_model == "reference_code":
            raise InvalidOption("direct_links", True, "the authors' rate_model='reference_code' has no direct link")
        if self.altitude is not None and not (is_number(self.altitude) and self.altitude > 0):
            raise InvalidOption("altitude", self.altitude, "give a finite positive height in cells, or None for h = L1")
        if self.altitude_m is not None:
            if not (is_number(self.altitude_m) and self.altitude_m > 0):
                raise InvalidOption("altitude_m", self.altitude_m, "give a finite positive height in metres, or None")
            if self.altitude is not None:
                reason = f"give the height once: altitude={self.altitude:g} (in cells) is set too"
                raise InvalidOption("altitude_m", self.altitude_m, reason)
        if self.is_physical:
            self._check_radio()
        self._check_city()
        self._check_physics()
        self._check_levels()  # before the energy model, whose climbs cost what the levels' heights say
        self._check_energy()
        sensing.check_observation(self.observation, self.comm_radius, self.message_size, self.is_physical)

    def _resolve_channel(self):
        """``g0`` and ``alpha`` of ``None`` become the power law's own; a channel refuses the options it does not read
        (left at a value other than the default, they would be silently ignored)."""
        if self.channel in radio.POWER_LAWS:
            g0, alpha = radio.POWER_LAWS[self.channel]
            object.__setattr__(self, "g0", g0 if self.g0 is None else self.g0)
            object.__setattr__(self, "alpha", alpha if self.alpha is None else self.alpha)
            unread, reads = PHYSICAL_OPTIONS, f"the physical channels {', '.join(map(repr, radio.PHYSICAL_CHANNELS))}"
        else:
            unread, reads = POWER_LAW_OPTIONS, "the power-law channels 'paper' and 'reference_code' (powers in W)"
        for name in unread:
            value = getattr(self, name)
            if value is not None and value != _DEFAULTS[name]:
                reason = f"only {reads} read it, not channel={self.channel!r}"
                if name in ("p_pt", "p_s", "p_u"):
                    reason += f": give the power in dBm as {name}_dbm"
                raise InvalidOption(name, value, reason)
        if self.channel in radio.TR36777 and self.environment != _DEFAULTS["environment"]:
            reason = (
                f"only channel='al_hourani' reads it, not channel={self.channel!r}, whose TR 36.777 scenario is the "
                f"environment (choose among {', '.join(map(repr, radio.TR36777))})"
            )
            raise InvalidOption("environment", self.environment, reason)
        if self.is_physical and self.rate_model == "reference_code":
            reason = "the authors' formula multiplies the power law's gains; use channel='paper' or 'reference_code'"
            raise InvalidOption("rate_model", self.rate_model, reason)
        if not self.is_physical and self.fading == "los_nlos":
            physical = " or ".join(map(repr, radio.PHYSICAL_CHANNELS))
            reason = f"channel={self.channel!r} has no line-of-sight state: use {physical}"
            raise InvalidOption("fading", self.fading, reason)
        if self.is_physical and self.direct_links:
            reason = f"channel={self.channel!r} has no model of the ground-to-ground link PT-PR"
            raise InvalidOption("direct_links", True, reason)

    def _check_radio(self):
        """The physical channels' options within where their models hold (:func:`uavrl.envs.limits.radio_problem`)."""
        _choice("environment", self.environment, ENVIRONMENTS)
        values = {name: getattr(self, name) for name in (*_PHYSICS_OPTIONS, "altitude_m")} | {"altitude": self.height}
        problem = radio_problem(values)
        if problem is not None:
            name, reason = problem
            raise InvalidOption(name, getattr(self, name), reason)

    def _check_levels(self):
        """Altitude levels: ascending distinct finite heights in m, each one where the channel holds and the rates are
        finite, as the one height is checked."""
        if self.altitudes_m is None:
            return
        levels = self.altitudes_m
        if isinstance(levels, (str, bytes)) or not hasattr(levels, "__len__") or not 1 <= len(levels) <= MAX_LEVELS:
            reason = f"give a list of 1 to {MAX_LEVELS} heights in m, ascending, e.g. [30, 100, 300]"
            raise InvalidOption("altitudes_m", levels, reason)
        if not all(is_number(h) and h > 0 for h in levels) or list(levels) != sorted(set(levels)):
            raise InvalidOption("altitudes_m", list(levels), "give distinct finite heights above 0 m, ascending")
        object.__setattr__(self, "altitudes_m", tuple(float(h) for h in levels))
        for metres in self.altitudes_m:
            values = {name: getattr(self, name) for name in (*_PHYSICS_OPTIONS, "altitude_m")}
            values |= {"altitude": metres / self.cell_size, "altitude_m": metres}
            problem = (radio_problem(values) if self.is_physical else None) or (None, physics_problem(values))
            if problem[1] is not None:
                reason = problem[1].removesuffix(" (altitude_m sets the height in metres)")
                raise InvalidOption("altitudes_m", list(self.altitudes_m), f"the level {metres:g} m: {reason}")

    @property
    def num_levels(self) -> int:
        """The UAVs' altitude levels: 1 unless ``altitudes_m`` gives several."""
        return 1 if self.altitudes_m is None else len(self.altitudes_m)

    @property
    def level_heights(self) -> tuple[float, ...]:
        """The UAVs' heights in cells, one per level (``height`` alone without ``altitudes_m``)."""
        return (self.height,) if self.altitudes_m is None else tuple(h / self.cell_size for h in self.altitudes_m)

    @property
    def num_positions(self) -> int:
        """The (cell, level) positions a UAV may take at most (those inside no building, in a city)."""
        return self.num_cells * self.num_levels

    def _check_city(self):
        """A city's options: refused where no city reads them, a city only under a physical channel (the power laws
        have no line-of-sight state), Al-Hourani's excess losses fitted to the city's own environment, numbers within
        P.1410's ranges (docs/model.md, Cities of buildings)."""
        _choice("city", self.city, CITIES)
        _choice("los", self.los, LOS_MODELS)
        if self.city == "none":
            for name in CITY_OPTIONS:
                if getattr(self, name) != _DEFAULTS[name]:
                    raise InvalidOption(name, getattr(self, name), "only a city reads it, not city='none'")
            return
        if not self.is_physical:
            physical = ", ".join(map(repr, radio.PHYSICAL_CHANNELS))
            reason = f"channel={self.channel!r} has no line-of-sight state for buildings to decide: use {physical}"
            raise InvalidOption("city", self.city, reason)
        if self.channel == "al_hourani" and self.environment != self.city:
            # eta_LoS and eta_NLoS were fitted to one environment's cities: the city's, unless said otherwise
            blamed = "city" if self.environment == _DEFAULTS["environment"] else "environment"
            reason = (
                f"channel='al_hourani' takes its excess losses from environment={self.environment!r} and the city is "
                f"{self.city!r}: give environment={self.city!r} too"
            )
            raise InvalidOption(blamed, getattr(self, blamed), reason)
        for name, high in (("city_alpha", 1.0), ("city_beta", math.inf), ("city_gamma", math.inf)):
            value = getattr(self, name)
            if value is not None and not (is_number(value) and 0 < value < high):
                bound = " and below 1" if high == 1.0 else ""
                raise InvalidOption(name, value, f"it must be a finite number above 0{bound}, or None for the city's")
        if not is_whole(self.city_seed) or not 0 <= self.city_seed < CITY_SEED_LIMIT:
            raise InvalidOption("city_seed", self.city_seed, "give a whole number from 0 to 2**63 - 1")
        object.__setattr__(self, "city_seed", int(self.city_seed))

    @property
    def city_parameters(self) -> tuple[float, float, float] | None:
        """The city's ITU-R P.1410 ``(alpha, beta per km^2, gamma m)``: its environment's, each replaced where given;
        ``None`` without a city."""
        if self.city == "none":
            return None
        given = (self.city_alpha, self.city_beta, self.city_gamma)
        return tuple(
            float(own if value is None else value) for own, value in zip(radio.P1410[self.city], given, strict=True)
        )

    @property
    def geometric_los(self) -> bool:
        """Whether a link's line of sight comes from the city's buildings (``los="geometric"`` in a city)."""
        return self.city != "none" and self.los == "geometric"

    def _check_physics(self):
        """A one-line refusal when the numbers would give NaN, infinite or everywhere-zero rates
        (:mod:`uavrl.envs.limits`), blaming the option whose preset value would pass, with the range that passes."""
        values = {name: getattr(self, name) for name in _PHYSICS_OPTIONS} | {"altitude": self.height}
        problem = physics_problem(values)
        if problem is None:
            return
        preset = {**_DEFAULTS, **_PRESETS.get(self.preset, {})}
        g0, alpha = radio.POWER_LAWS.get(self.channel, (None, None))
        preset["g0"] = g0 if preset["g0"] is None else preset["g0"]
        preset["alpha"] = alpha if preset["alpha"] is None else preset["alpha"]
        if preset["altitude_m"] is not None:
            preset["altitude"] = preset["altitude_m"] / preset["cell_size"]
        preset["altitude"] = float(self.grid[0]) if preset["altitude"] is None else preset["altitude"]
        changed = [name for name in (*PHYSICAL, "beta1", "beta2") if values[name] != preset[name]]
        for name in changed:
            if physics_problem({**values, name: preset[name]}) is None:
                if name == "altitude" and self.altitude_m is not None:  # the height was given in metres
                    raise InvalidOption("altitude_m", self.altitude_m, problem)
                reason = (
                    problem if name in ("beta1", "beta2") else f"{problem}; {allowed_range(values, name, preset[name])}"
                )
                raise InvalidOption(name, getattr(self, name), reason)
        name = changed[0] if changed else "grid"
        raise InvalidOption(name, getattr(self, name), problem)

    def _check_energy(self):
        """An energy model's options: refused where no model reads them, a base where one is needed, finite
        positive numbers, and a battery that starts above the largest reserve (docs/model.md, Energy and
        lifetime)."""
        _choice("energy", self.energy, ENERGIES)
        _choice("battery_init", self.battery_init, BATTERY_INITS)
        for name in ("battery_wh", "slot_s", "circuit_power_w"):
            value = getattr(self, name)
            may_be_zero = name == "circuit_power_w"  # a radio may draw nothing beyond its transmit power
            if not (is_number(value) and (value >= 0 if may_be_zero else value > 0)):
                raise InvalidOption(
                    name, value, f"it must be a finite {'number >= 0' if may_be_zero else 'positive number'}"
                )
        unread = ENERGY_OPTIONS + ROTARY_WING_OPTIONS if self.energy == "none" else ()
        unread = ROTARY_WING_OPTIONS if self.energy == "follow_up" else unread
        for name in unread:
            if getattr(self, name) != _DEFAULTS[name]:
                reads = "an energy model (follow_up, rotary_wing)" if name in ENERGY_OPTIONS else "energy='rotary_wing'"
                raise InvalidOption(name, getattr(self, name), f"only {reads} reads it, not energy={self.energy!r}")
        if self.energy == "none":
            return
        object.__setattr__(self, "base", power.check_energy_options(self, _DEFAULTS["slot_s"]))
        power.check_battery_reach(self, {**_DEFAULTS, **_PRESETS.get(self.preset, {}), "base": (-1, 0)})

    @property
    def steps_before_reserve(self) -> int | None:
        """Under an energy model, the most steps after which no battery can have reached its cell's reserve, however
        the UAVs act (every step at the dearest, a move, a stay, a climb or a descent, from the lowest start): within
        an episode of at most that many steps no UAV leaves service, and the batteries change nothing else.
        ``None`` under ``energy=none``.

        Example:
            >>> make_config("paper", grid=(3, 3), energy="follow_up", base=(-1, 0)).steps_before_reserve
            3325
        """
        return None if self.energy == "none" else power.steps_before_reserve(self)

    @property
    def step_energies(self) -> power.StepEnergies:
        """What a step costs a UAV under ``energy`` (not ``none``): :func:`uavrl.envs.physics.power.step_energies`."""
        return power.step_energies(
            self.energy,
            self.cell_size,
            self.slot_s,
            self.powers_w[2],
            self.circuit_power_w,
            self.battery_wh,
            self.altitudes_m if self.num_levels > 1 else None,
        )

    @property
    def num_cells(self) -> int:
        return self.grid[0] * self.grid[1]

    @property
    def height(self) -> float:
        """UAV altitude in cells: the paper's ``h = L1`` unless ``altitude`` (cells) or ``altitude_m`` is set."""
        if self.altitude_m is not None:
            return self.altitude_m / self.cell_size
        return float(self.grid[0] if self.altitude is None else self.altitude)

    @property
    def is_physical(self) -> bool:
        """A channel model in physical units (docs/model.md, Channel models), not a power law."""
        return self.channel in radio.PHYSICAL_CHANNELS

    @property
    def powers_w(self) -> tuple[float, float, float]:
        """Transmit powers ``(P_PT, P_S, P_U)`` in W: the options in W of the power laws, in dBm of the others."""
        if self.is_physical:
            return tuple(radio.dbm_to_watts(p) for p in (self.p_pt_dbm, self.p_s_dbm, self.p_u_dbm))
        return self.p_pt, self.p_s, self.p_u

    @property
    def noise_w(self) -> float:
        """Noise power in W: ``noise`` for the power laws, ``-174 dBm/Hz + 10 log10(B) + NF`` for the others."""
        if self.is_physical:
            return radio.dbm_to_watts(radio.noise_dbm(self.bandwidth_mhz, self.noise_figure_db))
        return self.noise

    @property
    def bandwidth_hz(self) -> float | None:
        """The bandwidth in Hz of the physical channels (a rate in bit/s/Hz times it is in bit/s); ``None`` for the
        power laws, whose rates are per Hz."""
        return self.bandwidth_mhz * 1e6 if self.is_physical else None

    @property
    def fleet_size(self) -> int:
        """The UAVs of a world, every one an agent: ``num_uavs`` serve at most at once, ``num_spares`` more wait."""
        return self.num_uavs + self.num_spares

    @property
    def num_actions(self) -> int:
        """A UAV's actions: the paper's 6, ``climb`` and ``descend`` (:data:`CLIMB`, :data:`DESCEND`) with altitude
        levels, ``return`` (:data:`RETURN`) under an energy model that recharges."""
        return NUM_ACTIONS + (self.recharge_steps is not None) + 2 * (self.num_levels > 1)

    @property
    def joint_action_base(self) -> int:
        """A UAV's actions within a joint action of the tabular learner and the exact solvers: ``num_actions``
        without ``return``."""
        return NUM_ACTIONS + 2 * (self.num_levels > 1)

    @property
    def num_joint_actions(self) -> int:
        return self.joint_action_base**self.num_uavs

    @property
    def num_states(self) -> int:
        """Size of the tabular state space (docs/model.md, the tabular learner), a Python int of any size."""
        base = 2 * self.num_positions if self.state_includes_tasks else self.num_positions
        return base**self.num_uavs

    @property
    def has_state_index(self) -> bool:
        return self.num_states <= 2**63 - 1

    @property
    def local(self) -> bool:
        """Whether each UAV observes only what lies within ``comm_radius`` (``observation="local"``)."""
        return self.observation == "local"

    @property
    def comm_radius_cells(self) -> float:
        """How far a UAV hears, in cells (``comm_radius`` in m under a physical channel; ``inf``: every UAV)."""
        if self.comm_radius is None:
            return math.inf
        return self.comm_radius / self.cell_size if self.is_physical else float(self.comm_radius)

    def replace(self, **changes) -> "ModelConfig":
        return dataclasses.replace(self, **changes)


_PRESETS = {
    "paper": {},
    "reference_code": dict(
        layout="reference_code",
        cell_size=1.0,
        altitude=10.0,
        channel="reference_code",
        rate_model="reference_code",
        reward="best_so_far",
        init_tasks="sensing",
    ),
    # docs/model.md, Channel models: the sources of these numbers (and of the physical defaults of ModelConfig)
    "a2g_urban": dict(
        grid=(10, 10), num_uavs=6, channel="al_hourani", environment="urban", cell_size=50.0, altitude_m=100.0
    ),
}
_DEFAULTS = {f.name: f.default for f in dataclasses.fields(ModelConfig)}
# what uavrl.envs.limits reads
_PHYSICS_OPTIONS = (
    *("grid", "num_uavs", "layout", "fading", "direct_links", "rate_model", "reward", "channel", "environment"),
    *(name for name in PHYSICAL if name != "altitude"),
    *("beta1", "beta2"),
)
OPTION_NAMES = tuple(f.name for f in dataclasses.fields(ModelConfig) if f.name != "preset")


def make_config(preset: str = "paper", **overrides) -> ModelConfig:
    """A :class:`ModelConfig` from a preset name plus option overrides."""
    _choice("preset", preset, PRESETS)
    unknown = sorted(set(overrides) - set(OPTION_NAMES))
    if unknown:
        message = f"unknown model option {unknown[0]!r}: allowed options are {', '.join(OPTION_NAMES)}"
        raise InvalidOption(unknown[0], message=message)
    return ModelConfig(**{**_PRESETS[preset], **overrides}, preset=preset)


def preset_options(preset: str) -> dict:
    """The options the preset ``preset`` sets; every other option keeps :class:`ModelConfig`'s default."""
    _choice("preset", preset, PRESETS)
    return dict(_PRESETS[preset])


def _choice(name, value, allowed):
    if value not in allowed:
        raise InvalidOption(name, value, f"allowed values are {', '.join(map(repr, allowed))}")
