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
column, or on plate 1. Without --initial the default scene's nominal values (the thesis
cell's measured initial values) are the starting point. Readings outside the scene's laser
window are refused. --out is checked before the fit (not an input, a writable place, not
a file other than an earlier result unless --force) and records the inputs with their
SHA-256 (provenance).

The calibration is recorded in the cell's history (``--history``, default planecal.db in
the working folder; docs/HISTORY.md) with its result and provenance, whatever its outcome.

Exit 0 when the fit converged and identified every free parameter; 1 when it did not (the
report and --out are still written, with the reason in one line); 2 on bad input.
"""

from __future__ import annotations

from planecal.base.errors import RunFailed
from planecal.commands.calibration_options import (add_calibration_arguments,
                                                   add_fit_arguments, calibration_settings,
                                                   fit_options, load_inputs)
from planecal.commands.history_options import (add_history_arguments, new_entry, open_history,
                                               parameter_rows, record, sample_worlds)
from planecal.commands.report_options import add_report_argument, write_command_report
from planecal.base.paths import DEFAULT_SCENE
from planecal.formats.params import RESULT_FORMAT, provenance, result_document


def add_arguments(p):
    p.add_argument("samples", nargs="+", help="sample file(s), seed format (7.1.4)")
    p.add_argument("--initial", help="initial parameter file (JSON); default: the scene's "
                                     "nominal values")
    p.add_argument("--scene", default=DEFAULT_SCENE,
                   help="scene for the nominal values and robot (default %(default)s)")
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
    from planecal.commands.io_options import (Files, report_output, rrd_output, scene_inputs,
                                              with_sidecars)
    f = Files().read(*with_sidecars(args.samples), args.initial, *scene_inputs(args.scene))
    f.write(args.out, "--out", RESULT_FORMAT)
    report_output(f, args.report, "--report")
    rrd_output(f, args.rrd)
    return f


def run(args) -> int:
    from planecal.estimation.accuracy import of_samples
    from planecal.estimation.calibrate import calibrate_samples
    from planecal.io.params import save_json
    from planecal.present.calibration import document, text

    inputs = [("samples", p) for p in args.samples] + (
        [("initial", args.initial)] if args.initial else [])
    out = args.out  # checked before the run (``files``)
    hist = open_history(args, [p for _, p in inputs] + [out])
    samples, scene, initial = load_inputs(args.samples, args.scene, args.initial)
    settings = calibration_settings(args, scene.robot, fit_options(args, scene.robot))
    cal = calibrate_samples(scene.robot, samples, initial, settings, scene.references)
    doc = result_document(document(cal, scene.robot, of_samples(scene, cal, samples)), provenance(
        inputs + [("scene", scene.path), ("robot", scene.robot.source)], scene.name,
        scene.robot.name))
    print(text(doc, samples.n_zero))
    if out:
        save_json(out, doc)
        print(f"result written to {out}")
    write_command_report(args.report, out or doc, samples=args.samples, scene=str(scene.path))
    if args.rrd:
        from planecal.present.rerun import log_fit_to_file
        path = log_fit_to_file(args.rrd, cal, samples, scene)
        print(f"recording written to {path}")
    why = cal.failure()
    record(hist, _entry(args, doc, out, why))
    if why:
        raise RunFailed(why)
    return 0


def _entry(args, doc: dict, out, why: str | None):
    """The history's record of this calibration: the result document, its parameters by
    name, the result file written (and its SHA-256), the world of its samples."""
    from planecal.base.paths import file_sha256
    summary = {"level": doc["level"], "compliance": doc["compliance"],
               "samples_used": doc["samples_used"], "residual_rms_mm": doc["residual_rms_mm"],
               "converged": doc["converged"], "failure": why}
    return new_entry(args, "calibrate", "failed" if why else "ok", 1 if why else 0,
                     doc["provenance"], robot_sha256=(doc.get("robot") or {}).get("sha256"),
                     world=sample_worlds(args.samples), summary=summary, document=doc,
                     parameters=parameter_rows(doc), output=str(out) if out else None,
                     result_sha256=file_sha256(out) if out else None)
