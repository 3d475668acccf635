"""Evaluate a saved agent: ``python -m uavrl.evaluate checkpoint=runs/tabular/paper/<stamp>``.

Rebuilds the agent from the checkpoint's own config (a run directory's newest
readable checkpoint, or the file given), runs the shared greedy evaluation
(``eval.*`` settings may be overridden, e.g. ``eval.num_starts=100``), prints
the metrics as JSON and writes them to ``eval.json`` beside the checkpoint.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from omegaconf import DictConfig

from uavrl.checkpoints import CheckpointError, load_checkpoint
from uavrl.cli import run_command
from uavrl.config import RUN_OPTION_SETTINGS, model_config, saved_config
from uavrl.io import save_json
from uavrl.settings import RUN_SETTINGS, check
from uavrl.train import eval_settings


def check_settings(cfg: DictConfig) -> None:
    """The settings of an evaluation, refused in one line before anything heavy is imported."""
    check(cfg, RUN_SETTINGS)
    if not cfg.checkpoint:
        raise ValueError("checkpoint is not set: give checkpoint=<run dir or checkpoint.pt>")
    if not Path(cfg.checkpoint).exists():
        raise FileNotFoundError(f"checkpoint={cfg.checkpoint!r} does not exist (give checkpoint.pt or a run directory)")


def load_agent(path, device="cpu"):
    """``(agent, saved config)`` from a ``checkpoint.pt`` or the run directory holding one."""
    import torch

    from uavrl.agents import agent_class

    state, file, skipped = load_checkpoint(path, "checkpoint")
    if skipped:
        print(f"warning: {'; '.join(skipped)}: evaluating {file} (iteration {state['iteration']})", file=sys.stderr)
    cfg = saved_config(state["config"])
    agent = agent_class(cfg.agent.name)(model_config(cfg), cfg, torch.device(device), int(cfg.seed))
    try:
        agent.load_state_dict(state["agent"])
    except (KeyError, RuntimeError, ValueError) as err:
        agent_kind, reason = f"a {cfg.agent.name} agent of this uavrl", f"{type(err).__name__}: {err}"
        raise CheckpointError(f"{file}: its agent state does not fit {agent_kind} ({reason})") from None
    return agent, cfg


def output_dir(checkpoint) -> Path:
    """Where an evaluation of ``checkpoint`` (a run directory or a file in one) writes: the run directory."""
    return Path(checkpoint) if Path(checkpoint).is_dir() else Path(checkpoint).parent


def evaluate_checkpoint(cfg: DictConfig) -> dict[str, float]:
    check_settings(cfg)
    import torch  # the heavy modules, once the settings are known to be good

    from uavrl.envs.world import resolve_device
    from uavrl.evaluation import evaluate_agent

    torch.set_num_threads(int(cfg.num_threads))
    device = resolve_device(cfg.device)
    agent, saved = load_agent(cfg.checkpoint, device)
    metrics = evaluate_agent(agent, model_config(saved), **eval_settings(cfg, device))
    out_dir = output_dir(cfg.checkpoint)
    save_json(metrics, out_dir / "eval.json")
    if cfg.eval.video:
        save_video(agent, saved, cfg, device, out_dir)
    return metrics


def save_video(agent, saved: DictConfig, cfg: DictConfig, device, out_dir: Path) -> None:
    """The greedy policy of the run ``saved`` beside the oracle (:mod:`uavrl.video`), as ``cfg.eval`` asks: files in
    ``out_dir`` and TensorBoard's ``eval/video`` at the agent's step, in the run's events."""
    from uavrl.logger import RunLogger
    from uavrl.video import comparison_frames, save_videos, video_settings

    policy, label = agent.policies()[0], saved.agent.name
    frames = comparison_frames(policy, model_config(saved), label=label, **video_settings(cfg, device))
    for path in save_videos(frames, out_dir, int(cfg.eval.video_fps)):
        print(f"wrote {path}", file=sys.stderr)
    logger = RunLogger(out_dir)
    logger.video("eval/video", frames, agent.env_steps, int(cfg.eval.video_fps))
    logger.close()


def print_evaluation(cfg: DictConfig, _overrides) -> None:
    """``python -m uavrl.evaluate``: the metrics as JSON on stdout."""
    print(json.dumps(evaluate_checkpoint(cfg), indent=2, sort_keys=True))


if __name__ == "__main__":
    run_command("config", print_evaluation, RUN_OPTION_SETTINGS)
