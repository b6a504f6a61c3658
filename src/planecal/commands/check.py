"""planecal check RUN.tsv --against RESULT.json [--calibration-samples FILE...] [--alpha A]
[--suspects NAMES] [--scene S] [--out VERDICT.json [--force]] [--json] [--history DB]
[--no-history] [--note TEXT] [--cell NAME]

Has the cell drifted since the calibration RESULT.json? A short run (a few dozen random
poses, ``rehearse`` or ``sample``) is predicted with the result's parameters and its
model errors are tested against the result's own model errors on its calibration samples
(found through the result's provenance, checked by their SHA-256, or given with
--calibration-samples): the exceedance test (a distribution-free two-sample median test
with each error studentized by its pose's leverage; ``planecal.estimation.drift``,
docs/HISTORY.md). Once the history holds earlier in-control checks of this result (at
least two, their run files here and unchanged), their runs are the reference instead
(--reference auto, the default; --reference calibration keeps the calibration's):
one calibration's residual scale is a single draw, later runs of the same result are
alike. The false-alarm rate is at most --alpha (default 0.01); the attained
rate is printed. Its null hypothesis assumes the run's poses are drawn as the
calibration's were (random poses on the same plates): a planned pose list of extreme
poses errs otherwise.

When the run drifted, each suspect (default: the six joint offsets; --suspects names
others, e.g. o_x,n1_z) is fitted alone to the run with the rest held at the result's
values: the amount (the run's value minus the result's) in robot terms (J3 (delta3),
mrad) with its std, the significant ones named, the best explanation first.

The run, the result and its calibration samples are read in their one cell (the runs'
sidecars, the result's provenance; a --scene that names another is refused).

Prints the verdict (--json: the JSON verdict instead), writes it to --out (format
planecal-check/1), and records it in the cell's history, linked to the calibration entry
that wrote RESULT.json. Exit 0: in control; 1: drifted; 2: bad input.
"""
from __future__ import annotations

from planecal.commands.history_options import (add_history_arguments, command_provenance,
                                               new_entry, open_history, record, result_link)
from planecal.commands.verdict_options import add_verdict_arguments, emit_verdict, verdict_out
from planecal.jobs.verdicts import MIN_REFERENCE_RUNS


def add_arguments(p):
    from planecal.commands.cell_options import add_scene_argument
    p.add_argument("run", metavar="RUN.tsv", help="the short run's sample file")
    p.add_argument("--against", required=True, metavar="RESULT.json",
                   help="the calibration result (planecal calibrate --out)")
    p.add_argument("--calibration-samples", nargs="+", default=None, metavar="FILE",
                   help="the result's calibration samples (default: the files its provenance "
                        "records, checked by their SHA-256)")
    add_verdict_arguments(p, "the false-alarm rate the test may not exceed",
                          "parameters to fit one at a time to a drifted run (default: the "
                          "joint offsets delta1..delta6)")
    p.add_argument("--reference", choices=("auto", "calibration"), default="auto",
                   help="the test's reference: auto (the runs of this result's earlier "
                        "in-control checks in the history, once there are at least "
                        f"{MIN_REFERENCE_RUNS}, here and unchanged; else the calibration's "
                        "residuals) or calibration (default %(default)s)")
    add_scene_argument(p, "the run and the result", reads="the runs' sidecars and the result's provenance")
    add_history_arguments(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.cell_options import result_scene_inputs
    from planecal.commands.io_options import Files, with_sidecars
    from planecal.present.drift import CHECK_FORMAT
    f = Files().read(*with_sidecars([args.run]), args.against,
                     *with_sidecars(args.calibration_samples or []),
                     *result_scene_inputs(args.against, args.scene))
    return f.write(args.out, "--out", CHECK_FORMAT)


def run(args) -> int:
    from planecal.jobs.verdicts import CheckRequest, check
    from planecal.present.drift import CHECK_FORMAT, check_text

    given = [args.run, args.against, *(args.calibration_samples or [])]
    out = verdict_out(args, given, CHECK_FORMAT)
    hist = open_history(args, given + [out])
    sha, against = result_link(hist, args.against)
    done = check(CheckRequest(args.run, args.against, args.calibration_samples, args.alpha,
                              args.suspects, args.reference, args.scene), hist, against)
    verdict = done.verdict
    emit_verdict(args, verdict, check_text, out)
    prov = command_provenance(done.result.scene, [
        ("run", args.run), ("result", args.against),
        *(("calibration samples", p) for p in done.calibration_paths),
        *(("reference run", p) for p in done.reference_paths)])
    record(hist, new_entry(args, "check", verdict["verdict"], verdict["exit_code"], prov,
                           robot_sha256=done.result.scene.robot.digest, against=against,
                           result_sha256=sha, world=done.world,
                           summary=_summary(verdict), document=verdict,
                           output=str(out) if out else None), args.json)
    return verdict["exit_code"]


def _summary(v: dict) -> dict:
    t = v["test"]
    return {"verdict": v["verdict"], "p_value": t["p_value"], "alpha": t["alpha"],
            "exceedances": t["exceedances"], "run_samples": t["run_samples"],
            "run_rms_mm": v["model_error"]["run_rms_mm"], "moved": v["moved"]}
