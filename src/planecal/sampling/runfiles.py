"""A sampling run's files: the sample file (the record: ``samples.SampleWriter`` writes
it), its sidecar ``RUN.tsv.json`` (format ``planecal-run/1``, ``formats.run``), the lock
that keeps a second run off the same file, and the error a run that cannot write them
stops with."""
from __future__ import annotations

import os
import weakref
from pathlib import Path

from planecal.base.errors import InputError, RunFailed
from planecal.formats import load_sidecar as read_sidecar


def sidecar_path(out: str | Path) -> Path:
    out = Path(out)
    return out.with_name(out.name + ".json")


class RunWriteError(RunFailed):
    """The run could not write its sample file or sidecar (disk full, ...): it stopped; the
    samples written are in the file, which a resumed run continues."""


class RunLock:
    """An exclusive lock on a file (a run's sample file, a study's results, a controller's
    state), held for a whole session, so two runs can never write the same file (one
    would truncate or interleave the other's samples). It is an ``flock`` on
    ``FILE.lock`` beside the file, which exists only while the lock is held: `close`
    removes it (still holding the lock) and then releases it; a process that ends without
    closing releases it too, and a killed one leaves ``FILE.lock`` behind until the next
    run on the file removes it. A lock file removed or replaced between another process's
    open and its lock is noticed (its inode is no longer the path's) and opened again.
    A forked child (the background planner) closes its copy at once: the lock ends with
    the process that took it, not with its children. ``what`` names the locked thing in
    the refusal (default: the file)."""

    def __init__(self, out: str | Path, what: str | None = None):
        import fcntl

        self.path = Path(out)
        self.lock_path = Path(str(self.path) + ".lock")
        self._fd: int | None = None
        for _ in range(100):  # each retry means another process removed the file meanwhile
            try:
                fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as e:
                raise InputError(f"{self.path}: cannot lock ({e.strerror})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                raise InputError(f"{what or self.path}: another run is "
                                 f"{'using it' if what else 'writing this file'}") from None
            except OSError as e:
                os.close(fd)
                raise InputError(f"{self.path}: cannot lock ({e.strerror})") from None
            try:
                same = os.path.samestat(os.stat(self.lock_path), os.fstat(fd))
            except FileNotFoundError:
                same = False
            if same:
                self._fd = fd
                _HELD.add(self)
                return
            os.close(fd)
        raise InputError(f"{self.path}: cannot lock ({self.lock_path} keeps changing)")

    def close(self) -> None:
        if self._fd is not None:
            try:
                os.unlink(self.lock_path)  # while held: nobody else can hold this inode
            except FileNotFoundError:
                pass
            os.close(self._fd)  # releases the lock
            self._fd = None
            _HELD.discard(self)


_HELD: "weakref.WeakSet[RunLock]" = weakref.WeakSet()


def _close_in_child() -> None:
    """After a fork, in the child: close the copies of the held locks' descriptors (the
    parent still holds them), so the lock is free as soon as the parent ends."""
    for lock in list(_HELD):
        if lock._fd is not None:
            try:
                os.close(lock._fd)
            except OSError:
                pass
            lock._fd = None
    _HELD.clear()


os.register_at_fork(after_in_child=_close_in_child)


def load_sidecar(out: str | Path) -> dict:
    """The run's sidecar, validated (``formats.run``): a plain dict."""
    p = sidecar_path(out)
    if not p.exists():
        raise InputError(f"{p}: no run sidecar to resume from")
    return read_sidecar(p)


def count_samples(path: Path) -> int:
    """Complete sample lines in a sample file (header and a partial last line excluded)."""
    if not path.exists():
        return 0
    data = path.read_bytes()
    lines = data.split(b"\n")[:-1]  # the part after the last newline is incomplete
    return sum(1 for ln in lines if ln.strip() and not ln.lstrip().lower().startswith(b"q1"))
