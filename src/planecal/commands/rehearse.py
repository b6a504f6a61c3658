"""`planecal rehearse`: a whole sampling run (seed 7.1) on the MuJoCo twin.

    planecal rehearse [--scene S] [--samples N] [--seed K] [--cone-deg A]
                      [--fixed-distance-mm D] --out RUN.tsv [--truth-out TRUTH.json]
                      [--rrd FILE] [--resume]

The same loop as ``planecal sample`` (``planecal.sampling.run``), with the twin as robot
link and laser, on its virtual clock (no sleeps), and collision checking always on
(``planecal.safety.collision.CollisionWorld``). The twin's hidden truth is drawn from
``--twin-seed`` (default: ``--seed``); ``--truth-out`` writes it in the parameter-file format
(``planecal.io.params``) for comparison with a calibration. The twin starts at the scene's
calibration position.

Writes the sample file, its sidecar ``RUN.tsv.json`` (with ``"twin": {"seed", "options"}``
so ``--resume`` rebuilds the same twin), shows progress on stderr, and prints a JSON
summary on stdout: samples, rejected_collision, rejected_laser, rejected_unreachable,
max_step_counts, robot_time_s, wall_time_s (over all sessions of the run), speedup (this
session's robot time over its wall time), ...
Exit 0 when all samples were taken, 1 when the run stopped or gave up (files valid).
"""
from __future__ import annotations

import argparse

from planecal.commands.value_options import seed


def add_arguments(p: argparse.ArgumentParser) -> None:
    from planecal.commands.sampling_options import add_sampling_arguments

    add_sampling_arguments(p)
    add_errors_argument(p)
    p.add_argument("--truth", dest="truth_in", default=None, metavar="TRUTH.json",
                   help="run in the world of this truth file (one --truth-out wrote, or edited "
                        "by hand, e.g. to inject a drift): its cell, the robot's true "
                        "geometry and phases, and its error profile")
    p.add_argument("--truth-out", dest="truth_out", default=None, metavar="TRUTH.json",
                   help="write the twin's hidden truth here (parameter-file format, with the "
                        "robot's true geometry and the world it was drawn in)")
    p.add_argument("--twin-seed", type=seed, default=None,
                   help="seed of the twin's hidden truth and noise (default: --seed)")
    p.add_argument("--exact", action="store_true",
                   help="no random noise (ideal servo, no laser noise, repeatability or "
                        "quantisation); the profile's systematic errors stay")


def add_errors_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--errors", default=None, metavar="ideal|realistic|FILE.json",
                   help="the twin's error profile: realistic (default: a robot of the MC70's "
                        "class), ideal (the nominal robot), or a profile file (copy "
                        "models/mc70/errors/realistic.json and edit it)")


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the run's
    files (``sampling_options.run_files``), the truth read and the truth written."""
    from planecal.commands.io_options import profile_inputs
    from planecal.commands.sampling_options import run_files
    from planecal.io.params import PARAMS_FORMAT
    f = run_files(args).read(args.truth_in, *profile_inputs(args.errors, args.scene))
    return f.write(args.truth_out, "--truth-out", PARAMS_FORMAT)


def run(args) -> int:
    from planecal.commands.sampling_options import sampling_request
    from planecal.jobs.rehearse import RehearseRequest, rehearse

    return rehearse(RehearseRequest(sampling_request(args), args.errors, args.truth_in,
                                    args.truth_out, args.twin_seed, args.exact))
