"""planecal predict SAMPLES --params P.json [--scene S] [--robot R]

Prints a header row (index, measured_mm, predicted_mm, error_mm) and one tab-separated
line per sample (the model error, predicted - measured: the one sign of planecal, docs/FORMATS.md). Index
is 0-based over the samples kept (laser zeros are skipped, as in calibrate). The cell is
the run's (its sidecar) and the result's (its provenance), else --scene, else
thesis_final; a --scene or --robot that contradicts them, and a result made for another
robot, are refused.
"""
from __future__ import annotations


def add_arguments(p):
    from planecal.commands.cell_options import add_scene_argument
    p.add_argument("samples", help="sample file, seed format (7.1.4)")
    p.add_argument("--params", required=True, help="parameter file (JSON)")
    add_scene_argument(p, "the robot, laser window and plates the samples are checked "
                          "against", reads="the run's sidecar and --params' provenance")
    p.add_argument("--robot", default=None, metavar="NAME|DIR",
                   help="the robot the samples must be of (default: the cell's; another "
                        "is refused)")


def run(args) -> int:
    from planecal.jobs.predict import predict
    return predict(args.samples, args.params, args.scene, args.robot)
