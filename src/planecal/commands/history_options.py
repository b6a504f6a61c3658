"""The history options every recording command takes (calibrate, validate, export, check,
compare, history rollback) and the entry each writes (``planecal.history``;
docs/HISTORY.md):

    --history FILE|URL   the cell's history (default: $PLANECAL_HISTORY, else planecal.db
                         in the working folder); a database URL for a server
    --no-history         record nothing
    --note TEXT          kept with the entry
    --cell NAME          the cell's name in a history several cells share (default: the
                         scene's name)

The history is opened (and checked: not an input, a writable place, a planecal history)
before the command's work; the entry is written after it, whatever the outcome (exit 0
or 1), with the command's provenance: its inputs with their SHA-256, the scene, the robot
and its description's hash, the world the data was made in, planecal's version, the date.
"""
from __future__ import annotations

import sys

from planecal.base.errors import InputError


def add_history_arguments(p) -> None:
    g = p.add_argument_group("the cell's history (docs/HISTORY.md)")
    g.add_argument("--history", metavar="FILE|URL", default=None,
                   help="record this command in this history: an SQLite file or a database "
                        "URL (default: $PLANECAL_HISTORY, else planecal.db in the working "
                        "folder)")
    g.add_argument("--no-history", action="store_true", help="record nothing")
    g.add_argument("--note", default=None, metavar="TEXT", help="a note kept with the entry")
    g.add_argument("--cell", default=None, metavar="NAME",
                   help="the cell's name in a history several cells share (default: the "
                        "scene's name)")


def open_history(args, inputs=(), create: bool = True):
    """The history the flags name, checked and opened before any work (None with
    --no-history)."""
    from planecal.history import History, location

    if args.no_history:
        if args.history or args.note:
            raise InputError("--no-history: nothing is recorded, so --history and --note "
                             "have nowhere to go")
        return None
    if args.note is not None and ("\0" in args.note or len(args.note) > 2000):
        raise InputError("--note: at most 2000 characters of text")
    return History.open(location(args.history), [i for i in inputs if i is not None], create)


def new_entry(args, kind: str, outcome: str, exit_code: int, prov: dict, **fields):
    """An ``Entry`` of this command: the flags' note and cell (default: the provenance's
    scene), the provenance's inputs, version, date, scene and robot; ``fields``: the
    entry's own (world, against, summary, document, ...)."""
    from planecal.history import Entry, InputRow

    inputs = [InputRow(i["role"], i["path"], i["sha256"], i["bytes"])
              for i in prov.get("inputs") or []]
    return Entry(kind=kind, outcome=outcome, exit_code=exit_code,
                 created_utc=prov["created_utc"], planecal_version=prov["planecal_version"],
                 cell=args.cell or prov.get("scene"), scene=prov.get("scene"),
                 robot=prov.get("robot"), note=args.note, inputs=inputs, **fields)


def command_provenance(scene, inputs) -> dict:
    """The provenance (``formats.params.provenance``) of a command's input files (role,
    path; None paths left out) with the scene's and the robot's files."""
    from planecal.formats.params import provenance
    files = [(r, p) for r, p in [*inputs, ("scene", scene.path), ("robot", scene.robot.source)]
             if p is not None]
    return provenance(files, scene.name, scene.robot.name)


def record(hist, entry, json_out: bool = False) -> int | None:
    """Write ``entry`` (nothing without a history); the line saying where goes to stdout
    beside the command's other "written to" lines (to stderr where stdout carries JSON,
    ``json_out``)."""
    if hist is None:
        return None
    try:
        n = hist.add(entry)
    finally:
        hist.close()
    print(f"history: entry {n} ({entry.kind}: {entry.outcome}) in {hist.label}",
          file=sys.stderr if json_out else sys.stdout)
    return n


def result_link(hist, path) -> tuple[str, int | None]:
    """(SHA-256 of a result file, the calibrate entry of ``hist`` that wrote it or None)."""
    from planecal.base.paths import file_sha256
    sha = file_sha256(path)
    return sha, (hist.find_result(sha) if hist is not None else None)


def parameter_rows(doc: dict) -> list:
    """A result document's parameters as the history's rows (by name, SI units)."""
    from planecal.history import ParameterRow
    from planecal.present.calibration import parameter_rows as rows
    return [ParameterRow(r.name, r.value, r.std, r.unit, r.status) for r in rows(doc)]
