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
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from uavrl.experiment.checkpoints import (
    CheckpointError,
    checkpoint_files,
    load_checkpoint,
    no_checkpoint,
    restore_agent,
    saved_agent,
)
from uavrl.cli import run_command
from uavrl.config import RUN_OPTION_SETTINGS, model_config, saved_config
from uavrl.experiment.io import Manifest, quoted, save_json
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
from uavrl.settings import (
    RUN_SETTINGS,
    check_evaluation_costs,
    check_evaluation_floor,
    check_read,
    check_run,
    check_typed,
)


def check_settings(cfg: DictConfig, video: bool | None = None, overrides=None) -> None:
    """The settings of an evaluation (``video``: with a video, default ``eval.video``), refused in one line before
    anything heavy is imported: with the run's saved ``config.yaml`` beside the checkpoint, also the ``env.*`` of a
    zero-shot evaluation and what the evaluation of that model costs (``overrides``: the command line's, so a
    refusal names what was typed)."""
    check_run(cfg)
    check_read(overrides, "evaluate")
    check_typed(cfg, overrides, RUN_SETTINGS)
    video = bool(cfg.eval.video) if video is None else video
    check_evaluation_floor(cfg, video, overrides)
    if not cfg.checkpoint:
        raise ValueError("checkpoint is not set: give checkpoint=<run dir or checkpoint.pt>")
    if not checkpoint_files(cfg.checkpoint):
        raise FileNotFoundError(no_checkpoint(cfg.checkpoint, "checkpoint"))
    saved = saved_run_config(cfg.checkpoint)
    if saved is not None:
        evaluated = evaluated_config(saved, cfg, overrides or (), f"checkpoint={quoted(cfg.checkpoint)}")
        check_evaluation_costs(cfg, saved, model_config(evaluated), video, overrides)


def saved_run_config(checkpoint) -> DictConfig | None:
    """The run's config as ``uavrl.train`` saved it beside the checkpoint (``config.yaml``), read without torch;
    ``None`` where there is none or it cannot be read (the checkpoint's own copy is checked once it is loaded)."""
    import yaml

    from uavrl.report import DamagedRun, SavedYamlLoader, read_small_text

    path = output_dir(checkpoint) / "config.yaml"
    if not path.is_file():
        return None
    try:
        data = yaml.load(read_small_text(path), Loader=SavedYamlLoader)
        return saved_config(data, quoted(path)) if isinstance(data, dict) else None
    except (DamagedRun, yaml.YAMLError, RecursionError, ValueError):
        return None


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
    from uavrl.agents.schema import network_refusal

    changed = [key for key in (o.split("=", 1)[0].lstrip("+~") for o in overrides) if key.startswith("env.")]
    if not changed:
        return saved
    if "env.max_steps" in changed:  # the evaluation plays eval.horizon steps from each start, whatever it is
        typed = next(o for o in overrides if o.split("=", 1)[0].lstrip("+~") == "env.max_steps").lstrip("+~")
        raise ValueError(
            f"{typed} is invalid for an evaluation, which plays eval.horizon steps from each start (env.max_steps "
            "is the training's episode length): give eval.horizon=<steps>"
        )
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
    import os

    from uavrl.experiment.io import read_regular_text

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
    """The metrics of ``cfg.checkpoint``'s greedy policy (the module doc), written beside it."""
    return evaluate_and_save(cfg, overrides)[0]


def evaluate_and_save(cfg: DictConfig, overrides=()) -> tuple[dict[str, float], DictConfig, DictConfig, Path]:
    """``(metrics, the saved run's config, the config evaluated, the JSON file written)``."""
    check_settings(cfg, overrides=list(overrides) or None)
    import torch  # the heavy modules, once the settings are known to be good

    from uavrl.agents.evaluation import evaluate_agent
    from uavrl.agents.lookahead import lookahead_settings
    from uavrl.envs.world import resolve_device

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
    """The greedy policy of the run ``saved`` beside the oracle (:mod:`uavrl.experiment.video`), as ``cfg.eval`` asks: files in
    ``out_dir`` and TensorBoard's ``eval/video`` at the agent's step, in the run's events."""
    from uavrl.experiment.logger import RunLogger
    from uavrl.experiment.video import VIDEO_RECORD, comparison_frames, save_videos, video_settings

    env_cfg, label = model_config(saved), saved.agent.name
    policy = agent.policy_for(env_cfg)
    frames = comparison_frames(policy, env_cfg, label=label, **video_settings(cfg, device))
    for path in save_videos(frames, out_dir, int(cfg.eval.video_fps), Manifest(out_dir, "checkpoint", VIDEO_RECORD)):
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
            optimality_line(cfg, metrics, saved.agent.name),
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
        print(f"metrics: {quoted(path)}", file=sys.stderr)
    else:
        print(summary(cfg, saved, evaluated, metrics, path))


if __name__ == "__main__":
    run_command("config", print_evaluation, RUN_OPTION_SETTINGS)
