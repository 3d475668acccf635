"""Watch a saved run: ``python -m uavrl.render runs/dqn/paper/<stamp>`` (or ``checkpoint=<run dir>``).

Plays the run's greedy policy (the policy :func:`uavrl.load_policy` returns) from the evaluation's
first ``eval.video_starts`` starts, the same starts the yardstick measures, for
``eval.horizon`` steps, beside the oracle from the same starts (one row per
start: the policy left, the oracle right), and writes ``video.gif`` (and
``video.mp4`` where PyAV is installed: ``pip install -e ".[video]"``) beside the
checkpoint, ``eval.video_fps`` steps per second.  ``python -m uavrl.evaluate
checkpoint=<run dir> eval.video=true`` writes the same video with the metrics.  It watches one run: two run
directories (or ``checkpoint=`` twice) are refused in one line that says how to render each in turn.

Under an energy model it also writes ``battery.png`` (:func:`uavrl.experiment.missions.mission_figure`): the batteries
of the mission the policy plays from the evaluation's first start for ``eval.horizon`` steps (default: the evaluation's,
the whole mission), one strip per UAV with its returns, arrivals, recharges and entries marked.

The settings are checked before torch is imported (:func:`uavrl.experiment.saved.check_evaluation`, the
evaluation's check with a video); the drawing is :mod:`uavrl.experiment.rendering`'s.
"""

from __future__ import annotations

import sys
from pathlib import Path

from omegaconf import DictConfig

from uavrl.cli import hydra_quoted, run_command
from uavrl.config import RUN_OPTION_SETTINGS
from uavrl.envs._moved import moved_names
from uavrl.experiment.saved import check_evaluation

# uavrl 0.2's names of this module that moved to the library (render_checkpoint): deprecated aliases
__getattr__ = moved_names(__name__, "uavrl.experiment.rendering")


def print_videos(cfg: DictConfig, overrides) -> None:
    """``python -m uavrl.render``: the paths written, one a line.

    Args:
        cfg: the composed config.
        overrides: the command line's overrides.
    """
    check_evaluation(cfg, video=True, overrides=overrides)
    from uavrl.experiment import rendering  # torch, the agents, matplotlib: only once the settings are good

    rendering.print_videos(cfg, overrides, checked=True)


def check_one_run(overrides) -> None:
    """A one-line ValueError when the command line names several runs (``render a b``, or ``checkpoint=`` twice):
    render watches one, and a composed config would keep only the last."""
    runs = [o for o in overrides or () if o.lstrip("+~").split("=", 1)[0] == "checkpoint"]
    if len(runs) > 1:
        given = " ".join(o.split("=", 1)[1] for o in runs)
        raise ValueError(
            f"{' '.join(runs)} is invalid: render watches one run, and {len(runs)} were given: give one (each in "
            f'turn: for run in {given}; do python -m uavrl.render "$run"; done)'
        )


def as_overrides(args: list[str]) -> list[str]:
    """The command line with a bare run directory written as ``checkpoint=<it>``: an argument that is no flag and
    either has no ``=`` or names a path that exists (a sweep's run directories end in ``seed=<seed>``)."""

    def is_path(arg: str) -> bool:
        return not arg.startswith("-") and ("=" not in arg or Path(arg).exists())

    return [f"checkpoint={hydra_quoted(arg)}" if is_path(arg) else arg for arg in args]


if __name__ == "__main__":
    sys.argv[1:] = as_overrides(sys.argv[1:])
    try:  # before the command line's rule of one value a setting, which would say less
        check_one_run(sys.argv[1:])
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
    run_command("config", print_videos, RUN_OPTION_SETTINGS)
