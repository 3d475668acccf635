"""Prioritized replay (``agent.replay=prioritized``): Schaul et al., "Prioritized Experience Replay", ICLR 2016,
the proportional variant.

Slot ``i`` is drawn with probability ``p_i^alpha / sum_j p_j^alpha``, ``p_i`` its last absolute TD error (plus a
small constant; a new transition gets the largest priority seen, so it is drawn at least once soon), and its loss is
weighted by ``(p_i^alpha / min_j p_j^alpha)^(-beta)``, Schaul's importance weight divided by its largest value.

TorchRL's ``PrioritizedSampler`` keeps the priorities in segment trees of its C++ extension, which fails to load
against this project's torch build (``SumSegmentTreeFp32 is not available``, torchrl 0.11 and 0.14 with torch 2.13);
:class:`ProportionalSampler` is the same sampler over one tensor of priorities, drawn with ``torch.multinomial``
(O(capacity) a sample: ~0.3 ms for 50,000 slots on this CPU, beside a ~17 ms gradient step). Its state is that
tensor, so a checkpoint stays readable with ``torch.load(weights_only=True)``.

Example:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
    >>> buffer = TensorDictReplayBuffer(
    ...     storage=LazyTensorStorage(8), sampler=ProportionalSampler(8, alpha=1.0, beta=1.0), batch_size=1000
    ... )
    >>> _ = buffer.extend(TensorDict({"x": torch.arange(4)}, [4]))
    >>> buffer.update_priority(torch.arange(4), torch.tensor([0.0, 0.0, 1.0, 3.0]))
    >>> sample = buffer.sample()
    >>> sorted(sample["x"].unique().tolist())  # the errors of 0 are drawn (almost) never
    [2, 3]
    >>> weight = sample["priority_weight"]  # drawn 3x as often: a third of the weight
    >>> round((weight[sample["x"] == 3].max() / weight[sample["x"] == 2].max()).item(), 4)
    0.3333
"""

from __future__ import annotations

from typing import Any

import torch
from torchrl.data.replay_buffers import Sampler

PRIORITY_EPS = 1e-6  # added to every |TD error|: no transition's probability is ever 0


class ProportionalSampler(Sampler):
    """Proportional prioritized sampling over a tensor of priorities (module doc).

    Args:
        capacity: the buffer's slots.
        alpha: how much the priorities count (0: uniform, 1: proportional to the TD error).
        beta: the importance weights' exponent (0: none, 1: full correction); :attr:`beta` may be changed between
            samples (the agent anneals it to 1 over the run).
    """

    def __init__(self, capacity: int, alpha: float, beta: float):
        super().__init__()
        self.alpha, self.beta = float(alpha), float(beta)
        self.priorities = torch.zeros(capacity, dtype=torch.float64)  # p^alpha of each slot; 0: never written
        self.max_priority = 1.0  # the largest p seen, a new transition's

    def sample(self, storage, batch_size: int) -> tuple[torch.Tensor, dict]:
        p = self.priorities[: len(storage)]
        index = torch.multinomial(p, batch_size, replacement=True)
        weight = (p[index] / p.min()).pow(-self.beta)
        return index, {"priority_weight": weight.to(torch.float32)}

    def extend(self, index: torch.Tensor) -> None:
        self.priorities[torch.as_tensor(index)] = self.max_priority**self.alpha

    def add(self, index: int) -> None:
        self.extend(index)

    def update_priority(self, index, priority, *, storage=None) -> None:
        p = torch.as_tensor(priority, dtype=torch.float64).detach().abs().reshape(-1).cpu() + PRIORITY_EPS
        self.max_priority = max(self.max_priority, float(p.max()))
        self.priorities[torch.as_tensor(index).reshape(-1).cpu()] = p.pow(self.alpha)

    def state_dict(self) -> dict[str, Any]:
        return {"priorities": self.priorities.clone(), "max_priority": self.max_priority, "beta": self.beta}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        self.priorities = state_dict["priorities"].clone()
        self.max_priority, self.beta = float(state_dict["max_priority"]), float(state_dict["beta"])

    def _empty(self) -> None:
        self.priorities.zero_()
        self.max_priority = 1.0

    def dumps(self, path):
        torch.save(self.state_dict(), path)

    def loads(self, path):
        self.load_state_dict(torch.load(path, weights_only=True))
