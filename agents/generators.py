"""A seeded ``torch.Generator`` that a policy can carry to another process.

TorchRL sends a policy to a ``MultiSyncCollector``'s (or ``ParallelEnv``'s)
worker through ``torch.multiprocessing``, which moves a plain generator's state
through shared memory and fails there ("unable to resize file").
:class:`PolicyGenerator` pickles as its seed state in bytes instead, so the
copy draws exactly what the original would have drawn next.

Example:
    >>> import pickle
    >>> g = PolicyGenerator(seed=3)
    >>> copy = pickle.loads(pickle.dumps(g))
    >>> torch.equal(torch.rand(4, generator=g), torch.rand(4, generator=copy))
    True
"""

from __future__ import annotations

import torch


class PolicyGenerator(torch.Generator):
    """``torch.Generator(device).manual_seed(seed)`` that pickles as its state (module doc)."""

    def __new__(cls, seed: int = 0, device="cpu"):  # torch.Generator takes its device in __new__
        return super().__new__(cls, device=device)

    def __init__(self, seed: int = 0, device="cpu"):
        self.manual_seed(seed)

    def __reduce__(self):
        return _restored, (str(self.device), bytes(self.get_state().numpy()))


def _restored(device: str, state: bytes) -> PolicyGenerator:
    generator = PolicyGenerator(device=device)
    generator.set_state(torch.frombuffer(bytearray(state), dtype=torch.uint8))
    return generator
