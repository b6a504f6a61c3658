"""What a sampling run (``planecal rehearse`` on the twin, ``planecal sample`` on the real
cell) is made of: its request (``SamplingRequest``: the values of the sampling options),
the run settings (a new run's from the scene and the request, a resumed run's from its
sidecar), the model it aims with, the planned pose list, the Rerun observer and the
session (``sampling.session.Session``) they describe."""
from __future__ import annotations

import sys
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

from planecal.base.errors import InputError
from planecal.sampling.laserread import LaserSettings
from planecal.sampling.run import RunSettings
from planecal.sampling.runfiles import load_sidecar, sidecar_path
from planecal.sampling.session import Session


@dataclass(frozen=True)
class SamplingRequest:
    """A sampling run's options (``commands.sampling_options``; the same defaults): the
    sample file ``out``, the scene and the pose settings of a new run (None: the scene's),
    the session (start and end moves, ``resume``, ``force``), the recording and the live
    view, the aiming model (``params``, ``encoder_offsets``) and the pose list."""
    out: str
    scene: str | None = None
    samples: int | None = None
    seed: int | None = None
    cone_deg: float | None = None
    fixed_distance_mm: float | None = None
    distance_mm: tuple | None = None
    roll_deg: float | None = None
    margin_mm: float | None = None
    plate_choice: str | None = None
    ik_choice: str | None = None
    clearance_mm: float | None = None
    laser_max_reads: int | None = None
    max_attempts: int | None = None
    start: str = "here"
    end: str = "stay"
    resume: bool = False
    force: bool = False
    decimal_comma: bool = False
    rrd: str | None = None
    live: bool = False
    live_port: int = 9876
    live_web_port: int = 9090
    params: str | None = None
    encoder_offsets: str | None = None
    poses: str | None = None
    foreground: bool = False
    robot_minutes: float | None = None

    @classmethod
    def of(cls, values: dict) -> "SamplingRequest":
        """The request of the options' values (a parsed command line's ``vars``)."""
        return cls(**{f.name: values[f.name] for f in fields(cls)})


# the options a resumed run takes from its sidecar instead
SETTING_FLAGS = ("scene", "seed", "cone_deg", "fixed_distance_mm", "distance_mm", "roll_deg",
                 "margin_mm", "plate_choice", "ik_choice", "clearance_mm", "laser_max_reads",
                 "max_attempts")


def settings_from(req: SamplingRequest, scene) -> RunSettings:
    """Run settings for a new run: the scene's sampling defaults, overridden by the
    request's."""
    st = RunSettings.for_scene(scene, seed=0 if req.seed is None else req.seed)
    pose = st.pose
    if req.cone_deg is not None:
        pose.cone_deg = req.cone_deg
    if req.distance_mm is not None:
        pose.distance_mm = tuple(req.distance_mm)
        if pose.distance_mm[0] > pose.distance_mm[1]:
            raise InputError(f"--distance-mm: LO {pose.distance_mm[0]} is above HI {pose.distance_mm[1]}")
    pose.fixed_distance_mm = req.fixed_distance_mm
    if req.roll_deg is not None:
        pose.roll_deg = req.roll_deg
    if req.margin_mm is not None:
        if req.margin_mm < 0:
            raise InputError(f"--margin-mm must be >= 0, got {req.margin_mm}")
        pose.margin_m = req.margin_mm * 1e-3
    if req.plate_choice is not None:
        pose.plate_choice = req.plate_choice
    if req.ik_choice is not None:
        pose.ik_choice = req.ik_choice
    pose.check(scene)
    laser = LaserSettings()
    if req.laser_max_reads is not None:
        if req.laser_max_reads < laser.buffer_len:
            raise InputError(f"--laser-max-reads must be at least {laser.buffer_len} (the buffer)")
        laser.max_reads = req.laser_max_reads
    st.laser = laser
    if req.samples is not None:
        st.samples = req.samples
    if st.samples < 1:
        raise InputError(f"--samples must be at least 1, got {st.samples}")
    if req.clearance_mm is not None:
        if req.clearance_mm < 0:
            raise InputError(f"--clearance-mm must be >= 0, got {req.clearance_mm}")
        st.clearance_m = req.clearance_mm * 1e-3
    if req.max_attempts is not None:  # 1 .. MAX_TRIES (its argparse type)
        st.max_attempts = req.max_attempts
    st.decimal_comma = bool(req.decimal_comma)
    st.robot_minutes = None if req.robot_minutes is None else robot_minutes(req.robot_minutes)
    return st


def robot_minutes(v: float) -> float:
    """--robot-minutes checked: a positive number of minutes."""
    if not v > 0:
        raise InputError(f"--robot-minutes must be > 0, got {v:g}")
    return float(v)


@dataclass(frozen=True)
class Prepared:
    """A run about to start: the request (a resumed run's with the pose list its sidecar
    records), its scene, its settings and its sidecar (None: a new run)."""
    req: SamplingRequest
    scene: object  # planecal.model.scene.Scene
    settings: RunSettings
    sidecar: dict | None
    # the --poses list, read and checked against the scene before anything heavy starts
    # (counts (n, 6), plates (n,), its document); None without --poses
    poses: tuple | None = None


def prepare(req: SamplingRequest, default_samples: int = 150) -> Prepared:
    """A new run or a resumed one; refuses to overwrite an existing sample file without
    ``resume`` or ``force``, and to continue a sample file with a line that is not a
    sample (nothing is appended after it). The outputs were checked before the run
    (``commands.sampling_options.run_files``, the output guard)."""
    from planecal.io.samples import check_continuable
    from planecal.model.scene import DEFAULT_SCENE, load_scene

    out = Path(req.out)
    if req.resume:
        side = load_sidecar(out)
        if not out.exists():
            raise InputError(f"{out}: the sample file of the run to resume is missing")
        check_continuable(out)
        values = asdict(req)
        given = [f"--{f.replace('_', '-')}" for f in SETTING_FLAGS if values[f] is not None]
        if given:
            print(f"note: --resume takes the scene and settings from {sidecar_path(out)}; "
                  f"ignoring {' '.join(given)}", file=sys.stderr)
        st = RunSettings.from_sidecar(side, str(sidecar_path(out)))
        if side.get("poses") and req.poses is None:
            req = replace(req, poses=side["poses"])
        if req.samples is not None:  # 1 .. MAX_SAMPLES (its argparse type)
            st.samples = req.samples
        if req.robot_minutes is not None:  # a new budget, as --samples is a new target
            st.robot_minutes = robot_minutes(req.robot_minutes)
        scene = load_scene(st.scene)
        st.pose.check(scene)
        return Prepared(req, scene, st, side, read_pose_list(req.poses, scene))
    if out.exists() and out.stat().st_size > 0 and not req.force:
        raise InputError(f"{out}: exists; use --resume to continue that run or --force to overwrite it")
    scene = load_scene(req.scene or DEFAULT_SCENE)
    poses = read_pose_list(req.poses, scene)
    st = settings_from(req, scene)
    if req.samples is None:
        st.samples = default_samples
    return Prepared(req, scene, st, None, poses)


def read_pose_list(path, scene) -> tuple | None:
    """A --poses list (``studies.planning.load_poses``) checked against the scene's plates:
    (counts, plates, document), None without one; a one-line InputError otherwise."""
    if not path:
        return None
    from planecal.studies.planning import load_poses
    counts, plates, doc = load_poses(path)
    if len(counts) == 0:
        raise InputError(f"{path}: the pose list is empty")
    if plates.min() < 0 or plates.max() >= len(scene.plates):
        raise InputError(f"{path}: plate numbers must be 0..{len(scene.plates) - 1} for scene "
                         f"{scene.name}")
    return counts, plates, doc


def rerun_observer(req: SamplingRequest, scene, twin=None):
    """The Rerun observer of a run (``planecal.present.rerun.sampling_observer``): a
    recording (--rrd), a live view (--live), both, or None."""
    if not (req.rrd or req.live):
        return None
    from planecal.present.rerun import sampling_observer
    live = None
    if req.live:
        from planecal.present.rerun.live import LiveOptions
        if req.live_port == req.live_web_port:
            raise InputError(f"--live-port and --live-web-port: both {req.live_port}")
        live = LiveOptions(req.live_port, req.live_web_port)
    obs = sampling_observer(req.rrd, scene=scene, twin=twin, live=live)
    if obs.live is not None:
        print(obs.live.describe(), file=sys.stderr, flush=True)
    return obs


def observer_summary(obs) -> dict:
    """The summary's record of the observer: the recording's path, the live view's
    addresses and the motion it dropped."""
    out = {}
    if obs is None:
        return out
    if obs.path is not None:
        out["rrd"] = str(obs.path)
    if obs.live is not None:
        out["live"] = {"grpc_url": obs.live.grpc_url, "web_url": obs.live.web_url,
                       "dropped_ticks": obs.dropped_ticks}
    return out


def pose_list_planner(req: SamplingRequest, poses, scene, settings: RunSettings, checker,
                      model=None, params_path: str | None = None):
    """With --poses (``poses``: ``Prepared.poses``): a planner serving the planned list,
    each entry approached from its side, a list made from the nominal cell aimed with the
    result the run aims with (``params_path``, --params or a resumed run's sidecar's:
    ``aim_list``; entries already in the sample file of a resumed run are skipped, as often as they
    are there); the run's target becomes the list's length unless --samples asks for
    fewer. None without --poses."""
    if poses is None:
        return None
    import numpy as np

    from planecal.io.samples import read_samples
    from planecal.sampling.planner import ListPlanner
    from planecal.studies.planning import approach_of

    path = req.poses
    counts, plates, doc = poses
    approach = approach_of(doc, len(counts))
    counts = aim_list(path, doc, counts, plates, scene, model, params_path)
    n = len(counts)
    out = Path(req.out)
    if req.resume and out.exists() and out.stat().st_size > 0:
        try:
            done = read_samples(out).qe
        except InputError:  # no sample yet
            done = np.zeros((0, 6), np.int64)
        keep = np.ones(n, bool)
        for c in done:  # each sample taken takes one entry of its counts
            hit = np.flatnonzero(keep & np.all(counts == c, axis=1))
            if len(hit):
                keep[hit[0]] = False
        counts, plates, approach = counts[keep], plates[keep], approach[keep]
    if req.samples is None:
        settings.samples = n
    elif settings.samples > n:
        raise InputError(f"--samples {settings.samples} is more than the {n} poses in {path}")
    return ListPlanner(scene, counts, plates, checker, model, approach)


def aim_list(path, doc: dict, counts, plates, scene, model, params_path):
    """A pose list's counts as the run takes them: a list made from the nominal cell
    (its ``aimed_with`` null) aimed with the run's model (--params: ``poses.aim_counts``,
    the same sensor pose on the same plate where the calibration puts the plate and the
    sensor); a list aimed with a result as it is, with that result only."""
    if model is None or not params_path:
        return counts
    made = doc.get("aimed_with")
    if made is None:
        from planecal.sampling.poses import aim_counts
        return aim_counts(scene, counts, plates, None, model)[0]
    if Path(str(made)).resolve() != Path(params_path).resolve():
        raise InputError(f"{path}: aimed with {made}; run it with --params {made}, or plan "
                         f"again with --params {params_path}")
    return counts


def session_for(req: SamplingRequest, planner=None, observer=None, extra=None,
                hold_while_planning: bool = False, model=None) -> Session:
    """The session the request describes (start and end moves, resume, planning, the
    model it aims with: ``model`` = ``command_model``'s (model, record))."""
    extra = dict(extra or {})
    if planner is not None:  # a resumed run finds its pose list in the sidecar
        extra["poses"] = str(Path(req.poses).resolve())
    cm, rec = model if model is not None else (None, None)
    if rec:
        extra["command"] = rec
    return Session(out=Path(req.out), start=req.start, end=req.end, resume=req.resume,
                   background=not req.foreground, hold_while_planning=hold_while_planning,
                   planner=planner, observer=observer, extra=extra or None, model=cm)


def command_model(req: SamplingRequest, scene, side=None):
    """What the run aims with (``poses.CommandModel``): the scene's nominal cell, or
    --params' result, with robot.json's encoder zeros or --encoder-offsets' (a resumed
    run takes them from its sidecar). None for the nominal model. Returns (model, the
    sidecar's record of it)."""
    import numpy as np

    from planecal.io.params import load_json
    from planecal.jobs.results import read_result
    from planecal.model.scene import nominal_params
    from planecal.sampling.poses import CommandModel

    rec = (side or {}).get("command") or {}
    params_path = rec.get("params") if side is not None else req.params
    offsets_path = rec.get("encoder_offsets") if side is not None else req.encoder_offsets
    if side is not None and (req.params or req.encoder_offsets):
        print("note: --resume aims with the model of its sidecar; ignoring --params and "
              "--encoder-offsets", file=sys.stderr)
    if not params_path and not offsets_path:
        return None, None
    params = (read_result(params_path, scene).params  # a result of this cell
              if params_path else nominal_params(scene))
    qe0 = scene.robot.qe0.copy()
    if offsets_path:
        doc = load_json(offsets_path)
        counts = doc.get("qe0_counts") if isinstance(doc, dict) else None
        if (not isinstance(counts, list) or len(counts) != 6
                or not all(isinstance(v, int) and not isinstance(v, bool) for v in counts)):
            raise InputError(f"{offsets_path}: qe0_counts: six integer counts expected "
                             "(planecal export --out writes them)")
        qe0 = np.array(counts, float)
        params = params.copy()
        params.joint_offsets = np.zeros(6)  # realised by the encoder zeros
    rec = {"params": str(Path(params_path).resolve()) if params_path else None,
           "encoder_offsets": str(Path(offsets_path).resolve()) if offsets_path else None}
    return CommandModel(params, qe0), rec


# the seed's live validation (8.2 before, 8.4 after calibration; 30 poses at 80 mm each):
# (mean, spread) of the readings in mm, with the sensor housing parallel to the plate
# ("fixed": beam along the plate normal) or random orientation
SEED_FIXED_DISTANCE = {("before", "fixed"): (72.49, 2.94), ("before", "random"): (71.14, 7.41),
                       ("after", "fixed"): (80.48, 2.45), ("after", "random"): (80.82, 3.47)}


def fixed_distance_summary(out, settings: RunSettings, command_record) -> dict:
    """A fixed-distance run's readings (live validation, seed 8.2 and 8.4): what was
    commanded, their mean, spread (max - min) and std, and the seed's own figures for the
    same kind of run (before or after calibration, fixed or random orientation)."""
    import numpy as np

    from planecal.io.samples import read_samples
    d = read_samples(out).d_mm
    pose = settings.pose
    orientation = "fixed" if pose.cone_deg == 0 and pose.roll_deg == 0 else "random"
    when = "after" if command_record else "before"
    seed_mean, seed_spread = SEED_FIXED_DISTANCE[when, orientation]
    return {"commanded_mm": pose.fixed_distance_mm, "readings": int(len(d)),
            "mean_mm": round(float(d.mean()), 4), "spread_mm": round(float(np.ptp(d)), 4),
            "std_mm": round(float(d.std(ddof=1)), 4) if len(d) > 1 else None,
            "orientation": orientation, "calibration": when,
            "seed": {"mean_mm": seed_mean, "spread_mm": seed_spread, "poses": 30,
                     "commanded_mm": 80.0,
                     "where": "seed 8.2 (before) / 8.4 (after), Figures 55-56 / 60-61"}}
