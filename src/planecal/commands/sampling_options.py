"""The sampling options ``planecal rehearse`` and ``planecal sample`` share: their flags,
the run settings from them (or from a sidecar on ``--resume``), the planned pose list
(``--poses``), the Rerun observer (``--rrd``) and the session they describe."""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from planecal.base.errors import InputError
from planecal.commands.value_options import (MAX_SAMPLES, MAX_TRIES, count, port,
                                             port_or_zero, seed)
from planecal.sampling.laserread import LaserSettings
from planecal.sampling.observer import RecordingObserver
from planecal.sampling.poses import IK_CHOICES, PLATE_CHOICES
from planecal.sampling.run import RunSettings
from planecal.sampling.runfiles import load_sidecar, sidecar_path
from planecal.sampling.session import Session


def finite_float(text: str) -> float:
    """argparse type: a finite number (``nan``, ``inf`` refused with the option named)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return v


def add_sampling_arguments(p: argparse.ArgumentParser, default_samples: int = 150) -> None:
    p.add_argument("--out", required=True, metavar="RUN.tsv",
                   help="sample file to write (its sidecar is RUN.tsv.json)")
    p.add_argument("--scene", default=None, help="scene name or JSON path (default thesis_final)")
    p.add_argument("--samples", type=count(MAX_SAMPLES), default=None,
                   help=f"number of samples (default {default_samples}; with --resume: a new target)")
    p.add_argument("--seed", type=seed, default=None, help="random seed of the poses (default 0)")
    p.add_argument("--cone-deg", type=finite_float, default=None,
                   help="half-angle of the beam cone about the plate normal (default: the scene's)")
    p.add_argument("--fixed-distance-mm", type=finite_float, default=None,
                   help="measure at this distance instead of a random one")
    p.add_argument("--distance-mm", type=finite_float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="range of random distances (default: the scene's)")
    p.add_argument("--roll-deg", type=finite_float, default=None,
                   help="random rotation about the beam within +-this (default 180: any)")
    p.add_argument("--margin-mm", type=finite_float, default=None,
                   help="keep the laser spot this far inside the plate edges (default 25)")
    p.add_argument("--plate-choice", choices=PLATE_CHOICES, default=None,
                   help="multi-plate scenes: plate per sample (default round_robin)")
    p.add_argument("--ik-choice", choices=IK_CHOICES, default=None,
                   help="IK solution per pose: wrist = the wrist branch changes at random, "
                        "p 0.1 per pose (seed 7.1.2: large joint changes), nearest = the "
                        "nearest to the current configuration (default wrist)")
    p.add_argument("--clearance-mm", type=finite_float, default=None,
                   help="collision clearance (default 10)")
    p.add_argument("--laser-max-reads", type=count(MAX_TRIES), default=None,
                   help="give a pose up after this many laser reads without a stable buffer "
                        "(default 1000)")
    p.add_argument("--max-attempts", type=count(MAX_TRIES), default=None,
                   help="stop after this many poses rejected in a row (default 500)")
    p.add_argument("--start", choices=("here", "calibration", "home"), default="here",
                   help="move there before sampling (default: sample from where the robot is)")
    p.add_argument("--end", choices=("stay", "calibration", "home"), default="stay",
                   help="move there after a complete run (default stay)")
    p.add_argument("--resume", action="store_true",
                   help="continue the run in --out with the scene and settings of its sidecar")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    p.add_argument("--decimal-comma", action="store_true",
                   help="write distances with a decimal comma (92,520000), as the seed's "
                        "LabVIEW tools do; readers accept both; a resumed run keeps its file's")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="record the run for Rerun (planecal view FILE opens it)")
    p.add_argument("--live", action="store_true",
                   help="stream the run to a Rerun viewer as it happens (the recording's "
                        "blueprint): a web viewer on --live-web-port, the stream on "
                        "127.0.0.1:--live-port; the real-time loop never waits for it")
    p.add_argument("--live-port", type=port, default=9876,
                   help="--live: the stream's gRPC port on 127.0.0.1 (default %(default)s)")
    p.add_argument("--live-web-port", type=port_or_zero, default=9090,
                   help="--live: the web viewer's port (0: none, connect a native viewer: "
                        "rerun rerun+http://127.0.0.1:PORT/proxy) (default %(default)s)")
    p.add_argument("--params", default=None, metavar="RESULT.json",
                   help="aim with this calibration result (its sensor pose, planes and joint "
                        "offsets) instead of the scene's nominal values: live validation "
                        "(seed 8.2, 8.4)")
    p.add_argument("--encoder-offsets", default=None, metavar="FD11.json",
                   help="the encoder offsets loaded into the controller (planecal export "
                        "--out): joint angles become counts with them; with --params its "
                        "joint offsets are taken as realised by them, not added again")
    p.add_argument("--poses", default=None, metavar="POSES.json",
                   help="visit this planned pose list (planecal plan) instead of random poses; "
                        "--samples defaults to its length")
    p.add_argument("--foreground", action="store_true",
                   help="plan poses in this process only (default: plan the next pose in a "
                        "forked process while the robot moves)")


SETTING_FLAGS = ("scene", "seed", "cone_deg", "fixed_distance_mm", "distance_mm", "roll_deg",
                 "margin_mm", "plate_choice", "ik_choice", "clearance_mm", "laser_max_reads",
                 "max_attempts")


def settings_from_args(args, scene) -> RunSettings:
    """Run settings for a new run: the scene's sampling defaults, overridden by flags."""
    st = RunSettings.for_scene(scene, seed=0 if args.seed is None else args.seed)
    pose = st.pose
    if args.cone_deg is not None:
        pose.cone_deg = args.cone_deg
    if args.distance_mm is not None:
        pose.distance_mm = tuple(args.distance_mm)
        if pose.distance_mm[0] > pose.distance_mm[1]:
            raise InputError(f"--distance-mm: LO {pose.distance_mm[0]} is above HI {pose.distance_mm[1]}")
    pose.fixed_distance_mm = args.fixed_distance_mm
    if args.roll_deg is not None:
        pose.roll_deg = args.roll_deg
    if args.margin_mm is not None:
        if args.margin_mm < 0:
            raise InputError(f"--margin-mm must be >= 0, got {args.margin_mm}")
        pose.margin_m = args.margin_mm * 1e-3
    if args.plate_choice is not None:
        pose.plate_choice = args.plate_choice
    if args.ik_choice is not None:
        pose.ik_choice = args.ik_choice
    pose.check(scene)
    laser = LaserSettings()
    if args.laser_max_reads is not None:
        if args.laser_max_reads < laser.buffer_len:
            raise InputError(f"--laser-max-reads must be at least {laser.buffer_len} (the buffer)")
        laser.max_reads = args.laser_max_reads
    st.laser = laser
    if args.samples is not None:
        st.samples = args.samples
    if st.samples < 1:
        raise InputError(f"--samples must be at least 1, got {st.samples}")
    if args.clearance_mm is not None:
        if args.clearance_mm < 0:
            raise InputError(f"--clearance-mm must be >= 0, got {args.clearance_mm}")
        st.clearance_m = args.clearance_mm * 1e-3
    if args.max_attempts is not None:  # 1 .. MAX_TRIES (its argparse type)
        st.max_attempts = args.max_attempts
    st.decimal_comma = bool(args.decimal_comma)
    return st


def recorded_files(side: dict | None) -> list:
    """The files a run's sidecar records (scene, pose list, aiming model, truth file, error
    profile file): what a resumed run reads."""
    if not isinstance(side, dict):
        return []
    twin = side.get("twin") if isinstance(side.get("twin"), dict) else {}
    cmd = side.get("command") if isinstance(side.get("command"), dict) else {}
    out = [side.get("scene_path"), side.get("poses"), cmd.get("params"),
           cmd.get("encoder_offsets"), twin.get("truth_file"), twin.get("errors")]
    return [p for p in out if isinstance(p, str) and p and ("/" in p or p.endswith(".json"))]


def run_files(args):
    """What a sampling run reads and writes (``commands.io_options``), for the output guard:
    the sample file, its sidecar and lock, the recording; the pose list, the aiming model
    and the scene, or on --resume those its sidecar records."""
    from planecal.commands.io_options import (SIDECAR_FORMAT, Files, lock_output, rrd_output,
                                              sample_file_is_ours, scene_inputs)
    from planecal.formats.base import read_json

    out = Path(args.out)
    side = None
    if args.resume:
        try:
            side = read_json(sidecar_path(out), "run sidecar")
        except InputError:
            side = None  # its reader says why, later
        side = side if isinstance(side, dict) else None
    f = Files().read(args.poses, args.params, args.encoder_offsets, *recorded_files(side),
                     *scene_inputs(args.scene if side is None else side.get("scene_path")))
    hint = "use --resume to continue that run or --force to overwrite it"
    f.write(out, "--out", (sample_file_is_ours,), keep=args.resume, hint=hint)
    f.write(sidecar_path(out), "--out's sidecar", SIDECAR_FORMAT, keep=args.resume, hint=hint)
    lock_output(f, out, "--out")
    rrd_output(f, args.rrd)
    return f


def prepare(args, default_samples: int = 150):
    """(scene, settings, sidecar or None) for a new run or a resumed one; refuses to
    overwrite an existing sample file without --resume or --force, and to continue a
    sample file with a line that is not a sample (nothing is appended after it). The
    outputs were checked before the run (``run_files``, the output guard)."""
    from planecal.io.samples import check_continuable
    from planecal.model.scene import DEFAULT_SCENE, load_scene

    out = Path(args.out)
    if args.resume:
        side = load_sidecar(out)
        if not out.exists():
            raise InputError(f"{out}: the sample file of the run to resume is missing")
        check_continuable(out)
        given = [f"--{f.replace('_', '-')}" for f in SETTING_FLAGS if getattr(args, f) is not None]
        if given:
            print(f"note: --resume takes the scene and settings from {sidecar_path(out)}; "
                  f"ignoring {' '.join(given)}", file=sys.stderr)
        st = RunSettings.from_sidecar(side, str(sidecar_path(out)))
        if side.get("poses") and getattr(args, "poses", None) is None:
            args.poses = side["poses"]
        if args.samples is not None:  # 1 .. MAX_SAMPLES (its argparse type)
            st.samples = args.samples
        scene = load_scene(st.scene)
        st.pose.check(scene)
        return scene, st, side
    if out.exists() and out.stat().st_size > 0 and not args.force:
        raise InputError(f"{out}: exists; use --resume to continue that run or --force to overwrite it")
    scene = load_scene(args.scene or DEFAULT_SCENE)
    st = settings_from_args(args, scene)
    if args.samples is None:
        st.samples = default_samples
    return scene, st, None


def rerun_observer(args, scene, twin=None) -> RecordingObserver | None:
    """The Rerun observer of a run (``planecal.present.rerun.sampling_observer``): a
    recording (--rrd), a live view (--live), both, or None."""
    if not (args.rrd or args.live):
        return None
    from planecal.present.rerun import sampling_observer
    live = None
    if args.live:
        from planecal.present.rerun.live import LiveOptions
        if args.live_port == args.live_web_port:
            raise InputError(f"--live-port and --live-web-port: both {args.live_port}")
        live = LiveOptions(args.live_port, args.live_web_port)
    obs = sampling_observer(args.rrd, scene=scene, twin=twin, live=live)
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


def pose_list_planner(args, scene, settings: RunSettings, checker, model=None):
    """With --poses: a planner serving the planned list (poses already in the sample file
    of a resumed run are skipped); the run's target becomes the list's length unless
    --samples asks for fewer. None without --poses."""
    path = getattr(args, "poses", None)
    if not path:
        return None
    import numpy as np

    from planecal.io.samples import read_samples
    from planecal.sampling.planner import ListPlanner
    from planecal.studies.planning import load_poses

    counts, plates, _ = load_poses(path)
    if len(counts) == 0:
        raise InputError(f"{path}: the pose list is empty")
    if plates.min() < 0 or plates.max() >= len(scene.plates):
        raise InputError(f"{path}: plate numbers must be 0..{len(scene.plates) - 1} for scene "
                         f"{scene.name}")
    n = len(counts)
    if args.resume and Path(args.out).exists() and Path(args.out).stat().st_size > 0:
        try:
            done = read_samples(args.out).qe
        except InputError:  # no sample yet
            done = np.zeros((0, 6), np.int64)
        keep = ~np.any(np.all(counts[:, None, :] == done[None, :, :], axis=2), axis=1) \
            if len(done) else np.ones(n, bool)
        counts, plates = counts[keep], plates[keep]
    if args.samples is None:
        settings.samples = n
    elif settings.samples > n:
        raise InputError(f"--samples {settings.samples} is more than the {n} poses in {path}")
    return ListPlanner(scene, counts, plates, checker, model)


def session_from_args(args, planner=None, observer=None, extra=None,
                      hold_while_planning: bool = False, model=None) -> Session:
    """The session the flags describe (start and end moves, resume, planning, the model it
    aims with: ``model`` = ``command_model``'s (model, record))."""
    extra = dict(extra or {})
    if planner is not None:  # a resumed run finds its pose list in the sidecar
        extra["poses"] = str(Path(args.poses).resolve())
    cm, rec = model if model is not None else (None, None)
    if rec:
        extra["command"] = rec
    return Session(out=Path(args.out), start=args.start, end=args.end, resume=args.resume,
                   background=not args.foreground, hold_while_planning=hold_while_planning,
                   planner=planner, observer=observer, extra=extra or None, model=cm)


def command_model(args, scene, side=None):
    """What the run aims with (``poses.CommandModel``): the scene's nominal cell, or
    --params' result, with robot.json's encoder zeros or --encoder-offsets' (a resumed
    run takes them from its sidecar). None for the nominal model. Returns (model, the
    sidecar's record of it)."""
    import numpy as np

    from planecal.io.params import load_json, load_params
    from planecal.sampling.poses import CommandModel
    from planecal.model.scene import nominal_params

    rec = (side or {}).get("command") or {}
    params_path = rec.get("params") if side is not None else args.params
    offsets_path = rec.get("encoder_offsets") if side is not None else args.encoder_offsets
    if side is not None and (args.params or args.encoder_offsets):
        print("note: --resume aims with the model of its sidecar; ignoring --params and "
              "--encoder-offsets", file=sys.stderr)
    if not params_path and not offsets_path:
        return None, None
    params = load_params(params_path) if params_path else nominal_params(scene)
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
