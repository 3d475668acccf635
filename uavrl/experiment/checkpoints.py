"""A run's checkpoints: the newest and the one before it, each written atomically, read newest first.

``checkpoint.pt`` is the newest.  When a new one replaces it, it becomes
``checkpoint.prev.pt``, so a newest file damaged after its write (a full disk,
a copy cut short, a stray edit) still leaves a readable one.  Reading tries the
newest first and says which files it skipped and why.

Reading runs nothing a file holds: every file is read with ``torch.load(...,
weights_only=True)``, which rebuilds tensors, numbers, strings and containers
and refuses anything else (a pickled function call among them), so a run
directory from anyone can be evaluated or resumed.  A file that holds other
objects is refused in one line, and is not skipped over for an older one: it
was not written by uavrl.

A checkpoint is read only as its run directory's own (:func:`load_checkpoint`): a file inside that directory (not a
link out of it), whose saved run (agent, network, model, seed) is the one the directory's ``config.yaml`` records.
Another run's checkpoint copied or linked there is refused in one line, never resumed into the directory or fallen
back to.  Only the standard library and PyYAML are imported here; torch is imported when a checkpoint is read or
written.
"""

from __future__ import annotations

import json
import os
import re
import warnings
from pathlib import Path

import yaml

from uavrl.experiment.io import DamagedRun, quoted, read_small_text, save_torch, special_kind

CHECKPOINT = "checkpoint.pt"
PREVIOUS_CHECKPOINT = "checkpoint.prev.pt"
RUN_CONFIG = "config.yaml"  # the run's resolved config, which its checkpoints must match
# what tells one run from another: a checkpoint whose saved config differs from its directory's config.yaml in any of
# these is another run's (what a run may change when resumed, its threads, progress bar and directory, is left out)
RUN_IDENTITY = ("agent", "seed", "env", "scenario")
_ENTRIES = ("agent", "iteration", "config")  # what every uavrl checkpoint holds
# A DQN checkpoint of an earlier version holds its replay buffer as a TensorDict, pickled as a call of the first
# name on the second and the stored entries; read, they stand for _stored_tensordict and _tensordict_class, which
# rebuild a plain TensorDict of those entries and run nothing else.
_TENSORDICT_NAMES = ("tensordict._reductions._make_td", "tensordict._td.TensorDict")


class CheckpointError(ValueError):
    """No readable uavrl checkpoint; the message says which files were tried and why each failed."""


class ForeignObjects(CheckpointError):
    """A file holds objects uavrl never writes: refused before any of them is rebuilt, so none of its code ran."""


class NotThisRun(CheckpointError):
    """A checkpoint (or ``config.yaml``) that is not its run directory's own: another run's, a link out of the
    directory, or a ``config.yaml`` it cannot be checked against; refused, never adopted or fallen back to."""


class SavedYamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader (plain data, no tags that build objects) without aliases: uavrl writes none, and a few
    nested aliases expand to billions of values."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise yaml.MarkedYAMLError(problem="an alias (*name), which uavrl never writes", problem_mark=mark)
        return super().compose_node(parent, index)


def checkpoint_files(path) -> list[Path]:
    """The files to try, newest first: those of a run directory, or the one file ``path`` (a link that leads nowhere
    among them, for its refusal to say so)."""
    path = Path(path)
    if path.is_dir():
        return [f for f in (path / CHECKPOINT, path / PREVIOUS_CHECKPOINT) if os.path.lexists(f)]
    return [path] if path.exists() else []


def run_dir_of(path) -> Path:
    """The run directory of a checkpoint given as ``path``: ``path`` itself, or the directory of the file given."""
    path = Path(path)
    return path if path.is_dir() else path.parent


def link_out(file: Path, run_dir: Path) -> str | None:
    """What ``file`` is when it is a symbolic link that leads out of ``run_dir`` or nowhere (``a symbolic link to
    '/x/checkpoint.pt', outside ...``), else None: a run's files are its own, inside it."""
    if not file.is_symlink() or special_kind(file) is not None:  # a link to a FIFO or device is refused as that
        return None
    target = Path(os.path.realpath(file))
    if not target.exists():
        return "a symbolic link that leads nowhere (a loop, or its target is gone)"
    if not target.is_relative_to(os.path.realpath(run_dir)):
        return f"a symbolic link to {quoted(target)}, outside the run directory"
    return None


def read_torch(path: Path):
    """What ``torch.save`` wrote to ``path``, rebuilt from data only (``weights_only=True``).

    Raises ForeignObjects when the file holds objects uavrl does not write
    (named in the message), CheckpointError when it is empty, damaged or no
    torch file.
    """
    import pickle

    import torch

    kind = special_kind(path)
    if kind is not None:
        raise CheckpointError(f"{kind}, not a regular file")
    if path.stat().st_size == 0:
        raise CheckpointError("empty file")
    try:
        with warnings.catch_warnings():  # torch warns about pickle protocols of files that are no torch files
            warnings.simplefilter("ignore")
            try:
                return torch.load(path, map_location="cpu", weights_only=True)
            except pickle.UnpicklingError as err:
                if _refused_global(err) not in _TENSORDICT_NAMES:
                    raise
                names = [(_stored_tensordict, _TENSORDICT_NAMES[0]), (_tensordict_class, _TENSORDICT_NAMES[1])]
                with torch.serialization.safe_globals(names):
                    return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # any failure to unpickle means an unreadable file, whatever the library raises
        name = _refused_global(err)
        if name is not None:
            raise ForeignObjects(f"it holds objects uavrl does not write ({name})") from None
        with open(path, "rb") as f:
            torch_file = f.read(2) == b"PK" or isinstance(err, EOFError)  # a zip, or a pickle that ends too soon
        kind = "truncated or damaged" if torch_file else "not a torch file"
        detail = _weights_only_detail(err) or " ".join(str(err).split()).split(". ")[0]
        raise CheckpointError(f"{kind} ({type(err).__name__}{': ' + detail if detail else ''})") from None


def _refused_global(err: Exception) -> str | None:
    """The name of the global (a function or class) that ``weights_only`` refused to rebuild, if that was the error."""
    found = re.search(r"GLOBAL ([\w.]+)", str(err))
    return found.group(1) if found else None


def _weights_only_detail(err: Exception) -> str | None:
    """The reason of a ``weights_only`` refusal without the advice around it (``Unsupported operand 149``)."""
    found = re.search(r"WeightsUnpickler error:\s*(.+?)\s*(?:\n\n|$)", str(err), re.S)
    return " ".join(found.group(1).split()) if found else None


def _tensordict_class(*args, **kwargs):
    """The TensorDict class in a stored pickle: only :func:`_stored_tensordict` takes it; calling it fails."""
    raise ValueError("a TensorDict is rebuilt from its stored entries only")


def _stored_tensordict(kind, state):
    """The TensorDict that an earlier version's checkpoint pickled: its entries and batch size, nothing else."""
    from tensordict import TensorDict

    if kind is not _tensordict_class or not isinstance(state, dict) or not isinstance(state.get("_tensordict"), dict):
        raise ValueError("not a TensorDict that uavrl writes")
    return TensorDict(state["_tensordict"], batch_size=state.get("_batch_size"), device=state.get("_device"))


def _read(path: Path) -> dict:
    """The checkpoint in ``path``; a CheckpointError with the reason when it is unreadable or not a uavrl checkpoint."""
    state = read_torch(path)
    if not isinstance(state, dict) or not all(k in state for k in _ENTRIES):
        raise CheckpointError(f"not a uavrl checkpoint (a {type(state).__name__} without {', '.join(_ENTRIES)})")
    for key, kind in (("config", dict), ("agent", dict), ("iteration", int)):
        if not isinstance(state[key], kind) or isinstance(state[key], bool):
            found = type(state[key]).__name__
            raise CheckpointError(
                f"not a uavrl checkpoint of this version (its {key} is a {found}, not a {kind.__name__})"
            )
    return state


def load_checkpoint(path, setting: str) -> tuple[dict, Path, list[str]]:
    """The newest readable checkpoint of a run directory (or of the file ``path``), given as ``setting=path``.

    Returns ``(state, its file, notes)`` where ``notes`` says, one entry per
    newer file that is missing or could not be read, which and why.  Raises
    FileNotFoundError when there is no checkpoint file and CheckpointError
    when none is readable or one holds objects uavrl does not write; their
    messages begin with ``setting=path``.
    """
    given = f"{setting}={quoted(path)}"
    files = checkpoint_files(path)
    if not files:
        raise FileNotFoundError(no_checkpoint(path, setting))
    run_dir = run_dir_of(path)
    run_config = read_run_config(run_dir, given)
    run = metrics_identity(run_dir) if run_config is None else identity(run_config, run_dir / RUN_CONFIG)
    notes = [f"{CHECKPOINT}: missing"] if Path(path).is_dir() and files[0].name != CHECKPOINT else []
    skipped = []
    for file in files:
        outside = link_out(file, run_dir)
        if outside is not None:
            raise NotThisRun(f"{given}: {file.name} is {outside}: a run's checkpoints are files of its own; refused")
        try:
            state = _read(file)
        except ForeignObjects as err:
            raise ForeignObjects(
                f"{given}: {quoted(file)}: {err}: it is not a uavrl file, or it was altered; refused, and "
                "nothing in it was run"
            ) from None
        except CheckpointError as err:
            skipped.append(f"{file.name}: {err}")
            continue
        check_belongs(state, file, run, given, notes + skipped)
        return state, file, notes + skipped
    raise CheckpointError(f"{given}: no readable checkpoint ({'; '.join(notes + skipped)})")


class RunIdentity(dict):
    """The settings that tell a run from another (:data:`RUN_IDENTITY`), flat (``agent.name``); ``label``: the agent
    as runs are filed (``dqn-set``); ``source``: the file they were read from."""

    label: str
    source: Path | None = None


def identity(cfg, source: Path | None = None) -> RunIdentity:
    """:class:`RunIdentity` of a saved run's config ``cfg`` (as :func:`uavrl.config.saved_config` reads it), read
    from the file ``source``."""
    from omegaconf import OmegaConf

    from uavrl.experiment.runs import agent_label

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


def read_run_config(run_dir, given: str):
    """The run directory's ``config.yaml`` as :func:`uavrl.config.saved_config` reads it (a DictConfig), read without
    torch; None where there is none; a one-line NotThisRun beginning with ``given`` (``checkpoint=<dir>``) when it is
    there but is no run's config that uavrl can read: a link out of the directory, no regular file, too large, not
    YAML, not a uavrl run's settings (no checkpoint there could then be told to be the run's)."""
    from uavrl.config import saved_config  # the settings' rules: only once a file is read

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
    from uavrl.config import saved_config

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


def no_checkpoint(path, setting: str) -> str:
    """Why ``setting=path`` has no checkpoint to read, and what to give instead."""
    path = Path(path)
    given = f"{setting}={quoted(path)}"
    if os.path.lexists(path) and not path.exists():
        return f"{given} is a symbolic link that leads nowhere (a loop, or its target is gone)"
    if not path.exists():
        return f"{given} does not exist (give a run directory or its {CHECKPOINT})"
    benchmarl = benchmarl_run(path)
    if benchmarl is not None:
        return f"{given} is a BenchMARL run (python -m uavrl.benchmarl): {benchmarl}"
    return f"{given}: no {CHECKPOINT} there (give a {CHECKPOINT} or a run directory)"


def benchmarl_run(run_dir: Path) -> str | None:
    """For a run directory of ``python -m uavrl.benchmarl``: where its results are and how BenchMARL reads them."""
    experiments = sorted(config.parent for config in run_dir.glob("*/config.pkl"))  # BenchMARL's own folder
    if not run_dir.is_dir() or not experiments:
        return None
    metrics = run_dir / "metrics.json"
    results = (
        f"its final evaluation is in {quoted(metrics)}"
        if metrics.exists()
        else "it holds no final evaluation (metrics.json)"
    )
    saved = sorted(experiments[-1].glob("checkpoints/checkpoint_*.pt"), key=_frames)
    reload = (
        f"Experiment.reload_from_file({str(saved[-1])!r})" if saved else "Experiment.reload_from_file(<checkpoint>)"
    )
    return (
        f"uavrl reads only its own {CHECKPOINT}; {results}; BenchMARL evaluates and resumes its runs itself: "
        f"from benchmarl.experiment import Experiment; {reload}.evaluate() (BenchMARL unpickles its files, which can "
        "run code: only for runs you trust)"
    )


def _frames(checkpoint: Path) -> int:
    digits = checkpoint.stem.rsplit("_", 1)[-1]
    return int(digits) if digits.isdigit() else -1


def run_directory(path, setting: str) -> Path:
    """The run directory of ``setting=path``: ``path`` itself, or the directory of the ``checkpoint.pt`` given.

    Continuing a run means continuing its directory from its newest readable
    checkpoint, so any other file is refused in one line that names the
    directory to give.
    """
    path = Path(path)
    if path.is_file() and path.name != CHECKPOINT:
        directory = quoted(path.parent)
        raise ValueError(
            f"{setting}={quoted(path)} is invalid: give the run directory, {setting}={directory} (it "
            "continues from the newest readable checkpoint there)"
        )
    return run_dir_of(path)


def restore_agent(agent, state: dict, file: Path, name: str) -> None:
    """``agent.load_state_dict(state["agent"])``; a CheckpointError naming ``file`` when that state does not fit."""
    try:
        agent.load_state_dict(state["agent"])
    except (AttributeError, IndexError, KeyError, RuntimeError, TypeError, ValueError) as err:
        reason = " ".join(f"{type(err).__name__}: {err}".split())
        raise CheckpointError(
            f"{quoted(file)}: its agent state does not fit a {name} agent of this uavrl ({reason})"
        ) from None


def check_resumable(state: dict, file: Path) -> None:
    """A CheckpointError naming ``file`` unless it holds the random state that a resume continues from."""
    import torch

    rng = state.get("torch_rng")
    if not (torch.is_tensor(rng) and rng.dtype == torch.uint8 and rng.shape == torch.get_rng_state().shape):
        found = "none" if rng is None else f"a {type(rng).__name__}"
        raise CheckpointError(
            f"{quoted(file)} cannot be resumed: it holds no torch random state (torch_rng: {found}), which "
            f"every uavrl checkpoint saves; evaluate it instead: python -m uavrl.evaluate "
            f"checkpoint={quoted(file)}"
        )


class CheckpointWriter:
    """Writes a run's newest checkpoint atomically, keeping the one it replaces as the previous one.

    ``newest_is_readable=False`` (a resume that had to skip an unreadable
    newest file) replaces that file without keeping it, so the readable
    previous one stays until a new readable checkpoint exists.

    Args:
        run_dir: the run directory the checkpoints are written to.
        newest_is_readable: whether the run's newest checkpoint file could be read (False: the first save replaces
            it without keeping it as the previous one).
    """

    def __init__(self, run_dir, newest_is_readable: bool = True):
        self.run_dir = Path(run_dir)
        self.keep_previous = newest_is_readable

    def save(self, state: dict) -> None:
        previous = self.run_dir / PREVIOUS_CHECKPOINT if self.keep_previous else None
        save_torch(state, self.run_dir / CHECKPOINT, previous=previous)
        self.keep_previous = True
