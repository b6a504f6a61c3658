"""The driver: the one owner of the robot link's delta, and the checked moves.

Every path (home, calibration position, samples) starts where the last one ended and no
step ever exceeds the step limit. The driver hands a whole move to the link when the link
can take it in one call (``MoveLink``: the twin, with an enable signal known ahead) and
sends it tick by tick otherwise (``RobotLink`` + ``Laser``: the FD11 and the ZS-LD80),
checking the enable signal before every tick; either way the same ticks go out and a
dropped enable signal stops the move before the tick it would have sent
(``EnableDropped``). Every tick's measured counts go through the driver, so it follows
each joint's approach direction (``approach.ApproachTracker``: ``Driver.direction``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.model.encoder import counts_to_joints, joints_to_counts
from planecal.links.base import EnableAhead, MoveLink
from planecal.model.robot import Robot, within_limits
from planecal.sampling.approach import ApproachTracker
from planecal.sampling.laserread import NO_READING_MM, LaserResult, LaserSettings, read_stable
from planecal.sampling.observer import NullObserver, Observer
from planecal.sampling.steps import COUNT_LIMIT, DWELL_TICKS, max_step, step_path
from planecal.model.scene import Scene


class EnableDropped(Exception):
    """The enable signal dropped: nothing more is sent."""


class PathBlocked(RuntimeError):
    """A requested move (home, calibration position) is not collision-free or reachable."""


@dataclass
class Block:
    """What a cell did with a block of deltas: ``sent`` ticks went out (fewer than asked
    when the enable signal dropped, or ``error`` when the link failed)."""
    reference: np.ndarray | None
    current: np.ndarray  # (sent, 6)
    readings: np.ndarray  # (sent,) mm, NaN: none, NO_READING_MM: no reply yet
    sent: int
    error: BaseException | None = None


class _MoveCell:
    """A whole move in one call (the twin): the enable signal reserves its ticks ahead."""

    def __init__(self, link: MoveLink, enable: EnableAhead):
        self.link, self.enable = link, enable

    def run(self, rows: np.ndarray, read: bool) -> Block:
        m = self.enable.reserve(len(rows))
        if m == 0:
            return Block(None, np.zeros((0, 6), np.int64), np.zeros(0), 0)
        ref, cur, readings = self.link.run(rows[:m] if m < len(rows) else rows, read)
        return Block(ref, cur, readings, m)


class _TickCell:
    """Tick by tick (the real cell): the enable signal checked before every tick."""

    def __init__(self, link, laser, enable):
        self.link, self.laser, self.enable = link, laser, enable

    def run(self, rows: np.ndarray, read: bool) -> Block:
        n = len(rows)
        cur = np.empty((n, 6), np.int64)
        readings = np.full(n, np.nan)
        ref, sent = None, 0
        try:
            for row in rows:
                if not self.enable.enabled():
                    break
                ref, cur[sent] = self.link.exchange(row)
                if read:
                    v = self.laser.read()
                    if v is not None:
                        readings[sent] = v
                sent += 1
        except Exception as e:  # the link failed: account for what went out, then raise
            return Block(ref, cur[:sent], readings[:sent], sent, e)
        return Block(ref, cur[:sent], readings[:sent], sent)


class Driver:
    """Sends deltas to the robot link and remembers the last one sent. ``laser`` is read
    during ``read_laser``; ``enable`` is checked before every tick. ``direction``: each
    joint's approach direction from the measured counts of every tick since this driver's
    first (``approach``)."""

    def __init__(self, link, laser, enable, robot: Robot, observer: Observer | None = None):
        self.robot = robot
        self.enable = enable
        self.observer = observer or NullObserver()
        if isinstance(link, MoveLink) and link is laser and isinstance(enable, EnableAhead):
            self._cell = _MoveCell(link, enable)
        else:
            self._cell = _TickCell(link, laser, enable)
        self.delta = np.zeros(robot.n_joints, np.int64)
        self.reference: np.ndarray | None = None
        self.current: np.ndarray | None = None
        self.approach = ApproachTracker.for_robot(robot)
        self.ticks = 0
        self.max_step_counts = 0

    def _send(self, rows: np.ndarray, read: bool) -> np.ndarray:
        """The rows, one per tick (all or, when enable drops, the ones before): returns the
        readings; raises EnableDropped when not all went out."""
        b = self._cell.run(rows, read)
        if b.sent:
            seen = b.readings
            if read and np.any(seen == NO_READING_MM):  # the observer's "none" is NaN
                seen = np.where(seen == NO_READING_MM, np.nan, seen)
            self.observer.on_ticks(self.ticks + 1, rows[:b.sent], b.reference, b.current,
                                   seen)
            self.approach.follow(b.current)
            self.ticks += b.sent
            self.delta = rows[b.sent - 1].copy()
            self.reference = b.reference
            self.current = b.current[-1].copy()
        if b.error is not None:
            raise b.error
        if b.sent < len(rows):
            raise EnableDropped()
        return b.readings

    def start(self) -> None:
        """First exchange: zero delta (commanded = reference), learn reference and current."""
        if self.reference is None:
            self._send(np.zeros((1, self.robot.n_joints), np.int64), read=False)

    def hold(self) -> None:
        """One tick holding the last delta."""
        self._send(self.delta[None], read=False)

    def follow(self, rows: np.ndarray) -> None:
        """Send each row, one per tick (stops, by ``EnableDropped``, when enable drops).
        A path with a step above the robot's limit (``max_step_counts``) is refused before anything
        is sent; the step generator never makes one, this is a second line of defence."""
        rows = np.ascontiguousarray(rows, np.int64)
        before = self.delta
        worst = max_step(before, rows)
        if worst > self.robot.max_step_counts:
            raise ValueError(f"refusing a path with a step of {worst} counts "
                             f"(limit {self.robot.max_step_counts})")
        t0 = self.ticks
        try:
            self._send(rows, read=False)
        finally:
            sent = self.ticks - t0
            self.max_step_counts = max(self.max_step_counts, max_step(before, rows[:sent]))

    def read_laser(self, settings: LaserSettings) -> LaserResult:
        """Hold still and read the laser until it is stable (``laserread``)."""
        hold = self.delta[None]
        return read_stable(lambda n: self._send(np.repeat(hold, n, axis=0), read=True),
                           settings)

    @property
    def direction(self) -> np.ndarray:
        """Per joint the sign (-1, 0 unknown, +1) of its last joint-side motion in the
        measured counts (int8, a copy)."""
        return self.approach.side

    @property
    def commanded_counts(self) -> np.ndarray:
        return self.reference.astype(np.int64) + self.delta

    def commanded_q(self) -> np.ndarray:
        return counts_to_joints(self.robot, self.commanded_counts)

    @property
    def robot_time_s(self) -> float:
        return self.ticks * self.robot.tick_s


def plan_move(driver: Driver, qe_goal: np.ndarray, nominal: int | None = None,
              dwell: int = DWELL_TICKS) -> np.ndarray | None:
    """Rows taking the robot from the last delta to absolute counts ``qe_goal`` at
    ``nominal`` counts a tick (default the robot's step, ``Robot.step_counts``), or None
    when the goal is outside the 24-bit encoder range."""
    qe_goal = np.asarray(qe_goal, np.int64)
    if np.any(qe_goal < 0) or np.any(qe_goal >= COUNT_LIMIT):
        return None
    goal = qe_goal - driver.reference.astype(np.int64)
    return step_path(driver.delta, goal, nominal or driver.robot.step_counts, dwell)


def move_to_counts(driver: Driver, qe_goal, checker, kind: str = "move",
                   nominal: int | None = None, dwell: int = DWELL_TICKS) -> int:
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
            raise PathBlocked(f"{kind}: {what} not collision-free"
                              + (f" ({res.pair[0]} - {res.pair[1]})" if res.pair else ""))
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
