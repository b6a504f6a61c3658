"""What ``planecal rehearse`` and ``planecal sample`` share: their sampling options, run
settings from them (or from a sidecar on ``--resume``), the progress display, the optional
Rerun observer, and the session itself (start move, the run, end move, JSON summary).

Rerun hook: ``--rrd FILE`` imports ``planecal.rerun_log`` and calls
``planecal.rerun_log.sampling_observer(path, scene=scene, twin=twin_or_None)``, which must
return an ``Observer`` (``planecal.sampling.run.Observer``; an optional ``close()`` is
called at the end). Without that module ``--rrd`` is refused before anything moves.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from planecal.errors import InputError
from planecal.sampling.laserread import LaserSettings
from planecal.sampling.poses import PLATE_CHOICES
from planecal.sampling.run import (Driver, EnableDropped, PathBlocked, RunLock, RunSettings,
                                   RunStats, SamplingRun, load_sidecar, move_home,
                                   move_to_calibration, sidecar_path)


def add_sampling_arguments(p: argparse.ArgumentParser, default_samples: int = 150) -> None:
    p.add_argument("--out", required=True, metavar="RUN.tsv",
                   help="sample file to write (its sidecar is RUN.tsv.json)")
    p.add_argument("--scene", default=None, help="scene name or JSON path (default thesis_final)")
    p.add_argument("--samples", type=int, default=None,
                   help=f"number of samples (default {default_samples}; with --resume: a new target)")
    p.add_argument("--seed", type=int, default=None, help="random seed of the poses (default 0)")
    p.add_argument("--cone-deg", type=float, default=None,
                   help="half-angle of the beam cone about the plate normal (default: the scene's)")
    p.add_argument("--fixed-distance-mm", type=float, default=None,
                   help="measure at this distance instead of a random one")
    p.add_argument("--distance-mm", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="range of random distances (default: the scene's)")
    p.add_argument("--roll-deg", type=float, default=None,
                   help="random rotation about the beam within +-this (default 180: any)")
    p.add_argument("--margin-mm", type=float, default=None,
                   help="keep the laser spot this far inside the plate edges (default 25)")
    p.add_argument("--plate-choice", choices=PLATE_CHOICES, default=None,
                   help="multi-plate scenes: plate per sample (default round_robin)")
    p.add_argument("--clearance-mm", type=float, default=None,
                   help="collision clearance (default 10)")
    p.add_argument("--laser-max-reads", type=int, default=None,
                   help="give a pose up after this many laser reads without a stable buffer "
                        "(default 1000)")
    p.add_argument("--max-attempts", type=int, default=None,
                   help="stop after this many poses rejected in a row (default 500)")
    p.add_argument("--start", choices=("here", "calibration", "home"), default="here",
                   help="move there before sampling (default: sample from where the robot is)")
    p.add_argument("--end", choices=("stay", "calibration", "home"), default="stay",
                   help="move there after a complete run (default stay)")
    p.add_argument("--resume", action="store_true",
                   help="continue the run in --out with the scene and settings of its sidecar")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="record the run for Rerun (needs planecal.rerun_log)")
    p.add_argument("--poses", default=None, metavar="POSES.json",
                   help="visit this planned pose list (planecal plan) instead of random poses; "
                        "--samples defaults to its length")
    p.add_argument("--foreground", action="store_true",
                   help="plan poses in this process only (default: plan the next pose in a "
                        "forked process while the robot moves)")


SETTING_FLAGS = ("scene", "seed", "cone_deg", "fixed_distance_mm", "distance_mm", "roll_deg",
                 "margin_mm", "plate_choice", "clearance_mm", "laser_max_reads", "max_attempts")


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
    if args.max_attempts is not None:
        if args.max_attempts < 1:
            raise InputError(f"--max-attempts must be at least 1, got {args.max_attempts}")
        st.max_attempts = args.max_attempts
    return st


def prepare(args, default_samples: int = 150):
    """(scene, settings, sidecar or None) for a new run or a resumed one; refuses to
    overwrite an existing sample file without --resume or --force."""
    from planecal.scene import DEFAULT_SCENE, load_scene

    out = Path(args.out)
    if args.resume:
        side = load_sidecar(out)
        if not out.exists():
            raise InputError(f"{out}: the sample file of the run to resume is missing")
        given = [f"--{f.replace('_', '-')}" for f in SETTING_FLAGS if getattr(args, f) is not None]
        if given:
            print(f"note: --resume takes the scene and settings from {sidecar_path(out)}; "
                  f"ignoring {' '.join(given)}", file=sys.stderr)
        st = RunSettings.from_sidecar(side, str(sidecar_path(out)))
        if side.get("poses") and getattr(args, "poses", None) is None:
            args.poses = side["poses"]
        if args.samples is not None:
            if args.samples < 1:
                raise InputError(f"--samples must be at least 1, got {args.samples}")
            st.samples = args.samples
        scene = load_scene(st.scene)
        st.pose.check(scene)
        return scene, st, side
    if out.exists() and out.stat().st_size > 0 and not args.force:
        raise InputError(f"{out}: exists; use --resume to continue that run or --force to overwrite it")
    if out.parent and not out.parent.exists():
        raise InputError(f"{out}: directory {out.parent} does not exist")
    scene = load_scene(args.scene or DEFAULT_SCENE)
    st = settings_from_args(args, scene)
    if args.samples is None:
        st.samples = default_samples
    return scene, st, None


def rerun_observer(path, scene, twin=None):
    """The Rerun observer from planecal.rerun_log, or an InputError saying why not."""
    try:
        import planecal.rerun_log as rl
    except ModuleNotFoundError as e:
        if e.name == "planecal.rerun_log":
            raise InputError("--rrd: Rerun logging is not available in this version "
                             "(no planecal.rerun_log module)") from None
        raise InputError(f"--rrd: Rerun logging cannot be loaded: missing module {e.name}") from None
    make = getattr(rl, "sampling_observer", None)
    if make is None:
        raise InputError("--rrd: planecal.rerun_log has no sampling_observer(path, scene, twin); "
                         "cannot record the run")
    return make(path, scene=scene, twin=twin)


class Progress:
    """Progress on stderr: a bar redrawn in place on a TTY, else a plain line every 10 %
    of the samples (and at each stop)."""

    def __init__(self, total: int, stream=None, every_s: float = 0.1):
        self.total = total
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.every_s = every_s
        self._last = 0.0
        self._last_line = -1

    @staticmethod
    def _clock(s: float) -> str:
        s = int(round(s))
        return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"

    def line(self, st: RunStats) -> str:
        r = st.rejected
        return (f"samples {st.samples}/{self.total}  rejected {sum(r.values())} "
                f"(collision {r['collision']}, laser {r['laser']}, unreachable {r['unreachable']})"
                f"  robot time {self._clock(st.robot_time_s)}")

    def __call__(self, st: RunStats) -> None:
        if self.tty:
            now = time.monotonic()
            if now - self._last < self.every_s and st.samples < self.total:
                return
            self._last = now
            width = 24
            k = int(width * st.samples / max(self.total, 1))
            self.stream.write(f"\r[{'#' * k}{'.' * (width - k)}] {self.line(st)}\033[K")
            self.stream.flush()
        else:
            step = max(1, self.total // 10)
            if st.samples != self._last_line and (st.samples % step == 0 or st.samples == self.total):
                self._last_line = st.samples
                print(self.line(st), file=self.stream, flush=True)

    def done(self, st: RunStats) -> None:
        if self.tty:
            self._last = 0.0
            self(st)
            self.stream.write("\n")
        elif st.samples != self._last_line:
            print(self.line(st), file=self.stream, flush=True)
        if st.status != "complete":
            print(f"run {st.status}: {st.stop_reason}", file=self.stream, flush=True)


def pose_list_planner(args, scene, settings: RunSettings, checker):
    """With --poses: a planner serving the planned list (poses already in the sample file
    of a resumed run are skipped); the run's target becomes the list's length unless
    --samples asks for fewer. None without --poses."""
    path = getattr(args, "poses", None)
    if not path:
        return None
    import numpy as np

    from planecal.samples import read_samples
    from planecal.studies.planning import ListPlanner, load_poses

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
    return ListPlanner(scene, counts, plates, checker)


def run_session(args, scene, settings: RunSettings, link, laser, enable, checker, *,
                observer=None, extra=None, hold_while_planning=False) -> tuple[int, dict]:
    """Start move, the sampling run, end move. Returns (exit code, summary): 0 when the run
    completed, 1 when it stopped or gave up (the files are valid either way)."""
    lock = RunLock(args.out)  # before anything moves: no second run on the same file
    try:
        return _session(args, scene, settings, link, laser, enable, checker, observer, extra,
                        hold_while_planning, lock)
    finally:
        lock.close()


def _session(args, scene, settings, link, laser, enable, checker, observer, extra,
             hold_while_planning, lock):
    drv = Driver(link, enable, scene.robot, observer)
    progress = Progress(settings.samples)
    moves = {}
    try:
        drv.start()
        if args.start != "here":
            move = move_home if args.start == "home" else move_to_calibration
            moves["start_ticks"] = move(drv, scene, checker)
    except PathBlocked as e:
        raise InputError(f"--start {args.start}: {e}") from None
    except EnableDropped:
        raise InputError(f"--start {args.start}: enable dropped on the way; nothing sampled") from None
    planner = pose_list_planner(args, scene, settings, checker)
    if planner is not None:  # a resumed run finds its pose list in the sidecar
        extra = {**(extra or {}), "poses": str(Path(args.poses).resolve())}
    run = SamplingRun(drv, laser, scene, settings, args.out, checker, resume=args.resume,
                      background=not args.foreground and planner is None,
                      hold_while_planning=hold_while_planning,
                      progress=progress, extra=extra, lock=lock, planner=planner)
    t0 = time.perf_counter()
    ticks0 = drv.ticks
    try:
        st = run.run()
    finally:
        progress.done(run.stats)
    summary = st.summary()
    summary["session_robot_time_s"] = round((drv.ticks - ticks0) * scene.robot.tick_s, 3)
    if st.status == "complete" and args.end != "stay":
        try:
            move = move_home if args.end == "home" else move_to_calibration
            summary["end_ticks"] = move(drv, scene, checker)
        except (PathBlocked, EnableDropped) as e:
            summary["end_move"] = f"not done: {e or 'enable dropped'}"
    summary.update(moves)
    summary["session_wall_time_s"] = round(time.perf_counter() - t0, 3)
    summary["planning_time_s"] = round(run.plan_time_s, 3)
    summary["out"] = str(args.out)
    summary["sidecar"] = str(sidecar_path(args.out))
    return (0 if st.status == "complete" else 1), summary


def print_summary(summary: dict) -> None:
    print(json.dumps(summary, indent=2))
