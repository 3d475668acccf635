"""A run directory held by one training process, and the interrupts that end a run with a checkpoint.

:func:`hold` creates or opens the run directory and takes its lock
(``filelock``'s ``fcntl`` lock on ``.uavrl.lock``, which the operating system
releases when the process dies, even by ``kill -9``): a second ``train`` or
``resume`` into a directory that a live process holds is refused at once,
naming the holder that ``.uavrl.lock.holder`` records.  Only the holder
removes the temporary files of killed writes, so no process deletes another's
write in flight.  A run that fails before it saved anything removes the
directory if it made it.

:class:`Interrupts` turns SIGINT (Ctrl-C) and SIGTERM (a scheduler's stop)
into a request that the training loop answers at the end of the iteration: it
saves a checkpoint there, so the resumed run ends exactly as an uninterrupted
one.  A second signal stops at once; the write it cuts short is discarded and
the checkpoints already on disk stay as they were.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import sys
import threading
from pathlib import Path

from uavrl.cli import typed
from uavrl.experiment.io import (
    EVENTS,
    WriteError,
    make_dirs,
    orphans,
    quoted,
    read_regular_text,
    save_text,
    special_kind,
)

LOCK = ".uavrl.lock"
HOLDER = ".uavrl.lock.holder"
# what a training run writes atomically (uavrl.experiment.io), whose orphaned temporary files the holder removes
RUN_FILES = ("checkpoint.pt", "checkpoint.prev.pt", "config.yaml", "metrics.json", HOLDER)
VALUABLE = ("checkpoint.pt", "checkpoint.prev.pt", "metrics.json")


def path_argument(setting: str, path) -> str:
    """``setting=path`` as one command-line argument that the shell and Hydra's override parser both read back."""
    return typed(setting, path)


def resume_command(run_dir) -> str:
    return f"python -m uavrl.train {path_argument('resume', run_dir)}"


class RunDirectoryInUse(OSError):
    """Another live process holds the run directory."""


class RunDirectory:
    """A run directory this process holds; :meth:`release` at the end, :meth:`discard` after a failure."""

    def __init__(self, path: Path, created: bool, lock, created_parents=()):
        self.path, self.created, self._lock = path, created, lock
        self.created_parents = list(created_parents)  # innermost first

    def holds_value(self) -> bool:
        return any((self.path / name).exists() for name in VALUABLE)

    def release(self) -> None:
        (self.path / HOLDER).unlink(missing_ok=True)
        self._lock.release()

    def discard(self) -> None:
        """Release; remove the directory too if this process made it and it holds no checkpoint or metrics."""
        if self.created and self.path.is_dir() and not self.holds_value():
            shutil.rmtree(self.path, ignore_errors=True)
            self._lock.release()
            for parent in self.created_parents:
                with contextlib.suppress(OSError):  # another run's directory in it since: it stays
                    parent.rmdir()
            return
        self.release()


def check_directory(path, setting: str) -> None:
    """A one-line NotADirectoryError when ``path`` (given as ``setting``: ``run_dir``, ``resume``) is a file."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        advice = f"resume={quoted(path.parent)}" if setting == "resume" else "a directory (new, or without a run)"
        raise NotADirectoryError(f"{setting}={quoted(path)} is a file, not a directory: give {advice}")


def check_run_files(path, setting: str) -> None:
    """A one-line ValueError, before a resumed run writes anything, when a file of ``path`` that the run reads back or
    replaces (its checkpoints, ``config.yaml``, ``metrics.json``, TensorBoard's events) is a directory, a FIFO or a
    device, itself or through a link: reading one blocks or never ends, and writing over one fails half way."""
    path = Path(path)
    for file in [*(path / name for name in RUN_FILES if name != HOLDER), *sorted(path.glob(EVENTS))]:
        kind = special_kind(file)
        if kind is not None:
            raise ValueError(
                f"{setting}={quoted(path)}: {file.name} is {kind}, not a regular file, and the run reads it back or "
                "writes it anew: move it away"
            )


def hold(path, setting: str, created: bool = False, created_parents=()) -> RunDirectory:
    """Create ``path`` if missing, lock it, record the holder and remove orphaned temporary files.

    ``setting`` is how the user gave the directory (``run_dir``, ``resume``), for
    the messages; ``created``: the caller made the directory (a new timestamped
    one), and ``created_parents`` the folders above it (innermost first).
    """
    from filelock import FileLock, Timeout

    path = Path(path)
    given = f"{setting}={quoted(path)}"
    check_directory(path, setting)
    if not path.exists():
        created, created_parents = True, missing_parents(path)
    make_dirs(path)
    lock = FileLock(path / LOCK, timeout=0)
    try:
        lock.acquire()
    except Timeout:
        raise RunDirectoryInUse(
            f"{given} is in use by another uavrl process ({holder(path)}): wait for it to end, or give another "
            "directory"
        ) from None
    except OSError as err:
        if created:
            shutil.rmtree(path, ignore_errors=True)
        raise WriteError(path / LOCK, err) from None
    held = RunDirectory(path, created, lock, created_parents)
    try:
        _remove_orphans(path)
        save_text(f"pid {os.getpid()} on {socket.gethostname()}\n", path / HOLDER)
    except BaseException:
        held.discard()
        raise
    return held


def missing_parents(path) -> list[Path]:
    """The folders above ``path`` that do not exist yet, innermost first."""
    return [parent for parent in Path(path).parents if not parent.exists()]


def tidy(path) -> None:
    """Remove the orphaned temporary files of the run directory ``path`` if no live process holds it."""
    from filelock import FileLock, Timeout

    path = Path(path)
    if not path.is_dir() or not _orphans(path):  # nothing to do: no lock file made in a directory not a run's
        return
    lock = FileLock(path / LOCK, timeout=0)
    try:
        lock.acquire()
    except (Timeout, OSError):  # held by a live process (its files are in use), or not ours to write
        return
    try:
        _remove_orphans(path)
    finally:
        lock.release()


def _orphans(path: Path) -> list[Path]:
    return [*(o for name in RUN_FILES for o in orphans(path / name)), *path.glob(f".{EVENTS}.tmp")]


def _remove_orphans(path: Path) -> None:
    for orphan in _orphans(path):
        orphan.unlink(missing_ok=True)


def holder(path: Path) -> str:
    """Who holds ``path``'s lock, as its holder file says."""
    try:
        return read_regular_text(path / HOLDER, limit=4096).strip() or "pid unknown"
    except (OSError, ValueError):
        return "pid unknown"


class Interrupted(KeyboardInterrupt):
    """The run was stopped by a signal; ``signum`` says which (the exit status is 128 + signum)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class Interrupts:
    """SIGINT and SIGTERM while the run holds its directory.

    Inside :meth:`deferred` (the training loop) the first signal is recorded
    in ``received`` and the loop saves at the end of the iteration; anywhere
    else, and for a second signal, :class:`Interrupted` is raised at once,
    except inside :meth:`shielded` (logging, the progress bar: code holding
    locks that an exception would leave held), which acts on it when it ends.
    Once :class:`Interrupted` is on its way (:meth:`stop`), further signals are
    dropped: the run is already stopping, and a new exception raised in its
    handlers would lose what they report.
    Handlers are installed only in the main thread (Python's rule); elsewhere
    (a launcher's worker thread) signals keep their default effect.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, notify=None):
        """``notify(line)`` shows the notice of a first signal (default: print to stderr)."""
        self.notify = notify or (lambda line: print(line, file=sys.stderr, flush=True))
        self.received: int | None = None
        self.working_on = "the current iteration"  # for the notice: ``iteration 7 of 50``
        self._deferring, self._shielded, self._pending, self._stopping = False, 0, None, False
        self._previous = {}

    def __enter__(self) -> Interrupts:
        if threading.current_thread() is threading.main_thread():
            self._previous = {signum: signal.signal(signum, self._handle) for signum in self.SIGNALS}
        return self

    def __exit__(self, *exc) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous = {}

    @contextlib.contextmanager
    def deferred(self):
        """A first signal received inside is recorded, not raised: the caller checks ``received``."""
        self._deferring = True
        try:
            yield
        finally:
            self._deferring = False

    @contextlib.contextmanager
    def shielded(self, act_after: bool = True):
        """Signals received inside wait for its end; ``act_after=False`` (cleanup while stopping) drops them."""
        self._shielded += 1
        try:
            yield
        finally:
            self._shielded -= 1
        pending, self._pending = self._pending, None
        if pending is not None and act_after and not self._shielded:
            self._act(pending)

    def stop(self, signum: int) -> Interrupted:
        """The exception that stops the run for ``signum``; signals after it are dropped."""
        self.received = self.received or signum
        self._stopping = True
        return Interrupted(signum)

    def _handle(self, signum, frame) -> None:
        if self._stopping:
            return
        if self._shielded:
            self._pending = signum
            return
        self._act(signum)

    def _act(self, signum: int) -> None:
        if self.received is None and self._deferring:
            self.received = signum
            self.notify(
                f"{signal.Signals(signum).name}: finishing {self.working_on}, then saving a checkpoint (a second "
                "Ctrl-C or SIGTERM stops at once, keeping the checkpoints already saved)"
            )
            return
        raise self.stop(signum)
