"""The city part: a model's ITU-R P.1410 city in the model's own frame, and what the channel, the layouts and the
World ask of it (docs/model.md, Cities of buildings).

:func:`city_part` gives the model's :class:`CityPart` (``None`` under ``city="none"``), built once per city (its
P.1410 numbers, seed, grid and cell size) and shared by every World, solver and agent of it, so a layout's tables are
computed once whatever the number of worlds.  The model's positions are in cells (a cell's centre at ``(x, y)``, the
ground at ``z = 0``); the city covers the area every layout may use, the grid widened by half a grid and one cell on
each side, as :mod:`.city` lays it out in metres.

Example:
    >>> import torch
    >>> from uavrl.envs import make_config
    >>> cfg = make_config("a2g_urban", city="urban", city_seed=3)
    >>> part = city_part(cfg)
    >>> nodes = torch.tensor([[0.0, 5.0, 0.0], [10.0, 5.0, 0.0], [-5.0, 5.0, 2.0], [15.0, 5.0, 2.0]])  # PT, PR, S, E
    >>> part.line_of_sight(torch.tensor([[0.0, 3.0, 2.0]]), nodes).tolist()  # a UAV at 100 m over cell (0, 3)
    [[True, False, True, True]]
"""

from __future__ import annotations

import functools

import numpy as np
import torch

from ..errors import InvalidOption
from ..limits import fixed_node_positions
from .city import City, generate_city, inside_building, line_of_sight, roof_height

GROUND_NODES = 2  # PT and PR stand on the ground (or a roof); S and E fly at the UAVs' height


def city_extent(grid: tuple[int, int]) -> tuple[float, float, float, float]:
    """``(x, y, width, depth)`` in cells of the city's area: the grid widened by half a grid and one cell per side,
    which holds every cell and every node a layout may place (docs/model.md, Where the four nodes are)."""
    L1, L2 = grid
    return -(L1 / 2 + 1), -(L2 / 2 + 1), 2.0 * L1 + 2, 2.0 * L2 + 2


class CityPart:
    """A model's city (:attr:`city`, metres) and the questions asked of it in the model's frame (cells).

    Args:
        name: the city option (``"urban"``, ...), for messages.
        parameters: P.1410's ``(alpha, beta, gamma)``.
        seed: the city's seed.
        grid: the model's ``(L1, L2)``.
        cell_size: a cell's side in m.
        height: the UAVs' (and S's and E's) height in cells.
        layout: the model's layout (a fixed one's S and E are checked to be in the air).
    """

    def __init__(self, name: str, parameters, seed: int, grid: tuple[int, int], cell_size: float, height, layout):
        self.name, self.seed, self.grid, self.cell_size, self.height, self.layout = (
            name,
            seed,
            grid,
            cell_size,
            height,
            layout,
        )
        x, y, width, depth = city_extent(grid)
        self._origin = np.array([x, y, 0.0])
        self.city: City = generate_city(*parameters, width * cell_size, depth * cell_size, seed=seed)

    def metres(self, xyz: torch.Tensor | np.ndarray) -> np.ndarray:
        """Positions ``xyz`` ``[..., 3]`` in the model's cells as the city's metres (a float64 array)."""
        cells = xyz.detach().to("cpu", torch.float64).numpy() if isinstance(xyz, torch.Tensor) else xyz
        return (cells - self._origin) * self.cell_size

    def footprints_cells(self) -> np.ndarray:
        """``[n, 4]`` float64: each building's ``(x0, y0, x1, y1)`` in the model's cells (the inverse of
        :meth:`metres`), for pictures."""
        corners = np.stack([self.city.x0, self.city.y0, self.city.x1, self.city.y1], -1)
        return corners / self.cell_size + np.tile(self._origin[:2], 2)

    def line_of_sight(self, uav_xyz: torch.Tensor, nodes: torch.Tensor) -> torch.Tensor:
        """``[..., N, 4]`` bool: does each link from a UAV ``uav_xyz`` ``[..., N, 3]`` to PT, PR, S, E ``nodes``
        ``[..., 4, 3]`` (cells) clear every building?  The links to S and E fly at the UAVs' height, above the roofs:
        always."""
        uav = self.metres(uav_xyz)[..., :, None, :]
        ground = self.metres(nodes[..., :GROUND_NODES, :])[..., None, :, :]
        clear = torch.from_numpy(line_of_sight(self.city, uav, ground)).to(uav_xyz.device)
        return torch.cat([clear, clear.new_ones(clear.shape[:-1] + (4 - GROUND_NODES,))], -1)

    def on_roofs(self, nodes: torch.Tensor) -> torch.Tensor:
        """The ``nodes`` ``[..., 4, 3]`` (cells) with PT and PR on the roof of the building they stand in, if any (a
        rooftop base station, our choice), the others as they are."""
        roofs = roof_height(self.city, self.metres(nodes[..., :GROUND_NODES, :])[..., :2]) / self.cell_size
        raised = nodes.clone()
        raised[..., :GROUND_NODES, 2] = torch.from_numpy(roofs).to(nodes)
        return raised

    def inside(self, xyz: torch.Tensor) -> torch.Tensor:
        """``[...]`` bool: is each position of ``xyz`` ``[..., 3]`` (cells) inside a building?"""
        return torch.from_numpy(inside_building(self.city, self.metres(xyz))).to(xyz.device)

    @functools.cached_property
    def blocked(self) -> tuple[int, bool, float]:
        """How many cell centres at the UAVs' height are inside a building, whether a fixed layout's S or E is, and
        the tallest roof over a cell centre in m."""
        L1, L2 = self.grid
        c = np.arange(L1 * L2)
        cells = np.stack([c % L1, c // L1, np.full(L1 * L2, self.height)], -1).astype(np.float64)
        fixed = fixed_node_positions(self.layout, self.grid, self.height)
        flying = np.asarray(fixed[GROUND_NODES:] if fixed else np.empty((0, 3)), dtype=np.float64)
        roofs = roof_height(self.city, self.metres(cells)[:, :2])
        return (
            int(inside_building(self.city, self.metres(cells)).sum()),
            bool(inside_building(self.city, self.metres(flying)).any()),
            float(roofs.max()),
        )


@functools.lru_cache(maxsize=16)
def _city_part(name, parameters, seed, grid, cell_size, height, layout) -> CityPart:
    return CityPart(name, parameters, seed, grid, cell_size, height, layout)


def city_part(cfg) -> CityPart | None:
    """The city part of the model ``cfg`` (``None`` under ``city="none"``), built once per city, grid and height and
    shared.  A model whose UAVs (at one level) or fixed S and E would hover inside a building is refused in one line
    naming the height as given; with altitude levels, the positions inside buildings are left out
    (:mod:`.positions`)."""
    if cfg.city == "none":
        return None
    try:
        part = _city_part(cfg.city, cfg.city_parameters, cfg.city_seed, cfg.grid, cfg.cell_size, cfg.height, cfg.layout)
    except InvalidOption as refused:  # too many buildings: the density given, or the area (the grid) of the city's
        if refused.option != "beta":
            raise
        name = "city_beta" if cfg.city_beta is not None else "grid"
        raise InvalidOption(name, getattr(cfg, name), str(refused).split(" is invalid: ", 1)[1]) from None
    blocked, nodes_blocked, tallest = part.blocked
    blocked *= cfg.num_levels == 1  # with altitude levels a position inside a building is one a UAV cannot take
    if blocked or nodes_blocked:
        name = "altitude_m" if cfg.altitude_m is not None else "altitude"
        where = f"{cfg.city} city (city_seed={cfg.city_seed})"
        if blocked:
            what = f"{blocked} of the {cfg.num_cells} cells{' and S or E' if nodes_blocked else ''}"
            advice = f"fly above its tallest roof over the grid, {tallest:.1f} m, or choose another city"
        else:  # with altitude levels only S and E fly at this height
            what, advice = "S or E", "fly S and E higher or choose another city"
        verb = "are" if blocked else "is"
        reason = f"{what} at {cfg.height * cfg.cell_size:g} m {verb} inside buildings of the {where}: {advice}"
        raise InvalidOption(name, getattr(cfg, name), reason)
    return part
