"""The one-line refusals of a model option or an argument, shared by the model's config and its physics, and the
kinds of value they test (standard library only, so a refusal needs neither torch nor numpy)."""

from __future__ import annotations

import numbers
import re


class InvalidOption(ValueError):
    """``option=value is invalid: reason``, with ``option`` kept so a command line can name it as its user typed it.

    Args:
        option: the argument or option refused, kept as ``.option``.
        value: its value, shown with ``repr``.
        reason: why, and what to give instead.
        message: the whole line in place of the three, for an argument whose value is better described than printed
            (a tensor).
    """

    def __init__(self, option: str, value=None, reason: str = "", *, message: str | None = None):
        super().__init__(message or f"{option}={value!r} is invalid: {reason}")
        self.option = option

    def renamed(self, names: dict[str, str]) -> str:
        """The message with each ``option=`` in ``names`` written as ``names[option]=`` (``grid=`` as ``env.grid=``)."""
        return re.sub(r"\b([a-z_0-9]+)=", lambda m: f"{names.get(m.group(1), m.group(1))}=", str(self))


class InvalidType(InvalidOption, TypeError):
    """An argument of the wrong type (a ``TypeError`` too): ``option=value is invalid: reason``; ``message`` the
    whole line in their place (arguments as :class:`InvalidOption`'s)."""


def is_whole(value) -> bool:
    """A whole number, not a bool: what a count or a seed must be."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def is_pair(value) -> bool:
    """Two whole numbers (of any type that converts exactly: ``[1, 2.0]`` is a pair, ``[1, 2.5]`` not)."""
    try:
        return len(value) == 2 and all(int(v) == v for v in value)
    except (TypeError, ValueError):
        return False
