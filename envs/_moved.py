"""The import paths of uavrl 0.2 whose modules or names moved in 0.3: each old one is the new one, with a warning
(standard library only, below every layer that keeps an old path)."""

from __future__ import annotations

import importlib
import sys
import warnings


def alias(old: str, new: str) -> None:
    """Make ``import old`` give module ``new`` (one module object under both names), warning once per import."""
    warnings.warn(f"{old} moved to {new} in uavrl 0.3; the old path goes in 0.4", DeprecationWarning, stacklevel=3)
    sys.modules[old] = importlib.import_module(new)  # a 0.2 path, kept for one release


def moved_names(old: str, *new: str):
    """A module ``__getattr__`` for a module whose names moved to the modules ``new``: ``old.name`` gives the first
    of them that has ``name`` (imported on first use), with a warning; a name none has is missing as usual."""

    def __getattr__(name: str):
        for module in new if not name.startswith("__") else ():
            value = getattr(importlib.import_module(module), name, __getattr__)  # a 0.2 name, for one release
            if value is not __getattr__:
                message = f"{old}.{name} moved to {module}.{name} in uavrl 0.3; the old path goes in 0.4"
                warnings.warn(message, DeprecationWarning, stacklevel=2)
                return value
        raise AttributeError(f"module {old!r} has no attribute {name!r}")

    return __getattr__
