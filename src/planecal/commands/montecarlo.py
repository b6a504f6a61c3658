"""planecal montecarlo [--scene S] [--runs R] [--samples N] [--out M.json]
[--jobs J | --scheduler tcp://HOST:PORT] [--results FILE.jsonl] [--resume]
[--mode twin|rehearse|synthetic] [--seed K] [--truth-seed T] [--vary-truth]
[--offsets-all] [--laser-noise-mm X] [--repeatability-mm X] [--quantization]
[--level offsets|full|nonkinematic] [--compliance] [--free NAMES] [--weighted] [--slope 50,100,200]
[--slope-runs R]
[--roll-deg X] [--ik-choice wrist|nearest] [--errors ideal|realistic|FILE.json] [--force]

Repeated rehearsals on the twin with fresh poses and noise, each calibrated from the
scene's nominal values: per parameter the bias, the empirical std, the Cramer-Rao bound
(white-noise form sigma^2 (J^T J)^-1 and the heteroscedastic form (J^T V^-1 J)^-1), the
sandwich covariance of the unweighted fit and the std the fit reports (unweighted, or
with --weighted the weighted fit of planecal.estimation.fit, which should reach the CRB); the chi-square
consistency of the reported covariance; with --slope the spread vs the number of samples
and its log-log slope. See planecal.studies.montecarlo for the modes and the noise model.

The runs go through planecal.studies.distributed: --jobs 1 in this process, by default a
local Dask cluster (one worker process per core), or --scheduler tcp://HOST:PORT a Dask
cluster you run; every way gives the same numbers (run k's seed is --seed + k, whoever
runs it). Each run is written as it completes to --results FILE.jsonl (default with
--out M.json: M.runs.jsonl next to it; --slope points: M.slope-N.runs.jsonl); --resume
runs only the runs not in it yet, so a killed study continues where it stopped.

The runs sample in the world of an error profile (--errors, default realistic; the
synthetic mode models the ideal world only and defaults to it). The noise options default
to the profile's. In the realistic world the fit's model is not the world's: the residuals
exceed the noise, the offsets absorb the difference, and their spread and bias exceed the
Cramer-Rao bound of the noise. The output says by how much; it is what a real robot does.
"""
from __future__ import annotations

from planecal.base.errors import InputError
from planecal.commands.value_options import MAX_RUNS, MAX_SAMPLES, count, seed


def add_arguments(p):
    from planecal.commands.calibration_options import add_calibration_arguments
    from planecal.sampling.poses import IK_CHOICES
    from planecal.studies.rehearsal import MODES
    from planecal.commands.cell_options import add_scene_argument
    add_scene_argument(p, "the runs", reads=None)
    p.add_argument("--runs", type=count(MAX_RUNS), default=50, help="Monte Carlo runs (default 50)")
    p.add_argument("--samples", type=count(MAX_SAMPLES), default=150, help="samples per run (default 150)")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="also write the plots as a Rerun recording (planecal view FILE)")
    p.add_argument("--out", help="write the summary (JSON) here")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier Monte Carlo result")
    p.add_argument("--mode", choices=MODES, default="twin",
                   help="twin: the sampling run's planner + twin at rest (default); rehearse: "
                        "full tick-by-tick rehearsal; synthetic: analytic model + noise model")
    p.add_argument("--seed", type=seed, default=1000, help="run k uses seed + k (default 1000)")
    p.add_argument("--truth-seed", type=seed, default=0, help="seed of the fixed truth (default 0)")
    p.add_argument("--vary-truth", action="store_true", help="draw a new truth for every run")
    p.add_argument("--offsets-all", action="store_true", help="truth with delta1, delta6 != 0 too")
    p.add_argument("--errors", default=None, metavar="ideal|realistic|FILE.json",
                   help="the twin's error profile (default: realistic; the synthetic mode: "
                        "ideal, the only world it models)")
    p.add_argument("--laser-noise-mm", type=float, default=None,
                   help="laser noise per reading (default: the profile's, 0.001; a sample "
                        "averages 100)")
    p.add_argument("--repeatability-mm", type=float, default=None,
                   help="robot repeatability (3-sigma flange; default: the profile's, ideal "
                        "the robot's 0.07, realistic 0.057; 0 = off)")
    p.add_argument("--quantization", action="store_true",
                   help="synthetic mode: add +-0.5 count encoder quantisation noise")
    add_calibration_arguments(p, weighted_help="fit by weighted least squares with the "
                              "world's noise model (repeatability, laser)")
    p.add_argument("--roll-deg", type=float, default=None,
                   help="twin/rehearse modes: the pose draw's roll about the beam within "
                        "+-this (default: the sampling run's, 180)")
    p.add_argument("--ik-choice", choices=IK_CHOICES, default=None,
                   help="twin/rehearse modes: the pose draw's IK branch choice (default: the "
                        "sampling run's, wrist)")
    p.add_argument("--slope", help="also measure the spread at these sample counts (e.g. 50,100,200)")
    p.add_argument("--slope-runs", type=count(MAX_RUNS), default=None, help="runs per slope point (default --runs)")
    from planecal.commands.engine_options import add_engine_arguments, add_results_arguments
    add_engine_arguments(p)
    add_results_arguments(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the summary,
    the results files (the slope points' too) and the recording."""
    from planecal.commands.engine_options import results_path
    from planecal.commands.io_options import (Files, profile_inputs, results_output,
                                              rrd_output, scene_inputs)
    from planecal.studies.common import parse_int_list
    from planecal.studies.montecarlo import FORMAT
    f = Files().read(*scene_inputs(args.scene), *profile_inputs(args.errors, args.scene))
    f.write(args.out, "--out", FORMAT)
    results_output(f, results_path(args), args.resume)
    for n in parse_int_list(args.slope, "--slope", 20, MAX_SAMPLES) if args.slope else []:
        results_output(f, results_path(args, f"slope-{n}"), args.resume)
    rrd_output(f, args.rrd)
    return f


def run(args) -> int:
    import functools
    import sys
    import time
    from dataclasses import replace

    from planecal.commands.calibration_options import calibration_settings
    from planecal.commands.engine_options import (check_results_path, engine_from_args,
                                                  results_path)
    from planecal.io.params import save_json
    from planecal.model.scene import load_scene
    from planecal.studies.common import parse_int_list
    from planecal.studies.distributed import warm_twin
    from planecal.studies.montecarlo import MCSettings, analyze, run_many, slope_study
    from planecal.present.montecarlo import format_montecarlo, format_slope
    from planecal.twin.profile import DEFAULT_PROFILE

    scene = load_scene(args.scene)  # InputError for a bad scene before any work
    errors = args.errors or ("ideal" if args.mode == "synthetic" else DEFAULT_PROFILE)
    cal = calibration_settings(args, scene=scene)
    st = MCSettings(scene=str(scene.path), samples=args.samples, runs=args.runs, seed=args.seed,
                    mode=args.mode, truth_seed=args.truth_seed, vary_truth=args.vary_truth,
                    offsets_all=args.offsets_all, errors=errors,
                    laser_noise_mm=args.laser_noise_mm,
                    repeatability_mm=args.repeatability_mm, quantization=args.quantization,
                    free=cal.free, weighted=args.weighted, roll_deg=args.roll_deg,
                    ik_choice=args.ik_choice, level=cal.level, compliance=cal.compliance,
                    geometry_prior=cal.geometry_prior, free_scale=cal.free_scale)
    st.check()
    slope_counts = parse_int_list(args.slope, "--slope", 20, MAX_SAMPLES) if args.slope else None
    if slope_counts is not None and len(slope_counts) < 2:
        raise InputError("--slope needs at least two sample counts")
    # the twin's numba tick: compiled (or loaded from its cache) once before the runs
    warm = None if st.mode == "synthetic" else functools.partial(warm_twin, st.scene)
    engine = engine_from_args(args, warmup=warm)  # its options checked before any file
    results = results_path(args)

    def slope_results(n: int):
        return results_path(args, f"slope-{n}")
    for path in [results] + [slope_results(n) for n in slope_counts or []]:
        check_results_path(path, args)
    with engine:
        t0 = time.perf_counter()
        runs = run_many(st, engine, results=results, resume=args.resume)
        dt = time.perf_counter() - t0
        if not args.quiet:
            print(f"runs: {st.runs} in {dt:.2f} s ({st.runs / dt:.4f} runs/s), "
                  f"{engine.describe()}" + (f"; each written to {results}" if results else ""),
                  file=sys.stderr, flush=True)
        res = analyze(runs, st)
        res["settings"]["scene"] = scene.name
        print(format_montecarlo(res))
        if slope_counts:
            s2 = replace(st, runs=args.slope_runs or st.runs)
            s2.check()
            sl = slope_study(s2, slope_counts, engine,
                             results=slope_results if results is not None else None,
                             resume=args.resume)
            res["slope"] = sl
            print()
            print(format_slope(sl))
    if args.out:
        save_json(args.out, res)
        print(f"result written to {args.out}")
    if args.rrd:
        from planecal.present.rerun.studies import log_montecarlo, order_pose_set
        from planecal.studies.rehearsal import twin_samples
        world, opts = st.world(0)  # the 3D view: run 0's world, the twin mode's draw
        qe, d, plate, _, _ = twin_samples(scene, world, st, st.seed, opts)
        poses = order_pose_set(qe, d, plate, world.params,
                               f"run 0's samples (twin mode draw, seed {st.seed})")
        print(f"plots written to {log_montecarlo(args.rrd, res, scene, poses)}")
    return 0
