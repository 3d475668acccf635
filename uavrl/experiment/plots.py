"""Figures: matplotlib without a display, PNGs written atomically.

:func:`pyplot` and :func:`save_figure` are what every figure of the package uses (the study report's, the
benchmark's and a mission's batteries, :mod:`uavrl.experiment.missions`).
"""

from __future__ import annotations

import io
import os
import sys
from pathlib import Path

from uavrl.envs._moved import moved_names
from uavrl.experiment.io import save_bytes

# uavrl 0.2's names of this module that moved to uavrl.experiment.missions (battery_figure, mission_history, ...):
# deprecated aliases
__getattr__ = moved_names(__name__, "uavrl.experiment.missions")


def pyplot():
    """matplotlib's pyplot, without a display unless the caller chose a backend: a script or notebook that imported
    pyplot first, or set ``MPLBACKEND``, keeps its own (so ``plt.show()`` still shows our figures there)."""
    import matplotlib

    if "matplotlib.pyplot" not in sys.modules and not os.environ.get("MPLBACKEND"):
        matplotlib.use("Agg")  # the commands only write PNGs: no window, and no display needed
    import matplotlib.pyplot as plt

    return plt


def save_figure(figure, path: Path) -> Path:
    """The figure as a PNG written atomically (a temporary file renamed over it), then closed; laid out by its own
    layout engine (``layout="constrained"``), else by ``tight_layout``.

    Args:
        figure: a matplotlib figure.
        path: the PNG file to write.

    Returns:
        ``path``.
    """
    if figure.get_layout_engine() is None:
        figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110, metadata={"Software": None})
    save_bytes(buffer.getvalue(), path)
    pyplot().close(figure)
    return path
