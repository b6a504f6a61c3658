"""planecal report RESULT.json --out DIR [--samples RUN.tsv ...] [--scene S]

A report a person reads: DIR/index.html with PNG figures beside it, for a calibration
result (calibrate --out, demo's result.json), a Monte Carlo, bootstrap, validate or plan
result. The kind comes from the file (its format field, else its content). A calibration
report recomputes the model error per sample from the sample files (--samples, or the
inputs the result records), in the cell the result and the runs record (a --scene that
contradicts it is refused). See planecal.present.report and planecal.jobs.report.
"""
from __future__ import annotations


def add_arguments(p):
    p.add_argument("result", help="result file (JSON) written by calibrate, demo, montecarlo, "
                                  "bootstrap, validate or plan")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="report directory (created): index.html and PNG figures")
    p.add_argument("--samples", nargs="+", metavar="RUN.tsv",
                   help="a calibration's sample file(s), in the order given to calibrate "
                        "(default: the inputs the result records)")
    from planecal.commands.cell_options import add_scene_argument
    add_scene_argument(p, "the robot, plate names and nominal values",
                       "the result's provenance and its runs' sidecars")
    p.add_argument("--force", action="store_true",
                   help="write into DIR even if it holds files planecal did not write (never "
                        "over an input)")


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the result,
    the sample files given or recorded in its provenance, the scene; the report folder."""
    from planecal.commands.io_options import (Files, recorded_inputs, report_output,
                                              scene_inputs)
    f = Files().read(args.result, *(args.samples or recorded_inputs(args.result)))
    f.read(*scene_inputs(args.scene) if args.scene else [])
    report_output(f, args.out, "--out")
    return f


def run(args) -> int:
    from planecal.jobs.report import report
    path = report(args.result, args.out, samples=args.samples, scene=args.scene)
    n = path.read_text(encoding="utf-8").count("<img ")
    print(f"report written to {path} ({n} figures)")
    return 0
