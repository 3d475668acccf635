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
import numbers
import re
from dataclasses import dataclass, field

from .limits import PHYSICAL, allowed_range, physics_problem

ACTION_NAMES = ("up", "down", "left", "right", "sense", "relay")
NUM_ACTIONS = len(ACTION_NAMES)
SENSING, RELAYING = 0, 1
NODE_NAMES = ("PT", "PR", "S", "E")

LAYOUTS = ("line", "random", "reference_code")
FADINGS = ("none", "rayleigh")
REWARDS = ("delta", "best_so_far", "log_gap")
RATE_MODELS = ("af", "reference_code")
INIT_TASKS = ("random", "sensing", "relaying")
RESET_POSITIONS = ("random", "keep")
PRESETS = ("paper", "reference_code")


class InvalidOption(ValueError):
    """``option=value is invalid: reason``, with ``option`` kept so a command line can name it as its user typed it."""

    def __init__(self, option: str, value, reason: str):
        super().__init__(f"{option}={value!r} is invalid: {reason}")
        self.option = option

    def renamed(self, names: dict[str, str]) -> str:
        """The message with each ``option=`` in ``names`` written as ``names[option]=`` (``grid=`` as ``env.grid=``)."""
        return re.sub(r"\b([a-z_0-9]+)=", lambda m: f"{names.get(m.group(1), m.group(1))}=", str(self))


@dataclass(frozen=True)
class ModelConfig:
    """One model of docs/model.md.  Lengths are in cells unless the name says metres.

    ``altitude`` of ``None`` means the paper's ``h = L1`` cells.  ``rate_model``
    ``"af"`` is the normalised amplify-and-forward form of docs/model.md (How good a configuration is);
    ``"reference_code"`` is the authors' published formula (docs/model.md, the authors' code),
    where ``reference_gain`` replaces the power products.
    """

    grid: tuple[int, int] = (6, 6)
    num_uavs: int = 2
    max_steps: int = 100
    layout: str = "line"
    cell_size: float = 10.0
    altitude: float | None = None
    alpha: float = 2.0
    g0: float = 1.0
    fading: str = "none"
    p_pt: float = 0.01
    p_s: float = 0.02
    p_u: float = 0.02
    noise: float = 1e-9
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
    preset: str = field(default="paper", compare=False)

    def __post_init__(self):
        grid = tuple(int(g) for g in self.grid) if _is_pair(self.grid) else None
        if grid is None or min(grid) < 1:
            raise InvalidOption("grid", self.grid, "give two integers L1, L2 >= 1, e.g. grid=(6, 6)")
        object.__setattr__(self, "grid", grid)
        cells = grid[0] * grid[1]
        if not _is_int(self.num_uavs) or not 1 <= self.num_uavs <= cells:
            reason = f"a {grid[0]}x{grid[1]} grid holds 1 to {cells} UAVs (one per cell)"
            raise InvalidOption("num_uavs", self.num_uavs, reason)
        if not _is_int(self.max_steps) or self.max_steps < 1:
            raise InvalidOption("max_steps", self.max_steps, "an episode needs a whole number of steps >= 1")
        object.__setattr__(self, "num_uavs", int(self.num_uavs))
        object.__setattr__(self, "max_steps", int(self.max_steps))
        _choice("layout", self.layout, LAYOUTS)
        _choice("fading", self.fading, FADINGS)
        _choice("reward", self.reward, REWARDS)
        _choice("rate_model", self.rate_model, RATE_MODELS)
        _choice("init_tasks", self.init_tasks, INIT_TASKS)
        _choice("reset_positions", self.reset_positions, RESET_POSITIONS)
        for name in ("p_pt", "p_s", "p_u", "noise", "cell_size", "g0", "alpha", "reference_gain"):
            value = getattr(self, name)
            if not (_is_real(value) and math.isfinite(value) and value > 0):
                raise InvalidOption(name, value, "it must be a finite positive number")
        for name in ("beta1", "beta2"):
            value = getattr(self, name)
            if not (_is_real(value) and math.isfinite(value)):
                raise InvalidOption(name, value, "it must be a finite number")
        if self.direct_links and self.rate_model == "reference_code":
            raise InvalidOption("direct_links", True, "the authors' rate_model='reference_code' has no direct link")
        if self.altitude is not None and not (
            _is_real(self.altitude) and math.isfinite(self.altitude) and self.altitude > 0
        ):
            raise InvalidOption("altitude", self.altitude, "give a finite positive height in cells, or None for h = L1")
        self._check_physics()

    def _check_physics(self):
        """A one-line refusal when the numbers would give NaN, infinite or everywhere-zero rates
        (:mod:`uavrl.envs.limits`), blaming the option whose preset value would pass, with the range that passes."""
        values = {name: getattr(self, name) for name in _PHYSICS_OPTIONS} | {"altitude": self.height}
        problem = physics_problem(values)
        if problem is None:
            return
        preset = {**_DEFAULTS, **_PRESETS.get(self.preset, {})}
        preset["altitude"] = float(self.grid[0]) if preset["altitude"] is None else preset["altitude"]
        changed = [name for name in (*PHYSICAL, "beta1", "beta2") if values[name] != preset[name]]
        for name in changed:
            if physics_problem({**values, name: preset[name]}) is None:
                reason = (
                    problem if name in ("beta1", "beta2") else f"{problem}; {allowed_range(values, name, preset[name])}"
                )
                raise InvalidOption(name, getattr(self, name), reason)
        name = changed[0] if changed else "grid"
        raise InvalidOption(name, getattr(self, name), problem)

    @property
    def num_cells(self) -> int:
        return self.grid[0] * self.grid[1]

    @property
    def height(self) -> float:
        """UAV altitude in cells: the paper's ``h = L1`` unless set."""
        return float(self.grid[0] if self.altitude is None else self.altitude)

    @property
    def num_joint_actions(self) -> int:
        return NUM_ACTIONS**self.num_uavs

    @property
    def num_states(self) -> int:
        """Size of the tabular state space (docs/model.md, the tabular learner), a Python int of any size."""
        base = 2 * self.num_cells if self.state_includes_tasks else self.num_cells
        return base**self.num_uavs

    @property
    def has_state_index(self) -> bool:
        return self.num_states <= 2**63 - 1

    def replace(self, **changes) -> "ModelConfig":
        return dataclasses.replace(self, **changes)


_PRESETS = {
    "paper": {},
    "reference_code": dict(
        layout="reference_code",
        cell_size=1.0,
        altitude=10.0,
        alpha=4.0,
        g0=2.0,
        rate_model="reference_code",
        reward="best_so_far",
        init_tasks="sensing",
    ),
}
_DEFAULTS = {f.name: f.default for f in dataclasses.fields(ModelConfig)}
# what uavrl.envs.limits reads
_PHYSICS_OPTIONS = (
    *("grid", "num_uavs", "layout", "fading", "direct_links", "rate_model", "reward"),
    *(name for name in PHYSICAL if name != "altitude"),
    *("beta1", "beta2"),
)
OPTION_NAMES = tuple(f.name for f in dataclasses.fields(ModelConfig) if f.name != "preset")


def make_config(preset: str = "paper", **overrides) -> ModelConfig:
    """A :class:`ModelConfig` from a preset name plus option overrides."""
    _choice("preset", preset, PRESETS)
    unknown = sorted(set(overrides) - set(OPTION_NAMES))
    if unknown:
        raise ValueError(f"unknown model option {unknown[0]!r}: allowed options are {', '.join(OPTION_NAMES)}")
    return ModelConfig(**{**_PRESETS[preset], **overrides}, preset=preset)


def _choice(name, value, allowed):
    if value not in allowed:
        raise InvalidOption(name, value, f"allowed values are {', '.join(map(repr, allowed))}")


def _is_int(value) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _is_real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _is_pair(value) -> bool:
    try:
        return len(value) == 2 and all(int(v) == v for v in value)
    except (TypeError, ValueError):
        return False
