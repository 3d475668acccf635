"""Train an agent: ``python -m uavrl.train agent=tabular env=paper env.grid=[6,6] agent.episodes=200``.

Each run writes ``runs/<agent>/<env>/<timestamp>/``: TensorBoard events, the
resolved ``config.yaml``, ``checkpoint.pt`` (atomic, every
``train.checkpoint_every`` iterations and at the end; the one it replaces is
kept as ``checkpoint.prev.pt``) and ``metrics.json`` with the final
evaluation.  ``resume=<run dir>`` continues a killed run from its newest
readable checkpoint with the run's saved config; with the same seed it ends
exactly as an uninterrupted run would.  One process at a time holds a run
directory; Ctrl-C or SIGTERM saves a checkpoint at the end of the iteration
and prints the command that resumes it (:mod:`uavrl.experiment.rundir`).

Every setting is checked before torch is imported (:mod:`uavrl.settings`), so a
mistyped override is refused at once; :func:`train` then imports the training
loop (:mod:`uavrl.experiment.training`) and runs it.
"""

from __future__ import annotations

import os
from pathlib import Path

import yaml
from omegaconf import DictConfig

from uavrl.cli import run_command
from uavrl.config import RUN_OPTION_SETTINGS, model_config
from uavrl.costs import check_run_costs
from uavrl.envs._moved import moved_names
from uavrl.envs.config import HELD_OUT_CITY_SEEDS
from uavrl.envs.errors import InvalidOption
from uavrl.experiment.checkpoints import checkpoint_files, no_checkpoint, run_directory
from uavrl.experiment.io import quoted, read_regular_text, special_kind
from uavrl.experiment.rundir import check_run_files, tidy
from uavrl.experiment.runs import already_a_run
from uavrl.experiment.saved import read_run_config
from uavrl.settings import (
    AGENT_SETTINGS,
    RUN_SETTINGS,
    check_agent_settings,
    check_read,
    check_run,
    check_scenario,
    check_typed,
)

# uavrl 0.2's names of this module that moved to the library (Training, summary, ...): deprecated aliases
__getattr__ = moved_names(__name__, "uavrl.experiment.training")


def train(cfg: DictConfig, overrides=()) -> Path:
    """Run training as configured; returns the run directory.

    The settings are checked first (:func:`check_settings`), then the training loop runs
    (:func:`uavrl.experiment.training.run_training`). The run directory is locked for the whole run; SIGINT and
    SIGTERM end the run with a checkpoint at the end of the iteration (:mod:`uavrl.experiment.rundir`); a run that
    fails before it saved anything removes the directory it made.

    Args:
        cfg: the run's composed config (``uavrl/configs/config.yaml`` with the overrides).
        overrides: the command line's overrides (a refusal names a setting as typed).

    Returns:
        The run directory.
    """
    try:
        check_settings(cfg, overrides if overrides else None)
    except FileNotFoundError:
        if cfg.resume:  # a run killed in its first checkpoint's write: its temporary file goes, though refused
            tidy(run_directory(cfg.resume, "resume"))
        raise
    from uavrl.experiment.training import run_training  # torch, the agents: only once the settings are good

    return run_training(cfg, overrides)


def check_settings(cfg: DictConfig, overrides=None) -> None:
    """Every setting of a run, refused in one line before anything heavy is imported or any file written;
    ``overrides`` (the command line's) let a refusal name the setting as typed."""
    check_run(cfg)
    check_read(overrides, "train")
    check_typed(cfg, overrides, {**RUN_SETTINGS, **AGENT_SETTINGS.get(cfg.agent.name, {})})
    check_scenario(cfg)
    model = model_config(cfg)
    if model.city_seed >= HELD_OUT_CITY_SEEDS:
        reason = "seeds from 2**62 name the benchmark's held-out cities, which no training run lays out"
        raise InvalidOption("city_seed", model.city_seed, f"{reason}: give a seed below 2**62")
    check_agent_settings(cfg, model)
    check_run_costs(cfg, model, overrides)
    if cfg.resume:
        resumed = run_directory(cfg.resume, "resume")
        if not checkpoint_files(resumed):
            raise FileNotFoundError(no_checkpoint(cfg.resume, "resume"))
        check_run_files(resumed, "resume")
        read_run_config(resumed, f"resume={quoted(cfg.resume)}")  # refused here, before torch, if unreadable
    run_dir = Path(cfg.run_dir) if cfg.run_dir and not cfg.resume else None
    if run_dir is not None and os.path.lexists(run_dir) and not run_dir.is_dir():
        kind = special_kind(run_dir) or "a file"
        raise NotADirectoryError(f"run_dir={quoted(run_dir)} is {kind}, not a directory: give a directory")
    if run_dir is not None and checkpoint_files(run_dir):
        raise FileExistsError(already_a_run(run_dir))
    if run_dir is not None:
        check_no_foreign_run_files(run_dir)


def check_no_foreign_run_files(run_dir: Path) -> None:
    """A new run into an existing folder replaces no file of its names that uavrl did not write: a
    ``metrics.json`` without a checkpoint, or a ``config.yaml`` that is no uavrl run's config (a run killed before
    its first checkpoint leaves its own, which a new run replaces)."""
    for name in ("metrics.json", "config.yaml"):
        path = run_dir / name
        if not os.path.lexists(path):
            continue
        if name == "config.yaml":
            try:
                saved = yaml.safe_load(read_regular_text(path))
            except (OSError, ValueError, yaml.YAMLError):
                saved = None
            if isinstance(saved, dict) and {"agent", "env", "train", "seed"} <= saved.keys():
                continue
        raise FileExistsError(
            f"run_dir={quoted(run_dir)} holds {name}, which uavrl did not write there and a new run would replace: "
            "give another run_dir (new or empty), or move that file away"
        )


if __name__ == "__main__":
    run_command("config", train, RUN_OPTION_SETTINGS, check=check_settings)
