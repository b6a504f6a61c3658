"""The validation job (``planecal validate``): ISO 9283 AP/RP and the gauge block on the
twin (``studies.validation``). Either a study over truths (each its own rehearsal and
calibration, on ``studies.distributed.Engine``), or one calibration result validated in
the world its run was made in: the run and the result read in their cell (``jobs.runs``,
``jobs.results``), the world from the truth file and the run's sidecar
(``jobs.runs.run_world``)."""
from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Callable

from planecal.base.errors import InputError
from planecal.base.progress import stage


@dataclass(frozen=True)
class ValidateRequest:
    """``planecal validate``'s options (the command's docstring): the scene of a study
    (None: the default; with a calibration given, the run's and the result's), --out,
    --rrd, the world (--errors, the truth seeds), the rehearsal (--samples, --seed,
    --offsets-all, --poses), the ISO settings (``settings``: ``ValidationSettings``), the
    breakdown, the calibration given (--calibrated, --truth, --run), the calibration's
    settings for a robot (``calibration``) and the study's engine (``engine``)."""
    settings: object  # planecal.studies.validation.ValidationSettings
    calibration: Callable
    engine: Callable
    scene: str | None = None
    out: str | None = None
    rrd: str | None = None
    errors: str | None = None
    truth_seeds: tuple | None = None
    samples: int = 150
    seed: int = 0
    offsets_all: bool = False
    poses: str | None = None
    breakdown: str = "alone"
    breakdown_truth: int | None = None
    calibrated: str | None = None
    truth: str | None = None
    run: str | None = None
    quiet: bool = False
    aim_samples: int | None = None  # --poses: the first random run that aims a list planned
    # from the nominal cell (None: ``AIM_SAMPLES`` for such a list, 0 for an aimed one)
    robot_minutes: float | None = None  # each truth's calibration run ends once it took this


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


def validate(req: ValidateRequest) -> tuple[dict, object]:
    """The validation (module docstring), printed, written to --out and recorded to
    --rrd: (its document, the scene)."""
    from planecal.io.params import save_json
    from planecal.model.scene import DEFAULT_SCENE, load_scene

    if req.calibrated and req.robot_minutes is not None:
        raise InputError("--robot-minutes budgets the rehearsed calibration runs; with "
                         "--calibrated there are none")
    if req.calibrated:
        doc, scene = _validate_given(req)
        cal = None
    else:
        scene = load_scene(req.scene or DEFAULT_SCENE)
        cal = req.calibration(scene.robot)
        doc = _study(req, scene, cal)
    if req.out:
        save_json(req.out, doc)
        print(f"result written to {req.out}")
    if req.rrd:
        print(f"recording written to {_record(req, scene, doc, cal)}")
    return doc, scene


AIM_SAMPLES = 30  # the first random run that aims a pose list planned from the nominal cell


def _poses(path, scene, least: int = 0):
    """A planned pose list as the study's job takes it (None without one): entries
    (counts, plate, approach side), and whether it was planned from the nominal cell;
    read as `sample --poses` reads it (its plates checked against ``scene``)."""
    if not path:
        return None, False
    from planecal.jobs.sampling import read_pose_list
    from planecal.studies.planning import approach_of
    pq, pp, doc = read_pose_list(path, scene)
    if len(pq) < least:
        raise InputError(f"{path}: {len(pq)} poses; a calibration set needs at least {least}")
    pa = approach_of(doc, len(pq))
    return (tuple((tuple(int(v) for v in c), int(k), int(a)) for c, k, a in zip(pq, pp, pa)),
            doc.get("aimed_with") is None)


def aim_samples(req: ValidateRequest, nominal: bool) -> int:
    """The first run's samples that aim --poses (``rehearsal.staged_samples``): as asked,
    else ``AIM_SAMPLES`` for a list planned from the nominal cell (the true cell is
    millimetres off: a nominal list loses poses to the laser's range), else 0."""
    if not req.poses:
        return 0
    if req.aim_samples is None:
        return AIM_SAMPLES if nominal else 0
    if req.aim_samples and req.aim_samples < 20:
        raise InputError(f"--aim-samples must be 0 or at least 20, got {req.aim_samples}")
    return req.aim_samples


def _study(req: ValidateRequest, scene, cal) -> dict:
    """Validation over truths, each rehearsed and calibrated on its own twin."""
    from planecal.jobs.sampling import robot_minutes
    from planecal.studies.distributed import warm_twin
    from planecal.studies.validation import TruthJob
    from planecal.twin.profile import DEFAULT_PROFILE, load_profile

    if req.samples < 20:
        raise InputError(f"--samples must be at least 20, got {req.samples}")
    seeds = list(req.truth_seeds or [0, 1, 2, 3, 4])  # checked seeds (value_options)
    profile = load_profile(req.errors or DEFAULT_PROFILE, scene.robot)
    poses, nominal = _poses(req.poses, scene, 20)
    aim = aim_samples(req, nominal)
    base = TruthJob(scene=str(scene.path), errors=str(profile.path), truth_seed=seeds[0],
                    samples=req.samples, seed=req.seed, offsets_all=req.offsets_all,
                    poses=poses, settings=req.settings, calibration=cal, aim_samples=aim,
                    robot_minutes=None if req.robot_minutes is None
                    else robot_minutes(req.robot_minutes))
    engine = req.engine(warm_twin)  # its options checked here
    what = f"the poses of {req.poses}" if req.poses else f"{req.samples} samples"
    if aim:
        what = f"{aim} random samples, calibrated at level offsets to aim {what}"
    if base.robot_minutes is not None:
        what += f" within {base.robot_minutes:g} robot minutes"
    with engine:  # the scheduler reached before anything is said
        if not req.quiet:
            print(f"{len(seeds)} truth(s) of the {profile.name} world ({scene.name}): "
                  f"rehearse {what} (seed {req.seed} + the truth's), calibrate "
                  f"(level {cal.label}), validate...", file=sys.stderr, flush=True)
        return _truths(req, seeds, base, profile, scene, engine)


def _truths(req: ValidateRequest, seeds, base, profile, scene, engine) -> dict:
    """Validation over the truth seeds (and the breakdown) on ``engine``: the document."""
    from dataclasses import replace

    from planecal.studies.validation import (ANCHORS, FORMAT, breakdown, cannot_remove,
                                             run_jobs, summarize, validate_truth)
    from planecal.present.validation import format_breakdown, format_truths
    results = run_jobs(validate_truth, [replace(base, truth_seed=t) for t in seeds],
                       engine, "validate", req.quiet)
    summary, med, worst = summarize(results)
    doc = {"format": FORMAT, "scene": scene.name, "errors": profile.name,
           "profile": str(profile.path), "level": base.calibration.level,
           "compliance": base.calibration.compliance,
           "calibration_settings": base.calibration.to_dict(), "truth_seeds": seeds,
           **summary, **_detail(med), "detail_truth_seed": med["truth_seed"]}
    print(format_truths(summary, profile.name, base.calibration.label))
    print()
    print(CELL_FRAME_NOTE)
    if req.breakdown != "none":
        t = seeds[0] if req.breakdown_truth is None else req.breakdown_truth
        print(f"\nbreakdown: truth {t} with each error source "
              + ("switched off in turn..." if req.breakdown == "off" else "alone..."),
              file=sys.stderr, flush=True)
        bd = breakdown(replace(base, truth_seed=t), req.breakdown, engine, req.quiet)
        bd["cannot_remove"] = cannot_remove(bd)
        doc["breakdown"] = bd
        print()
        print(format_breakdown(bd, base.calibration.label))
    print()
    print(ANCHORS)
    return doc


def _record(req: ValidateRequest, scene, doc, cal) -> str:
    """The Rerun recording of the validation doc's detailed truth: its calibration run
    again (a pure function of the job) for the samples and the identified parameters."""
    from planecal.present.rerun.studies import log_validate

    if req.calibrated:
        from planecal.jobs.results import read_runs_and_result
        runs, result = read_runs_and_result([req.run], req.calibrated, scene)
        s = runs.samples
        return log_validate(req.rrd, doc, scene, result.params, s.qe, s.d_mm * 1e-3, s.plate)
    from planecal.studies.validation import TruthJob, truth_run
    poses, nominal = _poses(req.poses, scene)
    job = TruthJob(scene=str(scene.path), errors=doc["profile"],
                   truth_seed=doc["detail_truth_seed"], samples=req.samples, seed=req.seed,
                   offsets_all=req.offsets_all, poses=poses, settings=req.settings,
                   calibration=cal, aim_samples=aim_samples(req, nominal),
                   robot_minutes=req.robot_minutes)
    v, fit, run = truth_run(job)
    if fit is None:
        raise InputError(f"--rrd: truth {job.truth_seed}'s run gave up: {v['failed']}")
    return log_validate(req.rrd, v, scene, fit.params, *run)


def _detail(v: dict) -> dict:
    """A truth's full result under the single-truth keys (what report readers use)."""
    keep = {k: v[k] for k in v if k not in ("truth_seed", "off")}
    return keep


def _validate_given(req: ValidateRequest) -> tuple[dict, object]:
    """--calibrated/--truth/--run: one calibration (any level) in the world it was made in
    (the run and the result read in their cell): the truth file's world, with the error
    profile the truth file or the run's sidecar records (``jobs.runs.run_world``;
    --errors only where neither does, and never against them). (document, scene)"""
    from planecal.jobs.results import read_runs_and_result
    from planecal.jobs.runs import run_world
    from planecal.present.validation import format_validation
    from planecal.safety.collision import CollisionWorld
    from planecal.studies.validation import FORMAT, summarize, validate
    from planecal.studies.validation.floors import ModelClass
    from planecal.twin.profile import load_profile
    from planecal.twin.world import sources_on

    runs, result = read_runs_and_result([req.run], req.calibrated, req.scene)
    scene, model = runs.scene, result.model()
    ref = run_world(runs.runs[0], req.truth, req.errors, None, default="ideal")
    with stage("validate", f"ISO 9283 and the gauge block on the twin of {ref.describe()}",
               quiet=req.quiet):
        world, opts = ref.build(scene)
        profile = load_profile(ref.errors, scene.robot)
        checker = CollisionWorld(scene, clearance_m=req.settings.clearance_m)
        v = validate(scene, world, model, runs.samples.qe, req.settings, checker,
                     ModelClass.of_document(scene.robot, result.doc, len(scene.plates)), opts,
                     runs.samples.direction)  # the level's floor from the result's own class
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
    summary["truths"][0]["truth_file"] = str(req.truth)
    return {"format": FORMAT, "errors": profile.name, "profile": str(profile.path),
            **v, **summary}, scene
