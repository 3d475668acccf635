"""The UAV spectrum-sharing model: batched TorchRL environment, physics, exact optimum and exact solver.

The package, as the API reference shows it (docs/architecture.md):

- :mod:`.config` (:class:`ModelConfig`, :func:`make_config`) and :mod:`.limits`: the model's options and the
  numbers that keep them finite and affordable, standard library only;
- :mod:`.physics`: geometry, channels, rates, random streams and the parts a :class:`World` is made of;
- :mod:`.solvers`: the exact optimum ``U*``, the exact solver, the bounds and the mission solvers;
- :mod:`.world` (:class:`World`, the batched physics, no TorchRL) and :mod:`.env` (:class:`UAVSpectrumEnv`, the
  TorchRL environment over it); :mod:`.render` draws a World's worlds;
- :mod:`.adapters`: Gymnasium and PettingZoo over the same World (the ``[gym]`` extra).

The options need only the standard library; the environment (TorchRL), the World (torch) and the joint-action
helpers load on first use, so the commands check their settings before those imports.  The subpackages' modules
also answer to the paths of uavrl 0.1 (:data:`MOVED`): ``uavrl.envs.exact`` is ``uavrl.envs.solvers.exact``.
"""

import importlib
import importlib.abc
import importlib.machinery
import sys

from .config import ACTION_NAMES, NUM_ACTIONS, ModelConfig, make_config
from .errors import InvalidOption, InvalidType

_LAZY = {
    "UAVSpectrumEnv": "env",
    "World": "world",
    "decode_joint_actions": "physics.grid",
    "joint_action_valid": "physics.grid",
    "joint_targets": "physics.grid",
    "NODE_FEATURES": "world",
    "DIAGNOSTICS": "world",
    "observation_with_nodes": "world",
}
__all__ = ["ACTION_NAMES", "NUM_ACTIONS", "InvalidOption", "InvalidType", "ModelConfig", "make_config", *_LAZY]

# The subpackage of each module that uavrl 0.1 had directly in envs/: ``uavrl.envs.<name>`` stays importable for
# code written against those paths and names the very same module, loaded on first use.
MOVED = {
    **dict.fromkeys(
        (
            "radio",
            "power",
            "pathloss",
            "grid",
            "channel",
            "streams",
            "layouts",
            "fading",
            "dynamics",
            "rewards",
            "energy",
        ),
        "physics",
    ),
    **dict.fromkeys(("optimum", "exact", "bounds", "mission", "mission_exact"), "solvers"),
    **dict.fromkeys(("gym_env", "pettingzoo_env"), "adapters"),
}


def __getattr__(name):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)  # torch only when asked for
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports ``uavrl.envs.<old name>`` as the module it moved to: one module object under both names."""

    def find_spec(self, fullname, path=None, target=None):
        package, _, name = fullname.rpartition(".")
        if package != __name__ or name not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec):
        name = spec.name.rpartition(".")[2]
        module = importlib.import_module(f"{__name__}.{MOVED[name]}.{name}")  # a 0.2 path, for one release
        spec.loader_state = module.__spec__  # the import system sets the alias's spec on the module next
        return module

    def exec_module(self, module):
        module.__spec__ = module.__spec__.loader_state  # the module keeps its own spec, and is already executed


sys.meta_path.append(_MovedModules())  # last: asked only for names no file answers
