"""The layout part: where each world's four nodes PT, PR, S, E are (docs/model.md, Where the four nodes are).

:class:`Layouts` holds ``fixed``, the ``[4, 3]`` float64 node positions (cells; ``z`` the height) of a fixed layout
(``line``, ``reference_code``: :func:`uavrl.envs.limits.fixed_node_positions`), or ``None`` for ``layout=random``,
whose :meth:`Layouts.sample` draws new positions for some worlds at each of their resets from their random streams.

Example:
    >>> import torch
    >>> from uavrl.envs import make_config
    >>> from uavrl.envs.physics import streams
    >>> layouts = Layouts(make_config("paper", grid=(6, 6), layout="random"))
    >>> layouts.fixed is None
    True
    >>> nodes = layouts.sample(streams.world_keys(0, 2), torch.ones(2, dtype=torch.long))
    >>> nodes.shape, nodes[:, :2, 2].tolist(), nodes[:, 2:, 2].tolist()  # PT, PR on the ground, S, E at h = 6
    (torch.Size([2, 4, 3]), [[0.0, 0.0], [0.0, 0.0]], [[6.0, 6.0], [6.0, 6.0]])
"""

from __future__ import annotations

import math

import torch

from ..config import ModelConfig
from . import streams
from .buildings import city_part
from .channel import fixed_layout


class Layouts:
    """The layouts of the model ``cfg``: ``fixed`` positions ``[4, 3]`` (``None`` for ``layout=random``) and
    :meth:`sample`.

    Args:
        cfg: the model (its ``layout`` and ``grid``).
        device: the torch device of the positions.
    """

    def __init__(self, cfg: ModelConfig, device="cpu"):
        self.cfg = cfg
        self.fixed = fixed_layout(cfg, torch.float64, device)  # ModelConfig refused one with a node on a UAV cell
        self.city = city_part(cfg)

    def sample(self, keys: torch.Tensor, counters: torch.Tensor) -> torch.Tensor:
        """``layout=random``: ``[k, 4, 3]`` nodes of ``k`` worlds (``keys``, ``counters`` ``[k]``: their streams),
        uniform in the grid widened by half a grid per side.

        PT-PR and S-E must be at least 0.6 grid diagonals apart.  Decision: S and E
        (at UAV altitude) must also be at least half a cell from every cell centre,
        so no UAV is ever at distance 0 from a node; in a city, S and E are outside every building and PT and PR
        stand on the roof of the building they are in, if any.  Rejection rounds run until
        every world is accepted; each world uses only its own stream.
        """
        (L1, L2), h, dev = self.cfg.grid, self.cfg.height, keys.device
        lo = torch.tensor([-L1 / 2, -L2 / 2], dtype=torch.float64, device=dev)
        span = torch.tensor([2.0 * L1, 2.0 * L2], dtype=torch.float64, device=dev)
        min_sep = 0.6 * math.hypot(L1, L2)
        nodes = torch.empty(len(keys), 4, 3, dtype=torch.float64, device=dev)  # every row is written below
        for pair, z in ((0, 0.0), (1, h)):  # (PT, PR) on the ground, (S, E) at UAV altitude
            pending = torch.arange(len(keys), device=dev)  # round r draws only for the worlds still pending
            rnd = 0
            while len(pending):
                u = streams.uniform(keys[pending], counters[pending], streams.LAYOUT + 2 * rnd + pair, 4)
                xy = lo + span * u.view(-1, 2, 2)
                ok = torch.linalg.vector_norm(xy[:, 0] - xy[:, 1], dim=-1) >= min_sep
                if z > 0:
                    nearest = torch.stack(
                        [xy[..., 0].round().clamp(0, L1 - 1), xy[..., 1].round().clamp(0, L2 - 1)], -1
                    )
                    ok &= (torch.linalg.vector_norm(xy - nearest, dim=-1) >= 0.5).all(-1)
                drawn = torch.cat([xy, xy.new_full((len(xy), 2, 1), z)], -1)
                if self.city is not None and z > 0:  # S and E fly in the open
                    ok &= ~self.city.inside(drawn).any(-1)
                nodes[pending[ok], 2 * pair : 2 * pair + 2] = drawn[ok]
                pending = pending[~ok]
                rnd += 1
        return nodes if self.city is None else self.city.on_roofs(nodes)
