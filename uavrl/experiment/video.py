"""Videos of a greedy policy: a few of the yardstick's starts, each played by the policy beside the oracle.

The starts are the evaluation's first ``eval.video_starts``: world ``i`` of the
evaluation seeded ``eval.seed`` is seeded ``eval.seed + i`` (docs/model.md,
Worlds), so a batch of ``k`` starts holds the first ``k`` of the yardstick's
``eval.num_starts``.  Each is played for the yardstick's horizon; a frame has
one row per start, the policy on the left and the oracle (an optimal plan) on
the right, drawn by :mod:`uavrl.envs.render`.  :func:`~uavrl.experiment.logger.encode` writes GIF bytes
with imageio (TensorBoard shows them as an animated image, what
``SummaryWriter.add_video`` makes with moviepy) and MP4 bytes where PyAV is
installed (the ``[video]`` extra).

Example:
    >>> from uavrl.agents.baselines import RandomPolicy
    >>> from uavrl.envs import make_config
    >>> frames = comparison_frames(RandomPolicy(seed=0), make_config("paper", grid=(3, 3)), starts=2, horizon=4)
    >>> frames.shape  # the start and 4 steps; 2 starts of 360 x 480 panels, 4 pixels apart
    (5, 724, 964, 3)
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import torch

from uavrl.agents.baselines import OraclePolicy
from uavrl.agents.evaluation import EVAL_SEED, default_horizon
from uavrl.envs import ModelConfig
from uavrl.envs.env import UAVSpectrumEnv
from uavrl.envs.render import WorldRenderer, tile
from uavrl.envs.rules import refuse, rule_of
from uavrl.experiment.io import save_bytes
from uavrl.experiment.logger import encode
from uavrl.schema import RunEvalSchema

DEFAULT_STARTS = RunEvalSchema.video_starts


def video_settings(cfg, device) -> dict:
    """Keyword arguments of :func:`comparison_frames` from a run's ``cfg.eval``."""
    return dict(starts=cfg.eval.video_starts, horizon=cfg.eval.horizon, seed=int(cfg.eval.seed), device=device)


def rollout_frames(policy, cfg: ModelConfig, starts: int, horizon: int, seed: int, device, label: str) -> list:
    """``[H + 1]`` lists of ``starts`` frames: the evaluation's first ``starts`` starts played by ``policy``.

    Args:
        policy: a TorchRL policy of the model.
        cfg: the model.
        starts: how many of the evaluation's starts to play.
        horizon: steps ``H`` per rollout.
        seed: the evaluation's seed.
        device: the torch device of the worlds.
        label: the policy's name in each frame's heading.
    """
    env = UAVSpectrumEnv(batch_size=starts, config=cfg.replace(max_steps=horizon), seed=seed, device=device)
    renderer = WorldRenderer(env.world, label=label)
    start = env.reset()
    if hasattr(policy, "bind_env"):  # a one-line error for a policy of another grid, number of UAVs or layout
        policy.bind_env(env)
    frames = [[renderer.frame(i) for i in range(starts)]]

    def record(_env, _td):
        frames.append([renderer.frame(i) for i in range(starts)])

    # TorchRL calls back after every step but the last
    env.rollout(horizon, policy, auto_reset=False, tensordict=start, break_when_any_done=False, callback=record)
    record(env, None)
    return frames


@torch.no_grad()
def comparison_frames(
    policy,
    cfg: ModelConfig,
    *,
    starts: int = DEFAULT_STARTS,
    horizon: int | None = None,
    seed: int = EVAL_SEED,
    device="cpu",
    label: str = "policy",
) -> np.ndarray:
    """``[H + 1, height, width, 3]`` uint8 frames: row ``i`` shows start ``i`` played by ``policy`` (left, headed
    ``label``) and by the oracle (right), for ``horizon`` steps (default: the yardstick's).

    Args:
        policy: a TorchRL policy of the model (``uavrl.load_policy`` returns one for a saved run).
        cfg: the model.
        starts: how many of the evaluation's starts, one row each.
        horizon: steps per rollout; None: the yardstick's.
        seed: the evaluation's seed (``eval.seed``).
        device: the torch device of the worlds.
        label: the policy's heading.

    Example:
        >>> from uavrl.agents.baselines import RandomPolicy
        >>> from uavrl.envs import make_config
        >>> frames = comparison_frames(RandomPolicy(), make_config("paper", grid=(3, 3)), starts=1, horizon=2)
        >>> len(frames), frames.dtype
        (3, dtype('uint8'))
    """
    refuse("starts", starts, rule_of(RunEvalSchema, "video_starts"))
    horizon = horizon or default_horizon(cfg.grid)
    played = rollout_frames(policy, cfg, starts, horizon, seed, device, label)
    oracle = rollout_frames(OraclePolicy(cfg), cfg, starts, horizon, seed, device, "oracle")
    return np.stack(
        [
            tile([f for pair in zip(mine, best, strict=True) for f in pair], 2)
            for mine, best in zip(played, oracle, strict=True)
        ]
    )


def can_write_mp4() -> bool:
    """Whether PyAV, imageio's MP4 writer, is installed (``pip install -e ".[video]"``)."""
    return importlib.util.find_spec("av") is not None


VIDEO_RECORD = ".uavrl-video-files.json"  # the videos and figures render and evaluate wrote in a run directory


def save_videos(frames: np.ndarray, out_dir, fps: int, manifest=None) -> list[Path]:
    """``video.gif`` in ``out_dir``, and ``video.mp4`` beside it where PyAV is installed; the paths written.

    Args:
        frames: ``[T, H, W, 3]`` uint8 frames (:func:`comparison_frames`).
        out_dir: the folder to write to.
        fps: frames (steps) per second.
        manifest: a :class:`~uavrl.experiment.io.Manifest` of ``out_dir``: a file of those names that uavrl did not
            write stays, and the video goes beside it (``video-2.gif``); None: the names as they are.
    """
    kinds = (".gif", ".mp4") if can_write_mp4() else (".gif",)
    paths = [Path(out_dir) / f"video{kind}" for kind in kinds]
    paths = paths if manifest is None else [manifest.free(path) for path in paths]
    for path, kind in zip(paths, kinds, strict=True):
        save_bytes(encode(frames, fps, kind), path)
    return paths
