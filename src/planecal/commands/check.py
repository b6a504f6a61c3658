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

Prints the verdict (--json: the JSON verdict instead), writes it to --out (format
planecal-check/1), and records it in the cell's history, linked to the calibration entry
that wrote RESULT.json. Exit 0: in control; 1: drifted; 2: bad input.
"""
from __future__ import annotations

from planecal.base.errors import InputError
from planecal.commands.history_options import (add_history_arguments, command_provenance,
                                               consult, new_entry, open_history, record,
                                               result_link, result_scene, sample_worlds)
from planecal.commands.verdict_options import add_verdict_arguments, emit_verdict, verdict_out

MIN_REFERENCE_RUNS = 2


def add_arguments(p):
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
    p.add_argument("--scene", default=None,
                   help="the scene (default: the one the result records)")
    add_history_arguments(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.io_options import Files, scene_inputs, with_sidecars
    from planecal.present.drift import CHECK_FORMAT
    f = Files().read(*with_sidecars([args.run]), args.against,
                     *with_sidecars(args.calibration_samples or []), *scene_inputs(args.scene))
    return f.write(args.out, "--out", CHECK_FORMAT)


def run(args) -> int:
    from planecal.estimation.drift import FittedResult, check_run, parse_suspects
    from planecal.formats.base import read_json
    from planecal.io.params import check_robot, recorded_samples
    from planecal.io.samples import read_many, read_samples
    from planecal.present.drift import CHECK_FORMAT, check_document, check_text
    from planecal.sampling.runfiles import check_run_robot

    given = [args.run, args.against, *(args.calibration_samples or [])]
    out = verdict_out(args, given, CHECK_FORMAT)
    hist = open_history(args, given + [out])
    doc = read_json(args.against, "calibration result")
    scene = result_scene(doc, args.scene)
    check_robot(doc, scene.robot, args.against)
    cal_paths = args.calibration_samples or recorded_samples(doc, args.against,
                                                            "--calibration-samples")
    if not cal_paths:
        raise InputError(f"{args.against}: records no calibration samples; give them with "
                         "--calibration-samples")
    for p in [args.run, *cal_paths]:
        check_run_robot(p, scene.robot)
    fr = FittedResult.of(doc, scene.robot, args.against)
    cal, run_s = read_many(cal_paths, scene), read_samples(args.run, scene)
    if run_s.plate.max(initial=0) >= fr.params.n_planes:
        raise InputError(f"{args.run}: samples on plate {run_s.plate.max() + 1}, the result "
                         f"holds {fr.params.n_planes} plane(s)")
    sha, against = result_link(hist, args.against)
    ref_paths = consult(hist, lambda h: _reference_runs(args, h, against), [])
    refs = [read_samples(p, scene) for p in ref_paths]
    chk = check_run(fr, (cal.qe, cal.d_mm * 1e-3, cal.plate),
                    (run_s.qe, run_s.d_mm * 1e-3, run_s.plate), args.alpha,
                    parse_suspects(args.suspects, fr.layout),
                    [(r.qe, r.d_mm * 1e-3, r.plate) for r in refs])
    verdict = check_document(chk, str(args.run), str(args.against), fr.noise is not None,
                             against, ref_paths)
    emit_verdict(args, verdict, check_text, out)
    prov = command_provenance(scene, [("run", args.run), ("result", args.against),
                                      *(("calibration samples", p) for p in cal_paths),
                                      *(("reference run", p) for p in ref_paths)])
    record(hist, new_entry(args, "check", verdict["verdict"], verdict["exit_code"], prov,
                           robot_sha256=scene.robot.digest, against=against,
                           result_sha256=sha, world=sample_worlds([args.run]),
                           summary=_summary(verdict), document=verdict,
                           output=str(out) if out else None), args.json)
    return verdict["exit_code"]


def _reference_runs(args, hist, against) -> list[str]:
    """The runs of the history's earlier in-control checks against the result's entry
    (here, with the content recorded), when --reference auto finds at least
    MIN_REFERENCE_RUNS of them; else none (the calibration's residuals)."""
    from pathlib import Path

    from planecal.base.paths import file_sha256
    if args.reference != "auto" or hist is None or against is None:
        return []
    here = Path(args.run).resolve()
    found: list[str] = []
    for e in hist.entries(kind="check"):
        if e.against != against or e.outcome != "in_control":
            continue
        for i in hist.get(e.id).inputs:
            p = Path(i.path)
            if (i.role == "run" and p.is_file() and p.resolve() != here
                    and str(p) not in found and file_sha256(p) == i.sha256):
                found.append(str(p))
    return found if len(found) >= MIN_REFERENCE_RUNS else []


def _summary(v: dict) -> dict:
    t = v["test"]
    return {"verdict": v["verdict"], "p_value": t["p_value"], "alpha": t["alpha"],
            "exceedances": t["exceedances"], "run_samples": t["run_samples"],
            "run_rms_mm": v["model_error"]["run_rms_mm"], "moved": v["moved"]}
