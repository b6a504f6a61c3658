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


def world_ref(args, side, seed: int):
    """The world the run is made in (``twin.world.WorldRef``): a resumed run's (its sidecar
    names it; a flag that contradicts it is refused), or the truth file's (--truth), or the
    error profile's draw for --twin-seed (default --seed)."""
    from planecal.twin.profile import DEFAULT_PROFILE, truth_file_errors
    from planecal.twin.world import WorldRef, file_sha256
    if side is not None:
        t = side.get("twin") or {}
        ref = WorldRef(str(t.get("errors", "ideal")),  # runs before profiles: the ideal world
                       None if t.get("truth_file") else int(t.get("seed", seed)),
                       t.get("truth_file"), t.get("truth_sha256"), bool(t.get("exact", False)))
        for flag, given, rec in (("--errors", args.errors, ref.errors),
                                 ("--truth", args.truth_in, ref.truth_file)):
            if given is not None and str(given) != str(rec):
                raise InputError(f"{flag} {given}: the run in {args.out} was made in "
                                 f"{ref.describe()}; --resume continues it there")
        return ref, int(t.get("seed", seed))
    twin_seed = seed if args.twin_seed is None else args.twin_seed
    if args.truth_in is not None:
        recorded = truth_file_errors(args.truth_in)
        if args.errors is not None and recorded is not None and args.errors != recorded:
            raise InputError(f"--errors {args.errors}: {args.truth_in} was drawn in the "
                             f"{recorded} world")
        return WorldRef(args.errors or recorded or DEFAULT_PROFILE, None, str(args.truth_in),
                        file_sha256(args.truth_in), args.exact), twin_seed
    return WorldRef(args.errors or DEFAULT_PROFILE, twin_seed, exact=args.exact), twin_seed


def run(args) -> int:
    from planecal.commands.sampling_options import (command_model, fixed_distance_summary,
                                                    observer_summary, pose_list_planner,
                                                    prepare, rerun_observer,
                                                    session_from_args)
    from planecal.links.base import AlwaysEnabled
    from planecal.safety.collision import CollisionWorld
    from planecal.sampling.session import print_summary, run_session
    from planecal.twin.profile import save_truth
    from planecal.twin.world import make_twin

    scene, settings, side = prepare(args)
    ref, twin_seed = world_ref(args, side, settings.seed)
    twin = make_twin(scene, ref, twin_seed)
    checker = CollisionWorld(scene, clearance_m=settings.clearance_m)
    errors = ref.errors
    if args.truth_out:
        try:
            save_truth(args.truth_out, twin, errors, ref.truth_seed)
        except OSError as e:
            raise InputError(f"--truth-out {args.truth_out}: cannot write ({e.strerror})") from None
    observer = rerun_observer(args, scene, twin)
    model = command_model(args, scene, side)
    session = session_from_args(args, pose_list_planner(args, scene, settings, checker, model[0]),
                                observer, extra={"twin": {"seed": twin_seed, "exact": ref.exact,
                                                          "errors": str(errors),
                                                          "truth_file": ref.truth_file,
                                                          "truth_sha256": ref.truth_sha256}},
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
    if args.truth_out:
        summary["truth"] = str(args.truth_out)
    if args.truth_in:
        summary["world"] = ref.describe()
    if settings.pose.fixed_distance_mm is not None:
        summary["fixed_distance"] = fixed_distance_summary(args.out, settings, model[1])
    summary.update(observer_summary(observer))
    print_summary(summary)
    return code
