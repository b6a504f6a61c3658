"""Sample files (seed 7.1.4).

One sample a line, tab-separated: q1..q6 encoder counts (integers in the 24-bit range)
and Dm, the laser distance in mm. The thesis's files use a decimal comma ("92,52") and a
header line ``q1 q2 q3 q4 q5 q6 Dm``; both decimal comma and point are read, the header is
optional, CRLF line ends are fine, blank lines are skipped. An optional 8th column
``plate`` (1-based plate index) is read and written for multi-plate runs.
Dm = 0 is the ZS-LD80's out-of-range reading: such samples are skipped and counted.
planecal writes 6 decimals (1 nm, below any laser noise), header included, with a decimal
point, or a decimal comma with ``decimal_comma=True`` (``--decimal-comma`` on rehearse and
sample). A file being continued (``append``) keeps the decimal mark its lines already use.

The approach direction (optional group ``dir1..dir6`` after ``Dm`` and ``plate``): per
joint, the sign (-1, 0, +1) of the joint's last motion into the pose (``Samples.direction``;
``sampling.approach``: 0 = not moved since the session began, side unknown). The group is
read only under a header line naming it (``q1 .. q6 Dm [plate] dir1 .. dir6``), and then
every line has exactly the header's columns; a headerless file has the seed's 7 or 8
columns (13 or 14 without a header are refused: by position, a direction could not be
told from other numbers). planecal's writer always writes the header, so its files say
what their columns are. A file without the group reads as before, ``direction`` None; a
file being continued (``append``) keeps its header's columns, with or without the group.

Reading streams the file within bounds (``MAX_FILE_BYTES``, ``MAX_LINES``,
``MAX_LINE_CHARS``, no NUL bytes): a binary file or /dev/zero ends on its first line.
Refused with the line named: a plate column on some lines only, a distance above
``MAX_DM_MM``, a line whose columns are not the header's (the direction group on some
lines only, or part of it), a direction other than -1, 0, 1, header columns after ``Dm``
other than ``plate`` and the whole group; with the file named: a file whose samples are
all one line repeated (no information). ``check_samples(samples, scene)`` refuses readings
outside the scene's laser window and plate numbers the scene lacks (``read_samples(path,
scene)`` does both).
"""
from __future__ import annotations

import io
import itertools
import math
import os
import re
import stat
from array import array
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from planecal.base.errors import InputError

HEADER = ["q1", "q2", "q3", "q4", "q5", "q6", "Dm"]
N_JOINTS = 6  # encoder columns q1..q6
DIRECTION = [f"dir{j + 1}" for j in range(N_JOINTS)]  # the approach direction group
COUNT_LIMIT = 1 << 24
# bounds of what a sample file can be: a run has hundreds of ~60-character lines
MAX_FILE_BYTES = 32 * 2**20
MAX_LINES = 200_000
MAX_LINE_CHARS = 1024
MAX_DM_MM = 10_000.0  # no laser distance sensor used for this measures 10 m
_INT = re.compile(r"[+-]?[0-9]+")


@dataclass
class Samples:
    qe: np.ndarray  # (N, 6) int64
    d_mm: np.ndarray  # (N,) float
    plate: np.ndarray  # (N,) int, 0-based
    lines: np.ndarray  # (N,) 1-based line numbers in the file
    n_zero: int  # laser zeros skipped
    path: Path | None = None
    # (N, 6) int8: per joint the sign (-1, 0, +1) of its last joint-side motion into the
    # pose, 0 unknown (``sampling.approach``); None: not recorded (no dir1..dir6 group)
    direction: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.d_mm)

    def subset(self, idx) -> "Samples":
        return Samples(self.qe[idx], self.d_mm[idx], self.plate[idx], self.lines[idx], 0,
                       self.path, None if self.direction is None else self.direction[idx])


def _is_header(fields: list[str]) -> bool:
    return [f.strip().lower() for f in fields[:7]] == [h.lower() for h in HEADER]


def _open(path: Path):
    """The file as text, read lazily; size checked first where the size is known."""
    from planecal.formats.base import open_input
    raw = open_input(path, "sample file")
    st = os.fstat(raw.fileno())
    if stat.S_ISREG(st.st_mode) and st.st_size > MAX_FILE_BYTES:
        raw.close()
        raise InputError(f"{path}: {st.st_size / 2**20:.0f} MiB is too large for a sample file "
                         f"(at most {MAX_FILE_BYTES // 2**20} MiB; a 150-sample run is ~10 kB)")
    return io.TextIOWrapper(raw, encoding="utf-8-sig", errors="replace", newline=None)


def _lines(path: Path, f):
    """(line number, text) of each line, streaming: a line cap, a line-length cap and no
    NUL bytes, so /dev/zero or a binary file ends on its first line."""
    for lineno in itertools.count(1):
        try:
            line = f.readline(MAX_LINE_CHARS + 1)
        except OSError as e:
            raise InputError(f"{path}:{lineno}: cannot read ({e.strerror})") from None
        if not line:
            return
        if "\0" in line:
            raise InputError(f"{path}:{lineno}: binary data (NUL bytes), not a text sample file "
                             f"(UTF-16? save it as UTF-8)")
        if len(line) > MAX_LINE_CHARS and not line.endswith("\n"):
            raise InputError(f"{path}:{lineno}: line longer than {MAX_LINE_CHARS} characters, "
                             f"not a sample file (a sample line is ~60)")
        if lineno > MAX_LINES:
            raise InputError(f"{path}: more than {MAX_LINES} lines, too many for a sample file "
                             f"(a run has hundreds)")
        yield lineno, line.rstrip("\n")


def _integer(text: str, digits: int) -> int | None:
    return int(text) if _INT.fullmatch(text) and len(text.lstrip("+-")) <= digits else None


@dataclass
class _Columns:
    """What a sample file's lines hold: fixed by a header naming the direction group
    (``count`` columns on every line), else by the first data line (7 or 8)."""
    count: int | None = None  # columns of every line; None: not fixed yet
    direction: bool = False
    line: int | None = None  # the line that fixed them (header or first data line)

    def check(self, path: Path, lineno: int, n: int) -> None:
        """Refuse a line of ``n`` columns that does not fit (module docstring)."""
        if self.direction:
            if n != self.count:
                raise InputError(f"{path}:{lineno}: {n} columns, but the header (line "
                                 f"{self.line}) names {self.count}: q1..q6, Dm"
                                 f"{', plate' if self.count == 14 else ''} and the "
                                 f"direction group dir1..dir6, on every line")
            return
        if n in (13, 14):
            raise InputError(f"{path}:{lineno}: {n} columns without a header naming them: "
                             f"the direction columns dir1..dir6 are read only under a header "
                             f"line q1 .. Dm [plate] dir1 .. dir6")
        if n not in (7, 8):
            raise InputError(f"{path}:{lineno}: expected 7 tab-separated columns "
                             f"(q1..q6, Dm), found {n}")
        if self.count is None:
            self.count, self.line = n, lineno
        elif n != self.count:
            raise InputError(f"{path}:{lineno}: {n} columns, but line {self.line} has "
                             f"{self.count}: the plate column must be on every line or on none")


def _header_columns(path: Path, lineno: int, fields: list[str]) -> _Columns:
    """The columns a header line names: after Dm nothing, ``plate``, the direction group
    or both (anything else is refused)."""
    extra = [f.strip().lower() for f in fields[len(HEADER):]]
    if extra in ([], ["plate"]):
        return _Columns()  # the seed's columns: fixed by the first data line, as headerless
    if extra in (DIRECTION, ["plate"] + DIRECTION):
        return _Columns(len(HEADER) + len(extra), True, lineno)
    raise InputError(f"{path}:{lineno}: header columns after Dm must be plate and/or the "
                     f"whole direction group dir1..dir6, found {' '.join(extra)!r}")


def _parse_line(path: Path, lineno: int, fields: list[str], direction: bool):
    """(counts, Dm mm, plate 0-based, directions or None) of one data line."""
    counts = []
    for j, text in enumerate(fields[:N_JOINTS]):
        c = _integer(text.strip(), 12)
        if c is None:
            raise InputError(f"{path}:{lineno}: column q{j + 1} is not an integer "
                             f"encoder count: {text.strip()!r}")
        if not 0 <= c < COUNT_LIMIT:
            raise InputError(f"{path}:{lineno}: column q{j + 1} = {c} is outside the "
                             f"24-bit encoder range 0..{COUNT_LIMIT - 1}")
        counts.append(c)
    dm_text = fields[N_JOINTS].strip()
    try:
        dm = float(dm_text.replace(",", ".")) if dm_text.isascii() else None
    except ValueError:
        dm = None
    if dm is None:
        raise InputError(f"{path}:{lineno}: column Dm is not a number: {dm_text!r}")
    if not math.isfinite(dm) or dm < 0:
        raise InputError(f"{path}:{lineno}: column Dm = {dm_text!r} is not a "
                         f"finite, non-negative distance in mm")
    if dm > MAX_DM_MM:
        raise InputError(f"{path}:{lineno}: column Dm = {dm_text} mm is not a plausible "
                         f"laser distance (at most {MAX_DM_MM:g} mm)")
    k = 0
    if len(fields) - (len(DIRECTION) if direction else 0) == len(HEADER) + 1:
        k = (_integer(fields[len(HEADER)].strip(), 6) or 0) - 1
        if k < 0:
            raise InputError(f"{path}:{lineno}: column plate must be a 1-based plate "
                             f"number, got {fields[len(HEADER)].strip()!r}")
    if not direction:
        return counts, dm, k, None
    dirs = []
    for j, text in enumerate(fields[-len(DIRECTION):]):
        v = _integer(text.strip(), 1)
        if v not in (-1, 0, 1):
            raise InputError(f"{path}:{lineno}: column dir{j + 1} must be -1, 0 or 1 (the "
                             f"sign of joint {j + 1}'s last motion), got {text.strip()!r}")
        dirs.append(v)
    return counts, dm, k, dirs


def _scan(path: Path, f):
    """Every line of an open sample file checked (module docstring): the arrays of its
    samples, the laser zeros and its columns."""
    qe, d, plate, lines, dirs = array("q"), array("d"), array("q"), array("q"), array("b")
    n_zero = 0
    columns = _Columns()
    for lineno, line in _lines(path, f):
        if not line.strip():
            continue
        fields = line.strip().split("\t") if "\t" in line else line.split()
        if _is_header(fields):
            if len(lines) or n_zero:
                raise InputError(f"{path}:{lineno}: header line in the middle of the data")
            columns = _header_columns(path, lineno, fields)
            continue
        columns.check(path, lineno, len(fields))
        counts, dm, k, dj = _parse_line(path, lineno, fields, columns.direction)
        if dm == 0.0:
            n_zero += 1
            continue
        qe.extend(counts)
        d.append(dm)
        plate.append(k)
        lines.append(lineno)
        if dj is not None:
            dirs.extend(dj)
    return qe, d, plate, lines, dirs, n_zero, columns


def check_continuable(path: str | Path) -> None:
    """A sample file a run is about to continue: every whole line is a sample line (a
    partial last line, which a killed run may leave, is cut off when the run continues);
    InputError naming the first line that is not, so nothing is appended after it."""
    path = Path(path)
    with _open(path) as f:
        text = f.read(MAX_FILE_BYTES + 1)
    whole = text[:text.rfind("\n") + 1]
    _scan(path, io.StringIO(whole))


def read_samples(path: str | Path, scene: "SceneLike | None" = None) -> Samples:
    """Read a sample file (module docstring). With ``scene``, also ``check_samples``."""
    path = Path(path)
    with _open(path) as f:
        qe, d, plate, lines, dirs, n_zero, columns = _scan(path, f)
    if not len(lines):
        what = f" ({n_zero} laser zeros)" if n_zero else ""
        raise InputError(f"{path}: no samples in the file{what}")
    direction = (np.frombuffer(dirs, np.int8).reshape(-1, N_JOINTS).copy()
                 if columns.direction else None)
    s = Samples(np.frombuffer(qe, np.int64).reshape(-1, 6).copy(), np.frombuffer(d).copy(),
                np.frombuffer(plate, np.int64).astype(int), np.frombuffer(lines, np.int64).astype(int),
                n_zero, path, direction)
    if len(s) > 1 and (np.all(s.qe == s.qe[0]) and np.all(s.d_mm == s.d_mm[0])
                       and np.all(s.plate == s.plate[0])):
        raise InputError(f"{path}: all {len(s)} samples are line {s.lines[0]} repeated: no "
                         f"information to calibrate from")
    if scene is not None:
        check_samples(s, scene)
    return s


class SceneLike(Protocol):
    """What ``check_samples`` needs of a ``planecal.model.scene.Scene``."""
    name: str
    laser_range_mm: tuple[float, float]
    plates: list


def check_samples(samples: Samples, scene: SceneLike) -> None:
    """Refuse readings the scene's sensor cannot give (outside its laser window; the
    ZS-LD80 reports 0 there, skipped on reading) and plate numbers the scene lacks.
    The message names the file and line of the first such sample."""
    where = samples.path if samples.path is not None else "samples"
    lo, hi = scene.laser_range_mm
    out = (samples.d_mm < lo) | (samples.d_mm > hi)
    if out.any():
        i = int(np.argmax(out))
        metres = ": a distance in m written as mm?" if lo <= samples.d_mm[i] * 1e3 <= hi else ""
        raise InputError(f"{where}:{samples.lines[i]}: Dm = {samples.d_mm[i]:g} mm is outside "
                         f"the laser window {lo:g}-{hi:g} mm of scene {scene.name}: not a "
                         f"reading this sensor gives ({int(out.sum())} such samples){metres}")
    n = len(scene.plates)
    if samples.plate.max() >= n:
        i = int(np.argmax(samples.plate >= n))
        raise InputError(f"{where}:{samples.lines[i]}: plate {samples.plate[i] + 1}, but scene "
                         f"{scene.name} has {n} plate{'s' if n > 1 else ''}")


def read_many(paths, scene: SceneLike | None = None) -> Samples:
    """Read several sample files into one set (lines keep their per-file numbers); with
    ``scene`` each file is checked against it (``check_samples``). ``direction``: None
    when no file has the group; else each file's, 0 (unknown) for a file without it."""
    return join_samples([read_samples(p, scene) for p in paths])


def join_samples(sets: list[Samples]) -> Samples:
    """Several files' samples as one set, in order (``read_many``)."""
    direction = None
    if any(s.direction is not None for s in sets):
        direction = np.concatenate([np.zeros((len(s), N_JOINTS), np.int8)
                                    if s.direction is None else s.direction for s in sets])
    return Samples(np.concatenate([s.qe for s in sets]), np.concatenate([s.d_mm for s in sets]),
                   np.concatenate([s.plate for s in sets]), np.concatenate([s.lines for s in sets]),
                   sum(s.n_zero for s in sets), sets[0].path if len(sets) == 1 else None,
                   direction)


def format_line(qe, d_mm: float, plate: int | None = None, decimal_comma: bool = False,
                direction=None) -> str:
    """One sample line: counts, Dm (6 decimals), the plate (1-based) and the direction
    group where given."""
    dm = f"{d_mm:.6f}"
    cols = [str(int(c)) for c in qe] + [dm.replace(".", ",") if decimal_comma else dm]
    if plate is not None:
        cols.append(str(int(plate) + 1))
    if direction is not None:
        cols.extend(str(int(v)) for v in direction)
    return "\t".join(cols) + "\n"


def write_samples(path: str | Path, qe, d_mm, plate=None, decimal_comma: bool = False,
                  direction=None) -> None:
    """A sample file of these samples (``direction`` (N, 6) or None: no group)."""
    with SampleWriter(path, with_plate=plate is not None, decimal_comma=decimal_comma,
                      with_direction=direction is not None) as w:
        for i in range(len(d_mm)):
            w.write(qe[i], d_mm[i], None if plate is None else plate[i],
                    None if direction is None else direction[i])


def _has_direction_group(path: Path) -> bool:
    """Whether a sample file's header names the direction group (a file being continued
    keeps its columns; a headerless file has none)."""
    with open(path, "rb") as f:
        for _ in range(100):  # blank lines before the header are allowed
            fields = f.readline(MAX_LINE_CHARS + 1).decode("utf-8-sig", "replace").split()
            if fields:
                names = [x.lower() for x in fields[len(HEADER):]]
                return _is_header(fields) and names[-len(DIRECTION):] == DIRECTION
    return False


def _uses_decimal_comma(path: Path, default: bool) -> bool:
    """The decimal mark of a sample file's last data line (Dm column), ``default`` when it
    has none: a continued file keeps one style."""
    with open(path, "rb") as f:
        f.seek(max(0, os.fstat(f.fileno()).st_size - 4096))
        tail = f.read().decode("utf-8", "replace").splitlines()
    for line in reversed(tail):
        fields = line.split("\t")
        if len(fields) >= 7 and not _is_header(fields):
            dm = fields[6].strip()
            return "," in dm if ("," in dm or "." in dm) else default
    return default


class SampleWriter:
    """Appends samples one line at a time, written unbuffered and fsynced, so nothing
    recorded is lost when a run is interrupted. ``append=True`` continues an existing file
    (its decimal mark, and its direction group or none, whatever is asked).
    ``with_direction``: the direction group dir1..dir6 on every line (``write``'s
    ``direction``). A line that cannot be written whole (disk full) is cut off again
    before the error is raised: the file always ends with a whole line."""

    def __init__(self, path: str | Path, append: bool = False, with_plate: bool = False,
                 decimal_comma: bool = False, with_direction: bool = False):
        self.path = Path(path)
        self.with_plate = with_plate
        self.decimal_comma = decimal_comma
        self.with_direction = with_direction
        exists = self.path.exists() and self.path.stat().st_size > 0
        if append and exists:
            self._repair_tail()
            self.decimal_comma = _uses_decimal_comma(self.path, decimal_comma)
            self.with_direction = _has_direction_group(self.path)
        self._f = open(self.path, "ab" if append else "wb", buffering=0)
        if not (append and exists):
            header = (HEADER + (["plate"] if with_plate else [])
                      + (DIRECTION if with_direction else []))
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

    def write(self, qe, d_mm: float, plate: int | None = None, direction=None) -> None:
        """One sample; ``direction`` (6 signs) is required when the file has the group
        and dropped when it has not (a continued file keeps its columns)."""
        if self.with_direction and direction is None:
            raise ValueError(f"{self.path}: the file has the direction group dir1..dir6; "
                             "a sample without its direction cannot be written to it")
        self._append(format_line(qe, d_mm, plate if self.with_plate else None,
                                 self.decimal_comma,
                                 direction if self.with_direction else None))

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
