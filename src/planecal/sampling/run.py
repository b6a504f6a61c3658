"""The sampling run loop (seed 7.1), shared by the twin rehearsal and the real cell.

It only talks to a ``RobotLink``, a ``Laser``, an ``EnableSignal`` (``planecal.links.base``)
and a collision checker (``check_config(q)`` / ``check_path(q0, q1)`` returning an object
with ``.ok``, like ``planecal.collision.CollisionWorld``). Per sample:

1. draw a random sensor pose (``poses.PoseGenerator``) on a plate, IK nearest to the
   configuration last commanded -> joint target; none within limits: rejected
   ``unreachable``;
2. collision check of the target configuration and of the straight joint-space motion to it
   (the step generator interpolates linearly in counts, hence in joint angles); not clear:
   rejected ``collision``. A rejected pose is replaced by a new draw (the robot does not move);
3. the step generator's rows (``steps.step_path``, <= 50 counts a tick, 5 dwell ticks) are
   sent one per tick with ``link.exchange`` while ``enable.enabled()``;
4. the laser is read, one reading per tick while the hold delta keeps being sent
   (``laserread.read_stable``); no stable reading: rejected ``laser`` (the robot moves on);
5. the sample -- current counts from the last reply and the distance in mm -- is appended
   to the sample file (``SampleWriter``: flushed and fsynced), then the sidecar is updated.

When the enable signal drops no further delta is sent; the run stops cleanly with
``status = "stopped"``: the sample file holds every sample taken, the sidecar is current.

Planning (steps 1-2) can run in a forked process for the next sample while the robot
moves to the current one (``background=True``); the results are the same.

Sidecar ``RUN.tsv.json`` (written atomically -- temp file renamed over it -- after every
sample and when the run ends; the commands add ``"twin"`` or ``"real_cell"``)::

    {"format": "planecal-run/1",
     "status": "running" | "complete" | "stopped" | "gave_up" | "error",
     "stop_reason": str | null,
     "scene": name, "scene_path": str, "robot": name, "seed": int,
     "samples_target": N, "samples": taken so far,
     "cone_deg": beam cone half-angle, "distance_mm": [lo, hi] or the fixed distance,
     "settings": {"pose": {cone_deg, distance_mm, fixed_distance_mm, margin_m, roll_deg,
                           plate_choice},
                  "laser": {buffer_len, spread_mm, max_out_of_range, max_reads},
                  "dwell_ticks", "nominal_step_counts", "max_attempts", "clearance_m",
                  "collision_checking": bool},
     "rejected": {"collision": n, "laser": n, "unreachable": n},
     "laser_give_ups": {"out_of_range": n, "not_stable": n},
     "recent_rejections": the last 50 as {"sample": index, "kind", "reason"},
     "ticks", "robot_time_s", "wall_time_s", "max_step_counts",   (over all sessions)
     "sessions": number of sessions (1 + resumes),
     "rng_state": numpy PCG64 bit-generator state after the last sample,
     "sample_file": file name, "plates": number of plates (plate column written if > 1),
     "updated_utc": ISO time}

``--resume`` reads the sidecar, takes scene and settings from it, counts the samples in the
file (the file wins if a run died between writing a sample and the sidecar), restores the
random generator, and goes on until ``samples_target`` -- from wherever the robot is.
"""
from __future__ import annotations

import os
import time
from collections import deque
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Protocol

import numpy as np

from planecal.encoder import counts_to_joints, joints_to_counts
from planecal.errors import InputError
from planecal.params import load_json, save_json
from planecal.robot import within_limits
from planecal.sampling.laserread import LaserResult, LaserSettings, read_stable
from planecal.sampling.poses import PoseGenerator, PoseSettings, SensorPose
from planecal.sampling.steps import COUNT_LIMIT, DWELL_TICKS, NOMINAL_STEP, max_step, step_path
from planecal.scene import Scene

SIDECAR_FORMAT = "planecal-run/1"
REJECT_KINDS = ("collision", "laser", "unreachable")
RECENT_REJECTIONS = 50  # kept in the sidecar with their reasons


# ----- observer -------------------------------------------------------------------------

class Observer(Protocol):
    """Hooks for logging (e.g. Rerun); the loop never depends on what they do.
    ``q`` are joint angles [rad] (nominal encoder model), counts are int64[6]."""

    def on_tick(self, tick: int, delta: np.ndarray, reference: np.ndarray,
                current: np.ndarray, laser_mm: float | None) -> None: ...

    def on_sample(self, index: int, qe: np.ndarray, d_mm: float, plate: int) -> None: ...

    def on_reject(self, q_target: np.ndarray | None, reason: str) -> None: ...

    def on_path(self, kind: str, q_start: np.ndarray, q_goal: np.ndarray,
                rows: np.ndarray) -> None: ...


class NullObserver:
    """Does nothing; subclass it and override what you need. The driver skips the per-tick
    call unless ``on_tick`` is overridden (or ``wants_ticks`` is set True)."""

    def on_tick(self, tick, delta, reference, current, laser_mm):
        pass

    def on_sample(self, index, qe, d_mm, plate):
        pass

    def on_reject(self, q_target, reason):
        pass

    def on_path(self, kind, q_start, q_goal, rows):
        pass


# ----- driver: the one owner of the link's delta ------------------------------------------

class EnableDropped(Exception):
    """The enable signal dropped: nothing more is sent."""


class PathBlocked(RuntimeError):
    """A requested move (home, calibration position) is not collision-free or reachable."""


class Driver:
    """Sends deltas to a RobotLink one tick at a time and remembers the last one sent, so
    every path (home, calibration position, samples) starts where the last one ended and
    no step ever exceeds the step limit. Before each tick it checks the enable signal and
    raises ``EnableDropped`` instead of sending."""

    def __init__(self, link, enable, robot, observer: Observer | None = None):
        self.link = link
        self.enable = enable
        self.robot = robot
        self.observer = observer or NullObserver()
        wants = getattr(self.observer, "wants_ticks", None)
        if wants is None:
            wants = getattr(type(self.observer), "on_tick", None) is not NullObserver.on_tick
        self._on_tick = self.observer.on_tick if wants else None
        self.delta = np.zeros(robot.n_joints, np.int64)
        self.reference: np.ndarray | None = None
        self.current: np.ndarray | None = None
        self.ticks = 0
        self.max_step_counts = 0

    def start(self) -> None:
        """First exchange: zero delta (commanded = reference), learn reference and current."""
        if self.reference is None:
            self.send(np.zeros(self.robot.n_joints, np.int64))

    def send(self, delta: np.ndarray, laser=None) -> float | None:
        """One tick: send ``delta``; with ``laser``, read it once and return the reading."""
        if not self.enable.enabled():
            raise EnableDropped()
        ref, cur = self.link.exchange(delta)
        self.ticks += 1
        self.delta = delta
        self.reference = ref
        self.current = cur
        reading = laser.read() if laser is not None else None
        if self._on_tick is not None:
            self._on_tick(self.ticks, delta, ref, cur, reading)
        return reading

    def hold(self) -> None:
        """One tick holding the last delta."""
        self.send(self.delta)

    def follow(self, rows: np.ndarray) -> None:
        """Send each row, one per tick (stops, by ``EnableDropped``, when enable drops).
        A path with a step above the robot's limit (51 counts) is refused before anything
        is sent; the step generator never makes one, this is a second line of defence."""
        before = self.delta
        worst = max_step(before, rows)
        if worst > self.robot.max_step_counts:
            raise ValueError(f"refusing a path with a step of {worst} counts "
                             f"(limit {self.robot.max_step_counts})")
        sent = 0
        try:
            for row in rows:
                self.send(row)
                sent += 1
        finally:
            self.max_step_counts = max(self.max_step_counts, max_step(before, rows[:sent]))

    def read_laser(self, laser, settings: LaserSettings) -> LaserResult:
        hold = self.delta
        return read_stable(lambda: self.send(hold, laser), settings)

    @property
    def commanded_counts(self) -> np.ndarray:
        return self.reference.astype(np.int64) + self.delta

    def commanded_q(self) -> np.ndarray:
        return counts_to_joints(self.robot, self.commanded_counts)

    @property
    def robot_time_s(self) -> float:
        return self.ticks * self.robot.tick_s


def plan_move(driver: Driver, qe_goal: np.ndarray, nominal: int = NOMINAL_STEP,
              dwell: int = DWELL_TICKS) -> np.ndarray | None:
    """Rows taking the robot from the last delta to absolute counts ``qe_goal``, or None
    when the goal is outside the 24-bit encoder range."""
    qe_goal = np.asarray(qe_goal, np.int64)
    if np.any(qe_goal < 0) or np.any(qe_goal >= COUNT_LIMIT):
        return None
    goal = qe_goal - driver.reference.astype(np.int64)
    return step_path(driver.delta, goal, nominal, dwell)


def move_to_counts(driver: Driver, qe_goal, checker, kind: str = "move",
                   nominal: int = NOMINAL_STEP, dwell: int = DWELL_TICKS) -> int:
    """A checked move to absolute encoder counts (home, calibration position). Raises
    ``PathBlocked`` if the goal is out of range/limits or the motion is not collision-free;
    ``EnableDropped`` if enable drops on the way. Returns the ticks used."""
    driver.start()
    robot = driver.robot
    qe_goal = np.asarray(qe_goal, np.int64)
    q_goal = counts_to_joints(robot, qe_goal)
    rows = plan_move(driver, qe_goal, nominal, dwell)
    if rows is None:
        raise PathBlocked(f"{kind}: target counts outside the 24-bit encoder range")
    if not within_limits(robot, q_goal):
        raise PathBlocked(f"{kind}: target outside the joint limits")
    q0 = driver.commanded_q()
    for what, res in (("target", checker.check_config(q_goal)),
                      ("path", checker.check_path(q0, q_goal))):
        if not res.ok:
            pair = getattr(res, "pair", None)
            raise PathBlocked(f"{kind}: {what} not collision-free"
                              + (f" ({pair[0]} - {pair[1]})" if pair else ""))
    driver.observer.on_path(kind, q0, q_goal, rows)
    t0 = driver.ticks
    driver.follow(rows)
    return driver.ticks - t0


def move_home(driver: Driver, scene: Scene, checker) -> int:
    """To the scene's home counts (seed: hard-coded encoder values)."""
    home = scene.home_counts if scene.home_counts is not None else scene.robot.home_counts
    return move_to_counts(driver, home, checker, "home")


def move_to_calibration(driver: Driver, scene: Scene, checker) -> int:
    """To the scene's calibration position (near the plates)."""
    if scene.calibration_q is None:
        raise PathBlocked(f"scene {scene.name} defines no calibration position")
    return move_to_counts(driver, joints_to_counts(scene.robot, scene.calibration_q), checker,
                          "calibration")


# ----- settings, sidecar -------------------------------------------------------------------

@dataclass
class RunSettings:
    scene: str
    samples: int = 150
    seed: int = 0
    pose: PoseSettings = field(default_factory=PoseSettings)
    laser: LaserSettings = field(default_factory=LaserSettings)
    dwell_ticks: int = DWELL_TICKS
    nominal_step_counts: int = NOMINAL_STEP
    max_attempts: int = 500  # poses rejected in a row before the run gives up
    clearance_m: float = 0.01
    collision_checking: bool = True

    @classmethod
    def for_scene(cls, scene: Scene, samples: int = 150, seed: int = 0) -> "RunSettings":
        """Defaults with the scene's own sampling cone and distance range."""
        return cls(scene=str(scene.path), samples=samples, seed=seed,
                   pose=PoseSettings(cone_deg=scene.cone_deg,
                                     distance_mm=tuple(scene.distance_mm)))

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
            scene = side.get("scene_path")
            if not scene or not Path(scene).exists():  # moved checkout: the scene by name
                scene = side["scene"]
            return cls(scene=scene, samples=int(side["samples_target"]),
                       seed=int(side["seed"]), pose=PoseSettings(**pose),
                       laser=LaserSettings(**s["laser"]),
                       **{k: s[k] for k in ("dwell_ticks", "nominal_step_counts", "max_attempts",
                                            "clearance_m", "collision_checking")})
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(f"{where}: not a planecal run sidecar ({type(e).__name__}: {e})") from None


def sidecar_path(out: str | Path) -> Path:
    out = Path(out)
    return out.with_name(out.name + ".json")


class RunLock:
    """An exclusive advisory lock (flock) on the sample file, held for a whole session, so
    two runs can never write the same file (one would truncate or interleave the other's
    samples). Taken without truncating; released when closed or when the process ends."""

    def __init__(self, out: str | Path):
        import fcntl
        self.path = Path(out)
        try:
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as e:
            raise InputError(f"{self.path}: cannot open ({e.strerror})") from None
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(self._fd)
            raise InputError(f"{self.path}: another run is writing this file") from None

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # releases the lock
            self._fd = None


def load_sidecar(out: str | Path) -> dict:
    p = sidecar_path(out)
    if not p.exists():
        raise InputError(f"{p}: no run sidecar to resume from")
    side = load_json(p)
    if not isinstance(side, dict) or side.get("format") != SIDECAR_FORMAT:
        raise InputError(f"{p}: not a planecal run sidecar (format {SIDECAR_FORMAT})")
    return side


def count_samples(path: Path) -> int:
    """Complete sample lines in a sample file (header and a partial last line excluded)."""
    if not path.exists():
        return 0
    data = path.read_bytes()
    lines = data.split(b"\n")[:-1]  # the part after the last newline is incomplete
    return sum(1 for ln in lines if ln.strip() and not ln.lstrip().lower().startswith(b"q1"))


@dataclass
class RunStats:
    samples: int = 0
    rejected: dict = field(default_factory=lambda: {k: 0 for k in REJECT_KINDS})
    laser_give_ups: dict = field(default_factory=lambda: {"out_of_range": 0, "not_stable": 0})
    ticks: int = 0
    robot_time_s: float = 0.0
    wall_time_s: float = 0.0
    max_step_counts: int = 0
    sessions: int = 1
    status: str = "running"
    stop_reason: str | None = None

    def summary(self) -> dict:
        return {"samples": self.samples, "rejected_collision": self.rejected["collision"],
                "rejected_laser": self.rejected["laser"],
                "rejected_unreachable": self.rejected["unreachable"],
                "laser_out_of_range": self.laser_give_ups["out_of_range"],
                "laser_not_stable": self.laser_give_ups["not_stable"],
                "max_step_counts": self.max_step_counts, "ticks": self.ticks,
                "robot_time_s": round(self.robot_time_s, 3),
                "wall_time_s": round(self.wall_time_s, 3),
                "status": self.status, "stop_reason": self.stop_reason,
                "sessions": self.sessions}


# ----- planning: pose -> IK -> collision checks ---------------------------------------------

@dataclass
class Plan:
    """The outcome of planning one sample from ``q_start``: the rejected draws (in order:
    (kind, q or None, reason)) and the accepted target (``q`` None when ``budget`` draws
    were all rejected). ``rng_after`` is the generator state after the last draw."""
    index: int
    q_start: np.ndarray
    rejections: list
    rng_after: dict
    q: np.ndarray | None = None
    qe_goal: np.ndarray | None = None
    pose: SensorPose | None = None
    check_time_s: float = 0.0


class Planner:
    """Draws poses until one is reachable and collision-free (configuration and the straight
    joint-space path from ``q_start``), at most ``budget`` draws. Pure: the random state comes
    in and goes out with the plan, so the same request gives the same plan anywhere."""

    def __init__(self, scene: Scene, settings: RunSettings, checker):
        self.robot = scene.robot
        self.poses = PoseGenerator(scene, settings.pose)
        self.checker = checker

    def plan(self, q_start: np.ndarray, index: int, rng_state: dict, budget: int) -> Plan:
        rng = np.random.default_rng()
        rng.bit_generator.state = rng_state
        rejections = []
        t0 = time.perf_counter()
        out = Plan(index, q_start, rejections, rng_state)
        for _ in range(budget):
            plate = self.poses.plate_for(index, rng)
            pose = self.poses.draw(rng, plate)
            q = self.poses.joint_target(pose, q_start)
            if q is None:
                rejections.append(("unreachable", None, "unreachable: no IK solution within limits"))
                continue
            qe = joints_to_counts(self.robot, q)
            if np.any(qe < 0) or np.any(qe >= COUNT_LIMIT):
                rejections.append(("unreachable", q, "unreachable: counts outside the encoder range"))
                continue
            res = self.checker.check_config(q)
            what = "target"
            if res.ok:
                res = self.checker.check_path(q_start, q)
                what = "path"
            if not res.ok:
                pair = getattr(res, "pair", None)
                rejections.append(("collision", q, f"collision ({what})"
                                   + (f": {pair[0]} - {pair[1]}" if pair else "")))
                continue
            out.q, out.qe_goal, out.pose = q, qe, pose
            break
        out.rng_after = rng.bit_generator.state
        out.check_time_s = time.perf_counter() - t0
        return out

    def index_matters(self) -> bool:
        """Whether a plan depends on the sample index (round robin over several plates)."""
        return self.poses.n_plates > 1 and self.poses.settings.plate_choice == "round_robin"


def _planner_worker(conn, parent_end, planner: Planner) -> None:
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the run's to handle, not ours
    # the fork gave us a copy of the run's end of the pipe too: close it, so that the
    # run's death (even SIGKILL) closes the pipe and ends this process (EOF, broken pipe)
    parent_end.close()
    while True:
        try:
            req = conn.recv()
        except (EOFError, OSError):  # the run is gone (closed, or reset with a plan unread)
            break
        if req is None:
            break
        try:
            plan = planner.plan(*req)
        except Exception as e:  # report it in the run's process
            plan = RuntimeError(f"planner: {type(e).__name__}: {e}")
        try:
            conn.send(plan)
        except OSError:  # the run is gone
            break


class BackgroundPlanner:
    """Plans in a forked process. The run asks for the next sample's plan as soon as the
    current target is known (the next path starts there) and the robot moves meanwhile.
    The request is speculative only in the sample index, which matters only for
    round-robin plate choice (after a laser rejection): then the plan made for the other
    index is dropped and the right one is planned. Results are identical to foreground planning (same requests,
    same random states; the checker must be stateless, as CollisionWorld is).

    ``take(req, idle)`` calls ``idle()`` while it waits (the real cell keeps ticking the
    hold delta so the RT link never goes quiet); with ``idle=None`` it just blocks."""

    def __init__(self, planner: Planner):
        import multiprocessing as mp
        ctx = mp.get_context("fork")  # the planner (with its FCL model) is inherited, not pickled
        self.planner = planner
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_planner_worker, args=(child, self._conn, planner),
                                 daemon=True)
        self._proc.start()
        child.close()
        self._pending = None

    def submit(self, *req) -> None:
        self.discard()
        self._conn.send(req)
        self._pending = req

    def take(self, *req, idle: Callable[[], None] | None = None) -> Plan:
        if self._pending is None or not _same_request(self._pending, req,
                                                      self.planner.index_matters()):
            self.submit(*req)
        if idle is not None:
            while not self._conn.poll():
                idle()
        self._pending = None
        plan = self._conn.recv()
        if isinstance(plan, BaseException):
            raise plan
        return plan

    def discard(self) -> None:
        if self._pending is not None:
            self._pending = None
            self._conn.recv()

    def close(self) -> None:
        try:
            self._pending = None
            self._conn.send(None)
        except (BrokenPipeError, OSError):
            pass
        self._proc.join(timeout=2)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()
        self._conn.close()


def _same_request(a, b, index_matters: bool) -> bool:
    # the budget (a[3]) may differ: giving up early is decided while consuming the plan
    return (np.array_equal(a[0], b[0]) and a[2] == b[2]
            and (a[1] == b[1] or not index_matters))


# ----- the run -------------------------------------------------------------------------------

class SamplingRun:
    """One sampling run into ``out`` (and its sidecar). ``driver`` may already have moved
    (e.g. to the calibration position); the run's tick counts include only its own ticks.
    ``resume=True`` continues the run recorded in the sidecar (``settings`` should come from
    ``RunSettings.from_sidecar``). ``background=True`` plans the next pose in a forked
    process while the robot moves (same results, less wall time on a multi-core machine);
    with ``hold_while_planning`` the hold delta keeps being sent, one per tick, whenever the
    loop waits for a plan (the real cell: the RT link is never left without a message;
    the twin's robot time then includes that wait).

    ``planner``: where the targets come from; default ``Planner`` (random poses, seed 7.1.2).
    Any object with ``plan(q_start, index, rng_state, budget) -> Plan`` and
    ``index_matters() -> bool`` will do, e.g. a planned pose list (``studies.planning``);
    one that keeps state between calls must run with ``background=False``."""

    def __init__(self, driver: Driver, laser, scene: Scene, settings: RunSettings, out,
                 checker, *, resume: bool = False, background: bool = False,
                 hold_while_planning: bool = False,
                 progress: Callable[[RunStats], None] | None = None,
                 extra: dict | None = None, lock: RunLock | None = None,
                 planner=None):
        if checker is None:
            raise ValueError("a collision checker is required")
        if settings.samples < 1:
            raise InputError(f"number of samples must be at least 1, got {settings.samples}")
        self.driver = driver
        self.laser = laser
        self.scene = scene
        self.robot = scene.robot
        self.settings = settings
        self.out = Path(out)
        self.checker = checker
        self.progress = progress
        self.extra = dict(extra or {})
        self.lock = lock  # the caller's, held for its session; else taken in run()
        self.observer = driver.observer
        self.planner = planner if planner is not None else Planner(scene, settings, checker)
        import multiprocessing as mp
        can_fork = "fork" in mp.get_all_start_methods()
        if hold_while_planning and not can_fork:
            raise RuntimeError("holding the RT link while planning needs a forking platform")
        self.background = (background or hold_while_planning) and can_fork
        self.hold_while_planning = hold_while_planning
        self.stats = RunStats()
        self.rng_state = np.random.default_rng(settings.seed).bit_generator.state
        self.plan_time_s = 0.0
        self.recent_rejections: deque = deque(maxlen=RECENT_REJECTIONS)
        self.resume = resume
        if resume:
            side = load_sidecar(self.out)
            st = self.stats
            st.rejected.update(side.get("rejected", {}))
            st.laser_give_ups.update(side.get("laser_give_ups", {}))
            st.ticks = int(side.get("ticks", 0))
            st.wall_time_s = float(side.get("wall_time_s", 0.0))
            st.max_step_counts = int(side.get("max_step_counts", 0))
            st.sessions = int(side.get("sessions", 1)) + 1
            st.samples = count_samples(self.out)
            self.recent_rejections.extend(side.get("recent_rejections", []))
            if side.get("rng_state"):
                self.rng_state = side["rng_state"]
            st.robot_time_s = st.ticks * self.robot.tick_s

    # -- sidecar
    def sidecar(self) -> dict:
        st = self.stats
        side = {
            "format": SIDECAR_FORMAT, "status": st.status, "stop_reason": st.stop_reason,
            "scene": self.scene.name,
            "scene_path": str(self.scene.path) if self.scene.path else None,
            "robot": self.robot.name, "seed": self.settings.seed,
            "samples_target": self.settings.samples, "samples": st.samples,
            "cone_deg": self.settings.pose.cone_deg,
            "distance_mm": (self.settings.pose.fixed_distance_mm
                            if self.settings.pose.fixed_distance_mm is not None
                            else list(self.settings.pose.distance_mm)),
            "settings": self.settings.to_dict(),
            "rejected": dict(st.rejected), "laser_give_ups": dict(st.laser_give_ups),
            "recent_rejections": list(self.recent_rejections),
            "ticks": st.ticks, "robot_time_s": round(st.robot_time_s, 3),
            "wall_time_s": round(st.wall_time_s, 3), "max_step_counts": st.max_step_counts,
            "sessions": st.sessions, "rng_state": self.rng_state,
            "sample_file": self.out.name, "plates": len(self.scene.plates),
            "updated_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        }
        side.update(self.extra)
        return side

    def _save(self) -> None:
        # no fsync: resume recounts the samples from the (fsynced) sample file
        save_json(sidecar_path(self.out), self.sidecar())

    def _account(self) -> None:
        st, drv = self.stats, self.driver
        st.ticks = self._ticks0 + drv.ticks - self._drv_ticks0
        st.robot_time_s = st.ticks * self.robot.tick_s
        st.wall_time_s = self._wall0 + time.perf_counter() - self._t_wall
        st.max_step_counts = max(self._step0, drv.max_step_counts)

    def _reject(self, kind: str, q, reason: str) -> None:
        self._account()
        self.stats.rejected[kind] += 1
        self._rejected_in_a_row += 1
        self.recent_rejections.append({"sample": self.stats.samples, "kind": kind,
                                       "reason": reason})
        self.observer.on_reject(q, reason)
        if self.progress:
            self.progress(self.stats)

    def _give_up(self) -> bool:
        if self._rejected_in_a_row >= self.settings.max_attempts:
            self.stats.status = "gave_up"
            self.stats.stop_reason = f"{self.settings.max_attempts} poses rejected in a row"
            return True
        return False

    # -- the loop
    def run(self) -> RunStats:
        from planecal.samples import SampleWriter

        st, s, drv = self.stats, self.settings, self.driver
        self._t_wall = time.perf_counter()
        self._wall0, self._ticks0, self._step0 = st.wall_time_s, st.ticks, st.max_step_counts
        self._drv_ticks0 = drv.ticks
        drv.max_step_counts = 0
        multi = len(self.scene.plates) > 1
        own_lock = RunLock(self.out) if self.lock is None else None
        try:
            writer = SampleWriter(self.out, append=self.resume, with_plate=multi)
        except BaseException:
            if own_lock:
                own_lock.close()
            raise
        self._rejected_in_a_row = 0
        bg = None
        st.status = "running"
        st.stop_reason = None
        try:
            drv.start()
            self._save()
            q0 = drv.commanded_q()
            if st.samples < s.samples:
                res = self.checker.check_config(q0)
                if not res.ok:
                    pair = getattr(res, "pair", None)
                    st.status = "gave_up"
                    st.stop_reason = ("the robot's configuration is not collision-free in the "
                                      "model" + (f" ({pair[0]} - {pair[1]})" if pair else "")
                                      + ": no path from it can be certified")
                    return st
                if self.background:
                    bg = BackgroundPlanner(self.planner)
            idle = drv.hold if self.hold_while_planning else None
            while st.samples < s.samples:
                req = (q0, st.samples, self.rng_state, s.max_attempts - self._rejected_in_a_row)
                plan = bg.take(*req, idle=idle) if bg else self.planner.plan(*req)
                self.plan_time_s += plan.check_time_s
                gave_up = False
                for kind, q, reason in plan.rejections:
                    self._reject(kind, q, reason)
                    if self._give_up():
                        gave_up = True
                        break
                if gave_up or plan.q is None:
                    self._give_up()
                    break
                self.rng_state = plan.rng_after
                rows = plan_move(drv, plan.qe_goal, s.nominal_step_counts, s.dwell_ticks)
                if rows is None:  # the planner checks the range; this cannot happen
                    raise RuntimeError("planned target outside the encoder range")
                q_goal = plan.q
                if bg:  # plan the next pose while the robot moves (assuming this one succeeds)
                    bg.submit(q_goal, st.samples + 1, self.rng_state, s.max_attempts)
                self.observer.on_path("sample", q0, q_goal, rows)
                drv.follow(rows)
                q0 = q_goal
                lr = drv.read_laser(self.laser, s.laser)
                if not lr.ok:
                    st.laser_give_ups[lr.reason] = st.laser_give_ups.get(lr.reason, 0) + 1
                    self._reject("laser", q_goal, f"laser: {lr.describe()}")
                    continue
                qe = np.asarray(drv.current, np.int64).copy()
                writer.write(qe, lr.value_mm, plan.pose.plate)
                self.observer.on_sample(st.samples, qe, lr.value_mm, plan.pose.plate)
                st.samples += 1
                self._rejected_in_a_row = 0
                self._account()
                self._save()
                if self.progress:
                    self.progress(st)
            else:
                st.status = "complete"
        except EnableDropped:
            st.status = "stopped"
            st.stop_reason = getattr(drv.enable, "reason", None) or "enable signal dropped"
        except KeyboardInterrupt:
            st.status = "stopped"
            st.stop_reason = "interrupted"
            raise
        except Exception as e:  # link or laser failure: keep the record straight, re-raise
            st.status = "error"
            st.stop_reason = f"{type(e).__name__}: {e}"
            raise
        finally:
            if bg:
                bg.close()
            writer.close()
            # the file is the record: a Ctrl-C between writing a line and counting it
            # must not leave the sidecar one short
            st.samples = count_samples(self.out)
            self._account()
            self._save()
            if own_lock:
                own_lock.close()
        return st
