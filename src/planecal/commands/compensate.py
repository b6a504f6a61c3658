"""planecal compensate TARGETS --params RESULT.json --out CORRECTED [--samples RUN.tsv...]
[--allow-outside] [--force]

Filter a program (docs/COMPENSATE.md): for each target of TARGETS (a CSV or JSON of flange
poses, joint angles in degrees or encoder counts), the joint target (counts, robot.json's
encoder model: the controller as it is) at which the calibrated model of RESULT.json puts
the flange where the nominal model says the target is. CORRECTED: a tab-separated table
(name, q1..q6) or, ending in .json, the whole record (planecal-compensated/1).

The calibrated region is where the calibration's samples are (--samples, or the sample
files the result's provenance records): the convex hull of their flange positions grown by
50 mm, and the range of each joint they visited grown by 2 deg. Targets outside it are
refused (exit 2), with how far outside; --allow-outside writes them and says so. A result
whose verdict found it no better than a simpler level (estimation.verdict) is refused
without --force. A target whose solve does
not converge fails the run (exit 1) and nothing is written.
"""
from __future__ import annotations

import numpy as np

from planecal.base.errors import InputError, RunFailed


def add_arguments(p):
    p.add_argument("targets", help="targets file: CSV (header x_mm,y_mm,z_mm,rx_deg,ry_deg,"
                                   "rz_deg or q1_deg..q6_deg or q1..q6; optional name) or "
                                   "JSON (planecal-targets/1)")
    p.add_argument("--params", required=True,
                   help="calibration result (planecal calibrate --out; any level)")
    p.add_argument("--out", required=True,
                   help="corrected targets: .json for the whole record, else a tab-separated "
                        "table name, q1..q6 (counts)")
    p.add_argument("--samples", nargs="+", default=None,
                   help="the calibration's sample file(s): the calibrated region (default: "
                        "the files the result's provenance records)")
    p.add_argument("--robot", default="mc70", help="robot description (default %(default)s)")
    p.add_argument("--allow-outside", action="store_true",
                   help="write targets outside the calibrated region too (and say how far)")
    p.add_argument("--frame", choices=["robot", "cell"], default="robot",
                   help="what the targets' coordinates are relative to: the robot's own frame "
                        "(J1's axis and zero, as the controller's programs; default) or the "
                        "calibration's cell frame (its planes')")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier compensate output, and "
                        "use a result whose verdict found it no better than a simpler level")


def _region(args, doc, robot):
    from pathlib import Path

    from planecal.estimation.compensate import Region
    from planecal.io.params import recorded_samples
    from planecal.io.samples import read_samples
    paths = [Path(s) for s in args.samples] if args.samples else recorded_samples(doc, args.params)
    if not paths:
        raise InputError(f"{args.params}: records no sample files (no provenance): give the "
                         "calibration's samples with --samples (they define the calibrated "
                         "region)")
    qe = np.vstack([read_samples(p).qe for p in paths])
    return Region.from_counts(robot, qe, ", ".join(str(p) for p in paths)), paths


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the targets,
    the result, the sample files given or recorded in it, the robot; the corrected
    targets (a record or a counts table)."""
    from planecal.commands.io_options import Files, recorded_inputs, with_sidecars
    from planecal.estimation.compensate import COMPENSATED_FORMAT
    from planecal.io.outputs import COUNTS_TABLE_MARK
    from planecal.model.robot import robot_path
    f = Files().read(args.targets, args.params, robot_path(args.robot),
                     *with_sidecars(args.samples or recorded_inputs(args.params)))
    return f.write(args.out, "--out", (COMPENSATED_FORMAT, COUNTS_TABLE_MARK))


def run(args) -> int:
    from pathlib import Path

    from planecal.commands.controller_options import refuse_worse
    from planecal.estimation.compensate import compensate, load_calibrated
    from planecal.io.targets import read_targets, write_counts_table
    from planecal.present.compensation import compensated_document
    from planecal.io.params import save_json
    from planecal.model.robot import load_robot

    out = Path(args.out)  # checked before the run (``files``)
    robot = load_robot(args.robot)
    model, doc = load_calibrated(robot, args.params)
    refuse_worse(doc, args.params, args.force)
    region, sample_paths = _region(args, doc, robot)
    targets = read_targets(args.targets, robot)
    comp = compensate(model, targets, region, frame=args.frame)
    s = comp.summary()
    bad = [comp.names[i] for i in np.flatnonzero(~comp.converged)]
    if bad:
        raise RunFailed(f"the calibrated model's inverse did not converge for {len(bad)} "
                        f"target(s) ({', '.join(bad[:5])}); nothing written")
    if s["outside"]:
        far = []
        if s["max_outside_mm_target"] is not None:
            far.append(f"{s['max_outside_mm_target']} {s['max_outside_mm']:.0f} mm beyond the "
                       "samples' flange positions")
        if s["max_outside_target"] is not None:
            far.append(f"{s['max_outside_target']} {s['max_outside_deg']:.2f} deg beyond J"
                       f"{s['max_outside_joint']}'s sampled range")
        what = (f"{s['outside']} of {s['targets']} targets lie outside the calibrated region "
                f"of {region.samples} samples (the furthest: {'; '.join(far)})")
        if not args.allow_outside:
            raise InputError(f"{args.targets}: {what}: refused (--allow-outside writes them)")
    lines = [f"compensated {s['targets']} targets with the {model.level} model of {args.params}",
             f"calibrated region: the flange positions and joint ranges of {region.samples} "
             f"samples, grown by {region.margin_m * 1e3:.0f} mm and "
             f"{np.degrees(region.margin_rad):.0f} deg ({region.source})",
             "max |correction| per joint: counts " + " ".join(f"{v:d}" for v in
                                                               s["max_correction_counts"])
             + "; mrad " + " ".join(f"{v:.3f}" for v in s["max_correction_mrad"]),
             f"solve: converged in <= {s['max_iterations']} iterations, residual <= "
             f"{s['max_residual_mm'] * 1e3:.2g} um, {s['max_residual_mrad'] * 1e3:.2g} urad; "
             f"at whole counts <= {s['max_rounded_residual_mm'] * 1e3:.1f} um, "
             f"{s['max_rounded_residual_mrad'] * 1e3:.1f} urad"]
    if s["outside"]:
        lines.append(f"WARNING {what} (--allow-outside): the calibration is not known there")
    print("\n".join(lines))
    if out.suffix.lower() == ".json":
        save_json(out, compensated_document(
            comp, model, region, {"targets": str(args.targets), "params": str(args.params),
                                  "samples": [str(p) for p in sample_paths]}, args.frame))
    else:
        write_counts_table(out, comp)
    print(f"corrected targets written to {out}")
    return 0
