"""What differs between the TorchRL releases uavrl supports (0.11, which BenchMARL needs, to 0.14), in one place.

>>> from uavrl.envs.compat import collector_keywords
>>> "frames_per_batch" in collector_keywords()
True
>>> import torch
>>> from tensordict import TensorDict
>>> layer = torch.nn.Linear(1, 1)
>>> with written_into(TensorDict({"weight": torch.zeros(1, 1), "bias": torch.ones(1)}), layer):
...     layer(torch.ones(1, 1)).item()
1.0
"""

from __future__ import annotations

import functools
import inspect

import torch
from tensordict import TensorDictBase
from torchrl.collectors import Collector


@functools.cache
def collector_keywords() -> frozenset[str]:
    """The keyword arguments this release's :class:`torchrl.collectors.Collector` takes."""
    return frozenset(inspect.signature(Collector.__init__).parameters)


def make_collector(env, policy, **kwargs) -> Collector:
    """A :class:`~torchrl.collectors.Collector` of ``policy`` in ``env`` that keeps the policy as given.

    torchrl 0.14 moves transforms the policy declares into the environment unless told not to
    (``auto_register_policy_transforms``); torchrl 0.11 never does and does not know the keyword.
    """
    if "auto_register_policy_transforms" in collector_keywords():
        kwargs["auto_register_policy_transforms"] = False
    return Collector(env, policy, **kwargs)


def written_into(params: TensorDictBase, module: torch.nn.Module):
    """``params.to_module(module)``, a context in which ``module`` computes with the tensors of ``params`` as they are.

    Gradients then flow to ``params`` (a loss's own parameter copies).  tensordict 0.14 instead keeps the module's
    parameter registrations unless told not to (``preserve_module_state=False``); 0.11 always writes them as they are.
    """
    if "preserve_module_state" in inspect.signature(params.to_module).parameters:
        return params.to_module(module, preserve_module_state=False)
    return params.to_module(module)


def load_buffer_state(buffer, state: dict) -> None:
    """``buffer.load_state_dict(state)`` with the storage on its device: torchrl 0.11 loads a storage's tensordict
    without one (then every sample has none), 0.14 keeps it."""
    buffer.load_state_dict(state)
    storage = buffer.storage
    if storage.initialized and storage._storage.device is None and storage.device is not None:
        storage._storage = storage._storage.to(storage.device)
