"""The collect core: plan -> acquire -> account, one sample after the other. The sampling
run (``run.SamplingRun``: sample file, sidecar, resume), every study and the pose-list
mode call it; they differ in where the plans come from (``planner``), how a sample is
acquired and where it goes (``Recorder``).

Acquire:
* ``DriveAcquirer`` drives the ticks: the step generator's path to the target
  (``Driver.follow``: at most the robot's step a tick, ``Robot.step_counts``; 5 dwell
  ticks), then the laser read while the
  hold delta keeps going out (``Driver.read_laser``). The real cell and ``rehearse``.
* ``RestAcquirer`` sets the twin at rest at the target (``Twin.set_counts``: a new rest,
  as after a move) and reads the laser the same way. For studies: the same plans,
  rejections, counts and readings as driving there, without the ticks of the move.

Each sample carries its approach direction (``approach``): per joint the sign of its last
joint-side motion in the measured counts, over the whole path, detour legs included
(``Driver.direction`` when the laser reading is taken). An acquirer that moves no robot
(``RestAcquirer``: a jump, which leaves the twin's backlash where it was; ``PlansOnly``;
the synthetic model's) records 0 for every joint: the side is unknown.

Account: each plan's rejected draws are reported in order (``collision``,
``unreachable``), then a laser that gives up is a ``laser`` rejection (the robot stays
where it moved to); ``max_attempts`` rejections in a row give up the run. With
``BackgroundPlanner`` the next plan is made in a forked process while the robot moves.

A ``Budget`` of robot time ends the run complete where the next pose might not fit in it:
its moves, detours included, and the laser's longest read (``LaserSettings.max_reads``:
a read never takes more), so a run's moves and reads never overrun it. On the real cell
the robot also holds while a plan is made (``idle``): that time counts as it passes, and
the wait for the last plan can take a run past its budget by that wait.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from planecal.base.progress import report
from planecal.sampling.aim import Aim
from planecal.sampling.driver import Driver, plan_move
from planecal.sampling.laserread import LaserResult, LaserSettings, read_stable
from planecal.sampling.planner import BackgroundPlanner, Plan, PlanSource, route_back
from planecal.sampling.steps import DWELL_TICKS

REJECT_KINDS = ("collision", "laser", "unreachable")


@dataclass(frozen=True)
class Budget:
    """Robot time a collection may take [s], how much it has taken (``spent``: the run's
    robot time so far, earlier sessions included) and the most a plan can take from
    where the robot is (``cost`` [s]: ``tour.Clock.ticks_for`` with the longest read)."""
    seconds: float
    spent: Callable[[], float]
    cost: Callable[[Plan], float]

    def fits(self, plan: Plan) -> bool:
        return self.spent() + self.cost(plan) <= self.seconds

    @classmethod
    def of(cls, minutes: float | None, spent: Callable[[], float], clock, reads: int,
           tick_s: float) -> "Budget | None":
        """``minutes`` of robot time (None: no budget) for a collection through ``clock``
        (``tour.Clock``): a plan may take its legs, dwell and ``reads`` laser reads."""
        if minutes is None:
            return None
        return cls(60.0 * minutes, spent, lambda plan: clock.ticks_for(plan, reads) * tick_s)


@dataclass
class Acquired:
    counts: np.ndarray  # the robot's encoder counts when the laser was read
    laser: LaserResult
    direction: np.ndarray | None = None  # int8 signs then (module docstring); None: unknown


class Acquirer(Protocol):
    """``idle``: called while the next plan is awaited (the real cell keeps ticking the
    hold delta, so the RT link never goes quiet), or None: just wait."""
    idle: Callable[[], None] | None

    def acquire(self, plan: Plan) -> Acquired: ...


class DriveAcquirer:
    """Drive the ticks to the target and read the laser there (``Driver``)."""

    def __init__(self, driver: Driver, laser: LaserSettings, nominal: int,
                 dwell: int = DWELL_TICKS, hold_while_planning: bool = False):
        self.driver, self.laser = driver, laser
        self.nominal, self.dwell = nominal, dwell
        self.idle = driver.hold if hold_while_planning else None

    def acquire(self, plan: Plan) -> Acquired:
        drv = self.driver
        q0 = plan.q_start
        for q, counts in plan.via:  # a detour's legs: no dwell on the way
            self._leg("via", q0, q, counts, 0)
            q0 = q
        self._leg("sample", q0, plan.q, plan.qe_goal, self.dwell)
        lr = drv.read_laser(self.laser)
        return Acquired(drv.current.copy(), lr, drv.direction)

    def _leg(self, kind, q0, q, counts, dwell) -> None:
        rows = plan_move(self.driver, counts, self.nominal, dwell)
        if rows is None:  # the planners check the range; this cannot happen
            raise RuntimeError("planned target outside the encoder range")
        self.driver.observer.on_path(kind, q0, q, rows)
        self.driver.follow(rows)


class RestAcquirer:
    """Put the twin at rest at the target, then read its laser as the driver would."""

    def __init__(self, twin, laser: LaserSettings):
        self.twin, self.laser = twin, laser
        self.idle = None

    def acquire(self, plan: Plan) -> Acquired:
        twin = self.twin
        twin.set_counts(plan.qe_goal)
        hold = (plan.qe_goal - twin.reference_counts)[None]
        lr = read_stable(lambda n: twin.run(np.repeat(hold, n, axis=0))[2], self.laser)
        return Acquired(twin.current_counts, lr)


class PlansOnly:
    """No measurement: every plan is taken as sampled at its target (the poses a run would
    visit if every laser read succeeded; the distance is not measured, 0)."""
    idle = None

    def acquire(self, plan: Plan) -> Acquired:
        return Acquired(plan.qe_goal, LaserResult(0.0, "stable", 0, None, 0))


class Recorder(Protocol):
    """Where accepted samples and rejections go (a sample file, lists in memory).
    ``direction``: the sample's approach direction, int8 (n_joints,), 0 where unknown."""

    def sample(self, index: int, counts: np.ndarray, d_mm: float, plan: Plan,
               direction: np.ndarray) -> None: ...

    def reject(self, kind: str, q: np.ndarray | None, reason: str) -> None: ...


@dataclass
class Tally:
    """What a collection counted; ``status`` 'complete' or 'gave_up' (then ``reason``;
    a pose list that ran out or a spent budget is 'complete' with the reason and the
    count)."""
    samples: int = 0
    rejected: dict = field(default_factory=lambda: {k: 0 for k in REJECT_KINDS})
    laser_give_ups: dict = field(default_factory=lambda: {"out_of_range": 0, "not_stable": 0})
    in_a_row: int = 0
    status: str = "running"
    reason: str | None = None
    planning_s: float = 0.0  # time the planner spent on the plans taken (its own process's)


@dataclass
class Cursor:
    """Where a collection stands between samples: the configuration the robot was last
    sent to (the next path starts there), the random state of the next plan and the way
    the robot came in (``planner.route_back``; empty where not known: a first sample, a
    robot moved since) and what the laser has read that aims the next draws."""
    q: np.ndarray
    rng_state: dict
    back: tuple = ()
    aim: Aim = field(default_factory=Aim)  # the random draws' distances (``sampling.aim``)


def collect(planner: PlanSource, acquirer: Acquirer, recorder: Recorder, target: int,
            cursor: Cursor, tally: Tally, max_attempts: int,
            background: BackgroundPlanner | None = None,
            on_progress: Callable[[Tally], None] | None = None,
            budget: Budget | None = None) -> Tally:
    """Sample until ``tally.samples`` reaches ``target``, ``max_attempts`` poses are
    rejected in a row or the ``budget`` is spent (module docstring). ``cursor`` and
    ``tally`` are updated in place (a stopped collection resumes from them). Exceptions (a
    dropped enable signal, a link failure) propagate with cursor and tally current."""

    def reject(kind, q, reason) -> bool:
        tally.rejected[kind] += 1
        tally.in_a_row += 1
        recorder.reject(kind, q, reason)
        if on_progress:
            on_progress(tally)
        return tally.in_a_row >= max_attempts

    while tally.samples < target:
        req = (cursor.q, tally.samples, cursor.rng_state, max_attempts - tally.in_a_row,
               cursor.back, cursor.aim.next)
        plan = background.take(*req, idle=acquirer.idle) if background else planner.plan(*req)
        tally.planning_s += plan.check_time_s
        if plan.exhausted:  # a pose list, done: what it could give (its last rejections said)
            for kind, q, reason in plan.rejections:
                reject(kind, q, reason)
            tally.status = "complete" if tally.samples or not plan.rejections else "gave_up"
            tally.reason = (f"{plan.reason}: {tally.samples} of the {target} samples asked "
                            "for; the rest were rejected (see the counts)")
            return tally
        if budget is not None and plan.q is not None and not budget.fits(plan):
            # the plan is dropped whole: its draws are drawn again by a resume with more
            tally.status = "complete"
            tally.reason = (f"the robot-time budget of {budget.seconds / 60:g} min is spent "
                            f"(the next pose might not fit): {tally.samples} of the {target} "
                            "samples asked for")
            return tally
        if any(reject(kind, q, reason) for kind, q, reason in plan.rejections) or plan.q is None:
            tally.status = "gave_up"
            tally.reason = (f"{max_attempts} poses rejected in a row"
                            if tally.in_a_row >= max_attempts else plan.reason)
            return tally
        cursor.rng_state = plan.rng_after
        back = route_back(plan)
        # the next plan is aimed with what is known before this pose is read: planned
        # ahead or in turn, the same plan
        cursor.aim.next = cursor.aim.shifts()
        if background:  # plan the next pose while the robot moves (assuming this one succeeds)
            background.submit(plan.q, tally.samples + 1, cursor.rng_state, max_attempts, back,
                              cursor.aim.next)
        got = acquirer.acquire(plan)
        cursor.q, cursor.back = plan.q, back
        if not got.laser.ok:
            if got.laser.reason == "out_of_range":
                cursor.aim.missed()
            tally.laser_give_ups[got.laser.reason] += 1
            if reject("laser", plan.q, f"laser: {got.laser.describe()}"):
                tally.status = "gave_up"
                tally.reason = f"{max_attempts} poses rejected in a row"
                return tally
            continue
        tally.samples += 1
        tally.in_a_row = 0
        # a random draw's excess (a pose list's poses are aimed before it runs)
        cursor.aim.read(plan.plate, None if plan.pose is None else plan.pose.distance_m,
                        got.laser.value_mm)
        direction = (np.zeros(len(got.counts), np.int8) if got.direction is None
                     else got.direction)
        recorder.sample(tally.samples - 1, got.counts, got.laser.value_mm, plan, direction)
        if on_progress:
            on_progress(tally)
    tally.status = "complete"
    return tally


class MemoryRecorder:
    """Samples and rejections in memory (studies), each said as progress of ``total``
    (``base.progress.report``: a study's run on a worker shows it on the client's bar)."""

    def __init__(self, total: int | None = None):
        self.counts: list[np.ndarray] = []
        self.d_mm: list[float] = []
        self.plates: list[int] = []
        self.directions: list[np.ndarray] = []
        self.total = total

    def sample(self, index, counts, d_mm, plan, direction):
        self.counts.append(np.asarray(counts, np.int64).copy())
        self.d_mm.append(float(d_mm))
        self.plates.append(int(plan.plate))
        self.directions.append(np.asarray(direction, np.int8).copy())
        report(len(self.counts), self.total, "samples")

    def reject(self, kind, q, reason):
        report(len(self.counts), self.total, "samples")

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(qe (N,6) int64, d (N,) m, plate (N,), direction (N,6) int8: the approach
        direction, 0 where unknown)."""
        return (np.array(self.counts, np.int64).reshape(-1, 6), np.array(self.d_mm) * 1e-3,
                np.array(self.plates, int), np.array(self.directions, np.int8).reshape(-1, 6))
