"""BenchMARL's algorithms on the UAV task: ``python -m uavrl.benchmarl algorithm=mappo task=uavrl/paper_6x6 seed=0``.

Needs the extra: ``pip install torch==2.13.0 -e ".[benchmarl]"``.  The config (``configs/benchmarl.yaml``)
composes our ``env`` (the model's options, typed as for ``uavrl.train``: ``env.fading=rayleigh``), a task of
``configs/task/uavrl/`` (the scenario: grid and UAVs), and BenchMARL's own ``experiment``, ``algorithm`` and
``model`` configs.  BenchMARL's :class:`~benchmarl.experiment.Experiment` trains as it always does; the run
directory ``runs/benchmarl_<algorithm>/<env>/<timestamp>/`` holds ``config.yaml``, our TensorBoard ``eval/...``
scalars (the shared evaluation of BenchMARL's greedy policy at each of its evaluations), ``metrics.json`` (the
final evaluation and the training seconds, as every agent's), ``curve.json`` (each evaluation with the frames and
seconds at which it was taken), and BenchMARL's own folder (its logs and final checkpoint).
"""

from __future__ import annotations

import functools
import importlib.util
import re
import sys
import time
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from uavrl.cli import one_line, run_command
from uavrl.config import RUN_OPTION_SETTINGS, config_dir, model_config
from uavrl.envs.rules import check
from uavrl.experiment.io import quoted, save_json, save_text
from uavrl.experiment.rundir import RunDirectory, check_directory
from uavrl.experiment.runs import claim_run_dir, eval_settings, yardstick_line
from uavrl.settings import BENCHMARL_SETTINGS, check_benchmarl_costs

INSTALL = 'pip install torch==2.13.0 -e ".[benchmarl]"'
# BenchMARL's own config groups (pkg://benchmarl.conf); everything else on the command line is ours
BENCHMARL_GROUPS = ("experiment", "algorithm", "model", "critic_model")


def algorithm_name(cfg: DictConfig) -> str:
    """The name of ``cfg.algorithm`` in BenchMARL's registry (``qmix``, ``mappo``, ...)."""
    from benchmarl.algorithms import algorithm_config_registry

    kind = OmegaConf.get_type(cfg.algorithm)
    return next(name for name, config in algorithm_config_registry.items() if config is kind)


def check_ours(cfg: DictConfig, overrides=None) -> None:
    """Our settings (not BenchMARL's own) refused in one line, the costs of our part of the run included."""
    check(cfg, BENCHMARL_SETTINGS)
    check_benchmarl_costs(cfg, model_config(cfg), overrides)
    if cfg.run_dir:
        check_directory(cfg.run_dir, "run_dir")
        if finished(Path(cfg.run_dir)):
            raise FileExistsError(already_finished(cfg.run_dir))


def check_settings(cfg: DictConfig, overrides=None) -> str:
    """Every setting refused in one line before anything is built; returns the algorithm's name.  ``overrides``:
    the command line's, so that a refusal names what was typed."""
    from benchmarl.algorithms import algorithm_config_registry

    check_ours(cfg, overrides)
    name = algorithm_name(cfg)
    if not algorithm_config_registry[name].supports_discrete_actions():
        discrete = [n for n, c in algorithm_config_registry.items() if c.supports_discrete_actions()]
        raise ValueError(
            f"algorithm={name} is invalid: it acts in continuous action spaces only, and the UAVs' actions are "
            f"discrete; allowed algorithms are {', '.join(discrete)}"
        )
    return name


def finished(run_dir: Path) -> bool:
    return (run_dir / "metrics.json").exists()


def already_finished(run_dir) -> str:
    return f"run_dir={run_dir!r} already holds a finished run: pick another run_dir"


def hold_run_dir(cfg: DictConfig, algorithm: str) -> RunDirectory:
    """``run_dir`` or a new ``runs/benchmarl_<algorithm>/<env>/<timestamp>``, claimed and locked as ``uavrl.train``'s
    are (:func:`uavrl.experiment.runs.claim_run_dir`)."""
    refusal = already_finished(cfg.run_dir) if cfg.run_dir else ""
    return claim_run_dir(cfg.run_dir, f"benchmarl_{algorithm}", cfg.env.name, finished, refusal)


def train(cfg: DictConfig, overrides=()) -> Path:
    """Run BenchMARL's experiment as configured, evaluate its policy with ours; returns the run directory."""
    algorithm = check_settings(cfg, overrides)
    held = hold_run_dir(cfg, algorithm)
    try:  # released, never removed: BenchMARL's own folder may hold its checkpoints
        return run_experiment(cfg, algorithm, held.path)
    finally:
        held.release()


def build_experiment(cfg: DictConfig, save_folder: Path, callbacks=(), **experiment_settings):
    """BenchMARL's :class:`~benchmarl.experiment.Experiment` of ``cfg`` (its task, algorithm, models and seed),
    keeping its folders under ``save_folder``; ``experiment_settings`` replace those of ``cfg.experiment``."""
    from benchmarl.experiment import Experiment
    from benchmarl.hydra_config import (
        load_algorithm_config_from_hydra,
        load_experiment_config_from_hydra,
        load_model_config_from_hydra,
    )

    from uavrl.agents.benchmarl import UAVTask

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
    experiment's ``config.pkl``).  A directory that is no finished run of the command is refused in one line.

    Args:
        run_dir: the run directory (``run_dir=`` of the command).
    """
    import json
    import shutil
    import tempfile
    import weakref

    import torch
    import yaml

    from uavrl.cli import compose_config
    from uavrl.experiment.io import DamagedRun, SavedYamlLoader, read_small_text

    run_dir = Path(run_dir)
    check_directory(run_dir, "run_dir")
    no_run = f"run_dir={quoted(run_dir)} is no finished run of python -m uavrl.benchmarl"
    try:
        metrics = json.loads(read_small_text(run_dir / "metrics.json"))
        saved = yaml.load(read_small_text(run_dir / "config.yaml"), Loader=SavedYamlLoader)
        algorithm, task = metrics["agent"].removeprefix("benchmarl_"), saved["task"]["name"]
    except (DamagedRun, OSError, ValueError, yaml.YAMLError, RecursionError, KeyError, TypeError, AttributeError):
        raise ValueError(
            f"{no_run}: its metrics.json and config.yaml cannot be read as the command writes them"
        ) from None
    frames = {p: p.stem.rpartition("_")[2] for p in run_dir.glob("*/checkpoints/checkpoint_*.pt")}
    checkpoints = sorted((p for p, n in frames.items() if n.isdigit()), key=lambda p: int(frames[p]))
    if not checkpoints:
        raise ValueError(f"{no_run}: it holds no checkpoint */checkpoints/checkpoint_<frames>.pt")
    cfg = OmegaConf.merge(compose_config("benchmarl", [f"algorithm={algorithm}", f"task=uavrl/{task}"]), saved)
    try:
        state = torch.load(checkpoints[-1], map_location="cpu", weights_only=True)
    except Exception as err:  # torch's unpickler refuses anything but tensors and plain containers
        raise ValueError(f"{quoted(checkpoints[-1])} cannot be read as weights ({one_line(err)[:200]})") from None
    folder = tempfile.mkdtemp(prefix="uavrl-benchmarl-")
    experiment = build_experiment(cfg, Path(folder), loggers=[])
    weakref.finalize(experiment, shutil.rmtree, folder, ignore_errors=True)  # the folder goes with the experiment
    experiment.load_state_dict(state)
    return experiment


def run_experiment(cfg: DictConfig, algorithm: str, run_dir: Path) -> Path:
    import torch

    from uavrl.agents.benchmarl import YardstickCallback
    from uavrl.experiment.logger import RunLogger

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


def tasks() -> list[str]:
    """The tasks of ``configs/task/uavrl/``, as ``task=`` takes them."""
    return sorted(f"uavrl/{path.stem}" for path in (Path(config_dir()) / "task" / "uavrl").glob("*.yaml"))


def check_task(arguments: list[str]) -> None:
    """A task we do not have is refused with ours (Hydra would list BenchMARL's task schemas)."""
    for argument in arguments:
        if argument.startswith("task=") and argument.removeprefix("task=") not in tasks():
            raise SystemExit(f"error: {argument} is invalid: allowed tasks are {', '.join(tasks())}")


def benchmarl_group(argument: str) -> bool:
    """Whether a command-line argument sets one of BenchMARL's groups (``algorithm=qmix``, ``model@critic_model=...``,
    ``experiment.max_n_frames=...``)."""
    key = argument.split("=", 1)[0].lstrip("+~")
    return re.split(r"[.@]", key)[0] in BENCHMARL_GROUPS


def refuse_without_benchmarl(arguments: list[str]) -> None:
    """Without the extra, our own settings are still checked and a bad one named as typed; then what needs BenchMARL
    is named with the line that installs it."""
    import warnings

    from hydra.core.config_store import ConfigStore

    # empty stand-ins for the defaults BenchMARL's package would bring, so that our part of the config composes
    for group, name in (("experiment", "base_experiment"), ("model/layers", "mlp"), ("algorithm", "unchecked")):
        ConfigStore.instance().store(group=group, name=name, node={})
    theirs = [argument for argument in arguments if benchmarl_group(argument)]
    ours = [argument for argument in arguments if argument not in theirs]
    if not any(argument.startswith("-") for argument in ours):  # a sweep's jobs are checked once it can run
        sys.argv[1:] = [*ours, "algorithm=unchecked"]
        with warnings.catch_warnings():  # Hydra warns that pkg://benchmarl.conf is missing: said below, once
            warnings.simplefilter("ignore", UserWarning)
            run_command("benchmarl", check_ours, RUN_OPTION_SETTINGS)
    needs = (
        f"{' '.join(theirs)} need{'s' if len(theirs) == 1 else ''} BenchMARL, which is" if theirs else "BenchMARL is"
    )
    raise SystemExit(f"error: {needs} not installed: {INSTALL}")


def main() -> None:
    check_task(sys.argv[1:])
    if importlib.util.find_spec("benchmarl") is None:
        refuse_without_benchmarl(sys.argv[1:])
    import benchmarl  # noqa: F401  registers its config schemas with Hydra's ConfigStore

    run_command("benchmarl", train, RUN_OPTION_SETTINGS)


if __name__ == "__main__":
    main()
    sys.exit(0)
