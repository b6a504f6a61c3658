"""The history options every recording command takes (calibrate, validate, export, check,
compare, history rollback) and the entry each writes (``planecal.history``;
docs/HISTORY.md):

    --history FILE|URL   the cell's history (default: $PLANECAL_HISTORY, else planecal.db
                         in the working folder); a database URL for a server
    --no-history         record nothing
    --note TEXT          kept with the entry
    --cell NAME          the cell's name in a history several cells share (default: the
                         scene's name)

The history is opened (and checked: not an input, a writable place, a planecal history of
a version this planecal reads; an older one upgraded) before the command's work: what
fails there is one line, exit 2, nothing done. The entry is written after the work,
whatever its outcome (exit 0 or 1), with the command's provenance: its inputs with their
SHA-256, the scene, the robot and its description's hash, the world the data was made in,
planecal's version, the date. Where the history fails then (locked past the wait, a server
lost), the command's outputs stand and one line says the entry was not written: exit 3
(``NOT_RECORDED``), or a verdict's own exit code (check, compare).
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
    --no-history): a file or a database that is not a planecal history this planecal can
    write, or that cannot be reached or written now, is refused here, in one line (exit 2),
    before anything is done."""
    from planecal.history import History, location

    if args.no_history:
        if args.history or args.note:
            raise InputError("--no-history: nothing is recorded, so --history and --note "
                             "have nowhere to go")
        return None
    check_labels(args)
    return History.open(location(args.history), [i for i in inputs if i is not None], create)


def check_labels(args) -> None:
    """--cell and --note: one line each, within the history's limits (the same on every
    backend), checked before any work."""
    from planecal.history import check_label
    from planecal.history.values import MAX_CELL, MAX_NOTE
    try:
        check_label(getattr(args, "cell", None), "--cell", MAX_CELL)
        check_label(getattr(args, "note", None), "--note", MAX_NOTE)
    except ValueError as e:
        raise InputError(str(e)) from None


def history_files(args) -> list:
    """The history's files, inputs of every command that records (``cli`` hands them to
    the output guard: no output replaces them, --force or not): an SQLite history and the
    files SQLite keeps beside it. None with --no-history or a database URL."""
    from pathlib import Path

    from planecal.history import location
    from planecal.history.place import place_of
    if not hasattr(args, "history") or getattr(args, "no_history", False):
        return []
    path = place_of(location(args.history)).path  # sqlite:///PATH too
    if path is None:
        return []
    return [path] + [Path(f"{path}{s}") for s in ("-wal", "-shm", "-journal")]


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


NOT_RECORDED = 3  # the exit code of a command whose work is done but not recorded


def record(hist, entry, json_out: bool = False) -> int:
    """Write ``entry`` (nothing without a history); the line saying where goes to stdout
    beside the command's other "written to" lines (to stderr where stdout carries JSON,
    ``json_out``). Returns 0, or ``NOT_RECORDED`` where the history failed: one line on
    stderr says why; the command's own outputs are written already and stand (a command
    with a verdict keeps its verdict's exit code)."""
    from planecal.history import HistoryError
    if hist is None:
        return 0
    try:
        n = hist.add(entry)
    except HistoryError as e:
        print(f"planecal: history: not recorded: {e}", file=sys.stderr)
        return NOT_RECORDED
    finally:
        hist.close()
    print(f"history: entry {n} ({entry.kind}: {entry.outcome}) in {hist.label}",
          file=sys.stderr if json_out else sys.stdout)
    if hist.unread is not None:  # recorded, but a lookup during the work had failed
        print(f"planecal: history: not consulted: {hist.unread}", file=sys.stderr)
    return 0


def result_link(hist, path) -> tuple[str, int | None]:
    """(SHA-256 of a result file, the calibrate entry of ``hist`` that wrote it or None)."""
    from planecal.base.paths import file_sha256
    from planecal.history import consult
    sha = file_sha256(path)
    return sha, consult(hist, lambda h: h.find_result(sha), None)


def parameter_rows(doc: dict) -> list:
    """A result document's parameters as the history's rows (by name, SI units)."""
    from planecal.history import ParameterRow
    from planecal.present.calibration import parameter_rows as rows
    return [ParameterRow(r.name, r.value, r.std, r.unit, r.status) for r in rows(doc)]
