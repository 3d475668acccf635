"""A saved run read without torch: where an evaluation of it writes, its ``config.yaml``, the model an evaluation
of it acts in, and the check of that evaluation (:func:`check_evaluation`: ``uavrl.evaluate``'s and
``uavrl.render``'s settings check, before either imports torch); its checkpoints read as its own only
(:func:`load_run_checkpoint`: another run's checkpoint copied or linked into the directory is refused); and its agent
rebuilt (:func:`load_agent`, which imports torch when called)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import yaml
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from uavrl.agents import agent_class
from uavrl.agents.schema import network_refusal
from uavrl.config import model_config, saved_config
from uavrl.costs import check_evaluation_costs, check_evaluation_floor
from uavrl.experiment.checkpoints import (
    CheckpointError,
    NotThisRun,
    checkpoint_files,
    link_out,
    load_checkpoint,
    no_checkpoint,
    restore_agent,
    run_dir_of,
)
from uavrl.experiment.io import DamagedRun, quoted, read_small_text
from uavrl.experiment.runs import agent_label
from uavrl.settings import RUN_SETTINGS, check_read, check_run, check_typed


class SavedYamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader (plain data, no tags that build objects) without aliases: uavrl writes none, and a few
    nested aliases expand to billions of values."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise yaml.MarkedYAMLError(problem="an alias (*name), which uavrl never writes", problem_mark=mark)
        return super().compose_node(parent, index)


def check_evaluation(cfg: DictConfig, video: bool | None = None, overrides=None) -> None:
    """The settings of an evaluation (``video``: with a video, default ``eval.video``), refused in one line before
    anything heavy is imported: with the run's saved ``config.yaml`` beside the checkpoint, also the ``env.*`` of a
    zero-shot evaluation and what the evaluation of that model costs (``overrides``: the command line's, so a
    refusal names what was typed); last, the checkpoint read with torch alone (:func:`load_run_checkpoint`).

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
    # torch alone reads it: a file that is no checkpoint of this run is refused before the agents and TorchRL load
    load_run_checkpoint(cfg.checkpoint)


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

    state, file, notes = load_run_checkpoint(path, setting)
    source = quoted(file)
    try:
        cfg = saved_config(state["config"], source)
    except ValueError as err:
        raise CheckpointError(str(err)) from None
    agent = saved_agent(cfg, model_config(cfg), torch.device(device), file)
    restore_agent(agent, state, file, cfg.agent.name)
    fallback = f"{'; '.join(notes)}: using {source} (iteration {state['iteration']})" if notes else None
    return agent, cfg, fallback


RUN_CONFIG = "config.yaml"  # the run's resolved config, which its checkpoints must match
# what tells one run from another: a checkpoint whose saved config differs from its directory's config.yaml in any of
# these is another run's (what a run may change when resumed, its threads, progress bar and directory, is left out)
RUN_IDENTITY = ("agent", "seed", "env", "scenario")


def load_run_checkpoint(path, setting: str = "checkpoint") -> tuple[dict, Path, list[str]]:
    """:func:`uavrl.experiment.checkpoints.load_checkpoint` of a run directory's own checkpoints only: one (or the
    ``checkpoint.prev.pt`` fallen back to) whose saved agent, network, model or seed differs from the directory's
    ``config.yaml`` (without one: its ``metrics.json``'s agent and environment), a link out of the directory, or any
    checkpoint beside a ``config.yaml`` that cannot be read, is refused in one line (NotThisRun) naming the file,
    before anything is written.

    Args:
        path: a run directory, or a checkpoint file in one.
        setting: how ``path`` was given (``checkpoint``, ``resume``, ``run_dir``), named by a refusal.

    Returns:
        ``(state, its file, notes)``, as :func:`~uavrl.experiment.checkpoints.load_checkpoint`'s.
    """
    if not checkpoint_files(path):
        raise FileNotFoundError(no_checkpoint(path, setting))
    given, run_dir = f"{setting}={quoted(path)}", run_dir_of(path)
    config = read_run_config(run_dir, given)
    run = metrics_identity(run_dir) if config is None else identity(config, run_dir / RUN_CONFIG)
    return load_checkpoint(path, setting, lambda state, file, notes: check_belongs(state, file, run, given, notes))


class RunIdentity(dict):
    """The settings that tell a run from another (:data:`RUN_IDENTITY`), flat (``agent.name``); ``label``: the agent
    as runs are filed (``dqn-set``); ``source``: the file they were read from."""

    label: str
    source: Path | None = None


def identity(cfg, source: Path | None = None) -> RunIdentity:
    """:class:`RunIdentity` of a saved run's config ``cfg`` (as :func:`uavrl.config.saved_config` reads it), read
    from the file ``source``."""
    found = RunIdentity()
    found.label, found.source = agent_label(cfg), source

    def add(value, name: str) -> None:
        if isinstance(value, dict) and value:
            for key, item in value.items():
                add(item, f"{name}.{key}")
        else:
            found[name] = value

    for section, value in OmegaConf.to_container(cfg).items():
        if section in RUN_IDENTITY:
            add(value, section)
    return found


def read_run_config(run_dir, given: str) -> DictConfig | None:
    """The run directory's ``config.yaml`` as :func:`uavrl.config.saved_config` reads it, read without torch; None
    where there is none; a one-line NotThisRun when it is there but is no run's config that uavrl can read: a link out
    of the directory, no regular file, too large, not YAML, not a uavrl run's settings (no checkpoint there could then
    be told to be the run's).

    Args:
        run_dir: the run directory.
        given: how the user gave it (``checkpoint=<dir>``), which a refusal begins with.
    """
    path = Path(run_dir) / RUN_CONFIG
    if not os.path.lexists(path):
        return None
    why = link_out(path, Path(run_dir))
    if why is None:
        try:
            data = yaml.load(read_small_text(path), Loader=SavedYamlLoader)
            if not isinstance(data, dict):
                why = "it is empty" if data is None else f"it holds a {type(data).__name__}, not a mapping of settings"
        except DamagedRun as err:
            why = str(err).removeprefix(f"{RUN_CONFIG} ")
        except (yaml.YAMLError, RecursionError, ValueError) as err:
            why = f"it is not valid YAML ({' '.join(str(getattr(err, 'problem', None) or err).split())})"
    advice = "no checkpoint there can be told to be that run's: restore it, or move it away"
    if why is not None:
        raise NotThisRun(f"{given}: {quoted(path)} is not readable as the run's config ({why}); {advice}")
    try:
        return saved_config(data, quoted(path))
    except ValueError as err:
        raise NotThisRun(f"{given}: {err}; {advice}") from None


def metrics_identity(run_dir: Path) -> RunIdentity | None:
    """The run a directory without ``config.yaml`` holds as its ``metrics.json`` names it (its agent and environment:
    a resume would write over it); None where there is none that can be read."""
    path = run_dir / "metrics.json"
    try:
        metrics = json.loads(read_small_text(path)) if os.path.lexists(path) else None
    except (DamagedRun, ValueError, RecursionError):
        return None
    if not isinstance(metrics, dict) or not all(isinstance(metrics.get(key), str) for key in ("agent", "env")):
        return None
    found = RunIdentity({"agent.name": metrics["agent"], "env.name": metrics["env"]})
    found.label, found.source = metrics["agent"], path  # a size-free network's metrics name the dqn
    return found


FIRST_TOLD = ("agent.name", "agent.network", "seed")  # the differences a refusal names first


def check_belongs(state: dict, file: Path, run: RunIdentity | None, given: str, notes) -> None:
    """A one-line NotThisRun naming ``file`` unless the run that saved ``state`` is the one its directory records
    (``run``: the :func:`identity` of its ``config.yaml``, else :func:`metrics_identity`; None: nothing to match); a
    CheckpointError when the checkpoint's own config is no uavrl run's.  A setting one version has and another
    lacks tells nothing apart."""
    try:
        saved = identity(saved_config(state["config"], quoted(file)))
    except ValueError as err:
        raise CheckpointError(str(err)) from None
    if run is None:
        return
    differing = [key for key in saved if key in run and saved[key] != run[key]]
    if not differing:
        return
    key = next((k for k in FIRST_TOLD if k in differing), differing[0])
    typed = "agent" if key == "agent.name" else key  # as a command line chooses it: agent=dqn
    theirs, ours, source = f"{typed}={_shown(saved[key])}", f"{typed}={_shown(run[key])}", quoted(run.source)
    found = (
        f"is a {saved.label} run's checkpoint ({theirs}), but {source} is a {run.label} run's ({ours})"
        if key in ("agent.name", "agent.network")
        else f"is another run's checkpoint ({theirs}), but {source} has {ours}"
    )
    after = f" (after {'; '.join(notes)})" if notes else ""
    raise NotThisRun(
        f"{given}: {file.name}{after} {found}: it belongs to another run; refused, nothing written (give the directory "
        f"of the run it belongs to, or put back this run's own {file.name})"
    )


def _shown(value) -> str:
    """A setting's value as typed on a command line: ``tabular``, ``[3, 3]``, ``null``."""
    return value if isinstance(value, str) else json.dumps(value)
