"""BenchMARL's algorithms on the UAV task: ``python -m uavrl.benchmarl algorithm=mappo task=uavrl/paper_6x6 seed=0``.

Needs the extra: ``pip install torch==2.13.0 -e ".[benchmarl]"``.  The config (``configs/benchmarl.yaml``)
composes our ``env`` (the model's options, typed as for ``uavrl.train``: ``env.fading=rayleigh``), a task of
``configs/task/uavrl/`` (the scenario: grid and UAVs), and BenchMARL's own ``experiment``, ``algorithm`` and
``model`` configs.  BenchMARL's :class:`~benchmarl.experiment.Experiment` trains as it always does; the run
directory ``runs/benchmarl_<algorithm>/<env>/<timestamp>/`` holds ``config.yaml``, our TensorBoard ``eval/...``
scalars (the shared evaluation of BenchMARL's greedy policy at each of its evaluations), ``metrics.json`` (the
final evaluation and the training seconds, as every agent's), ``curve.json`` (each evaluation with the frames and
seconds at which it was taken), and BenchMARL's own folder (its logs and final checkpoint).

Our settings (and BenchMARL's algorithm's kind of actions) are checked before anything is built
(:func:`check_settings`); the experiment is :mod:`uavrl.experiment.benchmarl`'s (``build_experiment``,
``load_experiment``).
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from uavrl.cli import BENCHMARL_INSTALL as INSTALL
from uavrl.cli import run_command
from uavrl.config import RUN_OPTION_SETTINGS, config_dir, model_config
from uavrl.costs import check_benchmarl_costs
from uavrl.envs._moved import moved_names
from uavrl.envs.rules import check
from uavrl.experiment.rundir import check_directory
from uavrl.experiment.runs import already_finished, finished
from uavrl.settings import BENCHMARL_SETTINGS

# uavrl 0.2's names of this module that moved to the library (build_experiment, load_experiment, ...): deprecated
# aliases
__getattr__ = moved_names(__name__, "uavrl.experiment.benchmarl")

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
    model = model_config(cfg)
    if model.message_size:  # a second action key in the group, which BenchMARL's discrete policies do not emit
        raise ValueError(
            f"env.message_size={model.message_size} is invalid for python -m uavrl.benchmarl: BenchMARL's policies "
            "choose the UAVs' discrete actions only; give env.message_size=0"
        )
    check_benchmarl_costs(cfg, model, overrides)
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


def train(cfg: DictConfig, overrides=()) -> Path:
    """Run BenchMARL's experiment as configured, evaluate its policy with ours; returns the run directory.

    Args:
        cfg: the composed ``benchmarl`` config.
        overrides: the command line's overrides, so that a refusal names what was typed.

    Returns:
        The run directory.
    """
    algorithm = check_settings(cfg, overrides)
    from uavrl.experiment.benchmarl import run_training  # torch, BenchMARL, TorchRL: once the settings are good

    return run_training(cfg, algorithm)


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
