"""What a setting allows: its rule, declared once beside its default in a schema dataclass (standard library and
omegaconf only).

A schema field made by :func:`setting` carries its default, its rule and its meaning; :func:`rules_of` reads the
rules of a schema (and of the schemas nested in it) as a table of dotted names, the names as typed on the command
line, and :func:`check` refuses the first value of a config that breaks its rule, in one line that names the
setting, the value and what is allowed::

    agent.episodes=0 is invalid: it must be a whole number >= 1

Example:
    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Learner:
    ...     alpha: float = setting(0.1, interval(0.0, 1.0, low_open=True), "step size")
    >>> rules_of(Learner, "agent")["agent.alpha"].allowed
    'it must lie in (0.0, 1.0]'
    >>> refuse("alpha", 0, rule_of(Learner, "alpha"))
    Traceback (most recent call last):
    ...
    ValueError: alpha=0 is invalid: it must lie in (0.0, 1.0]
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from typing import Any, Callable

from .limits import SEED_LIMIT

_ABSENT = object()
REAL = Any  # a schema's real number as typed (int or float: OmegaConf would turn 0 into 0.0), checked by its rule


@dataclass(frozen=True)
class Reader:
    """A setting read only where its sibling setting ``name`` is one ``reads`` accepts (``words``: that, as typed
    without the section: ``replay='prioritized'``); changed from its default elsewhere, it is refused, as nothing
    would read it."""

    name: str
    reads: Callable[[Any], bool]
    words: str


@dataclass(frozen=True)
class Rule:
    accepts: Callable[[Any], bool]
    allowed: str  # completes "<setting>=<value> is invalid: ..."
    reader: Reader | None = None  # read only where this sibling allows (rules_of sets it from the schema)
    default: Any = None  # the setting's default: the value an unread setting must keep


def _is_whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_real(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def whole(low: int) -> Rule:
    return Rule(lambda v: _is_whole(v) and v >= low, f"it must be a whole number >= {low}")


def whole_within(low: int, high: int) -> Rule:
    return Rule(lambda v: _is_whole(v) and low <= v <= high, f"it must be a whole number in [{low}, {high}]")


def interval(low: float, high: float, *, low_open: bool = False) -> Rule:
    def accepts(v):
        return _is_real(v) and (low < v if low_open else low <= v) and v <= high

    return Rule(accepts, f"it must lie in {'(' if low_open else '['}{low}, {high}]")


def at_least(low: float, *, whole_only: bool = False) -> Rule:
    """A finite number ``>= low`` (``whole_only``: with no fractional part, ``2.0`` as ``2``)."""

    def accepts(v):
        return _is_real(v) and v >= low and (not whole_only or v == int(v))

    return Rule(accepts, f"it must be a {'whole' if whole_only else 'finite'} number >= {low}")


def positive() -> Rule:
    return Rule(lambda v: _is_real(v) and v > 0, "it must be positive")


def one_of(*choices: str, what: str = "values") -> Rule:
    return Rule(lambda v: v in choices, f"allowed {what} are {', '.join(map(repr, choices))}")


def flag() -> Rule:
    return Rule(lambda v: isinstance(v, bool), "it must be true or false")


def path() -> Rule:
    return Rule(lambda v: isinstance(v, str) and v != "", "it must be a path")


def optional(rule: Rule, meaning: str) -> Rule:
    return Rule(lambda v: v is None or rule.accepts(v), f"{rule.allowed}, or null ({meaning})")


def grid_sizes() -> Rule:
    def accepts(v):
        return isinstance(v, list) and len(v) > 0 and all(_is_whole(g) and g >= 1 for g in v)

    return Rule(accepts, "give a list of grid sizes >= 1, e.g. [2,3,6]")


def names_among(names, what: str) -> Rule:
    """A non-empty list of names, each one of ``names``."""
    return Rule(
        lambda v: isinstance(v, list) and len(v) > 0 and set(v) <= set(names),
        f"give a list of {what} among {', '.join(map(repr, names))}",
    )


def read_if(name: str, *values) -> Reader:
    """A setting read only where its sibling ``name`` is one of ``values``."""
    return Reader(name, lambda v: v in values, " or ".join(f"{name}={shown(v)}" for v in values))


SEED = Rule(lambda v: _is_whole(v) and 0 <= v < SEED_LIMIT, "it must be a whole number in [0, 2^63)")
DEVICE = Rule(
    lambda v: isinstance(v, str) and bool(re.fullmatch(r"cpu|cuda(:\d+)?", v)), "use 'cpu', 'cuda' or 'cuda:<index>'"
)
UNIT = interval(0.0, 1.0)


# ------------------------------------------------------------------------------------- schemas and their rules
def setting(
    default=dataclasses.MISSING, rule: Rule | None = None, doc: str = "", *, factory=None, read: Reader | None = None
):
    """A schema field: its default (``factory`` for a list), the rule its values keep and what it means; ``read``:
    the sibling setting that decides whether anything reads it (:func:`read_if`)."""
    if read is not None:
        rule = dataclasses.replace(rule, reader=read, default=default)
    metadata = {"rule": rule, "doc": doc}
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def section(schema: type, doc: str = "", *, optional: bool = False):
    """A schema field holding the settings of the nested schema ``schema`` (``optional``: null unless chosen)."""
    metadata = {"section": schema, "doc": doc}
    if optional:
        return dataclasses.field(default=None, metadata=metadata)
    return dataclasses.field(default_factory=schema, metadata=metadata)


def rules_of(schema: type, prefix: str = "") -> dict[str, Rule]:
    """``{dotted setting: rule}`` of every field of ``schema`` with a rule, nested schemas included, in field order;
    ``prefix`` is the section the schema is typed under (``agent``)."""
    rules = {}
    for field in dataclasses.fields(schema):
        name = f"{prefix}.{field.name}" if prefix else field.name
        if field.metadata.get("rule") is not None:
            rules[name] = field.metadata["rule"]
        if "section" in field.metadata:
            rules |= rules_of(field.metadata["section"], name)
    return rules


def rule_of(schema: type, name: str) -> Rule:
    """The rule of the field ``name`` of ``schema``."""
    return next(field.metadata["rule"] for field in dataclasses.fields(schema) if field.name == name)


def default_of(schema: type, name: str):
    """The default of the field ``name`` of ``schema`` (a fresh list where its default is made by a factory)."""
    field = next(field for field in dataclasses.fields(schema) if field.name == name)
    return field.default if field.default_factory is dataclasses.MISSING else field.default_factory()


# ------------------------------------------------------------------------------------------------ refusals
def shown(value, *, label: bool = False) -> str:
    """A value as it is typed in an override: ``null``, ``true``, ``'text'``, ``[2, 3]``; ``label=True``: as a label
    of a report writes it, text unquoted and lists without spaces (``qmix``, ``[6,6]``)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (list, tuple)):
        return "[" + ("," if label else ", ").join(shown(v, label=label) for v in value) + "]"
    return str(value) if label else repr(value)


def refuse(name: str, value, rule: Rule) -> None:
    """A one-line ValueError unless ``rule`` accepts ``value``, naming the setting as ``name``."""
    if not rule.accepts(value):
        raise ValueError(f"{name}={shown(value)} is invalid: {rule.allowed}")


def refuse_unread(name: str, value, rule: Rule, sibling) -> None:
    """A one-line ValueError for ``value`` changed from the default of a setting that nothing reads where its
    ``rule.reader``'s sibling setting has the value ``sibling``: ``agent.priority_alpha=0.5 is invalid: only
    agent.replay='prioritized' reads it, not agent.replay='uniform'``."""
    if rule.reader is not None and value != rule.default and not rule.reader.reads(sibling):
        parent = name.rpartition(".")[0] + "." if "." in name else ""
        raise ValueError(
            f"{name}={shown(value)} is invalid: only {parent}{rule.reader.words} reads it, not "
            f"{parent}{rule.reader.name}={shown(sibling)}"
        )


def check(cfg, table: dict[str, Rule], section: str = "") -> None:
    """A one-line ValueError for the first setting of ``table`` (within ``section`` of ``cfg``) that breaks its rule,
    or that nothing reads (:func:`refuse_unread`); a setting missing from ``cfg`` (one a saved run's config predates)
    is skipped."""
    from omegaconf import DictConfig, ListConfig, OmegaConf

    prefix = f"{section}." if section else ""
    for name, rule in table.items():
        if not name.startswith(prefix):
            continue
        value = OmegaConf.select(cfg, name[len(prefix) :], default=_ABSENT)
        if value is _ABSENT:
            continue
        if isinstance(value, (DictConfig, ListConfig)):
            value = OmegaConf.to_container(value, resolve=True)
        refuse(name, value, rule)
        if rule.reader is not None:
            sibling = name.rpartition(".")[0] + "." + rule.reader.name if "." in name else rule.reader.name
            sibling = OmegaConf.select(cfg, sibling[len(prefix) :], default=_ABSENT)
            if sibling is not _ABSENT:  # a saved run's config may predate the sibling
                refuse_unread(name, value, rule, sibling)
