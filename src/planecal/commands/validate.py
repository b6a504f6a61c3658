"""planecal validate [--scene S] [--out V.json] [--errors ideal|realistic|FILE.json]
[--truth-seeds 0,1,2,3,4] [--samples N] [--seed K] [--offsets-all] [--cycles 30]
[--cube-mm E] [--tcp-mm X,Y,Z] [--block-mm L] [--poses POSES.json]
[--breakdown alone|off|none] [--breakdown-truth T] [--jobs J] [--level L]
[--compliance] [--free NAMES] [--calibrated R.json --truth T.json --run RUN.tsv]

ISO 9283 pose accuracy AP and repeatability RP (P1..P5, 30 cycles) in two cubes -- one
centred on a calibration sample (near the samples), and the standard's (the largest cube
inside the samples' flange hull) -- and the gauge-block test (seed 9.3, aimed with the
calibrated model; where it cannot be measured, why, beside the ISO figures) on the twin,
in the world of an error profile (--errors, default realistic). AP is measured where the
tool is: at the tool point (the laser's beam point at its measuring centre; each model
commands its own estimate of it onto the ISO point), with the flange and the scene's named
TCPs (and --tcp-mm's) beside it, in the robot's frame (J1's axis and zero) and the cell
frame. Every truth is commanded by the nominal model, the calibration at --level and at
each level below it (on the same poses), each level's floor (its own model with the
parameters that best fit the twin's true tool points at the samples' poses: the best a
calibration of that level can do) and the twin's own whole true model (the oracle,
backlash by the approach direction: repeatability and whole counts are what it leaves).

With no calibration given: for each truth seed T, draw that world, rehearse a calibration
set on its twin with seed --seed + T (the sampling run's planner with collision checks;
each truth its own draw of the poses and the noise: at --seed 0, truth T's run is
``planecal rehearse --seed T``'s), calibrate it from the nominal values with the
options every calibrating command takes (--level, --compliance, --free, ...: the one
calibration, ``estimation.calibrate``), and validate on the same world; the truths run
on ``studies.distributed.Engine`` (--jobs 1: in this process).
Prints the per-truth figures with the median and the worst truth, then (--breakdown,
default alone) the first truth again without the noise (the same poses rehearsed
noise-free: the noise's share apart) and with each error source of the profile on alone
(off: switched off in turn, the noise off too): what the calibration leaves of each, and
what limits it (docs/ERRORS.md).

With --calibrated, --truth and --run: validate an existing calibration result (any level)
in the world it was made in: the truth file of ``rehearse --truth`` holds that world (the
robot's true geometry, the gear and laser phases), the run's sidecar names its error
profile.

--out writes JSON (format planecal-validate/3; a /1 file, whose ``ap_after_mm`` was the
flange's, is refused by ``planecal report``): ``truths`` (per truth ``ap_before_tool_mm``,
``ap_after_tool_mm``, ``ap_floor_tool_mm``, ``ap_oracle_tool_mm``, ``rp_after_tool_mm``,
the same ``_flange_``, ``_cell_`` and in the standard's cube ``_standard_``, each level's
under ``levels``, the named TCPs', the ISO points' distances to the nearest sample in each
cube, ``gauge_failed``), their medians and worsts (``ap_after_tool_median_mm``, ...),
``breakdown``, ``level``, and the median truth's details under the single-truth keys
(``iso``, ``iso_standard``, ``cube``, ``standard_cube``, ``floors``, ``cell_frame``,
``gauge``, ...).
"""
from __future__ import annotations

import sys

import numpy as np

from planecal.base.errors import InputError
from planecal.commands.value_options import (MAX_ITERATIONS, MAX_SAMPLES, count, seed,
                                             seed_list)


def add_arguments(p):
    from planecal.model.scene import DEFAULT_SCENE
    p.add_argument("--scene", default=DEFAULT_SCENE, help="scene (default %(default)s)")
    p.add_argument("--out", help="write the result (JSON) here")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="also write a Rerun recording of the validation (the median truth's)")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier validate result")
    p.add_argument("--errors", default=None, metavar="ideal|realistic|FILE.json",
                   help="the twin's error profile (default: realistic; with --truth: the "
                        "run's, else ideal for a truth file without a world)")
    p.add_argument("--truth-seeds", type=seed_list, default=None,
                   help="seeds of the truths (worlds) to validate on (default 0,1,2,3,4)")
    p.add_argument("--truth-seed", type=seed, default=None,
                   help="one truth seed (the same as --truth-seeds T)")
    p.add_argument("--samples", type=count(MAX_SAMPLES), default=150, help="rehearsal samples (default 150)")
    p.add_argument("--seed", type=seed, default=0,
                   help="rehearsal seed: truth T's calibration run is rehearsed with seed "
                        "K + T (its poses and noise; at 0 it is `planecal rehearse --seed "
                        "T`'s run)")
    p.add_argument("--offsets-all", action="store_true",
                   help="the ideal world with delta1 and delta6 != 0 as well (the realistic "
                        "one has them)")
    p.add_argument("--cycles", type=count(MAX_ITERATIONS), default=30, help="ISO cycles (default 30)")
    p.add_argument("--cube-mm", type=float, default=None, help="ISO cube edge (default: from the samples)")
    p.add_argument("--tcp-mm", default=None, metavar="X,Y,Z",
                   help="a TCP in the flange frame [mm] to measure AP at too (named 'tcp'), "
                        "besides the tool point, the flange and the scene's named TCPs")
    p.add_argument("--block-mm", type=float, default=100.0, help="gauge block length (default 100)")
    p.add_argument("--gauge-repeats", type=count(MAX_ITERATIONS), default=10)
    p.add_argument("--poses", help="rehearse through this planned pose list (planecal plan) "
                                   "instead of random poses")
    p.add_argument("--breakdown", default="alone", choices=("alone", "off", "none"),
                   help="repeat one truth with each error source of the profile on alone "
                        "(alone), or switched off in turn (off), or not (none) "
                        "(default alone)")
    p.add_argument("--breakdown-truth", type=seed, default=None,
                   help="the truth seed of the breakdown (default: the first truth seed)")
    from planecal.commands.calibration_options import add_calibration_arguments
    add_calibration_arguments(p)
    from planecal.commands.engine_options import add_engine_arguments
    add_engine_arguments(p)
    p.add_argument("--calibrated", help="calibration result to validate (with --truth and --run)")
    p.add_argument("--truth", help="the truth file of the world the calibration's run was "
                   "made in (rehearse --truth-out, or the file rehearse --truth ran in)")
    p.add_argument("--run", help="the calibration's sample file (places the ISO cube)")
    from planecal.commands.history_options import add_history_arguments
    add_history_arguments(p)


def _tcp(text):
    if text is None:
        return None
    try:
        v = [float(x) * 1e-3 for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3 or not all(np.isfinite(v)):
        raise InputError(f"--tcp-mm: expected three numbers X,Y,Z, got {text!r}")
    return tuple(v)


CELL_FRAME_NOTE = (
    "AP is measured as ISO 9283 does, in the robot's base coordinate system (registered to "
    "its first axis and that axis's zero, which a laser tracker finds on the robot; a plane "
    "cell has no such reference), at the tool point, in two cubes: the near-sample cube "
    "(centred on a calibration sample: accuracy near the samples) and the standard's (the "
    "largest cube inside the samples' flange hull). After a plane calibration the "
    "flange's AP also holds the flange frame's error, which the calibrated sensor pose "
    "absorbs at the tool point (right for the laser, not for another tool on the flange). "
    "The cell frame adds the robot's placement in the cell and J1's zero offset delta1: a "
    "plane calibration cannot see them (the plates move with the robot), so they stay in "
    "any position taken from a drawing of the cell (the cell column: millimetres where "
    "delta1 is), but not in work located by the calibrated plates.")


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.io_options import (Files, profile_inputs, rrd_output, scene_inputs,
                                              with_sidecars)
    from planecal.studies.validation import FORMAT, OLD_FORMATS
    f = Files().read(*scene_inputs(args.scene), *profile_inputs(args.errors, args.scene),
                     args.poses, args.calibrated, args.truth, *with_sidecars([args.run]))
    f.write(args.out, "--out", (FORMAT, *OLD_FORMATS))  # a /1 or /2 file is validate's own too
    rrd_output(f, args.rrd)
    return f


def run(args) -> int:
    from planecal.io.params import save_json
    from planecal.model.scene import load_scene
    from planecal.studies.validation import TruthJob, ValidationSettings
    from planecal.twin.profile import DEFAULT_PROFILE, load_profile

    from planecal.commands.calibration_options import calibration_settings

    given = [a for a in (args.calibrated, args.truth, args.run) if a]
    if given and len(given) != 3:
        raise InputError("--calibrated, --truth and --run go together")
    from planecal.commands.history_options import open_history
    hist = open_history(args, given + [args.out])
    scene = load_scene(args.scene)
    cal = calibration_settings(args, scene.robot)
    st = ValidationSettings(cycles=args.cycles,
                            cube_edge_m=None if args.cube_mm is None else args.cube_mm * 1e-3,
                            tcp_m=_tcp(args.tcp_mm), block_length_m=args.block_mm * 1e-3,
                            gauge_repeats=args.gauge_repeats, seed=args.seed)
    st.check()
    if given:
        doc = _validate_given(args, scene, st)
    else:
        if args.samples < 20:
            raise InputError(f"--samples must be at least 20, got {args.samples}")
        if args.truth_seed is not None and args.truth_seeds is not None:
            raise InputError("--truth-seed and --truth-seeds: give one of them")
        seeds = ([args.truth_seed] if args.truth_seed is not None
                 else args.truth_seeds or [0, 1, 2, 3, 4])  # checked seeds (value_options)
        errors = args.errors or DEFAULT_PROFILE
        profile = load_profile(errors, scene.robot)
        poses = None
        if args.poses:
            from planecal.studies.planning import load_poses
            pq, pp, _ = load_poses(args.poses)
            if len(pq) < 20:
                raise InputError(f"{args.poses}: {len(pq)} poses; a calibration set needs at "
                                 "least 20")
            poses = tuple((tuple(int(v) for v in c), int(k)) for c, k in zip(pq, pp))
        base = TruthJob(scene=str(scene.path), errors=str(profile.path), truth_seed=seeds[0],
                        samples=args.samples, seed=args.seed, offsets_all=args.offsets_all,
                        poses=poses, settings=st, calibration=cal)
        from planecal.commands.engine_options import engine_from_args
        from planecal.studies.distributed import warm_twin
        engine = engine_from_args(args, warmup=warm_twin)  # its options checked here
        what = f"the poses of {args.poses}" if args.poses else f"{args.samples} samples"
        with engine:  # the scheduler reached before anything is said
            if not args.quiet:
                print(f"{len(seeds)} truth(s) of the {profile.name} world ({scene.name}): "
                      f"rehearse {what} (seed {args.seed} + the truth's), calibrate "
                      f"(level {cal.label}), validate...", file=sys.stderr, flush=True)
            doc = _truths(args, seeds, base, profile, scene, engine)
    if args.out:
        save_json(args.out, doc)
        print(f"result written to {args.out}")
    if args.rrd:
        print(f"recording written to {_record(args, scene, st, doc, cal)}")
    _history(args, hist, scene, doc)
    return 0


def _history(args, hist, scene, doc: dict) -> None:
    """The validation's entry in the cell's history (linked to the calibration it
    validated, where it read one)."""
    from planecal.commands.history_options import (command_provenance, new_entry, record,
                                                   result_link)
    if hist is None:
        return
    sha, against = result_link(hist, args.calibrated) if args.calibrated else (None, None)
    prov = command_provenance(scene, [("calibrated", args.calibrated), ("truth", args.truth),
                                      ("run", args.run)])
    world = doc.get("world") or {"errors": doc.get("errors"), "truth_seeds": doc.get("truth_seeds")}
    summary = {k: doc.get(k) for k in ("ap_before_tool_median_mm", "ap_after_tool_median_mm",
                                       "ap_after_tool_worst_mm", "ap_oracle_tool_median_mm",
                                       "ap_floor_tool_median_mm",
                                       "ap_after_tool_standard_median_mm")}
    summary.update(truths=len(doc.get("truths") or []), level=doc.get("level"),
                   where="the tool point (the laser's beam point), robot frame")
    record(hist, new_entry(args, "validate", "ok", 0, prov, robot_sha256=scene.robot.digest,
                           against=against, result_sha256=sha, world=world, summary=summary,
                           document=doc, output=args.out))


def _truths(args, seeds, base, profile, scene, engine) -> dict:
    """Validation over the truth seeds (and the breakdown) on ``engine``: the document."""
    from dataclasses import replace

    from planecal.studies.validation import ANCHORS, FORMAT, breakdown, cannot_remove, run_jobs, summarize, validate_truth
    from planecal.present.validation import format_breakdown, format_truths
    results = run_jobs(validate_truth, [replace(base, truth_seed=t) for t in seeds],
                       engine, "validate", args.quiet)
    summary, med, worst = summarize(results)
    doc = {"format": FORMAT, "scene": scene.name, "errors": profile.name,
           "profile": str(profile.path), "level": base.calibration.level,
           "compliance": base.calibration.compliance,
           "calibration_settings": base.calibration.to_dict(), "truth_seeds": seeds,
           **summary, **_detail(med), "detail_truth_seed": med["truth_seed"]}
    print(format_truths(summary, profile.name, base.calibration.label))
    print()
    print(CELL_FRAME_NOTE)
    if args.breakdown != "none":
        t = seeds[0] if args.breakdown_truth is None else args.breakdown_truth
        print(f"\nbreakdown: truth {t} with each error source "
              + ("switched off in turn..." if args.breakdown == "off" else "alone..."),
              file=sys.stderr, flush=True)
        bd = breakdown(replace(base, truth_seed=t), args.breakdown, engine, args.quiet)
        bd["cannot_remove"] = cannot_remove(bd)
        doc["breakdown"] = bd
        print()
        print(format_breakdown(bd, base.calibration.label))
    print()
    print(ANCHORS)
    return doc


def _record(args, scene, st, doc, cal) -> str:
    """The Rerun recording of the validation doc's detailed truth: its calibration run
    again (a pure function of the job) for the samples and the identified parameters."""
    from planecal.present.rerun.studies import log_validate

    if args.calibrated:
        from planecal.io.params import load_params
        from planecal.io.samples import read_samples
        run = read_samples(args.run)
        return log_validate(args.rrd, doc, scene, load_params(args.calibrated), run.qe,
                            run.d_mm * 1e-3, run.plate)
    from planecal.studies.validation import TruthJob, truth_run
    poses = None
    if args.poses:
        from planecal.studies.planning import load_poses
        pq, pp, _ = load_poses(args.poses)
        poses = tuple((tuple(int(v) for v in c), int(k)) for c, k in zip(pq, pp))
    job = TruthJob(scene=str(scene.path), errors=doc["profile"], truth_seed=doc["detail_truth_seed"], samples=args.samples, seed=args.seed,
                   offsets_all=args.offsets_all, poses=poses, settings=st, calibration=cal)
    v, fit, run = truth_run(job)
    if fit is None:
        raise InputError(f"--rrd: truth {job.truth_seed}'s run gave up: {v['failed']}")
    return log_validate(args.rrd, v, scene, fit.params, *run)


def _detail(v: dict) -> dict:
    """A truth's full result under the single-truth keys (what report readers use)."""
    keep = {k: v[k] for k in v if k not in ("truth_seed", "off")}
    return keep


def _validate_given(args, scene, st) -> dict:
    """--calibrated/--truth/--run: one calibration (any level) in the world it was made in:
    the truth file's world, with the error profile the truth file or the run's sidecar
    records (``twin.world.recorded_world``; --errors only where neither does, and never
    against them)."""
    from planecal.estimation.compensate import load_calibrated
    from planecal.safety.collision import CollisionWorld
    from planecal.io.samples import read_samples
    from planecal.twin.world import recorded_world, sources_on
    from planecal.studies.validation import FORMAT, summarize, validate
    from planecal.present.validation import format_validation
    from planecal.twin.profile import load_profile

    from planecal.studies.validation.floors import ModelClass
    model, cdoc = load_calibrated(scene.robot, args.calibrated)
    run = read_samples(args.run)
    qe = run.qe
    ref = recorded_world(scene, args.run, args.truth, args.errors, None, default="ideal")
    world, opts = ref.build(scene)
    profile = load_profile(ref.errors, scene.robot)
    checker = CollisionWorld(scene, clearance_m=st.clearance_m)
    v = validate(scene, world, model, qe, st, checker,
                 ModelClass.of_document(scene.robot, cdoc, len(scene.plates)), opts,
                 run.direction)
    v["scene"] = scene.name
    v["calibration"] = {}
    v["truth_offsets_rad"] = world.params.joint_offsets
    v["calibrated_offsets_rad"] = model.params.joint_offsets
    v["sources"] = sources_on(scene.robot, world, opts)
    v["world"] = ref.to_dict()
    v["level"] = model.level
    print(f"{ref.describe()}; error sources: {', '.join(v['sources']) or 'none'}")
    print(format_validation(v))
    summary, _, _ = summarize([{**v, "truth_seed": None}])
    summary["truths"][0]["truth_file"] = str(args.truth)
    return {"format": FORMAT, "errors": profile.name, "profile": str(profile.path),
            **v, **summary}
