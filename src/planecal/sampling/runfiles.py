"""A sampling run's files: the sample file (the record: ``samples.SampleWriter`` writes
it), its sidecar ``RUN.tsv.json`` (format ``planecal-run/1``, ``formats.run``), the lock
that keeps a second run off the same file, and the error a run that cannot write them
stops with."""
from __future__ import annotations

import os
from pathlib import Path

from planecal.errors import InputError, RunFailed
from planecal.formats import load_sidecar as read_sidecar


def sidecar_path(out: str | Path) -> Path:
    out = Path(out)
    return out.with_name(out.name + ".json")


class RunWriteError(RunFailed):
    """The run could not write its sample file or sidecar (disk full, ...): it stopped; the
    samples written are in the file, which a resumed run continues."""


class RunLock:
    """An exclusive advisory lock (flock) on the sample file, held for a whole session, so
    two runs can never write the same file (one would truncate or interleave the other's
    samples). Taken without truncating; released when closed or when the process ends."""

    def __init__(self, out: str | Path):
        import fcntl
        self.path = Path(out)
        try:
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as e:
            raise InputError(f"{self.path}: cannot open ({e.strerror})") from None
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(self._fd)
            raise InputError(f"{self.path}: another run is writing this file") from None

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # releases the lock
            self._fd = None


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
