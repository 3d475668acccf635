r"""How a command over its budget is refused: the settings the command line typed (:class:`Typed`), the numbers a cost
grows with (:class:`Factor`), a cost as a function of them (:class:`Cost`) and the one line that names the setting
typed that grows it, the estimate and the changes that would fit it (:func:`refuse_over`; standard library and
omegaconf only).  What each part of a command costs is :mod:`uavrl.costs`'.

Example:
    >>> cells = Factor("env.grid", 100, least=4, label="the cells of env.grid")
    >>> worlds = Factor("agent.worlds", 64)
    >>> table = product("the Q tables", [worlds, cells], scale=8)
    >>> table.amount, table.formula()
    (51200, 'the Q tables (agent.worlds x the cells of env.grid = 64 x 100)')
    >>> try:
    ...     refuse_over([table], 40_000, "agent.memory_budget", "bytes", Typed(None, ["agent.worlds=64"]))
    ... except ValueError as refusal:
    ...     print(str(refusal).replace(": ", ":\n").replace(", over ", ", over\n"))
    agent.worlds=64 is invalid:
    the Q tables (agent.worlds x the cells of env.grid = 64 x 100) needs about 51,200 bytes, over
    agent.memory_budget=40000:
    lower agent.worlds or env.grid, or raise agent.memory_budget=<bytes>
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from omegaconf import DictConfig, ListConfig, OmegaConf

from uavrl.envs.limits import gib
from uavrl.envs.rules import shown

GROUPS = ("scenario", "env", "agent")  # config groups: a setting of one may come from the group's choice


class Typed:
    """The settings a command line typed, ``{name: value as typed}`` (``+`` and ``~`` dropped; a group choice such
    as ``env=a2g_urban`` under its group's name).  ``overrides=None`` (the Python API): every setting counts as
    given."""

    def __init__(self, cfg: DictConfig, overrides=None):
        self.cfg = cfg
        self.given = None if overrides is None else {}
        for override in overrides or ():
            key, _, value = str(override).partition("=")
            self.given[key.lstrip("+~")] = value

    def __contains__(self, name: str) -> bool:
        return self.given is None or name in self.given

    def shown(self, name: str) -> str:
        """``name=<value>``: as typed, else the config's value and the choice it came from."""
        if self.given is not None and name in self.given:
            return f"{name}={self.given[name]}"
        value = OmegaConf.select(self.cfg, name, default=None)
        if isinstance(value, (DictConfig, ListConfig)):
            value = OmegaConf.to_container(value, resolve=True)
        text = f"{name}={shown(value, label=True)}"
        if self.given is None:
            return text
        chosen = [g for g in GROUPS if g in self.given and (name.startswith(f"{g}.") or g == "scenario")]
        if "agent" in self.given and name == "env.max_steps":  # an agent's yaml sets its training episode length
            chosen.append("agent")
        return f"{text} ({'from ' + self.shown(chosen[0]) if chosen else 'the default'})"


@dataclass(frozen=True)
class Factor:
    """A number a cost grows with: ``name`` the setting as typed (words, ``fixed``, for what no setting sets),
    ``size`` how much of the cost it makes (a grid: its cells), ``least`` the size its smallest value gives;
    ``origin``: for a setting left null, the settings its value follows from; ``label`` names it in the formula."""

    name: str
    size: int
    least: int = 1
    origin: tuple[str, ...] = ()
    label: str = ""
    fixed: bool = False
    multiplies: bool = True  # the cost is proportional to it (else it grows with it some other way)

    def at(self, lowered: frozenset) -> int:
        """Its size, or its least where ``lowered`` names it."""
        return self.least if self.name in lowered else self.size


@dataclass(frozen=True)
class Cost:
    """What one part of a command needs (bytes, team steps or CPU seconds): ``estimate(lowered)`` is the amount with
    the factors named in ``lowered`` at their least, so a refusal advises only the settings that would help."""

    what: str
    factors: tuple[Factor, ...]
    estimate: Callable[[frozenset], int]
    hint: str = ""  # another change that helps, in words
    summed: bool = False  # parts added up: the formula of no single part describes it

    @property
    def amount(self) -> int:
        return self.estimate(frozenset())

    def formula(self) -> str:
        """``what (a x b = 2 x 3; with c 4)``: the factors it is proportional to, then the others."""
        if self.summed:
            return self.what
        product = [f for f in self.factors if f.multiplies and (f.size != 1 or not f.fixed)]
        names = " x ".join(f.label or f.name for f in product)
        parts = [f"{names} = {' x '.join(count(f.size) for f in product)}"] if product else []
        others = [f"{f.label or f.name} {count(f.size)}" for f in self.factors if not f.multiplies]
        parts += [f"with {', '.join(others)}"] if others else []
        return f"{self.what} ({'; '.join(parts)})"


def product(what: str, factors, scale: int = 1) -> Cost:
    """A cost of ``scale`` times the product of the factors' sizes."""
    factors = tuple(factors)
    return Cost(what, factors, lambda low: scale * math.prod(f.at(low) for f in factors))


def count(value) -> str:
    """A whole number with thousands separators, or ``2.7e+296`` beyond 15 digits."""
    value = int(value)
    if abs(value) < 10**15:
        return f"{value:,}"
    digits = len(str(abs(value))) - 1
    return f"{int(str(abs(value))[:3]) / 100:.3g}e+{digits:02d}" if digits > 300 else f"{float(value):.3g}"


UNITS = {"bytes": "<bytes>", "steps": "<steps>", "seconds": "<hours>"}


def refuse_over(costs: list[Cost], budget, budget_name: str, unit: str, typed: Typed) -> None:
    """A one-line ValueError for the first part over ``budget``, or for the parts together (they are held at once):
    the setting typed that grows it, the estimate and the changes that would bring it within the budget."""
    for cost in [*costs, *([total(costs, held=True)] if len(costs) > 1 else [])]:
        amount = cost.amount
        limit = budget * 3600 if unit == "seconds" else budget
        if amount > limit:
            raise ValueError(over_budget(cost, amount, limit, budget_name, unit, typed))


def _listed(changes: list[str]) -> str:
    """``lower a, lower b, use c``: the changes, the ``lower`` ones run together (``lower a or b``)."""
    lowered = [c.removeprefix("lower ") for c in changes if c.startswith("lower ")]
    rest = [c for c in changes if not c.startswith("lower ")]
    joined = ([f"lower {' or '.join(lowered)}"] if lowered else []) + rest
    return ", ".join(joined)


def over_budget(cost: Cost, amount: int, limit, budget_name: str, unit: str, typed: Typed) -> str:
    settings = [f for f in cost.factors if not f.fixed and f.size > f.least]

    def lowered(f: Factor) -> frozenset:  # a setting lowered, and the null settings whose value follows from it alone
        return frozenset({f.name, *(g.name for g in cost.factors if g.origin == (f.name,))})

    helps = [f for f in settings if cost.estimate(lowered(f)) <= limit]

    def given(f: Factor) -> bool:
        return f.name in typed or any(name in typed for name in f.origin)

    pool = helps or settings or [f for f in cost.factors if not f.fixed] or list(cost.factors)

    def saving(f: Factor) -> float:  # how many times less the part needs with the setting at its least
        return math.log10(amount + 1) - math.log10(cost.estimate(lowered(f)) + 1)

    blamed = max(pool, key=lambda f: (given(f), saving(f)))
    name = blamed.name if blamed.name in typed else next((o for o in blamed.origin if o in typed), blamed.name)
    changes = []
    for f in sorted(helps, key=lambda f: not given(f)):
        if f.origin and name in f.origin and name not in {h.name for h in helps}:
            changes.append(f"change {name}")
        changes.append(f"give {f.name}={UNITS.get(f.name, '<smaller>')}" if f.origin else f"lower {f.name}")
    advice = _listed(list(dict.fromkeys(changes))[:3])
    advice = ", ".join(filter(None, [advice, cost.hint.removeprefix("or ") if not advice else cost.hint]))
    raise_it = f"raise {budget_name}={UNITS[unit]}"
    if unit == "bytes":
        estimate = gib(amount)
    elif unit == "steps":
        estimate = f"{count(amount)} team steps"
    else:
        estimate = f"{amount / 3600:.3g} hours of one CPU core"
    if budget_name in typed:
        budget_text = typed.shown(budget_name)
    else:
        budget_text = f"{budget_name}={limit / 3600:g}" if unit == "seconds" else f"{budget_name}={int(limit)}"
    return (
        f"{typed.shown(name)} is invalid: {cost.formula()} needs about {estimate}, over {budget_text}: "
        f"{advice + ', or ' if advice else ''}{raise_it}"
    )


def total(parts: list[Cost], held: bool = False) -> Cost:
    """The parts added up, named by the factors of the largest part; ``held``: the parts held at once, with every
    part's factors."""
    largest = max(parts, key=lambda part: part.amount)

    def estimate(low):
        return sum(part.estimate(low) for part in parts)

    if not held:
        return Cost(largest.what, largest.factors, estimate)
    factors = {f.name: f for part in sorted(parts, key=lambda part: part is not largest) for f in part.factors}
    what = f"{len(parts)} parts held at once ({largest.what} the largest)"
    return Cost(what, tuple(factors.values()), estimate, summed=True)
