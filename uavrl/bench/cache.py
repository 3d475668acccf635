"""The references of each task, computed once and kept on disk by content (JSON only: nothing in the cache runs).

An entry is ``<cache dir>/<key>.json`` where ``key`` hashes what the references depend on (the task's spec, the uavrl
version and :data:`REFERENCES_VERSION`); it holds the key and a sha256 of its payload.  An entry that cannot be read,
is not JSON, names another key or whose payload does not match its checksum is damaged: it is recomputed and
rewritten, never trusted.  The directory is ``cache_dir=`` on the command line, else ``$UAVRL_BENCH_CACHE``, else
``~/.cache/uavrl/bench``.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import uavrl
from uavrl.experiment.io import save_text

REFERENCES_VERSION = 1  # bump when what a reference means changes: every entry is then recomputed


class DefaultDir:
    """The default place of the cache, found when it is used (:func:`default_dir`), not when uavrl is imported."""

    def __repr__(self) -> str:
        return "$UAVRL_BENCH_CACHE or ~/.cache/uavrl/bench"


DEFAULT_DIR = DefaultDir()


def default_dir() -> Path:
    """``$UAVRL_BENCH_CACHE``, else ``~/.cache/uavrl/bench``."""
    return Path(os.environ.get("UAVRL_BENCH_CACHE") or Path.home() / ".cache" / "uavrl" / "bench")


def entry_key(task) -> str:
    """The content key of a task's references."""
    text = json.dumps(
        {"task": task.spec(), "uavrl": uavrl.__version__, "references": REFERENCES_VERSION}, sort_keys=True
    ).encode()
    return hashlib.sha256(text).hexdigest()


def _checksum(payload: dict) -> str:
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def load(directory: Path, key: str) -> dict | None:
    """The payload stored under ``key``, or None when there is none or it is damaged."""
    try:
        entry = json.loads((Path(directory) / f"{key}.json").read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if not isinstance(entry, dict) or entry.get("key") != key or not isinstance(entry.get("payload"), dict):
        return None
    if entry.get("sha256") != _checksum(entry["payload"]):
        return None
    return entry["payload"]


def store(directory: Path, key: str, payload: dict) -> None:
    """Write ``payload`` under ``key`` atomically (a reader sees the old entry or the new one, never half)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    save_text(json.dumps({"key": key, "sha256": _checksum(payload), "payload": payload}), directory / f"{key}.json")


def cached(directory: Path | None, key: str, compute) -> dict:
    """The payload under ``key``, else ``compute()``'s, stored for next time (``directory`` None: no cache)."""
    if directory is None:
        return compute()
    payload = load(directory, key)
    if payload is None:
        payload = compute()
        store(directory, key, payload)
    return payload
