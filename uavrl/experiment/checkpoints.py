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

A checkpoint is read only as its run directory's own: a file inside that directory (a link out of it is refused), and
with ``belongs`` (:func:`uavrl.experiment.saved.load_run_checkpoint`'s check) one whose saved run is the directory's.
Only the standard library is imported here; torch is imported when a checkpoint is read or written.
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

from uavrl.experiment.io import quoted, save_torch, special_kind

CHECKPOINT = "checkpoint.pt"
PREVIOUS_CHECKPOINT = "checkpoint.prev.pt"
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


def load_checkpoint(path, setting: str, belongs=None) -> tuple[dict, Path, list[str]]:
    """The newest readable checkpoint of a run directory (or of the file ``path``), given as ``setting=path``.

    Returns ``(state, its file, notes)`` where ``notes`` says, one entry per
    newer file that is missing or could not be read, which and why.  Raises
    FileNotFoundError when there is no checkpoint file and CheckpointError
    when none is readable or one holds objects uavrl does not write; their
    messages begin with ``setting=path``.  A file that is a link out of the run directory is refused (NotThisRun).

    Args:
        path: a run directory, or a checkpoint file in one.
        setting: how ``path`` was given (``checkpoint``, ``resume``, ``run_dir``), named by a refusal.
        belongs: ``belongs(state, file, notes)`` raises when a readable checkpoint is not the run directory's own
            (:func:`uavrl.experiment.saved.load_run_checkpoint`'s check): refused, never skipped for an older one.
    """
    given = f"{setting}={quoted(path)}"
    files = checkpoint_files(path)
    if not files:
        raise FileNotFoundError(no_checkpoint(path, setting))
    run_dir = run_dir_of(path)
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
        if belongs is not None:
            belongs(state, file, notes + skipped)
        return state, file, notes + skipped
    raise CheckpointError(f"{given}: no readable checkpoint ({'; '.join(notes + skipped)})")


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
