"""Evaluate a saved agent: ``python -m uavrl.evaluate checkpoint=runs/tabular/paper/<stamp>``.

Rebuilds the agent from the checkpoint's own config (a run directory's newest
readable checkpoint, or the file given), runs the shared greedy evaluation
(``eval.*`` settings may be overridden, e.g. ``eval.num_starts=100``), writes
the metrics as JSON to ``eval.json`` beside the checkpoint and prints a summary
in words: the agent, the model it was evaluated on, the headline metrics and
the yardstick, where the file went (``print_json=true`` prints the metrics as
JSON in its place).

A size-free network (``agent=dqn agent.network=set``) is evaluated zero-shot on another team size or grid with
``env.num_uavs=<N>``, ``env.grid=[L1,L2]`` and ``env.layout`` (``eval-<N>uav-<L1>x<L2>.json``); any other policy is
refused there in one line, as is any other ``env.*`` that differs from the saved run's.  The summary names the
teams the network trained on and the one it was evaluated on (``zero-shot: ...`` when it is not one of them).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from uavrl.checkpoints import (
    CheckpointError,
    checkpoint_files,
    load_checkpoint,
    no_checkpoint,
    restore_agent,
    saved_agent,
)
from uavrl.cli import run_command
from uavrl.config import RUN_OPTION_SETTINGS, model_config, saved_config
from uavrl.io import quoted, save_json
from uavrl.runs import (
    agent_words,
    eval_settings,
    is_size_free,
    model_words,
    optimality_line,
    size_free_teams,
    team_words,
    yardstick_line,
)
from uavrl.settings import check_evaluation_floor, check_run, check_video_cost


def check_settings(cfg: DictConfig, video: bool | None = None) -> None:
    """The settings of an evaluation (``video``: with a video, default ``eval.video``), refused in one line before
    anything heavy is imported."""
    check_run(cfg)
    check_evaluation_floor(cfg, bool(cfg.eval.video) if video is None else video)
    if not cfg.checkpoint:
        raise ValueError("checkpoint is not set: give checkpoint=<run dir or checkpoint.pt>")
    if not checkpoint_files(cfg.checkpoint):
        raise FileNotFoundError(no_checkpoint(cfg.checkpoint, "checkpoint"))


def load_agent(path, device="cpu", setting: str = "checkpoint"):
    """``(agent, saved config, fallback)`` from a ``checkpoint.pt`` or the run directory holding one (``setting=path``).

    ``fallback`` is None when the newest checkpoint was read, else one line
    saying which newer files were missing or unreadable and which file and
    iteration were used instead.  A checkpoint this uavrl cannot rebuild an
    agent from is a one-line CheckpointError naming its file.
    """
    import torch

    state, file, notes = load_checkpoint(path, setting)
    source = quoted(file)
    try:
        cfg = saved_config(state["config"], source)
    except ValueError as err:
        raise CheckpointError(str(err)) from None
    agent = saved_agent(cfg, model_config(cfg), torch.device(device), file)
    restore_agent(agent, state, file, cfg.agent.name)
    fallback = f"{'; '.join(notes)}: using {source} (iteration {state['iteration']})" if notes else None
    return agent, cfg, fallback


def output_dir(checkpoint) -> Path:
    """Where an evaluation of ``checkpoint`` (a run directory or a file in one) writes: the run directory."""
    return Path(checkpoint) if Path(checkpoint).is_dir() else Path(checkpoint).parent


def evaluated_config(saved: DictConfig, cfg: DictConfig, overrides, source: str) -> DictConfig:
    """The saved run's config with the command line's ``env.*`` overrides (``overrides``, as typed; ``cfg`` their
    values); a one-line ValueError beginning with ``source`` when the saved policy cannot act in that model."""
    from uavrl.agents.dqn.multisize import network_refusal

    changed = [key for key in (o.split("=", 1)[0].lstrip("+~") for o in overrides) if key.startswith("env.")]
    if not changed:
        return saved
    evaluated = saved.copy()
    for key in changed:
        OmegaConf.update(evaluated, key, OmegaConf.select(cfg, key), force_add=True)
    refusal = network_refusal(saved, model_config(evaluated), model_config(saved))
    if refusal:
        raise ValueError(f"{source}: {', '.join(changed)} given: {refusal}")
    return evaluated


def evaluation_file(saved: DictConfig, evaluated: DictConfig) -> str:
    """``eval.json`` for the run's own model, ``eval-<N>uav-<L1>x<L2>[-<layout>].json`` for another."""
    run, other = model_config(saved), model_config(evaluated)
    if (other.num_uavs, other.grid, other.layout) == (run.num_uavs, run.grid, run.layout):
        return "eval.json"
    layout = "" if other.layout == run.layout else f"-{other.layout}"
    return f"eval-{other.num_uavs}uav-{other.grid[0]}x{other.grid[1]}{layout}.json"


def evaluate_checkpoint(cfg: DictConfig, overrides=()) -> dict[str, float]:
    """The metrics of ``cfg.checkpoint``'s greedy policy (the module doc), written beside it."""
    return evaluate_and_save(cfg, overrides)[0]


def evaluate_and_save(cfg: DictConfig, overrides=()) -> tuple[dict[str, float], DictConfig, DictConfig, Path]:
    """``(metrics, the saved run's config, the config evaluated, the JSON file written)``."""
    check_settings(cfg)
    import torch  # the heavy modules, once the settings are known to be good

    from uavrl.agents.lookahead import lookahead_settings
    from uavrl.envs.world import resolve_device
    from uavrl.evaluation import evaluate_agent

    torch.set_num_threads(int(cfg.num_threads))
    device = resolve_device(cfg.device)
    agent, saved, fallback = load_agent(cfg.checkpoint, device)
    if fallback:
        print(f"warning: {fallback}", file=sys.stderr)
    evaluated = evaluated_config(saved, cfg, overrides, f"checkpoint={quoted(cfg.checkpoint)}")
    if cfg.eval.video:  # refused before the evaluation's work, not after it
        check_video_cost(cfg, model_config(evaluated))
    metrics = evaluate_agent(agent, model_config(evaluated), **eval_settings(cfg, device), **lookahead_settings(cfg))
    out_dir = output_dir(cfg.checkpoint)
    path = out_dir / evaluation_file(saved, evaluated)
    save_json(metrics, path)
    if cfg.eval.video:
        save_video(agent, evaluated, cfg, device, out_dir)
    return metrics, saved, evaluated, path


def save_video(agent, saved: DictConfig, cfg: DictConfig, device, out_dir: Path) -> None:
    """The greedy policy of the run ``saved`` beside the oracle (:mod:`uavrl.video`), as ``cfg.eval`` asks: files in
    ``out_dir`` and TensorBoard's ``eval/video`` at the agent's step, in the run's events."""
    from uavrl.logger import RunLogger
    from uavrl.video import comparison_frames, save_videos, video_settings

    env_cfg, label = model_config(saved), saved.agent.name
    policy = agent.policy_for(env_cfg)
    frames = comparison_frames(policy, env_cfg, label=label, **video_settings(cfg, device))
    for path in save_videos(frames, out_dir, int(cfg.eval.video_fps)):
        print(f"wrote {path}", file=sys.stderr)
    logger = RunLogger(out_dir)
    logger.video("eval/video", frames, agent.env_steps, int(cfg.eval.video_fps))
    logger.close()


def trained_teams(saved: DictConfig) -> set[tuple[int, tuple[int, int], str]]:
    """``{(N, (L1, L2), layout)}`` a size-free run trained on (``agent.sizes`` x ``agent.layouts``, or its own)."""
    from uavrl.agents.schema import training_models

    return {(m.num_uavs, tuple(m.grid), m.layout) for m in training_models(model_config(saved), saved.agent)}


def summary(cfg: DictConfig, saved: DictConfig, evaluated: DictConfig, metrics: dict, path: Path) -> str:
    """An evaluation in words: what was evaluated on which model (a size-free network: the teams it trained on, and
    ``zero-shot`` where the team evaluated is not one of them), the headline metrics, where they went."""
    run, model = model_config(saved), model_config(evaluated)
    lines = [
        f"evaluated {agent_words(saved)} of the {saved.env.name} run {quoted(cfg.checkpoint)} on: {model_words(model)}"
    ]
    if is_size_free(saved):
        unseen = (model.num_uavs, tuple(model.grid), model.layout) not in trained_teams(saved)
        evaluated_team = team_words(model.num_uavs, model.grid) + f" in layout {model.layout!r}"
        lines.append(
            f"{'zero-shot' if unseen else 'size-free'}: trained on {size_free_teams(saved, run)}, evaluated on "
            f"{evaluated_team}"
        )
    return "\n".join(
        [
            *lines,
            optimality_line(cfg, metrics),
            yardstick_line(cfg, metrics),
            f"metrics: {quoted(path)} (all {len(metrics)}, as JSON; print_json=true prints them in place of this "
            "summary)",
        ]
    )


def print_evaluation(cfg: DictConfig, overrides) -> None:
    """``python -m uavrl.evaluate``: the summary in words, or with ``print_json=true`` the metrics as JSON."""
    metrics, saved, evaluated, path = evaluate_and_save(cfg, overrides)
    if cfg.print_json:
        print(json.dumps(metrics, indent=2, sort_keys=True))
    else:
        print(summary(cfg, saved, evaluated, metrics, path))


if __name__ == "__main__":
    run_command("config", print_evaluation, RUN_OPTION_SETTINGS)
