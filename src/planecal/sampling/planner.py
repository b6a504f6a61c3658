"""Where the sampling loop's targets come from: a plan per sample (pose -> IK ->
collision checks), from random poses (``Planner``, seed 7.1.2) or a planned pose list
(``ListPlanner``), optionally in a forked process while the robot moves
(``BackgroundPlanner``).

A planner draws until a target is reachable and collision-free: the target configuration
and the straight joint-space motion to it from where the robot will be (the step
generator interpolates linearly in counts, hence in joint angles), at most ``budget``
draws. Every rejected draw is reported with its kind (``unreachable``, ``collision``) and
reason, in order.

When the straight path is blocked -- typically the wrist turning over from one branch to
the other next to the plate -- a detour is tried (``Detour``): back out along the beam,
move there (the wrist turns over far from the plate), approach along the target's beam.
Its two via-points and three straight legs are checked like any path; the plan then
carries the via-points. Where no such detour is clear, a far one (``detour``): through the
scene's calibration or home position, or back the way the robot came in (``back``: the
previous plan's via-points reversed, then the pose it left) and on from there; every leg
is checked again. A far detour costs up to a minute of robot time, so a pose list serves
its next pose reachable nearer first.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from planecal.model.encoder import counts_in_range, counts_to_joints
from planecal.model.ik import turns
from planecal.sampling.aim import Shifts
from planecal.sampling.detour import Checker, Detour, Verdict
from planecal.sampling.poses import CommandModel, PoseGenerator, PoseSettings, SensorPose
from planecal.sampling.steps import COUNT_LIMIT
from planecal.model.scene import Scene


@dataclass
class Plan:
    """The outcome of planning one sample from ``q_start``: the rejected draws (in order:
    (kind, q or None, reason)) and the accepted target (``q`` None when nothing was
    accepted: ``reason`` says why). ``rng_after`` is the generator state after the last
    draw."""
    index: int
    q_start: np.ndarray
    rejections: list
    rng_after: dict
    q: np.ndarray | None = None
    qe_goal: np.ndarray | None = None
    plate: int = 0
    pose: SensorPose | None = None
    check_time_s: float = 0.0
    reason: str | None = None
    via: list = field(default_factory=list)  # (joint angles, counts) passed on the way
    exhausted: bool = False  # a pose list with nothing left: the collection is done


class PlanSource(Protocol):
    """Anything that plans samples for the loop. ``pure``: the same request always gives
    the same plan (the random state travels with it), so it may plan in another process
    ahead of time; ``index_matters``: the plan depends on the sample index."""
    pure: bool

    def plan(self, q_start: np.ndarray, index: int, rng_state: dict, budget: int,
             back: tuple = (), aim: Shifts | None = None) -> Plan: ...

    def index_matters(self) -> bool: ...


@dataclass(frozen=True)
class Clear:
    ok: bool = True
    pair: tuple[str, str] | None = None


class NoCollisionChecks:
    """A checker that clears everything: runs with collision checking off (studies of the
    model alone; ``RunSettings.collision_checking`` False). Never drives a robot."""

    def check_config(self, q) -> Clear:
        return Clear()

    def check_path(self, q0, q1) -> Clear:
        return Clear()


def _collision_reason(what: str, res: Verdict) -> str:
    return f"collision ({what})" + (f": {res.pair[0]} - {res.pair[1]}" if res.pair else "")


def check_move(checker: Checker, q_start: np.ndarray, q: np.ndarray) -> str | None:
    """None when the target configuration and the straight path to it are clear, else the
    reason."""
    res = checker.check_config(q)
    if not res.ok:
        return _collision_reason("target", res)
    res = checker.check_path(q_start, q)
    if not res.ok:
        return _collision_reason("path", res)
    return None


def route_back(plan: Plan) -> tuple:
    """The configurations a plan's robot came in by, nearest first: its via-points
    reversed, then the pose it left (``Detour.find``'s ``back``)."""
    return tuple(np.array(q, float) for q, _ in reversed(plan.via)) + (
        np.array(plan.q_start, float),)


class Planner:
    """Random poses (``poses.PoseGenerator``), IK, collision checks, and detours where the
    wrist branch is drawn (``ik_choice`` wrist). Pure: the random state comes in and goes
    out with the plan."""
    pure = True

    def __init__(self, scene: Scene, pose: PoseSettings, checker: Checker,
                 model: CommandModel | None = None):
        self.robot = scene.robot
        self.poses = PoseGenerator(scene, pose, model)
        self.checker = checker
        # detours turn the wrist over where a straight path cannot: for the deliberate
        # wrist branches; with the nearest solution a blocked pose is drawn again
        self.detour = Detour(self.poses, checker) if pose.ik_choice == "wrist" else None

    def plan(self, q_start: np.ndarray, index: int, rng_state: dict, budget: int,
             back: tuple = (), aim: Shifts | None = None) -> Plan:
        rng = np.random.default_rng()
        rng.bit_generator.state = rng_state
        t0 = time.perf_counter()
        out = Plan(index, q_start, [], rng_state)
        for _ in range(budget):
            plate = self.poses.plate_for(index, rng)
            pose = self.poses.draw(rng, plate, 0.0 if aim is None else aim.of(plate))
            q = self.poses.joint_target(pose, q_start, rng)
            if q is None:
                out.rejections.append(("unreachable", None,
                                       "unreachable: no IK solution within limits"))
                continue
            qe = self.poses.counts_target(q)
            if np.any(qe < 0) or np.any(qe >= COUNT_LIMIT):
                out.rejections.append(("unreachable", q,
                                       "unreachable: counts outside the encoder range"))
                continue
            why = check_move(self.checker, q_start, q)
            if why is not None and self.detour and why.startswith("collision (path)"):
                out.via = self.detour.find(q_start, q, back) or []
                why = None if out.via else why
            if why is not None:
                out.rejections.append(("collision", q, why))
                continue
            out.q, out.qe_goal, out.pose, out.plate = q, qe, pose, pose.plate
            break
        if out.q is None:
            out.reason = f"{budget} poses rejected in a row"
        out.rng_after = rng.bit_generator.state
        out.check_time_s = time.perf_counter() - t0
        return out

    def index_matters(self) -> bool:
        """Whether a plan depends on the sample index (round robin over several plates)."""
        return self.poses.n_plates > 1 and self.poses.settings.plate_choice == "round_robin"


class ListPlanner:
    """A planned pose list (encoder counts, plate per pose) served in order, each checked
    like a random pose (target configuration and straight path from where the robot
    is); a pose whose path is blocked from here is left for later. Stateful: plans in the
    run's own process. A pose blocked straight is served by a near detour before any by
    a far one; where every pose left is blocked every way, one is served with a joint
    turned by whole turns (``_turned``). When no pose is left, or none of those left can
    be reached from here (they are rejected and dropped), the list is done: the plan says
    so (``q`` None, ``exhausted``, ``reason``). ``taken``: the indices of the poses
    served so far, in the order served. ``approach`` (n,) in -1, 0, +1: the side each
    pose is approached from (``approach.approach_point``: a last leg from just short of
    it, which a pose read again after another reading at it needs to settle anew; 0:
    straight in, the side its path leaves), where that leg is clear. A pose whose target
    configuration collides can be reached from nowhere: the first plan reports each such
    pose as a rejection and drops it (a list aimed anew with a calibration,
    ``poses.aim_counts``, can move a pose near an obstacle), so it cannot hold up the end
    of the list."""
    pure = False

    def __init__(self, scene: Scene, counts: np.ndarray, plates: np.ndarray, checker: Checker,
                 model: CommandModel | None = None, approach: np.ndarray | None = None):
        self.robot = scene.robot
        self.checker = checker
        poses = PoseGenerator(scene, PoseSettings(cone_deg=scene.cone_deg,
                                                  distance_mm=tuple(scene.distance_mm)), model)
        self.qe0 = poses.model.qe0
        self.detour = Detour(poses, checker)
        self.counts = np.asarray(counts, np.int64).reshape(-1, 6)
        self.plates = np.asarray(plates, int).reshape(-1)
        self.approach = (np.zeros(len(self.counts), np.int8) if approach is None
                         else np.asarray(approach, np.int8).reshape(-1))
        self.left = list(range(len(self.counts)))
        self.taken: list[int] = []
        self._screened = False

    def index_matters(self) -> bool:
        return False

    def _screen(self, out: Plan) -> None:
        """The poses whose target collides, rejected into ``out`` and dropped (once)."""
        self._screened = True
        for j in list(self.left):
            q = counts_to_joints(self.robot, self.counts[j], self.qe0)
            res = self.checker.check_config(q)
            if not res.ok:
                self.left.remove(j)
                out.rejections.append(("collision", q, _collision_reason("target", res)
                                       + f" (planned pose {j + 1}: dropped)"))

    def plan(self, q_start, index, rng_state, budget, back=(), aim=None):
        """The next pose of the list reachable on a straight path; else the next one
        reachable by a detour (``Detour.find``, ``back`` the way the robot came in); the
        poses passed over stay for later (``aim``: unused, a list is aimed before it
        runs)."""
        t0 = time.perf_counter()
        out = Plan(index, q_start, [], rng_state)
        if not self._screened:
            self._screen(out)
        blocked = []
        for j in list(self.left)[:budget]:
            q = counts_to_joints(self.robot, self.counts[j], self.qe0)
            why = check_move(self.checker, q_start, q)
            if why is None:
                self._take(out, j, q)
                break
            blocked.append((j, q, why))
        else:
            # the first reachable by a near detour, else the first by a far one
            path = [why.startswith("collision (path)") for _, _, why in blocked]
            near = next(((j, q, via) for (j, q, _), p in zip(blocked, path)
                         if p and (via := self.detour.find(q_start, q, far=False))), None)
            for (j, q, why), p in zip(blocked, path) if near is None else ():
                via = self.detour.far(q_start, q, back) if p else None
                if via:
                    self._take(out, j, q, via)
                    break
                out.rejections.append(("collision", q, f"{why} (planned pose {j + 1})"))
            else:
                if near is not None:
                    self._take(out, *near)
                elif self.left and self._turned(out, q_start, blocked, back):
                    pass
                elif not self.left:
                    out.exhausted = True
                    out.reason = "every pose of the list was tried"
                else:  # the list ends here: what is left is rejected above, and dropped
                    out.exhausted = True
                    out.reason = (f"the {len(self.left)} poses left cannot be reached from "
                                  "here, straight, by a detour or a turn away (dropped)")
                    self.left.clear()
        out.check_time_s = time.perf_counter() - t0
        return out

    def _turned(self, out: Plan, q_start: np.ndarray, blocked: list, back: tuple) -> bool:
        """Where every pose left is blocked every way from here, one of them taken with a
        joint turned by whole turns (the same sensor pose, ``ik.turns``): the nearest such
        configuration reachable straight or by a detour. Truth 419's list run stood where
        its last pose, J4 turned 5 rad from where the robot was, swept the wrist through
        a plate on every way; the same pose a turn away was 1.3 rad off."""
        det = self.detour
        cands = [(float(np.max(np.abs(v - q_start) * det.poses.weights)), j, v)
                 for j, _, _ in blocked
                 for v in turns(self.robot, counts_to_joints(self.robot, self.counts[j],
                                                             self.qe0))]
        for _, j, v in sorted(cands, key=lambda c: c[0]):
            qe = det.poses.counts_target(v)
            if not (counts_in_range(self.robot, qe) and self.checker.check_config(v).ok):
                continue
            via = [] if check_move(self.checker, q_start, v) is None else det.find(
                q_start, v, back)
            if via is not None:
                self._take(out, j, v, via, qe)
                return True
        return False

    def _take(self, out: Plan, j: int, q: np.ndarray, via=(), counts=None) -> None:
        self.left.remove(j)
        self.taken.append(j)
        out.q, out.plate = q, int(self.plates[j])
        out.qe_goal = self.counts[j].copy() if counts is None else np.asarray(counts, np.int64)
        out.via = list(via)
        if self.approach[j]:
            from planecal.sampling.approach import approach_point
            at = approach_point(self.robot, q, int(self.approach[j]), self.qe0)
            last = out.via[-1][0] if out.via else out.q_start
            c = self.checker
            if (at is not None and counts_in_range(self.robot, at[1])
                    and c.check_config(at[0]).ok and c.check_path(last, at[0]).ok
                    and c.check_path(at[0], q).ok):
                out.via.append(at)


AHEAD = 4  # plans the background planner makes ahead along the chain of plans


def _planner_worker(conn, parent_end, planner) -> None:
    import signal
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # the run's to handle: it
        signal.signal(sig, signal.SIG_IGN)  # ends this process (or its death closes the pipe)
    # the fork gave us a copy of the run's end of the pipe too: close it, so that the
    # run's death (even SIGKILL) closes the pipe and ends this process (EOF, broken pipe)
    parent_end.close()
    ahead = _Ahead(planner)
    while True:
        while ahead.wanted() and not conn.poll():  # nothing asked: plan along the chain
            ahead.plan_next()
        try:
            req = conn.recv()
        except (EOFError, OSError):  # the run is gone (closed, or reset with a plan unread)
            break
        if req is None:
            break
        plan = ahead.take(req)
        try:
            conn.send(plan)
        except OSError:  # the run is gone
            break


def _plan_or_error(planner, req):
    try:
        return planner.plan(*req)
    except Exception as e:  # report it in the run's process
        return RuntimeError(f"planner: {type(e).__name__}: {e}")


class _Ahead:
    """The background planner's plans made ahead: a run's requests form a chain (the next
    plan starts where this one's target is, with its random state after, the next
    index and its way back: ``collect``), so while the run moves the robot the planner
    makes the next ``AHEAD`` plans of the chain and serves a request that matches one
    (``_same_request``; a plan made with a budget at least the request's: a run that
    gives up early stops reading its rejections at the same one). A request off the
    chain (a round-robin index after a laser rejection, new aiming shifts after a reading:
    ``sampling.aim``) drops them and starts the chain
    again from itself. The planner is pure, so a plan made ahead is the plan."""

    def __init__(self, planner):
        self.planner = planner
        self.made: list[tuple] = []  # (request, plan) along the chain, oldest first
        self.next: tuple | None = None  # the chain's next request, None: no chain
        self.budget = 0  # the largest asked for (the run's max_attempts): the chain's

    def wanted(self) -> bool:
        return self.next is not None and len(self.made) < AHEAD

    def plan_next(self) -> None:
        req = self.next
        plan = _plan_or_error(self.planner, req)
        self.made.append((req, plan))
        self.next = _next_request(req, plan, self.budget)

    def take(self, req):
        matters = self.planner.index_matters()
        while self.made:
            made, plan = self.made.pop(0)
            if made[3] >= req[3] and _same_request(made, req, matters):
                return plan
        # off the chain (or none yet): plan it, the chain goes on from it
        plan = _plan_or_error(self.planner, req)
        if len(req) == 6:
            self.budget = max(self.budget, req[3])
        self.next = _next_request(req, plan, self.budget)
        return plan


def _next_request(req, plan, budget: int) -> tuple | None:
    """The request ``collect`` makes after ``plan`` succeeds (with ``budget``), or None
    where none follows (no target: the run ends or gives up; not a sampling request)."""
    if not isinstance(plan, Plan) or plan.q is None or len(req) != 6:
        return None
    return (plan.q, req[1] + 1, plan.rng_after, budget, route_back(plan), req[5])


@dataclass
class BackgroundPlanner:
    """Plans in a forked process. The run asks for the next sample's plan as soon as the
    current target is known (the next path starts there) and the robot moves meanwhile;
    the process makes the plans after it meanwhile too (``_Ahead``).
    The request is speculative only in the sample index, which matters only for
    round-robin plate choice (after a laser rejection): then the plan made for the other
    index is dropped and the right one is planned. Results are identical to planning in
    the run's process (same requests, same random states; the planner is pure and the
    checker stateless).

    ``take(req, idle)`` calls ``idle()`` while it waits (the real cell keeps ticking the
    hold delta so the RT link never goes quiet); with ``idle=None`` it just blocks."""
    planner: Planner
    _pending: tuple | None = field(default=None, init=False)

    def __post_init__(self):
        import gc
        import multiprocessing as mp
        ctx = mp.get_context("fork")  # the planner (with its FCL model) is inherited
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_planner_worker, args=(child, self._conn, self.planner),
                                 daemon=True)
        # the child inherits the caller's garbage: an SQLite connection closed by the child's
        # collector checkpoints into the caller's file (no connection across a fork)
        gc.collect()
        gc.freeze()
        try:
            self._proc.start()
        finally:
            gc.unfreeze()
        child.close()

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


def can_fork() -> bool:
    import multiprocessing as mp
    return "fork" in mp.get_all_start_methods()


def _same_request(a, b, index_matters: bool) -> bool:
    # the budget (a[3]) may differ: giving up early is decided while consuming the plan
    return (np.array_equal(a[0], b[0]) and a[2] == b[2]
            and (a[1] == b[1] or not index_matters) and len(a[4]) == len(b[4])
            and all(np.array_equal(u, v) for u, v in zip(a[4], b[4])) and a[5] == b[5])
