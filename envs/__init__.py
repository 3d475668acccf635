"""The UAV spectrum-sharing model: batched TorchRL environment, physics and exact optimum.

The model's options (:mod:`.config`) need only the standard library; the
environment and the optimum (torch, TorchRL) load on first use, so the
commands check their settings before those imports.
"""
from .config import ACTION_NAMES, NUM_ACTIONS, InvalidOption, ModelConfig, make_config

_HEAVY = ("UAVSpectrumEnv", "decode_joint_actions", "joint_action_valid", "joint_targets", "optimum")
__all__ = ["ACTION_NAMES", "NUM_ACTIONS", "InvalidOption", "ModelConfig", "make_config", *_HEAVY]


def __getattr__(name):
    if name not in _HEAVY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from . import env, optimum as solver

    # bound after both imports: importing the submodule .optimum set the name "optimum" to the module
    globals().update({heavy: getattr(solver if heavy == "optimum" else env, heavy) for heavy in _HEAVY})
    return globals()[name]


def __dir__():
    return sorted(set(globals()) | set(__all__))
