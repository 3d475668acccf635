"""Reproduce the paper: ``python -m uavrl.reproduce table2`` and ``python -m uavrl.reproduce figures``.

``table2`` runs the paper's protocol (Table II: 2 UAVs, per grid 10 runs x 200
episodes of 120 to 30,000 steps) with the compiled tabular learner and prints
the table beside the paper's timings, with the final greedy optimality.
``figures`` draws Figs. 3-5 for 6x6 (mean over runs, min-max band) as PNG from
the per-episode data that ``table2`` saved for the same settings (without any,
it runs that grid's protocol first, and writes no table).  Both also write the
curves to TensorBoard.

Overrides (Hydra): ``grids=[6] runs=3 episodes=50 seed=1``;
``state_includes_tasks=true`` learns over the full configuration instead of the
paper's joint location.  Each variant of the protocol writes to its own
directory: ``reproduction/paper`` for the paper's settings, else
``reproduction/<the settings that differ>`` (e.g.
``reproduction/grids-6_runs-3_episodes-50``).  ``out_dir=<dir>`` chooses the
directory; one that holds another variant is refused unless ``overwrite=true``,
which removes the files reproduce wrote there (listed in its ``.uavrl-written.json``) and nothing else: a file of
the same name that reproduce did not write is refused, never overwritten.

Every setting, and that the output directory holds no other variant, is checked before torch or numba is imported
(:func:`check_settings`); the protocol's files are :mod:`uavrl.experiment.protocol`'s, the runs
:mod:`uavrl.experiment.reproducing`'s.
"""

from __future__ import annotations

import os
import sys

from omegaconf import DictConfig

from uavrl.cli import run_command
from uavrl.costs import check_reproduce_costs
from uavrl.envs._moved import moved_names
from uavrl.envs.rules import check, shown
from uavrl.experiment.io import quoted, special_kind
from uavrl.experiment.protocol import (
    COMMANDS,
    OUTPUTS,
    PAPER_STEPS,
    PROTOCOL,
    REFUSAL,
    grid_model,
    output_dir,
    planned_files,
    saved_variant,
    variant,
    written_here,
)
from uavrl.schema import ReproduceSchema
from uavrl.settings import REPRODUCE_SETTINGS, check_typed

# uavrl 0.2's names of this module that moved to the library (table2, figures, variant, ...): deprecated aliases
__getattr__ = moved_names(__name__, "uavrl.experiment.reproducing", "uavrl.experiment.protocol")
# how the model's options are typed on this command line
OPTION_SETTINGS = {"grid": "grids", "max_steps": "steps"}


def check_settings(cfg: DictConfig, overrides=None) -> None:
    """Every setting, and that the output directory holds no other variant, before anything heavy is imported
    (``overrides``: the command line's, so a refusal names what was typed)."""
    check(cfg, REPRODUCE_SETTINGS)
    check_typed(cfg, overrides, REPRODUCE_SETTINGS, ReproduceSchema)
    models = []
    for size in cfg.grids:
        if not cfg.steps and size not in PAPER_STEPS:
            reason = f"grid {size}x{size} is not in Table II ({sorted(PAPER_STEPS)}): also give steps=<per episode>"
            raise ValueError(f"grids={shown(list(cfg.grids))} is invalid: {reason}")
        models.append(grid_model(size, cfg))
    check_reproduce_costs(cfg, models, overrides)
    if cfg.command == "figures" and cfg.figure_grid not in cfg.grids:
        raise ValueError(f"figure_grid={cfg.figure_grid} is invalid: it must be one of grids={shown(list(cfg.grids))}")
    out_dir = output_dir(cfg)
    if os.path.lexists(out_dir) and not out_dir.is_dir():
        kind = special_kind(out_dir) or "a file"
        raise NotADirectoryError(f"out_dir={quoted(out_dir)} is {kind}, not a directory: give a new or existing folder")
    if not out_dir.exists():
        return
    manifest = written_here(out_dir)
    saved = saved_variant(out_dir)
    if not cfg.overwrite:
        if saved is not None and saved != variant(cfg):
            mine = variant(cfg)
            changed = [key for key in PROTOCOL if saved.get(key) != mine[key]]
            differences = ", ".join(f"{key}={shown(saved.get(key))} there, {shown(mine[key])} here" for key in changed)
            raise FileExistsError(f"out_dir={quoted(out_dir)} holds another variant ({differences}): {REFUSAL}")
        if saved is None and any(any(out_dir.glob(pattern)) for pattern in OUTPUTS):
            raise FileExistsError(f"out_dir={quoted(out_dir)} holds results of unknown settings: {REFUSAL}")
    manifest.check_writable(planned_files(cfg, out_dir))


def reproduce(cfg: DictConfig, overrides=()) -> None:
    """``python -m uavrl.reproduce``: check the settings, then run ``cfg.command``.

    Args:
        cfg: the composed ``reproduce`` config.
        overrides: the command line's overrides, so a refusal names what was typed.
    """
    check_settings(cfg, [o for o in overrides if not o.startswith("command=")] or None)
    from uavrl.experiment.reproducing import run_reproduction  # torch, numba, the learner: once the settings are good

    run_reproduction(cfg)


def cli() -> None:
    """``python -m uavrl.reproduce table2|figures [overrides]``: the command word becomes ``command=``."""
    if len(sys.argv) > 1 and "=" not in sys.argv[1] and not sys.argv[1].startswith("-"):
        command = sys.argv.pop(1)
        if command not in COMMANDS:
            raise SystemExit(f"error: unknown command {command!r}: use one of {', '.join(COMMANDS)}")
        sys.argv.append(f"command={command}")
    run_command("reproduce", reproduce, OPTION_SETTINGS)


if __name__ == "__main__":
    cli()
