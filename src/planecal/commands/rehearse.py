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
import os

from planecal.base.errors import InputError
from planecal.commands.value_options import seed


def add_arguments(p: argparse.ArgumentParser) -> None:
    from planecal.commands.sampling_options import add_sampling_arguments

    add_sampling_arguments(p)
    add_errors_argument(p)
    p.add_argument("--truth-out", dest="truth", default=None, metavar="TRUTH.json",
                   help="write the twin's hidden truth here (parameter-file format, with the "
                        "robot's true geometry)")
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


def make_twin(scene, seed: int, errors: str, exact: bool = False):
    """The twin of the error profile ``errors`` for ``seed`` (exact: no random noise)."""
    from dataclasses import replace

    from planecal.twin import Twin
    from planecal.twin.profile import draw_world, load_profile

    world, opts = draw_world(scene, seed, load_profile(errors, scene.robot))
    if exact:
        opts = replace(opts, servo="ideal", laser_noise_mm=0.0, repeatability_mm=0.0,
                       quantization=False)
    return Twin(scene, truth=world, seed=seed, options=opts)


def make_checker(scene, clearance_m: float):
    from planecal.safety.collision import CollisionWorld
    return CollisionWorld(scene, clearance_m=clearance_m)


def run(args) -> int:
    from planecal.commands.sampling_options import (command_model, fixed_distance_summary,
                                                    pose_list_planner, prepare, rerun_observer,
                                                    session_from_args)
    from planecal.links.base import AlwaysEnabled
    from planecal.sampling.session import print_summary, run_session
    from planecal.twin.profile import DEFAULT_PROFILE, save_truth

    scene, settings, side = prepare(args, also_out={"--truth-out": args.truth})
    if side is not None:
        twin_info = side.get("twin") or {}
        twin_seed = int(twin_info.get("seed", settings.seed))
        exact = bool(twin_info.get("exact", False))
        errors = twin_info.get("errors", "ideal")  # runs before profiles: the ideal world
        if args.errors is not None and args.errors != errors:
            raise InputError(f"--errors {args.errors}: the run in {args.out} was sampled in "
                             f"the {errors} world; --resume continues it there")
    else:
        twin_seed = settings.seed if args.twin_seed is None else args.twin_seed
        exact = args.exact
        errors = args.errors or DEFAULT_PROFILE
    twin = make_twin(scene, twin_seed, errors, exact)
    checker = make_checker(scene, settings.clearance_m)
    if args.truth:
        try:
            save_truth(args.truth, twin)
        except OSError as e:
            raise InputError(f"--truth-out {args.truth}: cannot write ({e.strerror})") from None
    observer = rerun_observer(args.rrd, scene, twin) if args.rrd else None
    model = command_model(args, scene, side)
    session = session_from_args(args, pose_list_planner(args, scene, settings, checker, model[0]),
                                observer, extra={"twin": {"seed": twin_seed, "exact": exact,
                                                          "errors": str(errors)}},
                                model=model)
    try:
        code, summary = run_session(session, scene, settings, twin, twin, AlwaysEnabled(),
                                    checker)
    finally:
        if observer is not None:
            observer.close()
        twin.close()
    wall = summary["session_wall_time_s"]
    robot_s = summary["session_robot_time_s"]
    summary["speedup"] = round(robot_s / wall, 1) if wall > 0 else None
    summary["twin_seed"] = twin_seed
    summary["errors"] = str(errors)
    if args.foreground:
        summary["collision"] = checker.summary()
    summary["cpu_count"] = os.cpu_count()
    if args.truth:
        summary["truth"] = str(args.truth)
    if settings.pose.fixed_distance_mm is not None:
        summary["fixed_distance"] = fixed_distance_summary(args.out, settings, model[1])
    if args.rrd:
        summary["rrd"] = str(observer.path)
    print_summary(summary)
    return code
