"""planecal report RESULT.json --out DIR [--samples RUN.tsv ...] [--scene S]

A report a person reads: DIR/index.html with PNG figures beside it, for a calibration
result (calibrate --out, demo's result.json), a Monte Carlo, bootstrap, validate or plan
result. The kind comes from the file (its format field, else its content). A calibration
report recomputes the model error per sample from the sample files (--samples, or the
inputs the result records). See planecal.present.report.
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
    p.add_argument("--scene", default=None,
                   help="scene for the robot, plate names and nominal values (default: the "
                        "result's, else thesis_final)")


def run(args) -> int:
    from planecal.present.report import write_report
    path = write_report(args.result, args.out, samples=args.samples, scene=args.scene)
    n = path.read_text(encoding="utf-8").count("<img ")
    print(f"report written to {path} ({n} figures)")
    return 0
