"""A sampling run's files: the sample file (the record: ``samples.SampleWriter`` writes
it), its sidecar ``RUN.tsv.json`` (format ``planecal-run/1``, ``formats.run``), the lock
that keeps a second run off the same file, and the error a run that cannot write them
stops with."""
from __future__ import annotations

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
    """An exclusive lock on the sample file, held for a whole session, so two runs can
    never write the same file (one would truncate or interleave the other's samples). It
    is ``filelock``'s (fcntl on POSIX, msvcrt on Windows) on ``RUN.tsv.lock`` beside the
    file; released when closed or when the process ends."""

    def __init__(self, out: str | Path):
        from filelock import FileLock, Timeout
        self.path = Path(out)
        self._lock = FileLock(str(self.path) + ".lock")
        try:
            self._lock.acquire(timeout=0)
        except Timeout:
            raise InputError(f"{self.path}: another run is writing this file") from None
        except OSError as e:
            raise InputError(f"{self.path}: cannot lock ({e.strerror})") from None

    def close(self) -> None:
        if self._lock.is_locked:
            self._lock.release()


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
