"""The BenchMARL command's body (``python -m uavrl.benchmarl``, :mod:`uavrl.benchmarl`; the ``[benchmarl]`` extra):
BenchMARL's :class:`~benchmarl.experiment.Experiment` of a config (:func:`build_experiment`), run in a held run
directory with our evaluation (:func:`run_training`), and rebuilt from a finished run (:func:`load_experiment`).
BenchMARL is imported where an experiment is built, so that a run directory :func:`load_experiment` cannot use is
refused, and named, without it."""

from __future__ import annotations

import functools
import json
import os
import re
import shutil
import tempfile
import time
import weakref
from pathlib import Path

import torch
import yaml
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from uavrl.cli import BENCHMARL_INSTALL, compose_config
from uavrl.config import model_config
from uavrl.envs import InvalidOption, InvalidType
from uavrl.experiment.checkpoints import CheckpointError, read_torch
from uavrl.experiment.io import DamagedRun, quoted, read_small_text, save_json, save_text, special_kind
from uavrl.experiment.logger import RunLogger
from uavrl.experiment.rundir import RunDirectory
from uavrl.experiment.runs import already_finished, claim_run_dir, eval_settings, finished, yardstick_line
from uavrl.experiment.saved import SavedYamlLoader

try:
    from uavrl.agents.benchmarl import UAVTask, YardstickCallback
except ModuleNotFoundError as missing:  # no BenchMARL: load_experiment still refuses, naming it, a run it cannot use
    if missing.name.split(".")[0] != "benchmarl":
        raise
    UAVTask = YardstickCallback = None


def run_training(cfg: DictConfig, algorithm: str) -> Path:
    """Run BenchMARL's experiment as configured, once :func:`uavrl.benchmarl.check_settings` passed, and evaluate its
    policy with ours; returns the run directory.

    Args:
        cfg: the composed ``benchmarl`` config.
        algorithm: the algorithm's name in BenchMARL's registry (``qmix``, ``mappo``, ...).

    Returns:
        The run directory.
    """
    held = hold_run_dir(cfg, algorithm)
    try:  # released, never removed: BenchMARL's own folder may hold its checkpoints
        return run_experiment(cfg, algorithm, held.path)
    finally:
        held.release()


def hold_run_dir(cfg: DictConfig, algorithm: str) -> RunDirectory:
    """``run_dir`` or a new ``runs/benchmarl_<algorithm>/<env>/<timestamp>``, claimed and locked as ``uavrl.train``'s
    are (:func:`uavrl.experiment.runs.claim_run_dir`)."""
    refusal = already_finished(cfg.run_dir) if cfg.run_dir else ""
    return claim_run_dir(cfg.run_dir, f"benchmarl_{algorithm}", cfg.env.name, finished, refusal)


def build_experiment(cfg: DictConfig, save_folder: Path, callbacks=(), **experiment_settings):
    """BenchMARL's :class:`~benchmarl.experiment.Experiment` of ``cfg`` (its task, algorithm, models and seed),
    keeping its folders under ``save_folder``; ``experiment_settings`` replace those of ``cfg.experiment``."""
    from benchmarl.experiment import Experiment
    from benchmarl.hydra_config import (
        load_algorithm_config_from_hydra,
        load_experiment_config_from_hydra,
        load_model_config_from_hydra,
    )

    experiment_config = load_experiment_config_from_hydra(cfg.experiment)
    experiment_config.save_folder = str(save_folder.resolve())
    for name, value in experiment_settings.items():
        setattr(experiment_config, name, value)
    return Experiment(
        task=UAVTask.from_model_config(cfg.task.name, model_config(cfg)),
        algorithm_config=load_algorithm_config_from_hydra(cfg.algorithm),
        model_config=load_model_config_from_hydra(cfg.model),
        critic_model_config=load_model_config_from_hydra(cfg.critic_model),
        seed=int(cfg.seed),
        config=experiment_config,
        callbacks=list(callbacks),
    )


def load_experiment(run_dir):
    """The experiment of a ``python -m uavrl.benchmarl`` run directory at its last checkpoint, to act or be scored
    (``experiment.policy``; docs/leaderboard.md).

    It is rebuilt from the run's ``config.yaml`` as the command built it, in a temporary folder removed with it, and
    the checkpoint's weights are read with ``torch.load(weights_only=True)``: nothing in the run directory is
    written, and nothing read from it runs code (BenchMARL's own ``Experiment.reload_from_file`` unpickles the
    experiment's ``config.pkl``).  Every file is read through the guarded reader, and none through a link out of the
    directory.  A ``run_dir`` that is no path (TypeError), no directory, or no finished run of the command
    (ValueError) is refused in one line that names it, before BenchMARL is needed.

    Args:
        run_dir: the run directory (``run_dir=`` of the command): a str or a path.
    """
    if not isinstance(run_dir, (str, os.PathLike)) or not isinstance(os.fspath(run_dir), str):
        raise InvalidType(
            "run_dir",
            message=f"run_dir={run_dir!r} is invalid: give the run directory's path (a str or a pathlib.Path)",
        )
    run_dir = Path(run_dir)
    given = f"run_dir={quoted(run_dir)}"
    if not run_dir.is_dir():
        if not os.path.lexists(run_dir):
            raise InvalidOption("run_dir", message=f"{given} is invalid: no such directory")
        raise InvalidOption(
            "run_dir", message=f"{given} is invalid: it is {special_kind(run_dir) or 'a file'}, not a directory"
        )
    no_run = f"{given} is no finished run of python -m uavrl.benchmarl"
    cannot = f"{no_run}: its metrics.json and config.yaml cannot be read as the command writes them"
    try:
        metrics = json.loads(read_small_text(run_dir / "metrics.json", within=run_dir))
        saved = yaml.load(read_small_text(run_dir / "config.yaml", within=run_dir), Loader=SavedYamlLoader)
        algorithm, task = metrics["agent"].removeprefix("benchmarl_"), saved["task"]["name"]
    except DamagedRun as err:  # a file there that the guarded reader refuses (a FIFO, a link out, ...): named
        missing = not all(os.path.lexists(run_dir / name) for name in ("metrics.json", "config.yaml"))
        raise InvalidOption("run_dir", message=cannot if missing else f"{cannot} ({err})") from None
    except (OSError, ValueError, yaml.YAMLError, RecursionError, KeyError, TypeError, AttributeError):
        raise InvalidOption("run_dir", message=cannot) from None
    for what, name in (("metrics.json's agent", metrics["agent"]), ("config.yaml's task.name", task)):
        if not isinstance(name, str) or not re.fullmatch(r"\w+", name.removeprefix("benchmarl_")):
            raise InvalidOption("run_dir", message=f"{no_run}: {what}={name!r} names no algorithm or task of it")
    frames = {p: p.stem.rpartition("_")[2] for p in run_dir.glob("*/checkpoints/checkpoint_*.pt")}
    checkpoints = sorted((p for p, n in frames.items() if n.isdigit()), key=lambda p: int(frames[p]))
    if not checkpoints:
        raise InvalidOption("run_dir", message=f"{no_run}: it holds no checkpoint */checkpoints/checkpoint_<frames>.pt")
    last = checkpoints[-1]
    if not last.resolve().is_relative_to(run_dir.resolve()):
        raise InvalidOption("run_dir", message=f"{quoted(last)} is a link to {quoted(last.resolve())}, out of {given}")
    if UAVTask is None:
        raise ImportError(f"load_experiment({given}) needs BenchMARL, which is not installed: {BENCHMARL_INSTALL}")
    import benchmarl  # noqa: F401  registers its config schemas with Hydra's ConfigStore

    try:
        cfg = OmegaConf.merge(compose_config("benchmarl", [f"algorithm={algorithm}", f"task=uavrl/{task}"]), saved)
    except (SystemExit, OmegaConfBaseException) as err:  # Hydra's refusal of an algorithm or task it does not have
        raise InvalidOption(
            "run_dir", message=f"{no_run}: its config.yaml does not compose ({str(err).removeprefix('error: ')})"
        ) from None
    try:
        state = read_torch(last)
    except CheckpointError as err:  # torch's unpickler refuses anything but tensors and plain containers
        raise InvalidOption("run_dir", message=f"{quoted(last)} cannot be read as weights ({err})") from None
    folder = tempfile.mkdtemp(prefix="uavrl-benchmarl-")
    experiment = build_experiment(cfg, Path(folder), loggers=[])
    weakref.finalize(experiment, shutil.rmtree, folder, ignore_errors=True)  # the folder goes with the experiment
    try:
        experiment.load_state_dict(state)
    except (KeyError, RuntimeError, TypeError, ValueError, AttributeError) as err:
        raise InvalidOption(
            "run_dir", message=f"{quoted(last)} does not fit the run's config.yaml ({str(err).splitlines()[0][:200]})"
        ) from None
    return experiment


def run_experiment(cfg: DictConfig, algorithm: str, run_dir: Path) -> Path:
    """BenchMARL's experiment of ``cfg`` run in the held ``run_dir``, its policy evaluated with ours at each of its
    evaluations and at the end; writes ``config.yaml``, ``curve.json`` and ``metrics.json``, prints the summary and
    returns ``run_dir``."""
    torch.set_num_threads(int(cfg.num_threads))
    env_cfg = model_config(cfg)
    save_text(OmegaConf.to_yaml(OmegaConf.to_container(cfg, resolve=True)), run_dir / "config.yaml")
    open_log = functools.partial(RunLogger, run_dir, resume_step=0)
    yardstick = YardstickCallback(env_cfg, eval_settings(cfg, "cpu"), open_log)
    experiment = build_experiment(cfg, run_dir, [yardstick])
    started = time.perf_counter()
    experiment.run()
    final = yardstick.measure()
    yardstick.log(final, experiment.total_frames)
    yardstick.close()
    result = {
        "agent": f"benchmarl_{algorithm}",
        "env": cfg.env.name,
        "task": f"uavrl/{cfg.task.name}",
        "env_steps": experiment.total_frames,
        "iterations": experiment.n_iters_performed,
        "train_seconds": final["time/train_seconds"],
        "train_cpu_seconds": final["time/train_cpu_seconds"],
        "total_seconds": time.perf_counter() - started,
        **final,
    }
    save_json(yardstick.curve, run_dir / "curve.json")
    save_json(result, run_dir / "metrics.json")
    grid = f"{env_cfg.grid[0]}x{env_cfg.grid[1]} grid, {env_cfg.num_uavs} UAVs"
    print(
        f"trained BenchMARL {algorithm} on uavrl/{cfg.task.name} ({grid}): {result['env_steps']:,} frames in "
        f"{result['train_seconds']:.1f} s; optimality {final['eval/optimality']:.4f} "
        f"from {cfg.eval.num_starts} fixed starts"
    )
    print(yardstick_line(cfg, result))
    print(f"run directory: {run_dir} (config.yaml, metrics.json, curve.json, TensorBoard events, {experiment.name}/)")
    return run_dir
