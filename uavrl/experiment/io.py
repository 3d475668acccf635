"""Atomic writes: a file is either the old one or the complete new one, never half written.

A write goes to a temporary ``.<name>.<random>.tmp`` beside the file, then is
renamed over it.  A process killed mid-write leaves that temporary file; the
next run that holds the directory's lock removes it (:mod:`uavrl.experiment.rundir`), so
no process deletes another's write in flight.  A write that fails (a full
disk, no permission) raises :class:`WriteError`, which names the file, and
leaves the file as it was.  torch is imported by :func:`save_torch` only, so
the commands' light start-up can use this module.
"""

from __future__ import annotations

import json
import os
import secrets
import shlex
import stat
import tempfile
from pathlib import Path

EVENTS = "events.out.tfevents.*"  # TensorBoard's event files (uavrl.experiment.logger)
_UMASK = os.umask(0)
os.umask(_UMASK)


def quoted(path) -> str:
    """A path as a shell takes it back (spaces, quotes, non-ASCII letters): how every message prints one."""
    return shlex.quote(str(path))


class WriteError(OSError):
    """A file that could not be written or a directory that could not be made; the message names it."""

    def __init__(self, path, err: OSError, verb: str = "write"):
        super().__init__(err.errno, err.strerror or str(err), str(path))
        self.verb = verb

    def __str__(self) -> str:
        return f"could not {self.verb} {quoted(self.filename)}: {self.strerror}"


def nearest_existing(path) -> Path:
    """``path``, or the nearest folder above it that exists: where the folders missing below it would be made."""
    path = Path(path)
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def special_kind(path) -> str | None:
    """What ``path`` is when it exists and is no regular file (``a FIFO``, ``a directory``), else None: reading a FIFO
    or a device blocks or never ends, so every reader asks this first."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if stat.S_ISREG(mode):
        return None
    kinds = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"))
    kinds += ((stat.S_ISBLK, "a block device"), (stat.S_ISDIR, "a directory"))
    return next((kind for test, kind in kinds if test(mode)), "not a regular file")


class RefusedFile(ValueError):
    """A file refused unread (:func:`read_regular_text`): a link out of its directory, no regular file, too large, or
    no UTF-8 text; the message names it and why, in one line."""


def read_regular_text(path, limit: int = 16 * 2**20, within=None, shown: str | None = None) -> str:
    """The text of the regular file ``path`` (at most ``limit`` bytes): every reader of uavrl reads through this.

    Refused with a one-line ValueError that names the file as ``shown`` (default: ``path`` as given): a FIFO, a
    device, a socket or a directory (reading would block or never end), a file larger than ``limit`` (its size is
    read before its bytes: a link to ``/dev/zero`` or a huge sparse file is not read), a symbolic link that leads
    out of the directory ``within`` when one is given, text that is not UTF-8.  An OSError (FileNotFoundError, ...)
    when it cannot be opened.
    """
    shown = quoted(path) if shown is None else shown
    if within is not None and not Path(path).resolve().is_relative_to(Path(within).resolve()):
        raise RefusedFile(f"{shown} is a link to {quoted(Path(path).resolve())}, out of {quoted(within)}")
    kind = special_kind(path)
    if kind is not None:
        raise RefusedFile(f"{shown} is {kind}, not a regular file")
    # opened without blocking and checked again on the open file: a FIFO swapped in after the check is not read
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as file:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise RefusedFile(f"{shown} is not a regular file")
        data = file.read(limit + 1)  # a file that grew since its size was read is cut at the limit
        if info.st_size > limit or len(data) > limit:
            size = max(info.st_size, len(data))
            raise RefusedFile(f"{shown} holds {size:,} bytes, more than uavrl writes there ({limit:,})")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise RefusedFile(f"{shown} is not UTF-8 text") from None


class Manifest:
    """The files a command wrote into a folder that may hold a user's own files too, recorded in ``.uavrl-written.json``
    there (reproduce's; other commands name their own record): the command overwrites or removes only files it
    recorded, and refuses to write over anything else (or, :meth:`free`, writes beside it).

    Paths are kept relative to the folder; a file is recorded before it is first written (so one cut short is still
    the command's own).
    """

    NAME = ".uavrl-written.json"

    def __init__(self, folder, setting: str, name: str = NAME):
        """``setting``: how the user gave the folder (``out_dir``), for the messages; ``name``: the record's file,
        one per command that writes there (one command's record never lets it remove another's files)."""
        self.folder, self.setting = Path(folder), setting
        self.path = self.folder / name
        self.files: set[str] = set()
        if os.path.lexists(self.path):
            try:
                listed = json.loads(read_regular_text(self.path))
            except (ValueError, OSError) as err:
                raise RefusedFile(
                    f"{setting}={quoted(self.folder)}: its record of uavrl's files is unreadable ({err}): "
                    "give another folder"
                ) from None
            if not isinstance(listed, list) or not all(isinstance(name, str) and _inside(name) for name in listed):
                raise RefusedFile(
                    f"{setting}={quoted(self.folder)}: {quoted(self.path)} is not a list of file names inside it: "
                    "give another folder"
                )
            self.files = set(listed)

    def _name(self, path) -> str:
        return Path(path).relative_to(self.folder).as_posix()

    def owns(self, path) -> bool:
        return self._name(path) in self.files

    def check_writable(self, paths) -> None:
        """A FileExistsError naming the first of ``paths`` that exists and that this command did not write."""
        for path in paths:
            if os.path.lexists(path) and not self.owns(path):
                raise FileExistsError(
                    f"{self.setting}={quoted(self.folder)} holds {quoted(self._name(path))}, which uavrl did not write "
                    f"there: give another {self.setting}, or move that file away (it is not overwritten)"
                )

    def free(self, path) -> Path:
        """``path``, or ``<stem>-2<suffix>``, ``-3``, ... : the first that is absent or this command's own, recorded;
        a user's file of that name stays and the command writes beside it."""
        base = candidate = Path(path)
        n = 1
        while os.path.lexists(candidate) and not self.owns(candidate):
            n += 1
            candidate = base.with_name(f"{base.stem}-{n}{base.suffix}")
        self.record(candidate)
        return candidate

    def record(self, *paths) -> None:
        """Record ``paths`` as this command's before they are written."""
        names = {self._name(path) for path in paths}
        if not names <= self.files:
            self.files |= names
            save_json(sorted(self.files), self.path)

    def remove_all(self) -> list[str]:
        """Remove every recorded file (and the folders under ``folder`` left empty by it); the names removed."""
        removed, inside = [], self.folder.resolve()
        for name in sorted(self.files):
            path = self.folder / name
            if not path.parent.resolve().is_relative_to(inside):  # a folder swapped for a link to elsewhere
                continue
            if os.path.lexists(path) and not path.is_dir():
                path.unlink()
                removed.append(name)
            for parent in Path(name).parents:
                if parent != Path("."):
                    try:
                        (self.folder / parent).rmdir()  # only when empty: a user's file there keeps the folder
                    except OSError:
                        pass
        self.files = set()
        self.path.unlink(missing_ok=True)
        return removed


def _inside(name: str) -> bool:
    """A relative path that stays in its folder (no ``..``, not absolute): what a record of written files holds."""
    parts = Path(name).parts
    return bool(parts) and not Path(name).is_absolute() and ".." not in parts


def orphans(path) -> list[Path]:
    """The temporary files that killed writes of ``path`` left."""
    path = Path(path)
    return [orphan for orphan in path.parent.glob(f".{path.name}.*.tmp") if orphan.is_file()]


def claim_dir(base) -> Path:
    """Create and return ``base``, or ``base-1``, ``base-2``, ... if taken: one directory per caller, even for
    processes that start in the same second (``mkdir`` either creates the directory or fails)."""
    base = Path(base)
    make_dirs(base.parent)
    candidate, n = base, 1
    while True:
        try:
            candidate.mkdir()
            return candidate
        except FileExistsError:
            candidate, n = base.with_name(f"{base.name}-{n}"), n + 1
        except OSError as err:
            raise WriteError(candidate, err, "create") from None


def make_dirs(path) -> None:
    """``mkdir -p``; a :class:`WriteError` naming the directory when it cannot be made."""
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise WriteError(path, err, "create") from None


class _Recording:
    """A file whose write errors are kept: torch's zip writer replaces them (a full disk, an interrupt) with an
    error of its own that does not say the cause."""

    def __init__(self, file):
        self.file, self.error = file, None

    def write(self, data) -> int:
        try:
            return self.file.write(data)
        except BaseException as err:
            self.error = err
            raise

    def flush(self) -> None:
        self.file.flush()


def _keep_as_previous(path: Path, previous: Path) -> None:
    """Make ``previous`` the file ``path`` is now, leaving ``path`` in place: at every instant both names hold a
    complete checkpoint, so a kill between this and the rename of the new file loses nothing."""
    if previous.exists() and os.path.samefile(path, previous):  # a write cut short after the link: kept already
        return
    link = previous.with_name(f".{previous.name}.{secrets.token_hex(4)}.tmp")
    try:
        try:
            os.link(path, link)
        except OSError:  # a file system without hard links: a moment without ``path``, the previous file complete
            os.replace(path, previous)
            return
        os.replace(link, previous)
    except BaseException:
        link.unlink(missing_ok=True)
        raise


def _atomic(path: Path, write, previous: Path | None = None):
    path = Path(path)
    make_dirs(path.parent)
    tmp = file = None
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as raw:
            file = _Recording(raw)
            write(file)
            raw.flush()
            os.fsync(raw.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)
        if previous is not None and path.exists():
            _keep_as_previous(path, previous)
        os.replace(tmp, path)
    except BaseException as err:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        cause = err if file is None or file.error is None or isinstance(err, KeyboardInterrupt) else file.error
        if isinstance(cause, OSError) and not isinstance(cause, WriteError):
            raise WriteError(path, cause) from None
        if cause is not err:
            raise cause from None
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


# a run's files read back (config.yaml, metrics.json): guarded, without torch
# uavrl's config.yaml and metrics.json hold a few KB: a larger file is not one it wrote, and is not read whole
MAX_FILE_BYTES = 1 << 20


class DamagedRun(ValueError):
    """A run directory whose files the report cannot use; the message names the file and why, in one line."""


def read_small_text(path: Path, within=None) -> str:
    """The text of a run's small file (:func:`read_regular_text`, at most ``MAX_FILE_BYTES``), a DamagedRun naming it
    by its name when it cannot be read."""
    try:
        return read_regular_text(path, MAX_FILE_BYTES, within, shown=Path(path).name)
    except ValueError as err:
        raise DamagedRun(str(err)) from None
    except OSError as err:
        raise DamagedRun(f"{Path(path).name} cannot be read ({err.strerror or err})") from None
