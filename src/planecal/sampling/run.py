"""The sampling run (seed 7.1), shared by the twin rehearsal and the real cell: the collect
core (``collect``: plan -> drive -> laser -> account) writing a sample file and its
sidecar, resumable. Each sample (the current counts, the distance in mm and the approach
direction, ``approach``) is appended to the sample file (``SampleWriter``: flushed and
fsynced; a new file has the direction group dir1..dir6, a resumed one keeps its own
columns), then the sidecar is updated.
When the enable signal drops no further delta is sent; the run stops cleanly with
``status = "stopped"``: the sample file holds every sample taken, the sidecar is current.

Sidecar ``RUN.tsv.json`` (written atomically -- temp file renamed over it -- after every
sample and when the run ends; the commands add ``"twin"`` or ``"real_cell"``)::

    {"format": "planecal-run/1",
     "status": "running" | "complete" | "stopped" | "gave_up" | "error",
     "stop_reason": str | null,
     "scene": name, "scene_path": str, "robot": name, "seed": int,
     "samples_target": N, "samples": taken so far,
     "cone_deg": beam cone half-angle, "distance_mm": [lo, hi] or the fixed distance,
     "settings": {"pose": {cone_deg, distance_mm, fixed_distance_mm, margin_m, roll_deg,
                           plate_choice, ik_choice},
                  "laser": {buffer_len, spread_mm, max_out_of_range, max_reads},
                  "dwell_ticks", "nominal_step_counts", "max_attempts", "clearance_m",
                  "collision_checking": bool},
     "rejected": {"collision": n, "laser": n, "unreachable": n},
     "laser_give_ups": {"out_of_range": n, "not_stable": n},
     "recent_rejections": the last 50 as {"sample": index, "kind", "reason"},
     "ticks", "robot_time_s", "wall_time_s", "max_step_counts",   (over all sessions)
     "travel_ticks", "read_ticks": of "ticks", moving (legs without dwell) and reading the
       laser (``tour.Clock``); "robot_time_per_sample_s", "travel_per_sample_s",
     "sessions": number of sessions (1 + resumes),
     "rng_state": numpy PCG64 bit-generator state after the last sample,
     "sample_file": file name, "plates": number of plates (plate column written if > 1),
     "updated_utc": ISO time}

``--resume`` reads the sidecar, takes scene and settings from it, counts the samples in the
file (the file wins if a run died between writing a sample and the sidecar), restores the
random generator, and goes on until ``samples_target`` -- from wherever the robot is.
The approach direction starts unknown (0) again: a new session's driver has seen no motion
until each joint moves.
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import numpy as np

from planecal.model.encoder import counts_to_joints, joints_to_counts
from planecal.base.errors import InputError
from planecal.base.interrupts import stop_reason
from planecal.formats.run import SIDECAR_FORMAT
from planecal.io.params import save_json
from planecal.sampling.aim import Aim
from planecal.sampling.collect import Budget, Cursor, DriveAcquirer, Tally, collect
from planecal.sampling.driver import Driver, EnableDropped
from planecal.sampling.laserread import LaserSettings
from planecal.sampling.planner import (BackgroundPlanner, Checker, Plan, PlanSource, Planner,
                                       can_fork)
from planecal.sampling.poses import CommandModel, PoseSettings
from planecal.sampling.runfiles import (RunLock, RunWriteError, count_samples, load_sidecar,
                                        sidecar_path)
from planecal.sampling.steps import DWELL_TICKS
from planecal.sampling.tour import Clock
from planecal.model.scene import Scene

RECENT_REJECTIONS = 50  # kept in the sidecar with their reasons


@dataclass
class RunSettings:
    scene: str
    samples: int = 150
    seed: int = 0
    pose: PoseSettings = field(default_factory=PoseSettings)
    laser: LaserSettings = field(default_factory=LaserSettings)
    dwell_ticks: int = DWELL_TICKS
    nominal_step_counts: int | None = None  # None: the robot's (``Robot.step_counts``)
    max_attempts: int = 500  # poses rejected in a row before the run gives up
    clearance_m: float = 0.01
    collision_checking: bool = True
    decimal_comma: bool = False  # sample file distances as 92,52 (the seed's tools)
    robot_minutes: float | None = None  # the run ends complete once its robot time is this

    @classmethod
    def for_scene(cls, scene: Scene, samples: int = 150, seed: int = 0) -> "RunSettings":
        """Defaults with the scene's own sampling cone and distance range, and steps one
        count below the robot's step limit (the MC70's FD11: 50 of 51)."""
        return cls(scene=str(scene.path), samples=samples, seed=seed,
                   pose=PoseSettings(cone_deg=scene.cone_deg,
                                     distance_mm=tuple(scene.distance_mm)),
                   nominal_step_counts=scene.robot.step_counts)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["pose"]["distance_mm"] = list(self.pose.distance_mm)
        for k in ("scene", "samples", "seed"):
            d.pop(k)
        return d

    @classmethod
    def from_sidecar(cls, side: dict, where: str = "<sidecar>") -> "RunSettings":
        try:
            s = side["settings"]
            pose = dict(s["pose"])
            pose["distance_mm"] = tuple(pose["distance_mm"])
            pose.setdefault("ik_choice", "nearest")  # runs recorded before the choice existed
            scene = side.get("scene_path")
            if not scene or not Path(scene).exists():  # moved checkout: the scene by name
                scene = side["scene"]
            return cls(scene=scene, samples=int(side["samples_target"]),
                       seed=int(side["seed"]), pose=PoseSettings(**pose),
                       laser=LaserSettings(**s["laser"]),
                       **{k: s[k] for k in ("dwell_ticks", "nominal_step_counts", "max_attempts",
                                            "clearance_m", "collision_checking")},
                       decimal_comma=bool(s.get("decimal_comma", False)),
                       robot_minutes=s.get("robot_minutes"))
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(f"{where}: not a planecal run sidecar ({type(e).__name__}: {e})") from None


@dataclass
class RunStats(Tally):
    """The collection's tally plus the run's time and motion figures (all sessions)."""
    ticks: int = 0
    robot_time_s: float = 0.0
    travel_ticks: int = 0  # of ticks: moving (tour.Clock: the legs without their dwell)
    read_ticks: int = 0  # of ticks: reading the laser
    tick_s: float = 0.01
    wall_time_s: float = 0.0
    max_step_counts: int = 0
    sessions: int = 1

    @property
    def stop_reason(self) -> str | None:
        return self.reason

    def per_sample(self) -> dict:
        """Robot time and travel: totals and per sample taken (None before the first)."""
        n = self.samples
        return {"travel_ticks": self.travel_ticks, "read_ticks": self.read_ticks,
                "robot_time_per_sample_s": round(self.robot_time_s / n, 3) if n else None,
                "travel_per_sample_s": round(self.travel_ticks * self.tick_s / n, 3)
                if n else None}

    def summary(self) -> dict:
        return {"samples": self.samples, "rejected_collision": self.rejected["collision"],
                "rejected_laser": self.rejected["laser"],
                "rejected_unreachable": self.rejected["unreachable"],
                "laser_out_of_range": self.laser_give_ups["out_of_range"],
                "laser_not_stable": self.laser_give_ups["not_stable"],
                "max_step_counts": self.max_step_counts, "ticks": self.ticks,
                "robot_time_s": round(self.robot_time_s, 3),
                **self.per_sample(),
                "wall_time_s": round(self.wall_time_s, 3),
                "status": self.status, "stop_reason": self.reason,
                "sessions": self.sessions}


class SamplingRun:
    """One sampling run into ``out`` (and its sidecar). ``driver`` may already have moved
    (e.g. to the calibration position); the run's tick counts include only its own ticks.
    ``resume=True`` continues the run recorded in the sidecar (``settings`` should come from
    ``RunSettings.from_sidecar``). ``background=True`` plans the next pose in a forked
    process while the robot moves (same results, less wall time on a multi-core machine;
    only for a pure planner); with ``hold_while_planning`` the hold delta keeps being
    sent, one per tick, whenever the loop waits for a plan (the real cell: the RT link is
    never left without a message; the twin's robot time then includes that wait).

    ``planner``: where the targets come from; default ``Planner`` (random poses, seed
    7.1.2), e.g. ``ListPlanner`` for a planned pose list. ``model``: what the run aims
    with (``poses.CommandModel``; default the scene's nominal cell)."""

    def __init__(self, driver: Driver, scene: Scene, settings: RunSettings, out,
                 checker: Checker, *, resume: bool = False, background: bool = False,
                 hold_while_planning: bool = False,
                 progress: Callable[[RunStats], None] | None = None,
                 extra: dict | None = None, lock: RunLock | None = None,
                 planner: PlanSource | None = None, model: CommandModel | None = None):
        if checker is None:
            raise ValueError("a collision checker is required")
        if settings.samples < 1:
            raise InputError(f"number of samples must be at least 1, got {settings.samples}")
        self.driver = driver
        self.scene = scene
        self.robot = scene.robot
        if settings.nominal_step_counts is None:
            settings = replace(settings, nominal_step_counts=self.robot.step_counts)
        self.settings = settings
        self.out = Path(out)
        self.checker = checker
        self.progress = progress
        self.extra = dict(extra or {})
        self.lock = lock  # the caller's, held for its session; else taken in run()
        self.observer = driver.observer
        self.model = model or CommandModel.nominal(scene)
        self.planner = planner if planner is not None else Planner(scene, settings.pose, checker,
                                                                   self.model)
        if hold_while_planning and not can_fork():
            raise RuntimeError("holding the RT link while planning needs a forking platform")
        self.background = (background or hold_while_planning) and can_fork() and self.planner.pure
        self.acquirer = DriveAcquirer(driver, settings.laser, settings.nominal_step_counts,
                                      settings.dwell_ticks, hold_while_planning)
        self.stats = RunStats(tick_s=scene.robot.tick_s)
        self._cursor = Cursor(np.zeros(6), np.random.default_rng(settings.seed).bit_generator.state)
        self.recent_rejections: deque = deque(maxlen=RECENT_REJECTIONS)
        self._route_back: dict | None = None  # a resumed run's, from the sidecar
        self.resume = resume
        if resume:
            self._restore(load_sidecar(self.out))

    def _restore(self, side: dict) -> None:
        st = self.stats
        st.rejected.update(side.get("rejected", {}))
        st.laser_give_ups.update(side.get("laser_give_ups", {}))
        st.ticks = int(side.get("ticks", 0))
        st.travel_ticks = int(side.get("travel_ticks", 0))
        st.read_ticks = int(side.get("read_ticks", 0))
        st.wall_time_s = float(side.get("wall_time_s", 0.0))
        st.max_step_counts = int(side.get("max_step_counts", 0))
        st.sessions = int(side.get("sessions", 1)) + 1
        st.samples = count_samples(self.out)
        self.recent_rejections.extend(side.get("recent_rejections", []))
        if side.get("rng_state"):
            self._cursor.rng_state = side["rng_state"]
        self._route_back = side.get("route_back")
        self._cursor.aim = Aim.from_dict(side.get("aim"))
        st.robot_time_s = st.ticks * self.robot.tick_s

    # -- sidecar
    def sidecar(self) -> dict:
        st, pose = self.stats, self.settings.pose
        side = {
            "format": SIDECAR_FORMAT, "status": st.status, "stop_reason": st.reason,
            "scene": self.scene.name,
            "scene_path": str(Path(self.scene.path).resolve()) if self.scene.path else None,
            "robot": self.robot.name, "seed": self.settings.seed,
            "samples_target": self.settings.samples, "samples": st.samples,
            "cone_deg": pose.cone_deg,
            "distance_mm": (pose.fixed_distance_mm if pose.fixed_distance_mm is not None
                            else list(pose.distance_mm)),
            "settings": self.settings.to_dict(),
            "rejected": dict(st.rejected), "laser_give_ups": dict(st.laser_give_ups),
            "recent_rejections": list(self.recent_rejections),
            "ticks": st.ticks, "robot_time_s": round(st.robot_time_s, 3), **st.per_sample(),
            "wall_time_s": round(st.wall_time_s, 3), "max_step_counts": st.max_step_counts,
            "sessions": st.sessions, "rng_state": self._cursor.rng_state,
            "route_back": self._route_back_counts(), "aim": self._cursor.aim.to_dict(),
            "sample_file": self.out.name, "plates": len(self.scene.plates),
            "updated_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        }
        side.update(self.extra)
        return side

    def _route_back_counts(self) -> dict | None:
        """The way the robot came in (``Cursor.back``) as counts, with the counts it
        leads back from: a resumed run takes it only if the robot is still there."""
        c = self._cursor
        if not c.back:
            return None
        qe0 = self.model.qe0
        return {"from_counts": joints_to_counts(self.robot, c.q, qe0).tolist(),
                "counts": [joints_to_counts(self.robot, q, qe0).tolist() for q in c.back]}

    def _save(self) -> None:
        # no fsync: resume recounts the samples from the (fsynced) sample file
        save_json(sidecar_path(self.out), self.sidecar())

    def _account(self) -> None:
        st, drv = self.stats, self.driver
        st.ticks = self._ticks0 + drv.ticks - self._drv_ticks0
        st.robot_time_s = st.ticks * self.robot.tick_s
        st.wall_time_s = self._wall0 + time.perf_counter() - self._t_wall
        st.max_step_counts = max(self._step0, drv.max_step_counts)
        st.travel_ticks = self._travel0 + self._clock.travel_ticks
        st.read_ticks = self._read0 + self._clock.read_ticks

    def _spent_s(self) -> float:
        """The run's robot time so far [s], every session's (``RunSettings.robot_minutes``)."""
        self._account()
        return self.stats.robot_time_s

    # -- Recorder (the collect core's)
    def sample(self, index: int, counts: np.ndarray, d_mm: float, plan: Plan,
               direction: np.ndarray) -> None:
        # the sidecar first (with the random state past this sample's plan), then the line:
        # a kill between the two leaves the sidecar one ahead of the file, and the resumed
        # run (the file's count wins) plans a new pose instead of drawing this one again
        self._account()
        self._save()
        self._writer.write(counts, d_mm, plan.plate, direction)
        self.observer.on_sample(index, counts, d_mm, plan.plate)

    def reject(self, kind: str, q, reason: str) -> None:
        self.recent_rejections.append({"sample": self.stats.samples, "kind": kind,
                                       "reason": reason})
        self.observer.on_reject(q, reason)
        self._account()

    # -- the loop
    def run(self) -> RunStats:
        from planecal.io.samples import SampleWriter

        st, s, drv = self.stats, self.settings, self.driver
        self._t_wall = time.perf_counter()
        self._wall0, self._ticks0, self._step0 = st.wall_time_s, st.ticks, st.max_step_counts
        self._drv_ticks0 = drv.ticks
        self._travel0, self._read0 = st.travel_ticks, st.read_ticks
        self._clock = Clock(self.acquirer, np.zeros(6, np.int64),  # counts set at the start
                            s.nominal_step_counts, s.dwell_ticks)
        drv.max_step_counts = 0
        own_lock = RunLock(self.out) if self.lock is None else None
        try:
            self._writer = SampleWriter(self.out, append=self.resume,
                                        with_plate=len(self.scene.plates) > 1,
                                        decimal_comma=self.settings.decimal_comma,
                                        with_direction=True)
        except BaseException:
            if own_lock:
                own_lock.close()
            raise
        bg = None
        st.status, st.reason, st.in_a_row = "running", None, 0
        try:
            drv.start()
            self._cursor.q = counts_to_joints(self.robot, drv.commanded_counts, self.model.qe0)
            rb = self._route_back  # the way back of the last session, where the robot is
            if rb and np.array_equal(rb["from_counts"], drv.commanded_counts):
                self._cursor.back = tuple(counts_to_joints(self.robot, c, self.model.qe0)
                                          for c in rb["counts"])
            self._save()  # (with the way back: a session stopped before a sample keeps it)
            if st.samples < s.samples:
                res = self.checker.check_config(self._cursor.q)
                if not res.ok:
                    st.status = "gave_up"
                    st.reason = ("the robot's configuration is not collision-free in the "
                                 "model" + (f" ({res.pair[0]} - {res.pair[1]})" if res.pair
                                            else "") + ": no path from it can be certified")
                    return st
                if self.background:
                    bg = BackgroundPlanner(self.planner)
            self._clock.counts = np.asarray(drv.commanded_counts, np.int64).copy()
            collect(self.planner, self._clock, self, s.samples, self._cursor, st,
                    s.max_attempts, background=bg, on_progress=self.progress,
                    budget=Budget.of(s.robot_minutes, self._spent_s, self._clock,
                                     s.laser.max_reads, self.robot.tick_s))
        except EnableDropped:
            st.status = "stopped"
            st.reason = getattr(drv.enable, "reason", None) or "enable signal dropped"
        except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM/SIGHUP (base.interrupts)
            st.status, st.reason = "stopped", stop_reason(e)
            raise
        except OSError as e:  # writing the sample file or the sidecar (disk full, ...)
            st.status, st.reason = "error", f"cannot write: {e.strerror or e}"
            raise RunWriteError(
                f"cannot write {e.filename or self.out}: {e.strerror or e}; the "
                f"{count_samples(self.out)} samples taken are in {self.out}: make room and "
                "continue with --resume") from None
        except Exception as e:  # link or laser failure: keep the record straight, re-raise
            st.status, st.reason = "error", f"{type(e).__name__}: {e}"
            raise
        finally:
            if bg:
                bg.close()
            self._writer.close()
            # the file is the record: a Ctrl-C between writing a line and counting it
            # must not leave the sidecar one short
            st.samples = count_samples(self.out)
            self._account()
            try:
                self._save()
            except OSError:  # the disk is still full: the last sidecar stands (the file wins)
                pass
            if own_lock:
                own_lock.close()
        return st

