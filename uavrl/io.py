"""Atomic writes: a file is either the old one or the complete new one, never half written.

A write goes to a temporary ``.<name>.<random>.tmp`` beside the file, then is
renamed over it.  A process killed mid-write leaves that temporary file; the
next write of the same file removes it.  torch is imported by :func:`save_torch`
only, so the commands' light start-up can use this module.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

_UMASK = os.umask(0)
os.umask(_UMASK)


def remove_orphans(path) -> None:
    """Remove the temporary files that killed writes of ``path`` left."""
    path = Path(path)
    for orphan in path.parent.glob(f".{path.name}.*.tmp"):
        orphan.unlink(missing_ok=True)


def claim_dir(base) -> Path:
    """Create and return ``base``, or ``base-1``, ``base-2``, ... if taken: one directory per caller, even for
    processes that start in the same second (``mkdir`` either creates the directory or fails)."""
    base = Path(base)
    base.parent.mkdir(parents=True, exist_ok=True)
    candidate, n = base, 1
    while True:
        try:
            candidate.mkdir()
            return candidate
        except FileExistsError:
            candidate, n = base.with_name(f"{base.name}-{n}"), n + 1


def _atomic(path: Path, write, previous: Path | None = None):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_orphans(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)
        if previous is not None and path.exists():
            os.replace(path, previous)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_torch(obj, path, previous=None) -> None:
    """``torch.save`` to a temporary file in the same folder, then rename; the file replaced becomes ``previous``."""
    import torch

    _atomic(path, lambda f: torch.save(obj, f), None if previous is None else Path(previous))


def save_json(obj, path) -> None:
    _atomic(path, lambda f: f.write((json.dumps(obj, indent=2, sort_keys=True) + "\n").encode()))


def save_bytes(data: bytes, path) -> None:
    _atomic(path, lambda f: f.write(data))


def save_text(text: str, path) -> None:
    _atomic(path, lambda f: f.write(text.encode()))
