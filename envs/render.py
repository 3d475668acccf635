"""Pictures of the model: one world's grid, nodes, UAVs and links as an ``[H, W, 3]`` uint8 frame (docs/model.md).

:class:`WorldRenderer` draws the worlds of a :class:`~uavrl.envs.world.World`
from its tensors with matplotlib's Agg canvas (no display, no TorchRL);
:meth:`UAVSpectrumEnv.render <uavrl.envs.env.UAVSpectrumEnv.render>` returns
its frames (VMAS's ``render(mode="rgb_array")``), and ``python -m
uavrl.render`` turns them into videos.

A frame shows, for one world:

- the ``L1 x L2`` grid with its cells' coordinates along two sides (``x``
  from 0 at the left, ``y`` from 0 at the top: ``y`` grows downwards, so action
  0, *up*, moves a UAV up the picture; every cell numbered up to 12 a side, every
  few beyond) and the four nodes: PT and PR (the primary link, squares), S and E
  (the emergency link, triangles), each labelled;
- every UAV as a disc numbered by its index, blue when relaying (task 1), orange
  when sensing (task 0), with the links it serves: PT -> UAV -> PR for a relay,
  S -> UAV -> E for a sensing UAV, dashed grey where they earn nothing (the
  emergency link while no UAV relays, by the lease rule; in the authors' code,
  every link while all UAVs do the same job);
- a header with the step, the utility ``U = R_PU + R_SE`` of the step against the
  layout's exact optimum ``U*``, and both rates;
- a side panel with one row per UAV: its task and ``c/Σc``, its relay path's
  share of its network's sum (the term ``c`` it adds inside that network's log,
  docs/model.md, Rates), and under the rows a key to the colours, the grey
  dashed links and that column.

In a city (``env.city`` other than ``none``) a frame also shows the buildings at
true scale under the grid's lines, shaded from light (low) to dark (the
tallest roof, given in the key); under geometric line of sight
(``env.los=geometric``) a link from a UAV to PT or PR that a building blocks
is dashed (NLoS), every other link solid, grey still marking a link that earns
nothing.  Frames of ``env.city=none`` draw none of this.

With altitude levels (``env.altitudes_m``) each UAV's disc grows with its level (the lowest the smallest) and
carries a tag ``l0``, ``l1``, ... (its level, 0 the lowest) at its upper right; each panel row gives its height in m
and the key names the levels' heights.  Frames at one level draw none of this.

Under an energy model (``env.energy`` other than ``none``) a frame also shows
the base (``env.base``, off the grid) as a pad with one slot per UAV, UAV ``i``
``i`` cells from the base along the grid's side (towards the grid's middle); a
UAV out of service sits in its slot, coloured by its status (returning,
charging, waiting, out: :data:`STATUS_COLOURS`); under every UAV a gauge whose
length is its battery's fraction of the capacity, green, amber or red by level
(:data:`GAUGE_LEVELS`); in the header how many serve; and in each panel row the
battery and, out of service, the status (with its steps left).  Frames of
``env.energy=none`` draw none of this.

Every artist is made once per renderer; the parts that stay while a layout
stays are drawn once per layout and kept, so a frame draws only what a step
changes: about 15 ms of CPU for 2 UAVs on 6x6 and 25 ms for 6 UAVs on 10x10
(480 x 360 pixels; text is most of it).

Example:
    >>> from uavrl.envs import make_config
    >>> from uavrl.envs.world import World
    >>> world = World(make_config("paper", grid=(6, 6), num_uavs=2), batch_size=2)
    >>> _ = world.reset()
    >>> frame = WorldRenderer(world).frame(1)
    >>> frame.shape, frame.dtype
    ((360, 480, 3), dtype('uint8'))
"""

from __future__ import annotations

import math
import numbers
import weakref
from collections.abc import Sequence

import numpy as np
import torch

from .config import RELAYING, InvalidOption
from .limits import NODE_NAMES
from .physics.channel import PR, PT, E, S, cell_xyz
from .physics.energy import CHARGING, OUT, RETURNING, WAITING
from .solvers.optimum import optimum as exact_optimum

RENDER_MODES = ("rgb_array",)
RELAY_COLOUR = (0x1F, 0x77, 0xB4)  # matplotlib's tab:blue
SENSE_COLOUR = (0xFF, 0x7F, 0x0E)  # tab:orange
NODE_COLOURS = {PT: "#0b3c5d", PR: "#0b3c5d", S: "#a34700", E: "#a34700"}
IDLE_LINK = "#9a9a9a"  # links that earn nothing: sensing ones while no UAV relays (the lease rule: R_SE = 0)
TASK_NAMES = {0: "sense", 1: "relay"}
# under an energy model: a UAV out of service in its status' colour, and its battery gauge's colour by level
STATUS_COLOURS = {RETURNING: "#9467bd", OUT: "#3b3b3b", CHARGING: "#17becf", WAITING: "#8c8c8c"}  # purple .. grey
STATUS_NAMES = {RETURNING: "return", OUT: "out", CHARGING: "charge", WAITING: "wait"}
GAUGE_LEVELS = ((0.5, "#2ca02c"), (0.2, "#e8a202"), (0.0, "#d62728"))  # from this fraction up: green, amber, red
GAUGE_WIDTH, GAUGE_TOP, GAUGE_HEIGHT = 0.8, 0.36, 0.16  # in cells, below the UAV's centre (y grows downwards)
BASE_COLOUR = "#2f6b3a"
# the panel's layout in figure fractions: header on top, the map on the left, the per-UAV rows on the right
HEADER, MAP_RIGHT, MARGIN = 0.16, 0.7, 0.02
GRID_EDGE = "#b0b0b0"
COORDINATE_COLOUR = "#7a7a7a"
COORDINATE_GAP = 0.55  # cells (at least) between the grid's edge and the centre of its coordinates
# in a city: the buildings' shades of matplotlib's Greys, from 0 m to the tallest roof, light enough that the links
# and the nodes' names stay legible over the tallest
BUILDING_SHADES = (0.12, 0.55)
# the panel's key under its rows: (a swatch: a dot's RGB, ("line", colour, style), "shades" of the buildings, or ""
# for none; the text)
IDLE_SWATCH = ("line", IDLE_LINK, "--")
PANEL_KEY = (
    (RELAY_COLOUR, "relay: PT → UAV → PR"),
    (SENSE_COLOUR, "sense: S → UAV → E"),
    (IDLE_SWATCH, "earns nothing"),
    ("", "c/Σc: its path's share"),
    ("", "of its network's sum"),
)
ENERGY_KEY = (("", "away: status, steps left"),)
LEVEL_DISC = 0.6  # with altitude levels: the lowest level's disc, as a fraction of the highest's (its full size)
LOS_KEY = (("line", "#404040", "-"), "LoS"), (("line", "#404040", "--"), "NLoS: blocked")
DPI = 100
BACKGROUNDS_KEPT = 16  # layouts whose drawn background a renderer keeps (about 0.7 MB each at 480 x 360)


def building_shades(fractions: np.ndarray) -> np.ndarray:
    """``[..., 4]`` RGBA of buildings ``fractions`` (0 to 1) of the tallest roof high: greys within
    :data:`BUILDING_SHADES`, darker as taller (the map's buildings and the key's colour bar)."""
    from matplotlib import colormaps

    low, high = BUILDING_SHADES
    return colormaps["Greys"](low + (high - low) * fractions)


class WorldRenderer:
    """Frames of the worlds of ``world``, ``width x height`` pixels each, drawn on one reused Agg figure.

    ``label`` heads every frame (e.g. which policy acts).  The artists are made
    here; what stays while a layout stays (the grid, the nodes, their labels) is
    drawn once per layout and kept as a background, so :meth:`frame` draws only
    what a step changes.
    """

    def __init__(self, world, width: int = 480, height: int = 360, label: str | None = None):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        for name, value in (("width", width), ("height", height)):
            if not isinstance(value, numbers.Integral) or isinstance(value, bool) or value < 160:
                raise ValueError(f"{name}={value!r} is invalid: give a whole number of pixels >= 160")
        self.world, self.label, self.size = world, label, (int(height), int(width))
        self.figure = Figure(figsize=(width / DPI, height / DPI), dpi=DPI, facecolor="white")
        self.canvas = FigureCanvasAgg(self.figure)
        self._font = max(7.0, min(11.0, height / 36))
        self.energy = world.energy  # None for env.energy=none: nothing of the energy model is made or drawn
        self.city = world.parts.get("city")  # None for env.city=none: no building is drawn, no link dashed for NLoS
        # in a city of geometric line of sight the dash marks a blocked link (NLoS), and no longer a link that earns
        # nothing (grey either way)
        self.dash_nlos = self.city is not None and world.cfg.geometric_los
        self._los: dict[bytes, np.ndarray] = {}  # each layout's [C, 4] line of sight from every cell centre
        self.levels = world.cfg.num_levels > 1  # altitude levels: each UAV's level on the map and in its row
        self._make_map()
        self._make_header()
        self._make_panel()
        self._dynamic = [
            self._links, self._uavs, self._focus, *self._uav_labels, self._title, self._rates,
            self._row_dots, *self._rows,
        ]  # fmt: skip
        if self.levels:
            self._dynamic[3 + len(self._uav_labels) : 3 + len(self._uav_labels)] = self._level_tags  # over the numbers
        if self.energy is not None:
            self._make_base()
            self._dynamic[3:3] = [self._gauge_frames, self._gauges]  # over the UAVs, under their numbers
        if self.city is not None:  # the map's names and coordinates over the buildings: a white halo keeps them legible
            from matplotlib.patheffects import withStroke

            for text in set(self.ax.texts) - set(self._uav_labels):
                text.set_path_effects([withStroke(linewidth=2.5, foreground="white")])
        for artist in self._dynamic:  # animated: the figure's own draw (the background) leaves them out
            artist.set_animated(True)
        self._u_star: dict[bytes, float] = {}  # each layout's exact U*, keyed by its node positions
        # the background of each recent layout: a tiled batch of random layouts draws each once
        self._backgrounds: dict[bytes, object] = {}
        self._background, self._fitted = None, None

    def _make_map(self) -> None:
        """The grid and the nodes, then what a step moves: the links, the UAVs, their numbers, the focus ring.  Limits
        and sizes are set per layout (:meth:`_fit`), as random layouts move the nodes."""
        from matplotlib.collections import LineCollection
        from matplotlib.patches import Rectangle

        N, (L1, L2), font = self.world.num_uavs, self.world.cfg.grid, self._font
        ax = self.ax = self.figure.add_axes((MARGIN, MARGIN, MAP_RIGHT - 2 * MARGIN, 1 - HEADER - 2 * MARGIN))
        ax.set_axis_off()
        ax.add_patch(Rectangle((-0.5, -0.5), L1, L2, facecolor="#f3f3f3", edgecolor=GRID_EDGE, lw=1.0, zorder=0))
        if self.city is not None:
            self._make_buildings()
        lines = [((x - 0.5, -0.5), (x - 0.5, L2 - 0.5)) for x in range(1, L1)]
        lines += [((-0.5, y - 0.5), (L1 - 0.5, y - 0.5)) for y in range(1, L2)]
        ax.add_collection(LineCollection(lines, colors="#d6d6d6", linewidths=0.6, zorder=0))
        marker = {PT: "s", PR: "s", S: "^", E: "^"}
        self._nodes = [ax.scatter([0], [0], marker=marker[n], c=NODE_COLOURS[n], zorder=2, lw=0) for n in range(4)]
        self._node_labels = [
            ax.text(0, 0, NODE_NAMES[n], fontsize=font, ha="center", va="top", color=NODE_COLOURS[n], zorder=4)
            for n in range(4)
        ]
        self._links = ax.add_collection(LineCollection([], linewidths=1.6, zorder=1, capstyle="round"))
        self._uavs = ax.scatter(np.zeros(N), np.zeros(N), zorder=3, lw=0)
        self._focus = ax.scatter([0], [0], facecolors="none", edgecolors="black", lw=1.5, zorder=3)
        self._uav_labels = [
            ax.text(0, 0, str(i), ha="center", va="center", color="white", weight="bold", zorder=5) for i in range(N)
        ]
        if self.levels:  # each UAV's level, at its disc's upper right, dark on a white halo
            from matplotlib.patheffects import withStroke

            halo = [withStroke(linewidth=2, foreground="white")]
            self._level_tags = [
                ax.text(0, 0, "", ha="left", va="bottom", color="#202020", zorder=6, path_effects=halo)
                for _ in range(N)
            ]
        self._make_coordinates()

    def _make_buildings(self) -> None:
        """The city's buildings at true scale over the grid's ground, under its lines, shaded by height: one artist,
        static (in every layout's background)."""
        from matplotlib.collections import PolyCollection
        from matplotlib.patches import Rectangle

        x0, y0, x1, y1 = self.city.footprints_cells().T
        boxes = np.stack([np.stack(corner, -1) for corner in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))], 1)
        heights = self.city.city.height
        self.tallest = math.ceil(heights.max())
        shades = building_shades(heights / self.tallest)
        self.buildings = self.ax.add_collection(PolyCollection(boxes, facecolors=shades, linewidths=0, zorder=0))
        L1, L2 = self.world.cfg.grid  # the grid's edge again, over the buildings
        self.ax.add_patch(Rectangle((-0.5, -0.5), L1, L2, facecolor="none", edgecolor=GRID_EDGE, lw=1.0, zorder=0))

    def _make_coordinates(self) -> None:
        """Each column's ``x`` and each row's ``y`` beside the grid, and the axes' names; placed per layout
        (:meth:`_fit_coordinates`)."""
        (L1, L2), style = self.world.cfg.grid, dict(color=COORDINATE_COLOUR, ha="center", va="center", zorder=0)
        self._x_coordinates = [self.ax.text(x, 0, str(x), **style) for x in range(L1)]
        self._y_coordinates = [self.ax.text(0, y, str(y), **style) for y in range(L2)]
        self._x_name, self._y_name = (self.ax.text(0, 0, name, style="italic", **style) for name in "xy")

    def _make_base(self) -> None:
        """The base's pad of one slot per UAV (static), its label, and the battery gauges (one per UAV)."""
        from matplotlib.collections import PolyCollection
        from matplotlib.colors import to_rgb
        from matplotlib.patches import FancyBboxPatch

        N, (L1, L2), (bx, by) = self.world.num_uavs, self.world.cfg.grid, self.world.cfg.base
        # along the grid's side the base lies by, towards the grid's middle: the slots stay off the grid
        along_y = not 0 <= bx < L1
        middle = (L2 - 1) / 2 if along_y else (L1 - 1) / 2
        sign = 1 if (by if along_y else bx) <= middle else -1
        offsets = sign * np.arange(N, dtype=float)
        self.slots = np.stack(
            [np.full(N, bx, float), by + offsets] if along_y else [bx + offsets, np.full(N, by, float)], -1
        )
        lo, hi = self.slots.min(0) - 0.5, self.slots.max(0) + 0.5
        # the label along the pad, on its side away from the grid
        across = 0 if along_y else 1
        label_at = self.slots.mean(0)
        label_at[across] += -0.9 if (bx if along_y else by) < 0 else 0.9
        self.base_box = (np.minimum(lo, label_at - 0.4), np.maximum(hi, label_at + 0.4))  # what the map must hold
        self.ax.add_patch(
            FancyBboxPatch(
                lo + 0.06, *(hi - lo - 0.12), boxstyle="round,pad=0.06", facecolor="#e3efe5", edgecolor=BASE_COLOUR,
                lw=1.2, zorder=0,
            )
        )  # fmt: skip
        self.ax.text(
            *label_at, "base", fontsize=self._font * 0.85, color=BASE_COLOUR, weight="bold", ha="center", va="center",
            rotation=90 if along_y else 0, zorder=4,
        )  # fmt: skip
        self._gauge_frames = self.ax.add_collection(
            PolyCollection([], facecolors="white", edgecolors="#505050", linewidths=0.6, zorder=4)
        )
        self._gauges = self.ax.add_collection(PolyCollection([], linewidths=0, zorder=4))
        self._status_rgb = {status: to_rgb(colour) for status, colour in STATUS_COLOURS.items()}

    def _make_header(self) -> None:
        """Two lines: the label, the step and U against U*; the world and both rates."""
        top, font = 1 - MARGIN, self._font
        self._title = self.figure.text(MARGIN, top, "", fontsize=font * 1.1, va="top", weight="bold")
        self._rates = self.figure.text(MARGIN, top - HEADER / 2, "", fontsize=font, va="top", color="#404040")

    def _make_panel(self) -> None:
        """One row per UAV: a disc in its colour, its number, task and ``c/Σc``; under the rows, the key
        (:data:`PANEL_KEY`).  A large team gets smaller rows."""
        N = self.world.num_uavs
        panel = self.figure.add_axes((MAP_RIGHT, MARGIN, 1 - MAP_RIGHT - MARGIN, 1 - HEADER - 2 * MARGIN))
        panel.set_axis_off()
        key = PANEL_KEY + (ENERGY_KEY if self.energy is not None else ())
        if self.dash_nlos:  # grey solid for a link that earns nothing: the dash is a blocked link's
            key = tuple(
                (("line", IDLE_LINK, "-"), text) if swatch == IDLE_SWATCH else (swatch, text) for swatch, text in key
            )
            key += LOS_KEY
        if self.city is not None:
            key += (("shades", f"buildings 0–{self.tallest} m"),)
        rows = max(N, 6)
        lines = rows + 1.5 + 0.8 * len(key)  # the head, the rows, a gap, the key's closer lines
        row_points = panel.get_position().height * self.size[0] / (lines + 1) * 72 / DPI
        font = min(self._font * 0.85, 0.7 * row_points)
        panel.set_xlim(0, 1)
        panel.set_ylim(lines, -0.5)
        if self.energy is not None or self.levels:  # a fourth column, the battery or the height
            font *= 0.85
        if self.energy is not None and self.levels:  # and a fifth, both
            font *= 0.85
        head = "UAV task  c/Σc" if self.energy is None else "UAV task  c/Σc batt"
        if self.levels:  # the height
            head += "  alt"
            key += (("", "lN: level N, 0 lowest"),)
        panel.text(0.12, 0, head, fontsize=font, va="center", family="monospace", color="#404040")
        self._row_dots = panel.scatter(np.full(N, 0.05), np.arange(1, N + 1), s=(font * 1.05) ** 2, lw=0)
        self._rows = [panel.text(0.12, i + 1, "", fontsize=font, va="center", family="monospace") for i in range(N)]
        key_font = font * 0.9
        for k, (swatch, text) in enumerate(key):
            y = rows + 1.5 + 0.8 * k
            if swatch == "shades":  # the buildings' colour bar, lowest to tallest
                self._shades_swatch(panel, y)
            elif swatch and swatch[0] == "line":
                panel.plot([0.0, 0.09], [y, y], color=swatch[1], ls=swatch[2], lw=1.2)
            elif swatch:
                panel.scatter([0.05], [y], s=(key_font * 0.9) ** 2, lw=0, color=np.array(swatch) / 255)
            panel.text(0.12, y, text, fontsize=key_font, va="center", color="#404040")

    @staticmethod
    def _shades_swatch(panel, y: float) -> None:
        """A small colour bar of the buildings' shades at height ``y`` of the panel's key."""
        from matplotlib.colors import ListedColormap

        shades = ListedColormap(building_shades(np.linspace(0, 1, 64)))
        panel.imshow([np.linspace(0, 1, 64)], cmap=shades, extent=(0.0, 0.09, y + 0.25, y - 0.25), aspect="auto")

    # ----------------------------------------------------------- geometry
    def _fit(self, nodes: np.ndarray) -> None:
        """Limits that hold the grid and the nodes at equal scales, marker sizes from the cell size, and the layout's
        background (drawn unless kept)."""
        L1, L2 = self.world.cfg.grid
        box, (H, W) = self.ax.get_position(), self.size
        label_px = 1.6 * self._font * DPI / 72  # room below the lowest node for its label
        box_w, box_h = box.width * W, box.height * H
        # room around the grid for its coordinates: their gap and widest label, in pixels, so in cells once scaled
        font, digits = self._font * 0.8, len(str(max(L1, L2) - 1))
        room_px, room = (0.6 * font + 3.5 + 0.4 * digits * font) * DPI / 72, 1.1
        for _ in range(3):  # the room in cells grows as the scale shrinks with it: settled in a few rounds
            pad = 0.7  # cells around the outermost node
            x_lo, x_hi = min(-0.5 - room, nodes[:, 0].min() - pad), max(L1 - 0.5 + room, nodes[:, 0].max() + pad)
            y_lo, y_hi = min(-0.5 - room, nodes[:, 1].min() - pad), max(L2 - 0.5 + room, nodes[:, 1].max() + pad)
            if self.energy is not None:  # and the base's pad
                (bx_lo, by_lo), (bx_hi, by_hi) = self.base_box
                x_lo, x_hi, y_lo, y_hi = min(x_lo, bx_lo), max(x_hi, bx_hi), min(y_lo, by_lo), max(y_hi, by_hi)
            scale = min(box_w / (x_hi - x_lo), (box_h - label_px) / (y_hi - y_lo))  # pixels per cell
            room = max(1.1, room_px / scale)
        cx, cy = (x_lo + x_hi) / 2, (y_lo + y_hi + label_px / scale) / 2
        half_x, half_y = box_w / scale / 2, box_h / scale / 2
        self.ax.set_xlim(cx - half_x, cx + half_x)
        self.ax.set_ylim(cy + half_y, cy - half_y)  # y down: "up" (action 0) moves a UAV up the picture
        cell = scale * 72 / DPI  # one cell in points
        self._uavs.set_sizes([((0.72 if self.energy is None else 0.62) * cell) ** 2])  # room for the gauge below
        self._focus.set_sizes([(0.98 * cell) ** 2])
        label_offset = (min(0.6 * cell, 14.0) / 2 + 1) * DPI / 72 / scale  # just below the marker, in cells
        for n in range(4):
            self._nodes[n].set_offsets(nodes[n : n + 1])
            self._nodes[n].set_sizes([min(0.6 * cell, 14.0) ** 2])
            self._node_labels[n].set_position((nodes[n, 0], nodes[n, 1] + label_offset))
        for text in self._uav_labels:
            text.set_visible(scale >= 14)  # a smaller disc has no room for a digit
            text.set_fontsize(min(self._font * 0.9, 0.45 * cell))
        if self.levels:
            self._disc_area = self._uavs.get_sizes()[0]  # the highest level's; lower ones are smaller
            for text in self._level_tags:
                text.set_fontsize(max(6.0, min(self._font * 0.8, 0.4 * cell)))
        self._fit_coordinates(cell, nodes)
        key = nodes.tobytes()
        if key not in self._backgrounds:
            if len(self._backgrounds) >= BACKGROUNDS_KEPT:
                del self._backgrounds[next(iter(self._backgrounds))]
            self.canvas.draw()
            self._backgrounds[key] = self.canvas.copy_from_bbox(self.figure.bbox)
        self._background = self._backgrounds[key]

    def _fit_coordinates(self, cell: float, nodes: np.ndarray) -> None:
        """The coordinates for cells of ``cell`` points and the layout's ``nodes``: ``x`` below the grid and ``y`` left
        of it, or on the other side where the base's pad lies there or fewer nodes do; every one while they fit, else
        every 2nd, 5th, 10th, ...; one that a node or its name would cover is left out."""
        L1, L2 = self.world.cfg.grid
        base = self.world.cfg.base if self.energy is not None else None
        font, digits = min(self._font * 0.8, max(5.5, 0.6 * cell)), len(str(max(L1, L2) - 1))
        gap = max(COORDINATE_GAP, (0.6 * font + 1.5) / cell)  # clear of the grid's edge however small its cells
        columns = [
            c
            for c, free in ((-0.5 - gap, not base or base[0] >= 0), (L1 - 0.5 + gap, not base or base[0] < L1))
            if free
        ]
        rows = [
            r
            for r, free in ((L2 - 0.5 + gap, not base or base[1] < L2), (-0.5 - gap, not base or base[1] >= 0))
            if free
        ]

        # how far from a node (in cells) a label would touch its marker or its name (two letters under it)
        marker, half = min(0.6 * cell, 14.0) / 2, 0.5 * font  # half a node's marker, half a label's height, in points
        across = (max(marker, 0.65 * self._font) + 0.3 * digits * font) / cell
        above, below = (marker + half) / cell, (marker + 1 + self._font + half) / cell

        def covered(x: float, y: float) -> bool:
            return bool(
                ((abs(nodes[:, 0] - x) < across) & (y - nodes[:, 1] > -above) & (y - nodes[:, 1] < below)).any()
            )

        column = min(columns or [-0.5 - gap], key=lambda c: sum(covered(c, y) for y in range(L2)))
        row = min(rows or [L2 - 0.5 + gap], key=lambda r: sum(covered(x, r) for x in range(L1)))
        needed = font * (0.65 * digits + 0.5)  # points between the centres of two labels
        every = next(k for k in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 10**9) if k * cell >= needed)
        for x, text in enumerate(self._x_coordinates):
            text.set_position((x, row))
            text.set_visible(x % every == 0 and not covered(x, row))
        for y, text in enumerate(self._y_coordinates):
            text.set_position((column, y))
            text.set_visible(y % every == 0 and not covered(column, y))
        # each name at the end of its line away from the other line
        self._x_name.set_position((L1 - 0.5 + gap if column < 0 else -0.5 - gap, row))
        self._y_name.set_position((column, -0.5 - gap if row > 0 else L2 - 0.5 + gap))
        for text in (*self._x_coordinates, *self._y_coordinates, self._x_name, self._y_name):
            text.set_fontsize(font)

    def _draw_gauges(self, xy: np.ndarray, battery: np.ndarray) -> None:
        """Each UAV's battery gauge under it: a frame of :data:`GAUGE_WIDTH` cells filled to its fraction ``battery``
        ``[N]`` in the colour of its level."""
        left, top = xy[:, 0] - GAUGE_WIDTH / 2, xy[:, 1] + GAUGE_TOP
        bottom = top + GAUGE_HEIGHT

        def boxes(right):
            return np.stack([np.stack([left, top], -1), np.stack([right, top], -1),
                             np.stack([right, bottom], -1), np.stack([left, bottom], -1)], 1)  # fmt: skip

        self._gauge_frames.set_verts(boxes(left + GAUGE_WIDTH))
        self._gauges.set_verts(boxes(left + GAUGE_WIDTH * battery))
        self._gauges.set_facecolors([next(c for level, c in GAUGE_LEVELS if b >= level) for b in battery])

    def pixel_of(self, x: float, y: float) -> tuple[int, int]:
        """``(row, column)`` of the frame's pixel at the point ``(x, y)`` of the grid (cell units), as last drawn."""
        px, py = self.ax.transData.transform((x, y))
        return int(self.size[0] - py), int(px)

    # ------------------------------------------------------------- frames
    def _layout_optimum(self, index: int, nodes: torch.Tensor) -> float:
        key = nodes.cpu().numpy().tobytes()
        if key not in self._u_star:
            world = self.world
            contributions, direct = world.cell_contributions[index : index + 1], world.direct[index : index + 1]
            self._u_star[key] = float(exact_optimum(contributions, direct, world.cfg)[0][0])
        return self._u_star[key]

    def _line_of_sight(self, nodes: torch.Tensor) -> np.ndarray:
        """``[P, 4]`` bool: the layout ``nodes``' links from every position (a cell centre at the UAVs' height, or at
        each altitude level), clear of every building or not; computed once per layout."""
        key = nodes.cpu().numpy().tobytes()
        if key not in self._los:
            if len(self._los) >= BACKGROUNDS_KEPT:
                del self._los[next(iter(self._los))]
            if self.levels:
                cells = self.world.dynamics.positions.xyz.to(nodes.device, nodes.dtype)
            else:
                cells = cell_xyz(self.world.cfg, nodes.dtype, nodes.device)
            self._los[key] = self.city.line_of_sight(cells, nodes).cpu().numpy()
        return self._los[key]

    def frame(self, index: int = 0, focus: int | None = None) -> np.ndarray:
        """The ``[H, W, 3]`` uint8 picture of world ``index`` now; ``focus``: the UAV to ring."""
        world, cfg = self.world, self.world.cfg
        state = world.state
        nodes_t = world.nodes[index]
        nodes = nodes_t[:, :2].cpu().numpy()
        if nodes.tobytes() != self._fitted:
            self._fit(nodes)
            self._fitted = nodes.tobytes()
        cells, tasks = state.cell[index].cpu().numpy(), state.task[index].cpu().numpy()  # cells: position indices
        if self.levels:  # (x, y, level) of each position; one out of service is drawn at the base below
            serving_position = state.cell[index].clamp(max=world.num_positions - 1)
            *xy, level = world.position_coordinates(serving_position).cpu().numpy().T
            xy = np.stack(xy, -1).astype(float)
        else:
            xy = np.stack([cells % cfg.grid[0], cells // cfg.grid[0]], -1).astype(float)
        away = cells >= world.num_positions  # out of service (returning, out, charging, waiting): at the base
        relaying = tasks == RELAYING
        colours = np.where(relaying[:, None], np.array(RELAY_COLOUR), np.array(SENSE_COLOUR)) / 255
        if self.energy is not None:
            status = state.status[index].cpu().numpy()
            battery = (state.battery[index] / self.energy.capacity).clamp(0, 1).cpu().numpy()
            xy[away] = self.slots[away]
            colours[away] = np.reshape([self._status_rgb[int(s)] for s in status[away]], (-1, 3))
            self._draw_gauges(xy, battery)
        self._uavs.set_offsets(xy)
        self._uavs.set_facecolors(colours)
        for i, text in enumerate(self._uav_labels):
            text.set_position(xy[i])
        if self.levels:
            grow = LEVEL_DISC + (1 - LEVEL_DISC) * level / (cfg.num_levels - 1)  # the disc's diameter by level
            self._uavs.set_sizes(self._disc_area * grow**2)
            for i, tag in enumerate(self._level_tags):  # at the disc's upper right (y grows downwards)
                tag.set_position((xy[i, 0] + 0.25 * grow[i], xy[i, 1] - 0.25 * grow[i]))
                tag.set_text("" if away[i] else f"l{int(level[i])}")
        self._focus.set_visible(focus is not None)
        if focus is not None:
            self._focus.set_offsets(xy[focus : focus + 1])
        # links that earn nothing (docs/model.md): the emergency link's while no UAV relays (the lease rule); in the
        # authors' code, every link while all UAVs do the same job
        if cfg.rate_model == "reference_code":
            paid, unpaid_note = 0 < relaying.sum() < cfg.num_uavs, "   one job for all: no rates"
        else:
            paid, unpaid_note = bool(relaying.any()) or not cfg.lease_rule, "   no relay: no lease"
        # in a city of geometric line of sight, a blocked link (PT or PR only: S and E fly above the roofs) is dashed
        clear = self._line_of_sight(nodes_t) if self.dash_nlos else None
        segments, link_colours, styles = [], [], []
        for i in range(len(cells)):
            ends = (PT, PR) if relaying[i] else (S, E)
            src, dst = nodes[ends[0]], nodes[ends[1]]
            segments += [(src, xy[i]), (xy[i], dst)] if not away[i] else [(xy[i], xy[i])] * 2
            colour = (*colours[i], 0.45) if paid else IDLE_LINK
            link_colours += [colour, colour]
            if clear is None:
                styles += ["solid" if paid else "dashed"] * 2
            else:
                styles += ["solid" if away[i] or clear[cells[i], n] else "dashed" for n in ends]
        self._links.set_segments(segments)
        self._links.set_colors(link_colours)
        self._links.set_linestyles(styles)
        # the step's rates (faded draws where fading is on) against the layout's U* (mean channels)
        r_pu, r_se = (float(v) for v in state.r[index])
        u, u_star = r_pu + r_se, self._layout_optimum(index, nodes_t)
        head = f"{self.label}  " if self.label else ""
        self._title.set_text(f"{head}step {int(state.steps[index])}   U {u:.3f} / U* {u_star:.3f} ({u / u_star:.1%})")
        note = "" if paid else unpaid_note
        serving = "" if self.energy is None else f"   serving {int((~away).sum())}/{cfg.num_uavs}"
        self._rates.set_text(f"world {index}   R_PU {r_pu:.3f}   R_SE {r_se:.3f}{serving}{note}")
        # per UAV: its share of its network's sum inside the log
        contributions = world.cell_contributions[index].cpu().numpy()  # [C, 2]
        contributions = np.concatenate([contributions, np.zeros((1, 2))])  # row C: a UAV out of service adds nothing
        own = np.where(relaying, contributions[cells, 0], contributions[cells, 1])
        totals = np.where(relaying, own[relaying].sum(), own[~relaying].sum())
        shares = np.divide(own, totals, out=np.zeros_like(own), where=totals > 0)
        for i, row in enumerate(self._rows):
            text = f"{i:>3} {TASK_NAMES[int(tasks[i])]} {shares[i]:4.0%}"
            if self.energy is not None:  # the battery; out of service, the status and its steps left instead
                if away[i]:
                    steps_left = f" {int(state.timer[index, i])}" if status[i] in (RETURNING, CHARGING) else ""
                    text = f"{i:>3} {STATUS_NAMES[int(status[i])] + steps_left:<10}"
                text += f" {battery[i]:4.0%}"
            if self.levels and not away[i]:
                text += f" {cfg.altitudes_m[int(level[i])]:>4g}m"
            row.set_text(text)
        self._row_dots.set_facecolors(colours)
        self.canvas.restore_region(self._background)
        for artist in self._dynamic:
            self.figure.draw_artist(artist)
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def frames(self, indices: Sequence[int], focus: int | None = None, columns: int | None = None) -> np.ndarray:
        """The frames of worlds ``indices`` tiled, ``columns`` per row (default: about a square); ``focus``: the UAV
        to ring."""
        return tile([self.frame(i, focus) for i in indices], columns)


def tile(frames: Sequence[np.ndarray], columns: int | None = None, gap: int = 4) -> np.ndarray:
    """``[H, W, 3]`` frames of one size side by side, ``columns`` per row (default ``ceil(sqrt(n))``), ``gap``
    white pixels apart."""
    n = len(frames)
    columns = columns or math.ceil(math.sqrt(n))
    rows = math.ceil(n / columns)
    h, w, _ = frames[0].shape
    out = np.full((rows * h + (rows - 1) * gap, columns * w + (columns - 1) * gap, 3), 255, dtype=np.uint8)
    for k, frame in enumerate(frames):
        r, c = divmod(k, columns)
        out[r * (h + gap) : r * (h + gap) + h, c * (w + gap) : c * (w + gap) + w] = frame
    return out


_RENDERERS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # one reused figure per World


def render(world, mode: str = "rgb_array", env_index=0, agent_index_focus: int | None = None) -> np.ndarray:
    """VMAS's ``render`` for a :class:`World`: world ``env_index``'s frame, or the frames of a list of worlds tiled.

    Refuses, in one line, a mode other than ``"rgb_array"``, a world or UAV index out of range, and a world never
    reset.

    Args:
        world: the :class:`World` (``env.world``), reset at least once.
        mode: ``"rgb_array"``, the only mode.
        env_index: the world to draw, or a list of worlds to tile.
        agent_index_focus: the UAV to ring in the picture, or None.

    Returns:
        The ``[H, W, 3]`` uint8 frame.

    Example:
        >>> from uavrl.envs import UAVSpectrumEnv
        >>> env = UAVSpectrumEnv(batch_size=2, grid=(4, 4), num_uavs=2)
        >>> _ = env.reset()
        >>> frame = render(env.world, env_index=1, agent_index_focus=0)
        >>> frame.ndim, frame.shape[-1], frame.dtype
        (3, 3, dtype('uint8'))
    """
    if mode not in RENDER_MODES:
        raise InvalidOption(
            "mode",
            message=f"render(mode={mode!r}) is invalid: UAVSpectrumEnv renders mode='rgb_array' only (an [H, W, 3] "
            "uint8 frame; show it with matplotlib's imshow)",
        )
    B, N = world.num_worlds, world.num_uavs
    indices = [env_index] if isinstance(env_index, numbers.Integral) else env_index
    if (
        isinstance(env_index, bool)
        or not isinstance(indices, Sequence)
        or not indices
        or not all(isinstance(i, numbers.Integral) and not isinstance(i, bool) and 0 <= i < B for i in indices)
    ):
        message = f"render(env_index={env_index!r}) is invalid: give a world 0..{B - 1} or a list of them"
        raise InvalidOption("env_index", message=message)
    if agent_index_focus is not None and not (
        isinstance(agent_index_focus, numbers.Integral)
        and not isinstance(agent_index_focus, bool)
        and 0 <= agent_index_focus < N
    ):
        raise ValueError(
            f"render(agent_index_focus={agent_index_focus!r}) is invalid: give a UAV 0..{N - 1}, or None for none"
        )
    if not world.was_reset:
        raise RuntimeError("render() before any reset: call env.reset() first (the worlds have no UAVs yet)")
    renderer = _RENDERERS.get(world)
    if renderer is None:
        renderer = _RENDERERS[world] = WorldRenderer(world)
    if isinstance(env_index, numbers.Integral):
        return renderer.frame(int(env_index), agent_index_focus)
    return renderer.frames([int(i) for i in indices], agent_index_focus)
