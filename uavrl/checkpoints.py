"""A run's checkpoints: the newest and the one before it, each written atomically, read newest first.

``checkpoint.pt`` is the newest.  When a new one replaces it, it becomes
``checkpoint.prev.pt``, so a newest file damaged after its write (a full disk,
a copy cut short, a stray edit) still leaves a readable one.  Reading tries the
newest first and says which files it skipped and why.  Only the standard
library is imported here; torch is imported when a checkpoint is read or written.
"""

from __future__ import annotations

from pathlib import Path

from uavrl.io import save_torch

CHECKPOINT = "checkpoint.pt"
PREVIOUS_CHECKPOINT = "checkpoint.prev.pt"
_ENTRIES = ("agent", "iteration", "config")  # what every uavrl checkpoint holds


class CheckpointError(ValueError):
    """No readable uavrl checkpoint; the message says which files were tried and why each failed."""


def checkpoint_files(path) -> list[Path]:
    """The files to try, newest first: those of a run directory, or the one file ``path``."""
    path = Path(path)
    if path.is_dir():
        return [f for f in (path / CHECKPOINT, path / PREVIOUS_CHECKPOINT) if f.exists()]
    return [path] if path.exists() else []


def _read(path: Path) -> dict:
    """The checkpoint in ``path``; a CheckpointError with the reason when it is unreadable or not a uavrl checkpoint."""
    import torch

    if path.stat().st_size == 0:
        raise CheckpointError("empty file")
    try:
        state = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as err:  # any failure to unpickle means an unreadable file, whatever the library raises
        with open(path, "rb") as f:
            kind = "truncated or damaged" if f.read(2) == b"PK" else "not a torch file"
        detail = " ".join(str(err).split()).split(". ")[0]  # the library's first sentence, on one line
        raise CheckpointError(f"{kind} ({type(err).__name__}: {detail})") from None
    if not isinstance(state, dict) or not all(k in state for k in _ENTRIES):
        raise CheckpointError(f"not a uavrl checkpoint (a {type(state).__name__} without {', '.join(_ENTRIES)})")
    return state


def load_checkpoint(path, setting: str) -> tuple[dict, Path, list[str]]:
    """The newest readable checkpoint of a run directory (or of the file ``path``), given as ``setting=path``.

    Returns ``(state, its file, skipped)`` where ``skipped`` says, one entry per
    newer file that could not be read, which and why.  Raises FileNotFoundError
    when there is no checkpoint file and CheckpointError when none is readable;
    their messages begin with ``setting=path``.
    """
    given = f"{setting}={str(path)!r}"
    files = checkpoint_files(path)
    if not files:
        raise FileNotFoundError(f"{given}: no {CHECKPOINT} there (give a checkpoint.pt or a run directory)")
    skipped = []
    for file in files:
        try:
            return _read(file), file, skipped
        except CheckpointError as err:
            skipped.append(f"{file.name}: {err}")
    raise CheckpointError(f"{given}: no readable checkpoint ({'; '.join(skipped)})")


class CheckpointWriter:
    """Writes a run's newest checkpoint atomically, keeping the one it replaces as the previous one.

    ``newest_is_readable=False`` (a resume that had to skip an unreadable
    newest file) replaces that file without keeping it, so the readable
    previous one stays until a new readable checkpoint exists.
    """

    def __init__(self, run_dir, newest_is_readable: bool = True):
        self.run_dir = Path(run_dir)
        self.keep_previous = newest_is_readable

    def save(self, state: dict) -> None:
        previous = self.run_dir / PREVIOUS_CHECKPOINT if self.keep_previous else None
        save_torch(state, self.run_dir / CHECKPOINT, previous=previous)
        self.keep_previous = True
