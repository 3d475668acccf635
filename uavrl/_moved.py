"""The import paths of uavrl 0.2 whose modules moved in 0.3: each old module is the new one, with a warning."""

from __future__ import annotations

import importlib
import sys
import warnings


def alias(old: str, new: str) -> None:
    """Make ``import old`` give module ``new`` (one module object under both names), warning once per import."""
    warnings.warn(f"{old} moved to {new} in uavrl 0.3; the old path goes in 0.4", DeprecationWarning, stacklevel=3)
    sys.modules[old] = importlib.import_module(new)
