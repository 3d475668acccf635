"""Evaluate a saved agent: ``python -m uavrl.evaluate checkpoint=runs/tabular/paper/<stamp>``.

Rebuilds the agent from the checkpoint's own config (a run directory's newest
readable checkpoint, or the file given), runs the shared greedy evaluation
(``eval.*`` settings may be overridden, e.g. ``eval.num_starts=100``), writes
the metrics as JSON to ``eval.json`` beside the checkpoint (an earlier evaluation there with other settings or of
another checkpoint stays: this one then goes to ``eval-2.json``, ``eval-3.json``, ...; the settings of each are
recorded in ``.uavrl-evaluations.json``) and prints a summary
in words: the agent, the model it was evaluated on, the headline metrics and
the yardstick, where the file went (``print_json=true`` prints the metrics as
JSON in its place).

A size-free network (``agent=dqn agent.network=set``) is evaluated zero-shot on another team size or grid with
``env.num_uavs=<N>``, ``env.grid=[L1,L2]`` and ``env.layout`` (``eval-<N>uav-<L1>x<L2>.json``); any other policy is
refused there in one line, as is any other ``env.*`` that differs from the saved run's.  The summary names the
teams the network trained on and the one it was evaluated on (``zero-shot: ...`` when it is not one of them).

Every setting is checked before torch is imported (:func:`check_settings`); the evaluation itself is
:mod:`uavrl.experiment.evaluating`'s (``evaluate_checkpoint``; ``load_agent`` is
:func:`uavrl.experiment.saved.load_agent`).
"""

from __future__ import annotations

from omegaconf import DictConfig

from uavrl.cli import run_command
from uavrl.config import RUN_OPTION_SETTINGS
from uavrl.envs._moved import moved_names
from uavrl.experiment.saved import check_evaluation

# uavrl 0.2's names of this module that moved to the library (load_agent, evaluate_checkpoint, output_dir, ...):
# deprecated aliases
__getattr__ = moved_names(__name__, "uavrl.experiment.saved", "uavrl.experiment.evaluating")


def check_settings(cfg: DictConfig, video: bool | None = None, overrides=None) -> None:
    """The settings of an evaluation (``video``: with a video, default ``eval.video``), refused in one line before
    anything heavy is imported (:func:`uavrl.experiment.saved.check_evaluation`, which ``uavrl.render`` checks
    too).

    Args:
        cfg: the composed config (``checkpoint=`` and the ``eval.*`` settings).
        video: whether a video is made; None: ``eval.video``.
        overrides: the command line's overrides, so a refusal names what was typed.
    """
    check_evaluation(cfg, video, overrides)


def print_evaluation(cfg: DictConfig, overrides) -> None:
    """``python -m uavrl.evaluate``: the summary in words, or with ``print_json=true`` the metrics as JSON.

    Args:
        cfg: the composed config.
        overrides: the command line's overrides.
    """
    check_settings(cfg, overrides=list(overrides) or None)
    from uavrl.experiment import evaluating  # torch, the agents: only once the settings are good

    evaluating.print_evaluation(cfg, overrides, checked=True)


if __name__ == "__main__":
    run_command("config", print_evaluation, RUN_OPTION_SETTINGS)
