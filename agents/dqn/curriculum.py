"""A curriculum over the teams and layouts of a size-free run (``agent.curriculum``): how much of every gradient
step each team (``agent.sizes`` x ``agent.layouts``, a group of :class:`~.multisize.SetDQNAgent`) gets.

- ``none``: equal shares, ``agent.batch_size`` split evenly (pure RL's default);
- ``loss``: sampling by recent loss, a group-level prioritised replay: team ``g``'s share of each batch is
  ``1 / (2 G) + L_g / (2 sum_h L_h)``, ``L_g`` the moving average (decay :data:`DECAY` per gradient step) of its
  double-DQN TD loss, so a team still far from its targets (random layouts, the larger teams) draws more samples and
  none drops below half its equal share.  Each team's loss is weighted by its share over the equal one, so the step
  is the sum of the per-sample losses as with equal shares.

Every group still plays its episodes each iteration; only the updates move.

Example:
    >>> curriculum = Curriculum("loss", groups=2, batch_size=100)
    >>> curriculum.batch_sizes()  # no loss seen yet: equal shares
    [50, 50]
    >>> curriculum.record(torch.tensor([3.0, 1.0]))
    >>> curriculum.batch_sizes()  # 1/4 + 3/8, 1/4 + 1/8
    [62, 38]
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase

DECAY = 0.99  # the moving average of each team's TD loss keeps 99% a gradient step: ~100 steps of memory


class Curriculum:
    """Each group's share of ``batch_size`` transitions a gradient step (module doc), for ``groups`` groups."""

    def __init__(self, kind: str, groups: int, batch_size: int):
        self.kind, self.groups, self.batch_size = kind, groups, batch_size
        self.average = torch.zeros(groups, dtype=torch.float64)  # each group's recent TD loss; 0: none seen yet

    def shares(self) -> torch.Tensor:
        """``[G]`` each group's share of a batch (they sum to 1)."""
        equal = torch.full((self.groups,), 1.0 / self.groups, dtype=torch.float64)
        if self.kind == "none" or not bool((self.average > 0).all()):
            return equal
        return equal / 2 + self.average / self.average.sum() / 2

    def batch_sizes(self) -> list[int]:
        """Each group's transitions of the next gradient step (at least one)."""
        return [max(1, round(float(s) * self.batch_size)) for s in self.shares()]

    def record(self, losses: torch.Tensor) -> None:
        """Fold one gradient step's TD losses ``[G]`` (detached) into the moving averages."""
        losses = losses.detach().double().cpu()
        seen = self.average > 0
        self.average = torch.where(seen, DECAY * self.average + (1 - DECAY) * losses, losses)

    def total(self, losses: list[torch.Tensor], sizes: list[int]) -> torch.Tensor:
        """The step's loss from the groups' mean TD losses: their sum, each weighted by its batch over the equal one
        (with equal shares: their plain sum)."""
        if self.kind == "none":
            return sum(losses)
        equal = self.batch_size / self.groups
        return sum(loss * (size / equal) for loss, size in zip(losses, sizes, strict=True))

    def state_dict(self) -> dict:
        return {"average": self.average.clone()}

    def load_state_dict(self, state: dict) -> None:
        self.average = state["average"].clone()


def uniform_sample(buffer, size: int) -> TensorDictBase:
    """``size`` transitions of a replay ``buffer`` drawn uniformly with replacement, as its own sampler draws them
    (full transitions: the buffer's transform rebuilds them)."""
    return buffer[torch.randint(len(buffer), (size,), device=buffer.storage.device)]
