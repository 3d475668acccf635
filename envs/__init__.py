"""The UAV spectrum-sharing model: batched TorchRL environment, physics, exact optimum and exact solver.

The model's options (:mod:`.config`) need only the standard library; the
environment (TorchRL), its physics :class:`World` (torch) and the joint-action
helpers load on first use, so the commands check their settings before those
imports.  The optimum and
the solvers live in their modules: :mod:`.optimum`, :mod:`.exact`, :mod:`.bounds`.
"""

from .config import ACTION_NAMES, NUM_ACTIONS, InvalidOption, ModelConfig, make_config

_LAZY = {
    "UAVSpectrumEnv": "env",
    "World": "world",
    "decode_joint_actions": "grid",
    "joint_action_valid": "grid",
    "joint_targets": "grid",
    "NODE_FEATURES": "world",
    "DIAGNOSTICS": "world",
    "observation_with_nodes": "world",
}
__all__ = ["ACTION_NAMES", "NUM_ACTIONS", "InvalidOption", "ModelConfig", "make_config", *_LAZY]


def __getattr__(name):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
