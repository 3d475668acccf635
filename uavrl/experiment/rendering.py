"""The render command's body (``python -m uavrl.render``, :mod:`uavrl.render`): a saved run's greedy policy beside
the oracle as ``video.gif`` (and ``video.mp4``), and under an energy model the mission's batteries as
``battery.png``, written beside its checkpoint."""

from __future__ import annotations

import sys
from pathlib import Path

import torch
from omegaconf import DictConfig

from uavrl.config import model_config
from uavrl.costs import check_video_cost
from uavrl.envs.world import resolve_device
from uavrl.experiment.io import Manifest
from uavrl.experiment.missions import mission_figure
from uavrl.experiment.saved import check_evaluation, load_agent, output_dir
from uavrl.experiment.video import VIDEO_RECORD, comparison_frames, save_videos, video_settings


def render_checkpoint(cfg: DictConfig, overrides=None, checked: bool = False) -> list[Path]:
    """The run's video files, written.

    Args:
        cfg: the composed config (``checkpoint=`` and the ``eval.*`` settings).
        overrides: the command line's overrides, named by a refusal.
        checked: the settings passed :func:`uavrl.experiment.saved.check_evaluation` (with a video) already.

    Returns:
        The files written: the videos, and under an energy model ``battery.png``.
    """
    if not checked:
        check_evaluation(cfg, video=True, overrides=overrides)
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


def print_videos(cfg: DictConfig, overrides, checked: bool = False) -> None:
    """``python -m uavrl.render``: the paths written, one a line (``checked``: as :func:`render_checkpoint`'s)."""
    for path in render_checkpoint(cfg, overrides, checked):
        print(path)
