"""planecal validate [--scene S] [--out V.json] [--samples N] [--seed K] [--truth-seed T]
[--offsets-all] [--cycles 30] [--cube-mm E] [--tcp-mm X,Y,Z] [--block-mm L]
[--poses POSES.json] [--calibrated R.json --truth T.json --run RUN.tsv]

ISO 9283 pose accuracy AP and repeatability RP (P1..P5 in a cube over the calibrated
region, 30 cycles) and the gauge-block test (seed 9.3) on the twin, with the nominal and
the calibrated model. With no arguments: rehearse on the default scene (the sampling
run's planner with collision checks, the twin at rest per sample), calibrate, validate.
With --calibrated, --truth and --run: validate an existing calibration result against the
twin truth it was made on (the run's samples place the ISO cube).
Prints both and writes JSON with ap_before_mm, ap_after_mm, rp_mm, gauge_error_before_mm,
gauge_error_after_mm (and the per-pose details).
"""
from __future__ import annotations

import sys

import numpy as np

from planecal.errors import InputError


VALIDATE_FORMAT = "planecal-validate/1"


def add_arguments(p):
    from planecal.scene import DEFAULT_SCENE
    p.add_argument("--scene", default=DEFAULT_SCENE, help="scene (default %(default)s)")
    p.add_argument("--out", help="write the result (JSON) here")
    p.add_argument("--samples", type=int, default=150, help="rehearsal samples (default 150)")
    p.add_argument("--seed", type=int, default=0, help="rehearsal seed (poses, noise)")
    p.add_argument("--truth-seed", type=int, default=0, help="seed of the twin's truth (default 0)")
    p.add_argument("--offsets-all", action="store_true",
                   help="truth with delta1 and delta6 != 0 as well")
    p.add_argument("--cycles", type=int, default=30, help="ISO cycles (default 30)")
    p.add_argument("--cube-mm", type=float, default=None, help="ISO cube edge (default: from the samples)")
    p.add_argument("--tcp-mm", default="0,0,0", help="TCP in the flange frame, mm (default flange)")
    p.add_argument("--block-mm", type=float, default=100.0, help="gauge block length (default 100)")
    p.add_argument("--gauge-repeats", type=int, default=10)
    p.add_argument("--poses", help="rehearse through this planned pose list (planecal plan) "
                                   "instead of random poses")
    p.add_argument("--calibrated", help="calibration result to validate (with --truth and --run)")
    p.add_argument("--truth", help="the twin truth (parameter file) the calibration was made on")
    p.add_argument("--run", help="the calibration's sample file (places the ISO cube)")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="also write a Rerun recording (planecal view FILE)")


def _tcp(text):
    try:
        v = [float(x) * 1e-3 for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3 or not all(np.isfinite(v)):
        raise InputError(f"--tcp-mm: expected three numbers X,Y,Z, got {text!r}")
    return tuple(v)


def run(args) -> int:
    from planecal.collision import CollisionWorld
    from planecal.fit import Problem, solve
    from planecal.params import load_params, save_json
    from planecal.scene import load_scene, nominal_params
    from planecal.studies.montecarlo import MCSettings, twin_samples
    from planecal.studies.validation import ValidationSettings, format_validation, validate
    from planecal.twin.truth import Tolerances, draw_truth, load_truth

    if args.out:  # checked before any work (issue 16)
        from planecal.outputs import check_output
        check_output(args.out, [args.calibrated, args.truth, args.run, args.poses],
                     VALIDATE_FORMAT)
    scene = load_scene(args.scene)
    st = ValidationSettings(cycles=args.cycles,
                            cube_edge_m=None if args.cube_mm is None else args.cube_mm * 1e-3,
                            tcp_m=_tcp(args.tcp_mm), block_length_m=args.block_mm * 1e-3,
                            gauge_repeats=args.gauge_repeats, seed=args.seed)
    st.check()
    given = [a for a in (args.calibrated, args.truth, args.run) if a]
    info = {}
    if given:
        if len(given) != 3:
            raise InputError("--calibrated, --truth and --run go together")
        from planecal.samples import read_samples
        calibrated = load_params(args.calibrated)
        truth = load_truth(scene, args.truth)
        run_samples = read_samples(args.run)
        qe = run_samples.qe
        d_m, plate = run_samples.d_mm * 1e-3, run_samples.plate
        fit = None
    else:
        if args.samples < 20:
            raise InputError(f"--samples must be at least 20, got {args.samples}")
        truth = draw_truth(scene, args.truth_seed, Tolerances(offsets_all=args.offsets_all))
        mc = MCSettings(scene=str(scene.path), samples=args.samples, seed=args.seed)
        what = f"the poses of {args.poses}" if args.poses else f"{args.samples} samples"
        print(f"rehearsing {what} on the twin ({scene.name}, seed {args.seed}, "
              f"truth seed {args.truth_seed})...", file=sys.stderr, flush=True)
        if args.poses:
            from planecal.studies.montecarlo import pose_list_samples
            from planecal.studies.planning import load_poses
            pq, pp, _ = load_poses(args.poses)
            mc = MCSettings(scene=str(scene.path), samples=len(pq), seed=args.seed,
                            poses=tuple((tuple(int(v) for v in c), int(k)) for c, k in zip(pq, pp)))
            qe, d, plate, rejected = pose_list_samples(scene, truth, mc, args.seed)
        else:
            qe, d, plate, rejected = twin_samples(scene, truth, mc, args.seed)
        d_m = d
        fit = solve(Problem.from_arrays(scene.robot, qe, d, nominal_params(scene), plate))
        calibrated = fit.params
        info = {"samples": len(d), "rejected": rejected, "fit_rms_mm": fit.rms_mm(),
                "offsets_std_rad": fit.std[fit.layout.slice("joint_offsets")]}
        print(f"calibrated: rms {fit.rms_mm() * 1e3:.1f} um; validating...", file=sys.stderr,
              flush=True)
    checker = CollisionWorld(scene, clearance_m=st.clearance_m)
    v = validate(scene, truth, calibrated, qe, st, checker, fit)
    v["scene"] = scene.name
    v["calibration"] = info
    v["truth_offsets_rad"] = truth.joint_offsets
    v["calibrated_offsets_rad"] = calibrated.joint_offsets
    print(format_validation(v))
    if args.out:
        save_json(args.out, {"format": VALIDATE_FORMAT, **v})
        print(f"result written to {args.out}")
    if args.rrd:
        from planecal.rerun_log.studies import log_validate
        print(f"recording written to {log_validate(args.rrd, v, scene, calibrated, qe, d_m, plate)}")
    return 0
