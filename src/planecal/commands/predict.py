"""planecal predict SAMPLES --params P.json

Prints a header row (index, measured_mm, predicted_mm, error_mm) and one tab-separated line
per sample: the model error is predicted - measured, the one sign of planecal
(docs/FORMATS.md). Index is 0-based over the samples kept (laser zeros are skipped, as in
calibrate). A result made
for another robot than --robot is refused.
"""
from __future__ import annotations

import sys

from planecal.model.measurement import predict
from planecal.base.errors import InputError
from planecal.io.params import load_params
from planecal.model.robot import load_robot
from planecal.io.samples import read_samples


HEADER = ("index", "measured_mm", "predicted_mm", "error_mm")


def add_arguments(p):
    p.add_argument("samples", help="sample file, seed format (7.1.4)")
    p.add_argument("--params", required=True, help="parameter file (JSON)")
    p.add_argument("--robot", default="mc70", help="robot description (default %(default)s)")
    p.add_argument("--scene", default=None,
                   help="scene whose laser window and plates the samples are checked against, "
                        "as calibrate checks them (default: thesis_final, or with --robot "
                        "none: any reading up to the format's bound)")


def run(args) -> int:
    from planecal.model.scene import DEFAULT_SCENE, load_scene
    name = args.scene or (DEFAULT_SCENE if args.robot == "mc70" else None)
    s = read_samples(args.samples, load_scene(name) if name else None)
    robot = load_robot(args.robot)
    params = load_params(args.params, robot)
    if s.plate.max() >= params.n_planes:
        raise InputError(f"{args.samples}: samples refer to plate {s.plate.max() + 1}, "
                         f"{args.params} holds {params.n_planes} plane(s)")
    d = predict(robot, s.qe, params, s.plate) * 1e3
    out = sys.stdout
    out.write("\t".join(HEADER) + "\n")
    for i, (m, p) in enumerate(zip(s.d_mm, d)):
        out.write(f"{i}\t{m:.4f}\t{p:.4f}\t{p - m:.4f}\n")
    return 0
