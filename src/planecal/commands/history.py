"""planecal history list | show N | diff A B | rollback N   [--history DB] ...

The cell's history (docs/HISTORY.md): every calibrate, validate, export, check, compare and
rollback, recorded with its provenance in one database (``--history``: an SQLite file,
default planecal.db in the working folder or $PLANECAL_HISTORY, or a database URL).

    list [--cell NAME] [--kind KIND]   one line per entry, oldest first
    show N [--json]                    entry N in full: provenance, world, parameters
    diff A B [--alpha 0.01]            two calibrations, parameter by parameter: the change
                                       B - A against both results' std, the significant
                                       ones flagged (``estimation.drift.parameter_changes``)
    rollback N [--format ...] [--out FILE]
                                       the controller file of calibration N (the writer of
                                       ``planecal export``), recorded as a rollback entry

``--json`` prints list, show and diff as JSON. Exit 0; 2 for an entry that is not there
or not a calibration where one is needed.
"""
from __future__ import annotations

import json

from planecal.base.errors import InputError
from planecal.commands.controller_options import add_controller_arguments, current_qe0
from planecal.commands.value_options import count

ACTIONS = ("list", "show", "diff", "rollback")


def add_arguments(p):
    from planecal.history import KINDS
    p.add_argument("action", choices=ACTIONS, help="list, show N, diff A B, rollback N")
    p.add_argument("entries", nargs="*", type=count(10**12), metavar="N", help="entry numbers")
    p.add_argument("--history", metavar="FILE|URL", default=None,
                   help="the history (default: $PLANECAL_HISTORY, else planecal.db in the "
                        "working folder)")
    p.add_argument("--cell", default=None, metavar="NAME",
                   help="list: only this cell's entries; rollback: the cell recorded")
    p.add_argument("--kind", choices=KINDS, default=None, help="list: only this kind")
    p.add_argument("--json", action="store_true", help="list, show, diff: print JSON")
    p.add_argument("--alpha", type=float, default=0.01,
                   help="diff: the family-wise false-alarm rate of the flags (default "
                        "%(default)s)")
    p.add_argument("--note", default=None, metavar="TEXT", help="rollback: a note kept with it")
    p.add_argument("--scene", default=None,
                   help="rollback: the scene (default: the one the calibration records)")
    g = p.add_argument_group("rollback: the controller file (as planecal export writes it)")
    add_controller_arguments(g)


_COUNTS = {"list": 0, "show": 1, "diff": 2, "rollback": 1}


def files(args):
    """What the output guard checks before the run (``commands.io_options``): rollback's
    controller file."""
    from planecal.commands.io_options import Files, scene_inputs
    from planecal.io.outputs import YAML_MARK
    from planecal.present.controller import FORMAT, OFFSETS_FORMAT
    f = Files().read(*(scene_inputs(args.scene) if args.scene else []))
    return f.write(args.out, "--out", (FORMAT, OFFSETS_FORMAT, YAML_MARK))


def run(args) -> int:
    from planecal.commands.history_options import check_labels
    from planecal.history import History, location

    want = _COUNTS[args.action]
    if len(args.entries) != want:
        raise InputError(f"history {args.action}: takes {want} entry number(s), got "
                         f"{len(args.entries)}")
    if args.action != "rollback":
        for flag in ("format", "out", "current_qe0", "note", "scene"):
            if getattr(args, flag):
                raise InputError(f"--{flag.replace('_', '-')}: only for history rollback")
    out = args.out if args.action == "rollback" else None  # checked before the run (files)
    if args.action == "rollback":
        check_labels(args)
    hist = History.open(location(args.history), [out], create=args.action == "rollback",
                        new=False)
    try:
        return {"list": _list, "show": _show, "diff": _diff,
                "rollback": _rollback}[args.action](args, hist, out)
    finally:
        hist.close()


def _list(args, hist, _out) -> int:
    from planecal.present.history import entry_document, list_text
    entries = hist.entries(args.cell, args.kind)
    if args.json:
        print(json.dumps([entry_document(e) for e in entries], indent=2))
    else:
        print(list_text(entries, hist.label))
    return 0


def _show(args, hist, _out) -> int:
    from planecal.present.history import entry_document, show_text
    e = hist.get(args.entries[0])
    print(json.dumps(entry_document(e), indent=2) if args.json else show_text(e, hist.label))
    return 0


def _calibration(hist, n: int):
    e = hist.get(n)
    if e.kind != "calibrate" or not isinstance(e.document, dict) and not e.problems:
        raise InputError(f"history {hist.label}: entry {n} is a {e.kind}, not a calibration")
    if e.problems:
        raise InputError(f"history {hist.label}: entry {n} holds what planecal does not write "
                         f"({'; '.join(e.problems[:2])}): it cannot be used (history show "
                         f"{n} says what)")
    return e


def _diff(args, hist, _out) -> int:
    from planecal.estimation.drift import parameter_changes
    from planecal.present.drift import diff_document, diff_text
    a, b = (_calibration(hist, n) for n in args.entries)
    changes, limit = parameter_changes({p.name: (p.value, p.std) for p in a.parameters},
                                       {p.name: (p.value, p.std) for p in b.parameters},
                                       args.alpha)
    if args.json:
        print(json.dumps(diff_document(a.id, b.id, changes, limit, args.alpha), indent=2))
    else:
        print(diff_text(a.id, b.id, changes, limit, args.alpha))
    if a.robot_sha256 and b.robot_sha256 and a.robot_sha256 != b.robot_sha256:
        print(f"note: entries {a.id} and {b.id} were made for different robot descriptions")
    return 0


def _rollback(args, hist, out) -> int:
    """Calibration N's controller file, with export's writer; a rollback entry."""
    from planecal.commands.history_options import command_provenance, new_entry, record
    from planecal.jobs.exports import write_controller
    from planecal.jobs.results import CalibrationResult
    from planecal.present.controller import ControllerFile

    e = _calibration(hist, args.entries[0])
    where = f"history entry {e.id}"
    result = CalibrationResult.from_document(e.document, where, args.scene)
    req = ControllerFile(args.format, out, current_qe0(args.current_qe0), where,
                         e.result_sha256 or "0" * 64)
    written = write_controller(result, req, args.force)
    scene = result.scene
    prov = command_provenance(scene, [])
    return record(hist, new_entry(args, "rollback", "ok", 0, prov,
                                  robot_sha256=scene.robot.digest, against=e.id,
                                  result_sha256=e.result_sha256, summary=written,
                                  output=str(out) if out else None, world=e.world))
