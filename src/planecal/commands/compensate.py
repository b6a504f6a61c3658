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
refused (exit 2), with how far outside; --allow-outside writes them and says so. A target whose solve does
not converge fails the run (exit 1) and nothing is written. The robot is the one of the
result's cell (its provenance); a result that is not a calibration (its fit did not
converge or could not identify a free parameter) is refused, nothing written, unless
--force.
"""
from __future__ import annotations


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
    p.add_argument("--robot", default=None, metavar="NAME|DIR",
                   help="the robot the result must be of (default: the one its cell records; "
                        "another is refused)")
    p.add_argument("--allow-outside", action="store_true",
                   help="write targets outside the calibrated region too (and say how far)")
    p.add_argument("--frame", choices=["robot", "cell"], default="robot",
                   help="what the targets' coordinates are relative to: the robot's own frame "
                        "(J1's axis and zero, as the controller's programs; default) or the "
                        "calibration's cell frame (its planes')")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier compensate output, and "
                        "compensate with a result that is not a calibration (said on stderr)")


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the targets,
    the result, the sample files given or recorded in it, the result's cell; the corrected
    targets (a record or a counts table)."""
    from planecal.commands.cell_options import result_scene_inputs
    from planecal.commands.io_options import Files, recorded_inputs, with_sidecars
    from planecal.estimation.compensate import COMPENSATED_FORMAT
    from planecal.io.outputs import COUNTS_TABLE_MARK
    f = Files().read(args.targets, args.params, *result_scene_inputs(args.params, None),
                     *with_sidecars(args.samples or recorded_inputs(args.params)))
    return f.write(args.out, "--out", (COMPENSATED_FORMAT, COUNTS_TABLE_MARK))


def run(args) -> int:
    from planecal.jobs.exports import CompensateRequest, compensate
    compensate(CompensateRequest(args.targets, args.params, args.out,
                                 None if args.samples is None else tuple(args.samples),
                                 args.robot, args.allow_outside, args.frame, args.force))
    return 0
