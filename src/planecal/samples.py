"""Sample files (seed 7.1.4).

One sample a line, tab-separated: q1..q6 encoder counts (integers in the 24-bit range)
and Dm, the laser distance in mm. The thesis's files use a decimal comma ("92,52") and a
header line ``q1 q2 q3 q4 q5 q6 Dm``; both decimal comma and point are read, the header is
optional, CRLF line ends are fine, blank lines are skipped. An optional 8th column
``plate`` (1-based plate index) is read and written for multi-plate runs.
Dm = 0 is the ZS-LD80's out-of-range reading: such samples are skipped and counted.
planecal writes dot decimals with 6 digits (1 nm, below any laser noise), header included.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planecal.errors import InputError

HEADER = ["q1", "q2", "q3", "q4", "q5", "q6", "Dm"]
COUNT_LIMIT = 1 << 24


@dataclass
class Samples:
    qe: np.ndarray  # (N, 6) int64
    d_mm: np.ndarray  # (N,) float
    plate: np.ndarray  # (N,) int, 0-based
    lines: np.ndarray  # (N,) 1-based line numbers in the file
    n_zero: int  # laser zeros skipped
    path: Path | None = None

    def __len__(self) -> int:
        return len(self.d_mm)

    def subset(self, idx) -> "Samples":
        return Samples(self.qe[idx], self.d_mm[idx], self.plate[idx], self.lines[idx], 0, self.path)


def _is_header(fields: list[str]) -> bool:
    return [f.strip().lower() for f in fields[:7]] == [h.lower() for h in HEADER]


def read_samples(path: str | Path) -> Samples:
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, not a sample file") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    qe, d, plate, lines = [], [], [], []
    n_zero = 0
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        fields = line.strip().split("\t") if "\t" in line else line.split()
        if _is_header(fields):
            if qe or n_zero:
                raise InputError(f"{path}:{lineno}: header line in the middle of the data")
            continue
        if len(fields) not in (7, 8):
            raise InputError(f"{path}:{lineno}: expected 7 tab-separated columns "
                             f"(q1..q6, Dm), found {len(fields)}")
        counts = []
        for j, f in enumerate(fields[:6]):
            try:
                c = int(f.strip())
            except ValueError:
                raise InputError(f"{path}:{lineno}: column q{j + 1} is not an integer "
                                 f"encoder count: {f.strip()!r}") from None
            if not 0 <= c < COUNT_LIMIT:
                raise InputError(f"{path}:{lineno}: column q{j + 1} = {c} is outside the "
                                 f"24-bit encoder range 0..{COUNT_LIMIT - 1}")
            counts.append(c)
        dm_text = fields[6].strip().replace(",", ".")
        try:
            dm = float(dm_text)
        except ValueError:
            raise InputError(f"{path}:{lineno}: column Dm is not a number: {fields[6].strip()!r}") from None
        if not math.isfinite(dm) or dm < 0:
            raise InputError(f"{path}:{lineno}: column Dm = {fields[6].strip()!r} is not a "
                             f"finite, non-negative distance in mm")
        k = 0
        if len(fields) == 8:
            try:
                k = int(fields[7].strip()) - 1
            except ValueError:
                k = -1
            if k < 0:
                raise InputError(f"{path}:{lineno}: column plate must be a 1-based plate "
                                 f"number, got {fields[7].strip()!r}")
        if dm == 0.0:
            n_zero += 1
            continue
        qe.append(counts)
        d.append(dm)
        plate.append(k)
        lines.append(lineno)
    if not qe:
        what = f" ({n_zero} laser zeros)" if n_zero else ""
        raise InputError(f"{path}: no samples in the file{what}")
    return Samples(np.array(qe, np.int64), np.array(d), np.array(plate, int),
                   np.array(lines, int), n_zero, path)


def read_many(paths) -> Samples:
    """Read several sample files into one set (lines keep their per-file numbers)."""
    sets = [read_samples(p) for p in paths]
    return Samples(np.concatenate([s.qe for s in sets]), np.concatenate([s.d_mm for s in sets]),
                   np.concatenate([s.plate for s in sets]), np.concatenate([s.lines for s in sets]),
                   sum(s.n_zero for s in sets), sets[0].path if len(sets) == 1 else None)


def format_line(qe, d_mm: float, plate: int | None = None) -> str:
    cols = [str(int(c)) for c in qe] + [f"{d_mm:.6f}"]
    if plate is not None:
        cols.append(str(int(plate) + 1))
    return "\t".join(cols) + "\n"


def write_samples(path: str | Path, qe, d_mm, plate=None) -> None:
    with SampleWriter(path, with_plate=plate is not None) as w:
        for i in range(len(d_mm)):
            w.write(qe[i], d_mm[i], None if plate is None else plate[i])


class SampleWriter:
    """Appends samples one line at a time, written unbuffered and fsynced, so nothing
    recorded is lost when a run is interrupted. ``append=True`` continues an existing file.
    A line that cannot be written whole (disk full) is cut off again before the error is
    raised: the file always ends with a whole line."""

    def __init__(self, path: str | Path, append: bool = False, with_plate: bool = False):
        self.path = Path(path)
        self.with_plate = with_plate
        exists = self.path.exists() and self.path.stat().st_size > 0
        if append and exists:
            self._repair_tail()
        self._f = open(self.path, "ab" if append else "wb", buffering=0)
        if not (append and exists):
            header = HEADER + (["plate"] if with_plate else [])
            self._append("\t".join(header) + "\n")

    def _repair_tail(self):
        """A run killed mid-write may leave a partial last line: cut it off."""
        data = self.path.read_bytes()
        if data and not data.endswith(b"\n"):
            cut = data.rfind(b"\n") + 1
            with open(self.path, "r+b") as f:
                f.truncate(cut)

    def _append(self, line: str) -> None:
        fd = self._f.fileno()
        size = os.fstat(fd).st_size
        try:
            data = line.encode("utf-8")
            while data:
                data = data[os.write(fd, data):]
            os.fsync(fd)
        except OSError:
            os.ftruncate(fd, size)  # frees space: possible on a full disk
            raise

    def write(self, qe, d_mm: float, plate: int | None = None) -> None:
        self._append(format_line(qe, d_mm, plate if self.with_plate else None))

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
