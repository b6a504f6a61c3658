"""planecal calibrate SAMPLES... [--initial P.json] [--out R.json] [--max-iter N]
[--improvement-limit X] [--outlier-sigma K] [--method gn|lm] [--free NAMES]
[--level offsets|full|nonkinematic] [--compliance] [--geometry-prior MM,MRAD]
[--weighted [--repeatability-mm R] [--distance-sigma-um S]] [--rrd FILE]
[--history DB] [--no-history] [--note TEXT] [--cell NAME]

The one calibration (planecal.estimation.calibrate), with the options every command that
calibrates takes (commands.calibration_options). --level offsets (default) is the seed's
level 1 (joint offsets, sensor, planes); --level full the whole kinematic model. The
parameters the samples can identify are chosen from their Jacobian (a pivoted QR,
planecal.estimation.identifiability), the others stay at their initial values and the
report and the result file name each with its reason. --compliance adds the joint
compliance of J2 and J3 (gravity torque from robot.json's link masses). --free overrides
the candidates.

Several sample files may be given; a file's samples are on the plate named in its 8th
column, or on plate 1. The cell is the one the runs' sidecars record (they must agree; a
--scene that names another is refused; a file without a sidecar takes --scene, else the
others' cell, else thesis_final: ``planecal.jobs.runs``). Without --initial the cell's
nominal values are the starting point. Readings outside the cell's laser window are
refused. --out is checked before the fit (not an input, a writable place, not
a file other than an earlier result unless --force) and records the inputs with their
SHA-256 (provenance).

The calibration is recorded in the cell's history (``--history``, default planecal.db in
the working folder; docs/HISTORY.md) with its result and provenance, whatever its outcome.

Exit 0 when the fit converged and identified every free parameter; 1 when it did not (the
report and --out are still written, with the reason in one line, and the result's
``status`` says so: ``not_identifiable`` or ``max_iterations``, which export and urdf
refuse); 2 on bad input. The pipeline is ``planecal.jobs.calibrate``: the demo and the
Python API take the same.
"""

from __future__ import annotations

from planecal.base.errors import RunFailed
from planecal.commands.calibration_options import (add_calibration_arguments,
                                                   add_fit_arguments, calibration_settings,
                                                   fit_options)
from planecal.commands.cell_options import add_scene_argument, run_scene_inputs
from planecal.commands.history_options import (add_history_arguments, new_entry, open_history,
                                               parameter_rows, record)
from planecal.commands.report_options import add_report_argument
from planecal.formats.params import RESULT_FORMAT


def add_arguments(p):
    p.add_argument("samples", nargs="+", help="sample file(s), seed format (7.1.4)")
    p.add_argument("--initial", help="initial parameter file (JSON); default: the scene's "
                                     "nominal values")
    add_scene_argument(p, "the nominal values and robot", "the runs' sidecars")
    p.add_argument("--out", help="write the result (JSON) here")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier result file")
    add_calibration_arguments(p)
    add_fit_arguments(p)
    add_report_argument(p)
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="write a Rerun recording of the fit (a file name, a directory, or "
                        "'auto' for recordings/calibrate-<scene>-<time>.rrd)")
    add_history_arguments(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.io_options import Files, report_output, rrd_output, with_sidecars
    f = Files().read(*with_sidecars(args.samples), args.initial,
                     *run_scene_inputs(args.samples, args.scene))
    f.write(args.out, "--out", RESULT_FORMAT)
    report_output(f, args.report, "--report")
    rrd_output(f, args.rrd)
    return f


def run(args) -> int:
    from planecal.jobs.calibrate import CalibrateRequest, calibrate_files

    hist = open_history(args, [*args.samples, args.initial, args.out])
    done = calibrate_files(CalibrateRequest(
        tuple(args.samples), lambda robot: calibration_settings(args, robot,
                                                                fit_options(args, robot)),
        args.scene, args.initial, args.out, args.report, args.rrd))
    why = done.failure()
    unrecorded = record(hist, _entry(args, done, why))
    if why:
        raise RunFailed(why)
    return unrecorded


def _entry(args, done, why: str | None):
    """The history's record of this calibration: the result document, its parameters by
    name, the result file written (and its SHA-256), the world of its samples."""
    from planecal.base.paths import file_sha256
    doc, out = done.doc, args.out
    summary = {"level": doc["level"], "compliance": doc["compliance"],
               "samples_used": doc["samples_used"], "residual_rms_mm": doc["residual_rms_mm"],
               "converged": doc["converged"], "failure": why}
    return new_entry(args, "calibrate", "failed" if why else "ok", 1 if why else 0,
                     doc["provenance"], robot_sha256=(doc.get("robot") or {}).get("sha256"),
                     world=done.runs.record(), summary=summary, document=doc,
                     parameters=parameter_rows(doc), output=str(out) if out else None,
                     result_sha256=file_sha256(out) if out else None)
