"""A program's targets for ``planecal compensate`` (docs/COMPENSATE.md): flange poses,
joint angles in degrees or encoder counts, from a CSV or a JSON file (``read_targets``),
and the corrected targets written back as a counts table (``write_counts_table``)."""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from planecal.base.errors import InputError
from planecal.formats.base import MAX_JSON_BYTES, read_bounded, read_json
from planecal.model.encoder import counts_to_joints
from planecal.model.robot import Robot

TARGETS_FORMAT = "planecal-targets/1"
MAX_TARGETS = 100_000
COUNT_LIMIT = 1 << 24

CARTESIAN = ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")
JOINTS_DEG = tuple(f"q{j}_deg" for j in range(1, 7))
COUNTS = tuple(f"q{j}" for j in range(1, 7))


@dataclass(frozen=True)
class Targets:
    """Targets read from a file. ``pose`` (N, 4, 4) for Cartesian targets (NaN rows for
    joint targets), ``q`` (N, 6) rad for joint targets (NaN rows for Cartesian ones);
    ``where``: the line (CSV) or entry (JSON) of each, for messages."""
    names: list
    pose: np.ndarray
    q: np.ndarray
    where: list
    source: str

    def __len__(self) -> int:
        return len(self.names)

    @property
    def cartesian(self) -> np.ndarray:
        return np.isfinite(self.pose[:, 0, 0])


def pose_from(xyz_mm, rxyz_deg) -> np.ndarray:
    """Flange pose from a position [mm] and fixed-axis angles rx, ry, rz [deg]:
    R = Rz(rz) Ry(ry) Rx(rx) (scipy ``from_euler('xyz')``, extrinsic)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", rxyz_deg, degrees=True).as_matrix()
    T[:3, 3] = np.asarray(xyz_mm, float) * 1e-3
    return T


def angles_of(T: np.ndarray) -> np.ndarray:
    """(rx, ry, rz) [deg] of ``pose_from``'s convention, (..., 3)."""
    return Rotation.from_matrix(T[..., :3, :3]).as_euler("xyz", degrees=True)


def _finite(v: str, where: str, col: str) -> float:
    try:
        x = float(v)
    except ValueError:
        raise InputError(f"{where}: {col}: not a number: {v!r}") from None
    if not np.isfinite(x):
        raise InputError(f"{where}: {col}: not a finite number: {v!r}")
    return x


def _counts(vals, where: str, cols) -> np.ndarray:
    out = []
    for v, c in zip(vals, cols):
        if isinstance(v, str):
            v = v.strip()
            if not v.lstrip("+-").isdigit():
                raise InputError(f"{where}: {c}: encoder counts are integers, got {v!r}")
            v = int(v)
        elif isinstance(v, bool) or not isinstance(v, int):
            raise InputError(f"{where}: {c}: encoder counts are integers, got {v!r}")
        if not 0 <= v < COUNT_LIMIT:
            raise InputError(f"{where}: {c}: {v} outside the 24-bit encoder range")
        out.append(v)
    return np.array(out, np.int64)


class _Builder:
    def __init__(self, robot: Robot, source: str):
        self.robot, self.source = robot, source
        self.names, self.pose, self.q, self.where = [], [], [], []

    def add(self, name, where, pose=None, q=None):
        if len(self.names) >= MAX_TARGETS:
            raise InputError(f"{self.source}: more than {MAX_TARGETS} targets")
        if name and not name.isprintable():
            raise InputError(f"{where}: name: holds a control character (tab, newline, ...)")
        self.names.append(name if name else f"T{len(self.names) + 1}")
        self.where.append(where)
        self.pose.append(np.full((4, 4), np.nan) if pose is None else pose)
        self.q.append(np.full(6, np.nan) if q is None else q)

    def done(self) -> Targets:
        if not self.names:
            raise InputError(f"{self.source}: no targets")
        return Targets(self.names, np.array(self.pose), np.array(self.q), self.where,
                       self.source)


def read_targets(path, robot: Robot) -> Targets:
    """A targets file: JSON (``planecal-targets/1``) if it ends in .json, else CSV (comma,
    semicolon or tab separated, a header naming the columns). docs/COMPENSATE.md."""
    p = Path(path)
    if p.suffix.lower() == ".json":
        return _read_json_targets(p, robot)
    return _read_csv_targets(p, robot)


def _read_csv_targets(p: Path, robot: Robot) -> Targets:
    raw = read_bounded(p, "targets file", MAX_JSON_BYTES)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(f"{p}: not UTF-8 text (byte {e.start}), not a targets file") from None
    lines = text.splitlines()
    first = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")),
                 None)
    if first is None:
        raise InputError(f"{p}: no targets (an empty file)")
    head = lines[first]
    delim = "\t" if "\t" in head else (";" if ";" in head else ",")
    rows = csv.reader(io.StringIO("\n".join(lines)), delimiter=delim)
    try:
        return _csv_rows(p, robot, rows)
    except csv.Error as e:  # a field over the csv module's limit, a stray quote
        raise InputError(f"{p}:{rows.line_num}: not a row of the targets table ({e})") from None


def _csv_rows(p: Path, robot: Robot, rows) -> Targets:
    cols = None
    b = _Builder(robot, str(p))
    for lineno, row in enumerate(rows, 1):
        if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
            continue
        row = [c.strip() for c in row]
        if cols is None:
            cols = [c.lower() for c in row]
            twice = sorted({c for c in cols if cols.count(c) > 1})
            if twice:
                raise InputError(f"{p}:{lineno}: column {twice[0]!r} appears twice in the "
                                 "header")
            kinds = [k for k in (CARTESIAN, JOINTS_DEG, COUNTS) if set(k) <= set(cols)]
            if len(kinds) != 1:
                raise InputError(f"{p}:{lineno}: the header names the columns: "
                                 f"{','.join(CARTESIAN)} (a flange pose), or "
                                 f"{','.join(JOINTS_DEG)} (joints), or {','.join(COUNTS)} "
                                 f"(encoder counts); optional 'name'. Got {','.join(row)}")
            kind = kinds[0]
            unknown = set(cols) - set(kind) - {"name"}
            if unknown:
                raise InputError(f"{p}:{lineno}: unknown column(s) {', '.join(sorted(unknown))}")
            idx = [cols.index(c) for c in kind]
            iname = cols.index("name") if "name" in cols else None
            continue
        where = f"{p}:{lineno}"
        if len(row) != len(cols):
            raise InputError(f"{where}: {len(row)} fields, the header has {len(cols)}")
        vals = [row[i] for i in idx]
        name = row[iname] if iname is not None else None
        if kind is CARTESIAN:
            v = [_finite(x, where, c) for x, c in zip(vals, kind)]
            b.add(name, where, pose=pose_from(v[:3], v[3:]))
        elif kind is JOINTS_DEG:
            b.add(name, where, q=np.radians([_finite(x, where, c) for x, c in zip(vals, kind)]))
        else:
            b.add(name, where, q=counts_to_joints(robot, _counts(vals, where, kind)))
    return b.done()


def _read_json_targets(p: Path, robot: Robot) -> Targets:
    doc = read_json(p, "targets file")
    if not isinstance(doc, dict) or doc.get("format") != TARGETS_FORMAT:
        raise InputError(f"{p}: format: a targets file carries \"format\": \"{TARGETS_FORMAT}\"")
    ts = doc.get("targets")
    if not isinstance(ts, list) or not ts:
        raise InputError(f"{p}: targets: a non-empty list of targets")
    unknown = set(doc) - {"format", "targets", "description"}
    if unknown:
        raise InputError(f"{p}: unknown key(s) {', '.join(sorted(unknown))}")
    b = _Builder(robot, str(p))
    keys = {"name", "position_mm", "rotation_deg", "joints_deg", "counts"}

    def vec(t, k, n, where):
        v = t.get(k)
        if not isinstance(v, list) or len(v) != n or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            raise InputError(f"{where}.{k}: {n} numbers")
        return [_finite(str(x), where, k) for x in v]

    for i, t in enumerate(ts):
        where = f"{p}: targets[{i}]"
        if not isinstance(t, dict):
            raise InputError(f"{where}: a target is an object {{...}}")
        bad = set(t) - keys
        if bad:
            raise InputError(f"{where}: unknown key(s) {', '.join(sorted(bad))}")
        name = t.get("name")
        if name is not None and not isinstance(name, str):
            raise InputError(f"{where}.name: a string")
        given = [k for k in ("position_mm", "joints_deg", "counts") if k in t]
        if len(given) != 1 or (("rotation_deg" in t) != (given == ["position_mm"])):
            raise InputError(f"{where}: give position_mm with rotation_deg, or joints_deg, "
                             "or counts")
        if given[0] == "position_mm":
            b.add(name, where, pose=pose_from(vec(t, "position_mm", 3, where),
                                              vec(t, "rotation_deg", 3, where)))
        elif given[0] == "joints_deg":
            b.add(name, where, q=np.radians(vec(t, "joints_deg", 6, where)))
        else:
            c = t["counts"]
            if not isinstance(c, list) or len(c) != 6:
                raise InputError(f"{where}.counts: 6 integers")
            b.add(name, where, q=counts_to_joints(robot, _counts(c, where, COUNTS)))
    return b.done()


def write_counts_table(path, comp) -> None:
    """The corrected targets of a compensation (``estimation.compensate.Compensation``) as
    a tab-separated table: name, q1..q6 (counts)."""
    lines = ["name\t" + "\t".join(COUNTS)]
    for name, c in zip(comp.names, comp.counts_corrected):
        lines.append(name + "\t" + "\t".join(str(int(v)) for v in c))
    p = Path(path)
    tmp = p.with_name(f"{p.name}.tmp")
    try:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
        tmp.replace(p)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
