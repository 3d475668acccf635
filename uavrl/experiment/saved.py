"""A saved run read without torch: where an evaluation of it writes, its ``config.yaml``, the model an evaluation
of it acts in, and the check of that evaluation (:func:`check_evaluation`: ``uavrl.evaluate``'s and
``uavrl.render``'s settings check, before either imports torch); and its agent rebuilt (:func:`load_agent`, which
imports torch when called)."""

from __future__ import annotations

from pathlib import Path

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from uavrl.agents import agent_class
from uavrl.agents.schema import network_refusal
from uavrl.config import model_config, saved_config
from uavrl.costs import check_evaluation_costs, check_evaluation_floor
from uavrl.experiment.checkpoints import (
    CheckpointError,
    checkpoint_files,
    load_checkpoint,
    no_checkpoint,
    read_run_config,
    restore_agent,
    run_dir_of,
)
from uavrl.experiment.checkpoints import SavedYamlLoader as SavedYamlLoader  # where benchmarl imports it from
from uavrl.experiment.io import quoted
from uavrl.settings import RUN_SETTINGS, check_read, check_run, check_typed


def check_evaluation(cfg: DictConfig, video: bool | None = None, overrides=None) -> None:
    """The settings of an evaluation (``video``: with a video, default ``eval.video``), refused in one line before
    anything heavy is imported: with the run's saved ``config.yaml`` beside the checkpoint, also the ``env.*`` of a
    zero-shot evaluation and what the evaluation of that model costs (``overrides``: the command line's, so a
    refusal names what was typed).

    Args:
        cfg: the composed config (``checkpoint=`` and the ``eval.*`` settings).
        video: whether a video is made; None: ``eval.video``.
        overrides: the command line's overrides.
    """
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
        try:
            check_evaluation_costs(cfg, saved, model_config(evaluated), video, overrides)
        except (OmegaConfBaseException, AttributeError, KeyError, TypeError) as err:  # as saved_agent's: a config.yaml
            reason = " ".join(f"{type(err).__name__}: {err}".split())  # whose agent section is another agent's
            config = quoted(output_dir(cfg.checkpoint) / "config.yaml")
            raise CheckpointError(
                f"checkpoint={quoted(cfg.checkpoint)}: {config}: its saved config does not fit a {saved.agent.name} "
                f"agent ({reason})"
            ) from None


def saved_run_config(checkpoint) -> DictConfig | None:
    """The run's config as ``uavrl.train`` saved it beside the checkpoint (``config.yaml``), read without torch;
    ``None`` where there is none; a one-line refusal where it is there but unreadable
    (:func:`uavrl.experiment.checkpoints.read_run_config`: no checkpoint there could be told to be the run's)."""
    return read_run_config(output_dir(checkpoint), f"checkpoint={quoted(checkpoint)}")


def output_dir(checkpoint) -> Path:
    """Where an evaluation of ``checkpoint`` (a run directory or a file in one) writes: the run directory."""
    return run_dir_of(checkpoint)


def evaluated_config(saved: DictConfig, cfg: DictConfig, overrides, source: str) -> DictConfig:
    """The saved run's config with the command line's ``env.*`` overrides (``overrides``, as typed; ``cfg`` their
    values); a one-line ValueError beginning with ``source`` when the saved policy cannot act in that model."""
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


def saved_agent(cfg, env_cfg, device, file: Path):
    """The agent of a saved run's config ``cfg`` (model ``env_cfg``), built as ``uavrl.train`` builds it; a
    CheckpointError naming ``file`` when this uavrl cannot build that agent from that config."""
    source = quoted(file)
    try:
        return agent_class(cfg.agent.name, cfg.agent)(env_cfg, cfg, device, int(cfg.seed))
    except (OmegaConfBaseException, KeyError, TypeError) as err:
        reason = " ".join(f"{type(err).__name__}: {err}".split())
        raise CheckpointError(f"{source}: its saved config does not fit a {cfg.agent.name} agent ({reason})") from None
    except ValueError as err:
        raise CheckpointError(f"{source}: in its saved config, {err}") from None


def load_agent(path, device="cpu", setting: str = "checkpoint"):
    """``(agent, saved config, fallback)`` from a ``checkpoint.pt`` or the run directory holding one (``setting=path``).

    ``fallback`` is None when the newest checkpoint was read, else one line
    saying which newer files were missing or unreadable and which file and
    iteration were used instead.  A checkpoint this uavrl cannot rebuild an
    agent from is a one-line CheckpointError naming its file.

    Args:
        path: a ``checkpoint.pt`` or the run directory holding one.
        device: the torch device of the agent.
        setting: the setting ``path`` was given as, named by a refusal (``checkpoint``, ``run_dir``, ...).
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
