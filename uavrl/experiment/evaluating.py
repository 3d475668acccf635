"""The evaluation command's body (``python -m uavrl.evaluate``, :mod:`uavrl.evaluate`): a saved agent's greedy
evaluation, written beside its checkpoint.

:func:`evaluate_checkpoint` rebuilds the agent from the checkpoint's own config, runs the shared greedy evaluation
(``eval.*`` settings may be overridden), writes the metrics as JSON to ``eval.json`` beside the checkpoint (an
earlier evaluation there with other settings or of another checkpoint stays: this one then goes to ``eval-2.json``,
...; the settings of each are recorded in ``.uavrl-evaluations.json``); :func:`print_evaluation` prints the summary
in words.  A size-free network is evaluated zero-shot on another team size or grid (``eval-<N>uav-<L1>x<L2>.json``),
or city (``...-city<seed>.json``).
The settings are checked first, without torch, then the checkpoint read with torch alone
(:func:`uavrl.experiment.saved.check_evaluation`).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path

import torch
from omegaconf import DictConfig, OmegaConf

from uavrl.agents.evaluation import evaluate_agent
from uavrl.agents.lookahead_rules import lookahead_settings
from uavrl.agents.schema import CITY_MODEL_OPTIONS, training_models
from uavrl.config import model_config
from uavrl.costs import check_evaluation_costs
from uavrl.envs.world import resolve_device
from uavrl.experiment.io import Manifest, quoted, read_regular_text, save_json
from uavrl.experiment.logger import RunLogger
from uavrl.experiment.runs import (
    agent_words,
    eval_settings,
    is_size_free,
    model_words,
    optimality_line,
    size_free_teams,
    team_words,
    yardstick_line,
)
from uavrl.experiment.saved import check_evaluation, evaluated_config, load_agent, output_dir


def evaluation_file(saved: DictConfig, evaluated: DictConfig) -> str:
    """``eval.json`` for the run's own model, ``eval-<N>uav-<L1>x<L2>[-<layout>][-<city><seed>[-<digest>]].json`` for
    another (a size-free network acts in other cities too; ``digest``: of the city's other options and the levels
    where they differ, so no two models share a file)."""
    run, other = model_config(saved), model_config(evaluated)
    named = ("city", "city_seed", "environment")  # in the name (al_hourani's environment is the city's)
    options = [getattr(other, name) for name in CITY_MODEL_OPTIONS if name not in named]
    same_options = options == [getattr(run, name) for name in CITY_MODEL_OPTIONS if name not in named]
    digest = "" if same_options else "-" + hashlib.sha256(repr(options).encode()).hexdigest()[:8]
    same_city = [getattr(other, name) for name in named] == [getattr(run, name) for name in named] and same_options
    if (other.num_uavs, other.grid, other.layout) == (run.num_uavs, run.grid, run.layout) and same_city:
        return "eval.json"
    layout = "" if other.layout == run.layout else f"-{other.layout}"
    city = "" if same_city else f"-{other.city}{other.city_seed}{digest}"
    return f"eval-{other.num_uavs}uav-{other.grid[0]}x{other.grid[1]}{layout}{city}.json"


EVALUATIONS = ".uavrl-evaluations.json"  # in the run directory: each evaluation file's settings
EVALUATION_KEYS = ("num_starts", "horizon", "gamma", "seed")  # the eval.* settings that change the metrics


def checkpoint_name(checkpoint) -> str:
    path = Path(checkpoint)
    return "checkpoint.pt" if path.is_dir() else path.name


def free_evaluation_file(out_dir: Path, name: str, made_with: dict) -> Path:
    """Where an evaluation made with ``made_with`` (its settings, the checkpoint and its steps) goes in ``out_dir``:
    ``name`` when that is free or holds an evaluation with the same settings, else ``<stem>-2.json``, ``-3``, ...:
    an earlier evaluation with other settings, or a file uavrl did not record, is never replaced.  The settings of
    each file are recorded in ``.uavrl-evaluations.json`` there."""
    record_path = out_dir / EVALUATIONS
    try:
        records = json.loads(read_regular_text(record_path)) if os.path.lexists(record_path) else {}
    except (OSError, ValueError):  # an unreadable record: no file there counts as this evaluation's own
        records = {}
    records = records if isinstance(records, dict) else {}
    stem, n = name.removesuffix(".json"), 1
    while True:
        path = out_dir / (name if n == 1 else f"{stem}-{n}.json")
        if not os.path.lexists(path) or records.get(path.name) == made_with:
            break
        n += 1
    save_json({**records, path.name: made_with}, record_path)
    return path


def evaluate_checkpoint(cfg: DictConfig, overrides=()) -> dict[str, float]:
    """The metrics of ``cfg.checkpoint``'s greedy policy (the module doc), written beside it; the settings are
    checked first (:func:`uavrl.experiment.saved.check_evaluation`).

    Args:
        cfg: the composed config (``checkpoint=`` and the ``eval.*`` settings).
        overrides: the command line's overrides, so a refusal names what was typed.

    Returns:
        The metrics, as written to the evaluation's JSON file.
    """
    return evaluate_and_save(cfg, overrides)[0]


def evaluate_and_save(
    cfg: DictConfig, overrides=(), checked: bool = False
) -> tuple[dict[str, float], DictConfig, DictConfig, Path]:
    """``(metrics, the saved run's config, the config evaluated, the JSON file written)``; ``checked``: the
    settings passed :func:`uavrl.experiment.saved.check_evaluation` already."""
    if not checked:
        check_evaluation(cfg, overrides=list(overrides) or None)
    torch.set_num_threads(int(cfg.num_threads))
    device = resolve_device(cfg.device)
    agent, saved, fallback = load_agent(cfg.checkpoint, device)
    if fallback:
        print(f"warning: {fallback}", file=sys.stderr)
    evaluated = evaluated_config(saved, cfg, overrides, f"checkpoint={quoted(cfg.checkpoint)}")
    # refused before the evaluation's work, not after it (a checkpoint without its run's config.yaml is known now)
    check_evaluation_costs(cfg, saved, model_config(evaluated), bool(cfg.eval.video), list(overrides) or None)
    metrics = evaluate_agent(
        agent, model_config(evaluated), **eval_settings(cfg, device), **lookahead_settings(cfg, saved.get("agent"))
    )
    out_dir = output_dir(cfg.checkpoint)
    made_with = {
        **{key: OmegaConf.select(cfg, f"eval.{key}") for key in EVALUATION_KEYS},
        "checkpoint": checkpoint_name(cfg.checkpoint),
        "env_steps": int(getattr(agent, "env_steps", 0)),
    }
    path = free_evaluation_file(out_dir, evaluation_file(saved, evaluated), made_with)
    save_json(metrics, path)
    if cfg.eval.video:
        save_video(agent, evaluated, cfg, device, out_dir)
    return metrics, saved, evaluated, path


def save_video(agent, saved: DictConfig, cfg: DictConfig, device, out_dir: Path) -> None:
    """The greedy policy of the run ``saved`` beside the oracle (:mod:`uavrl.experiment.video`), as ``cfg.eval``
    asks: files in ``out_dir`` and TensorBoard's ``eval/video`` at the agent's step, in the run's events."""
    from uavrl.experiment import video  # TorchRL and tensordict only when a video is asked for

    env_cfg, label = model_config(saved), saved.agent.name
    policy = agent.policy_for(env_cfg)
    frames = video.comparison_frames(policy, env_cfg, label=label, **video.video_settings(cfg, device))
    manifest = Manifest(out_dir, "checkpoint", video.VIDEO_RECORD)
    for path in video.save_videos(frames, out_dir, int(cfg.eval.video_fps), manifest):
        print(f"wrote {path}", file=sys.stderr)
    logger = RunLogger(out_dir)
    logger.video("eval/video", frames, agent.env_steps, int(cfg.eval.video_fps))
    logger.close()


def trained_teams(saved: DictConfig) -> set[tuple[int, tuple[int, int], str]]:
    """``{(N, (L1, L2), layout)}`` a size-free run trained on (``agent.sizes`` x ``agent.layouts``, or its own)."""
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
            optimality_line(cfg, metrics, saved.agent.name),
            yardstick_line(cfg, metrics),
            f"metrics: {quoted(path)} (all {len(metrics)}, as JSON; print_json=true prints them in place of this "
            "summary)",
        ]
    )


def print_evaluation(cfg: DictConfig, overrides, checked: bool = False) -> None:
    """``python -m uavrl.evaluate``: the summary in words, or with ``print_json=true`` the metrics as JSON
    (``checked``: the settings passed :func:`uavrl.experiment.saved.check_evaluation` already)."""
    metrics, saved, evaluated, path = evaluate_and_save(cfg, overrides, checked)
    if cfg.print_json:
        print(json.dumps(metrics, indent=2, sort_keys=True))
        print(f"metrics: {quoted(path)}", file=sys.stderr)
    else:
        print(summary(cfg, saved, evaluated, metrics, path))
