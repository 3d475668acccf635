"""The references of each task, computed once and kept on disk by content (JSON only: nothing in the cache runs).

An entry is ``<cache dir>/<key>.json`` where ``key`` hashes what the references depend on (the task's spec, the uavrl
version and :data:`REFERENCES_VERSION`); it holds the key and a sha256 of its payload.  The checksum catches a damaged
file, not a forged one (anyone can recompute an unkeyed hash), so every entry is read as untrusted input: through the
guarded reader (a regular file in the cache directory, of bounded size), and its payload checked for the structure,
types and finite values the scoring reads (:data:`PAYLOAD`).  An entry that fails any of this is damaged: the cache is
derived data and uavrl's own, so it is recomputed and only that entry rewritten, with one warning on stderr naming it;
a damaged entry never fails a run and is never trusted.  The directory is ``cache_dir=`` on the command line, else
``$UAVRL_BENCH_CACHE``, else ``~/.cache/uavrl/bench``; one that is no directory or cannot be written is refused in one
line before any reference is computed (:func:`check_dir`).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path

import uavrl
from uavrl.bench.results import NUMBER, NUMBERS, TABLE, TEXT, Invalid, conform
from uavrl.envs.rules import Rule, flag, one_of, optional, whole
from uavrl.experiment.io import nearest_existing, quoted, read_regular_text, save_text, special_kind

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


def _tensor(values: Rule) -> Rule:
    """A tensor as :func:`uavrl.bench.run._tensor` stores it: a dtype of torch's numbers and its values."""
    dtypes = ("float64", "float32", "int64", "int32", "bool")
    return Rule(
        lambda v: isinstance(v, dict) and set(v) == {"dtype", "values"} and v["dtype"] in dtypes
        and values.accepts(v["values"]),
        f"it must be {{dtype: one of {', '.join(dtypes)}, values: {values.allowed.removeprefix('it must be ')}}}",
    )  # fmt: skip


BASELINE = {"values": NUMBERS, "summary": {"*": NUMBER}}
PAYLOAD = {  # what uavrl.bench.run.compute_references writes and the scoring reads
    "starts": {
        "u_star": _tensor(NUMBERS),
        "u_start": _tensor(NUMBERS),
        "u_star_gap": NUMBER,
        "best_return": optional(_tensor(NUMBERS), "no exact best return fits"),
        "min_steps": _tensor(TABLE),
        "min_steps_levels": [TEXT],
        "exact": flag(),
        **{f"{key}?": _tensor(NUMBERS) for key in ("delivered_bound", "horizon_bound", "delivered_optimum")},
    },
    "baselines": {"random": BASELINE, "*": BASELINE},
    "planner": one_of("oracle", "planner"),
    "reference": {"kind": TEXT, "values": NUMBERS},
    "value": TEXT,
    "horizon": whole(1),
    "cpu_seconds": NUMBER,
}


def check_payload(payload) -> None:
    """An :class:`~uavrl.bench.results.Invalid` naming the first field of a cache entry's payload that the scoring
    could not use: its schema, the planner's baseline present, one value per start in every per-start list."""
    conform(payload, PAYLOAD, "payload")
    if payload["planner"] not in payload["baselines"]:
        raise Invalid(f"payload.baselines.{payload['planner']} is missing")
    starts = len(payload["reference"]["values"])
    lists = {f"baselines.{name}.values": b["values"] for name, b in payload["baselines"].items()}
    lists.update({f"starts.{k}.values": v["values"] for k, v in payload["starts"].items() if isinstance(v, dict)})
    for name, values in lists.items():
        if len(values) != starts:
            raise Invalid(f"payload.{name} is invalid: it must hold {starts} values, one per start")
    if not sum(payload["reference"]["values"]) > sum(payload["baselines"]["random"]["values"]):
        # what uavrl.bench.run.normalised divides by: a reference computed here always beats random
        raise Invalid("payload.reference.values is invalid: the reference must beat the random policy on average")


def load(directory: Path, key: str) -> dict | None:
    """The payload stored under ``key``, or None when there is none; a ValueError saying why when the entry is
    damaged (unreadable, not JSON, another key's, a checksum that does not match, a payload :func:`check_payload`
    refuses)."""
    path = Path(directory) / f"{key}.json"
    if not os.path.lexists(path):
        return None
    try:
        entry = json.loads(read_regular_text(path, within=directory, shown="it"))
    except OSError as err:
        raise ValueError(f"it cannot be read ({err.strerror or err})") from None
    except RecursionError:
        raise ValueError("it nests deeper than an entry does") from None
    except ValueError as err:  # the guarded reader's refusal, or not JSON
        raise ValueError(str(err) if str(err).startswith("it ") else f"it is not JSON ({err})") from None
    if not isinstance(entry, dict) or entry.get("key") != key or not isinstance(entry.get("payload"), dict):
        raise ValueError("it is not the entry of its key")
    if entry.get("sha256") != _checksum(entry["payload"]):
        raise ValueError("its payload does not match its checksum")
    check_payload(entry["payload"])
    return entry["payload"]


def check_dir(directory, setting: str = "cache_dir") -> None:
    """Refuse in one line a cache ``directory`` (given as ``setting``) that is no directory, or whose entries could
    not be written (checked before any reference is computed, so none is computed in vain)."""
    directory = Path(directory)
    existing = nearest_existing(directory)
    given = f"{setting}={quoted(directory)}"
    if not existing.is_dir():
        kind = special_kind(existing) or "a file"
        raise NotADirectoryError(f"{given} is invalid: {quoted(existing)} is {kind}, not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise PermissionError(f"{given} is invalid: {quoted(existing)} is not writable: give a writable cache_dir")


def store(directory: Path, key: str, payload: dict) -> None:
    """Write ``payload`` under ``key`` atomically (a reader sees the old entry or the new one, never half)."""
    save_text(
        json.dumps({"key": key, "sha256": _checksum(payload), "payload": payload}), Path(directory) / f"{key}.json"
    )


def cached(directory: Path | None, key: str, compute) -> dict:
    """The payload under ``key``, else ``compute()``'s, stored for next time (``directory`` None: no cache); a
    damaged entry is recomputed and rewritten, said once on stderr."""
    if directory is None:
        return compute()
    try:
        payload = load(directory, key)
    except ValueError as why:
        entry = quoted(Path(directory) / f"{key}.json")
        print(
            f"warning: the references' cache entry {entry} is damaged ({why}): recomputed and rewritten",
            file=sys.stderr,
        )
        payload = None
    if payload is None:
        payload = compute()
        store(directory, key, payload)
    return payload
