"""Watch a saved run: ``python -m uavrl.render runs/dqn/paper/<stamp>`` (or ``checkpoint=<run dir>``).

Plays the run's greedy policy (the policy :func:`uavrl.load_policy` returns) from the evaluation's
first ``eval.video_starts`` starts, the same starts the yardstick measures, for
``eval.horizon`` steps, beside the oracle from the same starts (one row per
start: the policy left, the oracle right), and writes ``video.gif`` (and
``video.mp4`` where PyAV is installed: ``pip install -e ".[video]"``) beside the
checkpoint, ``eval.video_fps`` steps per second.  ``python -m uavrl.evaluate
checkpoint=<run dir> eval.video=true`` writes the same video with the metrics.

Under an energy model it also writes ``battery.png`` (:func:`uavrl.experiment.plots.mission_figure`): the batteries of the
mission the policy plays from the evaluation's first start for ``eval.horizon`` steps (default: the evaluation's,
the whole mission), one strip per UAV with its returns, arrivals, recharges and entries marked.
"""

from __future__ import annotations

import sys
from pathlib import Path

from omegaconf import DictConfig

from uavrl.cli import hydra_quoted, run_command
from uavrl.config import RUN_OPTION_SETTINGS, model_config
from uavrl.evaluate import check_settings, load_agent, output_dir
from uavrl.experiment.io import Manifest
from uavrl.settings import check_video_cost


def render_checkpoint(cfg: DictConfig, overrides=None) -> list[Path]:
    """The run's video files, written (``overrides``: the command line's, named by a refusal)."""
    check_settings(cfg, video=True, overrides=overrides)
    import torch

    from uavrl.envs.world import resolve_device
    from uavrl.experiment.plots import mission_figure
    from uavrl.experiment.video import VIDEO_RECORD, comparison_frames, save_videos, video_settings

    torch.set_num_threads(int(cfg.num_threads))
    device = resolve_device(cfg.device)
    agent, saved, fallback = load_agent(cfg.checkpoint, device)  # named checkpoint=, as the command line has it
    if fallback:
        print(f"warning: {fallback}", file=sys.stderr)
    env_cfg = model_config(saved)
    check_video_cost(cfg, env_cfg, overrides)
    policy, out_dir = agent.policies()[0], output_dir(cfg.checkpoint)
    frames = comparison_frames(policy, env_cfg, **video_settings(cfg, device))
    written_here = Manifest(out_dir, "checkpoint", VIDEO_RECORD)  # a user's video.gif or battery.png there stays
    written = save_videos(frames, out_dir, int(cfg.eval.video_fps), written_here)
    if env_cfg.energy != "none":  # the mission's batteries
        horizon, seed = cfg.eval.horizon, int(cfg.eval.seed)
        label = f"{saved.agent.name} (greedy)"
        written.append(
            mission_figure(
                policy,
                env_cfg,
                written_here.free(out_dir / "battery.png"),
                horizon=horizon,
                seed=seed,
                device=device,
                label=label,
            )
        )
    return written


def print_videos(cfg: DictConfig, overrides) -> None:
    """``python -m uavrl.render``: the paths written, one a line."""
    for path in render_checkpoint(cfg, overrides):
        print(path)


def as_overrides(args: list[str]) -> list[str]:
    """The command line with a bare run directory written as ``checkpoint=<it>``: an argument that is no flag and
    either has no ``=`` or names a path that exists (a sweep's run directories end in ``seed=<seed>``)."""

    def is_path(arg: str) -> bool:
        return not arg.startswith("-") and ("=" not in arg or Path(arg).exists())

    return [f"checkpoint={hydra_quoted(arg)}" if is_path(arg) else arg for arg in args]


if __name__ == "__main__":
    sys.argv[1:] = as_overrides(sys.argv[1:])
    run_command("config", print_videos, RUN_OPTION_SETTINGS)
