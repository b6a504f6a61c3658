"""The whole model's sampling design (issue 31): which poses, how many readings at each and
from which side, chosen for the error a calibration leaves at the tool point per second of
robot time. ``planecal plan --design tool`` makes it; ``rehearse``/``sample --poses`` run it.

What a level-3 calibration of 150 random samples leaves at the tool is the noise of its
samples (docs/ERRORS.md: without the noise it reaches its floor), and where a random run's
robot time goes is travel: on three_plates 20 of its 22 s a sample are moves between
random poses, 1.5 s the laser's stable read. So the design buys readings where they are
cheap:

* **readings**: a pose read again after a short move away and back (``approach``: four
  steps of every motor, 4-8 mrad a joint on the MC70, four ticks each way) costs the laser's read and the dwell, 1.6 s on the
  MC70, against a new pose's travel; each rest draws the robot's repeatability anew
  (``twin.ticks``: the twin's noise is independent between rests; on a real robot
  ``planecal sample --poses`` of a list that repeats a pose measures it). At most
  ``MAX_READS`` a pose: the model's mismatch at a pose is not averaged down by reading it
  again, so the design keeps many poses;
* **approach sides**: every reading approaches its pose from a chosen side (its last leg
  from 2 mrad short of it on every joint: each joint's backlash on the flank that side
  leaves it), a pose read twice from both, so the backlash terms are measured, not left to
  the tour;
* **the criterion**: the tool point's mean square error over the candidate poses (the
  beam point at the scene's standoff, robot frame: ``estimation.accuracy``'s figure),
  tr(G H^-1) with H the tempered posterior's information the calibration will have
  (``fit.fit_prior``: the level's prior and the known lengths weighed against
  ``TEMPER`` times the noise model's level, as the fit weighs them at that residual
  level), chosen by ``design.budget_greedy`` per robot second and improved by
  ``design.exchange_poses``;
* **robot time**: the poses ordered into the collision-checked tour (``tour.order``, each
  pose's readings together), the run's own list planner's moves (``tour.visit_list``)
  timed at the robot's step with ``tour.READ_TICKS_MEAN`` a read; the greedy's cost of a
  new pose is re-estimated from that tour until the list fits the budget;
* **margins**: candidates are collision-checked at ``DESIGN_CLEARANCE_M`` (twice the
  run's 10 mm), so a list aimed anew with a first calibration (``poses.aim_counts``,
  millimetres and milliradians from the nominal cell) stays reachable, and their
  distances are the scene's sampling range (70-90 mm on the ZS-LD80's 65-95: 5 mm each
  side for the aiming model's error; the nominal cell is up to 37 mm off, which is why a
  list is aimed with a first calibration before it runs).

Beside the design the plan predicts the random run of the same robot time (the sampling
run's own poses, up to that time if every laser read succeeded), on the same criterion.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.base.errors import InputError
from planecal.studies.design import (TOOL_WHERE, budget_greedy, exchange_poses,
                                     tool_criterion, tool_rows)

DESIGN_CLEARANCE_M = 0.02  # candidates and tour checked with twice the run's clearance
MAX_READS = 4  # readings of one pose at most (two from each side)
BUDGET_PASSES = 3  # greedy runs, the cost of a new pose re-estimated from each one's tour
TOOL_STAGES = 3 + BUDGET_PASSES  # progress steps of ``plan --design tool``


@dataclass
class Readings:
    """What the candidates offer: two readings a pose (rows ``+`` then ``-``: approached
    from each side), each row of the distance Jacobian over the base set scaled by 1 / the
    noise (``A``), the prior's information (``H0``), the tool criterion's ``G`` and the
    noise level ``sigma_m``."""
    qe: np.ndarray
    plate: np.ndarray
    A: np.ndarray
    H0: np.ndarray
    G: np.ndarray
    sigma_m: float
    layout: object
    free: np.ndarray
    params: object

    @property
    def n(self) -> int:
        return len(self.qe)

    @property
    def pose_of(self) -> np.ndarray:
        return np.concatenate([np.arange(self.n), np.arange(self.n)])

    @property
    def side_of(self) -> np.ndarray:
        return np.concatenate([np.ones(self.n, int), -np.ones(self.n, int)])

    def tool_mm(self, rows: np.ndarray, A: np.ndarray | None = None) -> float:
        """The predicted tool-point error (rms over the candidates, 1 sigma) [mm] of the
        readings ``rows`` of A (default: the candidates')."""
        A = self.A if A is None else A
        return float(np.sqrt(tool_criterion(self.G, self.H0 + A[rows].T @ A[rows])) * 1e3)


def readings(scene, qe, q, plate, settings, params=None) -> Readings:
    """The candidates' readings (``Readings``) for a calibration with ``settings``, at
    ``params`` (default: the scene's nominal cell)."""
    from planecal.estimation.calibrate import base_set, calibration_prior
    from planecal.estimation.fit import TEMPER, fit_prior
    from planecal.estimation.noise import repeatability_sigma, sample_sigma_m, sample_variance
    from planecal.model.measurement import joints_of_counts, predict_joints_with_jacobian
    from planecal.model.scene import nominal_params
    robot = scene.robot
    params = nominal_params(scene) if params is None else params
    both = np.concatenate([np.ones((len(qe), 6), np.int8), -np.ones((len(qe), 6), np.int8)])
    qe2, plate2 = np.vstack([qe, qe]), np.concatenate([plate, plate])
    layout, bs = base_set(robot, qe2, params, plate2, settings, direction=both,
                          references=scene.references)
    free = bs.mask(layout)
    _, J = predict_joints_with_jacobian(robot, joints_of_counts(robot, qe2, both, True), params,
                                        plate2, layout)
    v = sample_variance(robot, J[:, layout.slice("joint_offsets")], repeatability_sigma(robot),
                        sample_sigma_m(0.001), True)
    sigma = float(np.sqrt(v.mean()))
    fp = fit_prior(layout, free, params, calibration_prior(layout, settings),
                   scene.references, TEMPER * sigma)
    p = int(free.sum())
    P = np.zeros((0, p)) if fp is None else fp.rows(params.to_vector(layout)[free], p)[0]
    # parameters without a prior (cell, offsets) held by a prior of 1 (SI) only, so H0 is
    # invertible; the data's information is 10^9 times that
    H0 = P.T @ P / sigma ** 2 + np.eye(p)
    T = tool_rows(scene, q, params, layout, free)
    G = np.einsum("nik,nil->kl", T, T) / len(T)
    return Readings(np.asarray(qe), np.asarray(plate), J[:, free] / sigma, H0, G, sigma,
                    layout, free, params)


def read_seconds(robot) -> float:
    """Robot time of one more reading at the pose the robot is at: the approach leg away
    and back (``approach.approach_point``), the dwell and a mean laser read."""
    from planecal.sampling.approach import APPROACH_TICKS
    from planecal.sampling.steps import DWELL_TICKS
    from planecal.sampling.tour import READ_TICKS_MEAN
    return (2 * APPROACH_TICKS + DWELL_TICKS + READ_TICKS_MEAN) * float(robot.tick_s)


def list_entries(units: np.ndarray, rd: Readings, order: np.ndarray):
    """The pose list of the readings ``units`` visiting their poses in ``order`` (pose
    indices): (counts (k, 6), plates (k,), approach (k,), readings per pose in that
    order); a pose's readings together, their sides alternating."""
    pose_of, side_of = rd.pose_of[units], rd.side_of[units]
    counts, plates, approach, reads = [], [], [], []
    for p in order:
        sides = list(side_of[pose_of == p])
        plus, minus = sides.count(1), sides.count(-1)
        seq = []
        while plus or minus:
            if plus:
                seq.append(1)
                plus -= 1
            if minus:
                seq.append(-1)
                minus -= 1
        counts += [rd.qe[p]] * len(seq)
        plates += [int(rd.plate[p])] * len(seq)
        approach += seq
        reads.append(len(seq))
    return (np.array(counts, np.int64).reshape(-1, 6), np.array(plates, int),
            np.array(approach, np.int8), np.array(reads, int))


def rows_at(scene, rd: Readings, qe, plate, side) -> np.ndarray:
    """Readings' rows (as ``Readings.A``) at poses ``qe`` approached from ``side`` (n,)."""
    from planecal.model.measurement import joints_of_counts, predict_joints_with_jacobian
    direction = (np.asarray(side, np.int8)[:, None] * np.ones((1, 6), np.int8))
    _, J = predict_joints_with_jacobian(scene.robot, joints_of_counts(scene.robot, qe, direction,
                                                                      True),
                                        rd.params, plate, rd.layout)
    return J[:, rd.free] / rd.sigma_m


@dataclass
class ToolPlan:
    """A design's pose list and what it costs: entries (``counts``, ``plates``,
    ``approach``), readings per pose in visiting order, the robot time [s] and the
    predicted tool-point error [mm]; ``dropped``: why the run cannot visit the rest."""
    counts: np.ndarray
    plates: np.ndarray
    approach: np.ndarray
    reads: np.ndarray
    time_s: float
    tool_mm: float
    tour: object
    dropped: str | None = None


def _one_design(scene, rd: Readings, budget_s: float, new_s: float, read_s: float,
                max_reads: int, checker, start) -> ToolPlan:
    """The greedy and exchanged design within ``budget_s`` (a new pose costing ``new_s``),
    its tour and the robot time of the run that visits it."""
    from planecal.model.encoder import counts_to_joints
    from planecal.sampling import tour
    robot = scene.robot
    units = budget_greedy(rd.A, rd.G, rd.H0, rd.pose_of, new_s, read_s, budget_s, max_reads)
    if not len(units):
        raise InputError(f"a budget of {budget_s / 60:.1f} robot minutes buys no pose")
    units = exchange_poses(rd.A, rd.G, rd.H0, rd.pose_of, rd.side_of, units)
    poses = np.unique(rd.pose_of[units])
    tr = tour.order(rd.qe[poses], start, checker, scene, nominal=robot.step_counts)
    counts, plates, approach, reads = list_entries(units, rd, poses[np.array(tr.order, int)])
    visits, taken, why = tour.visit_list(scene, counts, plates, checker,
                                         counts_to_joints(robot, start), approach)
    keep = np.sort(taken)
    if why is not None:
        why = f"{len(counts) - len(keep)} of the {len(counts)} planned readings dropped ({why})"
    counts, plates, approach = counts[keep], plates[keep], approach[keep]
    time_s = tour.robot_time_s(visits, start, robot, read_ticks=tour.READ_TICKS_MEAN)
    A = rows_at(scene, rd, counts, plates, approach)
    tool = float(np.sqrt(tool_criterion(rd.G, rd.H0 + A.T @ A)) * 1e3)
    return ToolPlan(counts, plates, approach, reads, time_s, tool, tr, why)


def design_tool(scene, rd: Readings, budget_s: float, max_reads: int, checker, start,
                travel_s: float = 5.0, progress=None) -> ToolPlan:
    """The design that fits ``budget_s`` of robot time: the greedy's cost of a new pose
    (``travel_s`` + a reading) re-estimated from each design's tour, its budget shrunk by
    what the last one overran; the best (lowest predicted tool error) within the budget."""
    read_s = read_seconds(scene.robot)
    best, target = None, budget_s
    for k in range(BUDGET_PASSES):
        if progress is not None:
            progress.update(note=f"design {k + 1}: a new pose at {travel_s + read_s:.1f} s")
        d = _one_design(scene, rd, target, travel_s + read_s, read_s, max_reads, checker, start)
        if d.time_s <= budget_s and (best is None or d.tool_mm < best.tool_mm):
            best = d
        n_pose = max(len(d.reads), 1)
        travel_s = max((d.time_s - len(d.counts) * read_s) / n_pose, 0.5)
        target *= min(1.0, budget_s / d.time_s) if d.time_s > budget_s else 1.0
    if best is None:
        raise InputError(f"no design within {budget_s / 60:.1f} robot minutes: the last took "
                         f"{d.time_s / 60:.1f}; give more --robot-minutes")
    return best


def random_at(scene, rd: Readings, budget_s: float, seed: int, checker, model=None):
    """The sampling run's own random poses up to ``budget_s`` of robot time (if every
    laser read succeeded): (samples, robot time [s], predicted tool error [mm])."""
    from planecal.sampling import tour
    from planecal.studies.planning import run_design
    robot = scene.robot
    start = _start(scene)
    n = int(budget_s / 8.0) + 10  # more than a random run can sample in the budget
    qe, plate, visits = run_design(scene, n, seed, checker, with_visits=True, model=model)
    t, cur, k = 0.0, start, 0
    for v in visits:
        dt = tour.robot_time_s([v], cur, robot, read_ticks=tour.READ_TICKS_MEAN)
        if t + dt > budget_s:
            break
        t, cur, k = t + dt, v.goal, k + 1
    side = np.where(np.arange(k) % 2 == 0, 1, -1)
    A = rows_at(scene, rd, qe[:k], plate[:k], side)
    return k, t, float(np.sqrt(tool_criterion(rd.G, rd.H0 + A.T @ A)) * 1e3)


def _start(scene) -> np.ndarray:
    from planecal.model.encoder import joints_to_counts
    q0 = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    return joints_to_counts(scene.robot, q0)


def plan_tool(scene, minutes: float, m: int, seed: int = 0, settings=None, model=None,
              max_reads: int = MAX_READS, progress=None) -> dict:
    """The whole model's design (module docstring) within ``minutes`` of robot time from
    ``m`` candidates (``planning.candidate_pool``, aimed with ``model``: an earlier
    calibration's ``CommandModel``, default the nominal cell), for a calibration with
    ``settings`` (default level 3): the plan's document (format ``planecal-poses/1``)."""
    from planecal.estimation.calibrate import CalibrationSettings
    from planecal.formats.poses import POSES_FORMAT
    from planecal.model.encoder import counts_to_joints
    from planecal.safety.collision import CollisionWorld
    from planecal.studies.planning import candidate_pool
    if not (np.isfinite(minutes) and minutes > 0):
        raise InputError(f"--robot-minutes must be a finite number > 0, got {minutes}")
    if not 1 <= max_reads <= 100:
        raise InputError(f"--max-reads must be 1..100, got {max_reads}")
    settings = settings or CalibrationSettings(level="nonkinematic")
    checker = CollisionWorld(scene, clearance_m=DESIGN_CLEARANCE_M)
    if progress is not None:
        progress.update(note=f"drawing {m} candidate poses")
    qe, _, plate = candidate_pool(scene, m, seed, checker, model)
    q = counts_to_joints(scene.robot, qe)
    rd = readings(scene, qe, q, plate, settings, None if model is None else model.params)
    budget = minutes * 60.0
    d = design_tool(scene, rd, budget, max_reads, checker, _start(scene), progress=progress)
    if progress is not None:
        progress.update(note="the random run of the same robot time")
    n_r, t_r, tool_r = random_at(scene, rd, d.time_s, seed, checker, model)
    names = rd.layout.names_of(rd.free)
    return {"format": POSES_FORMAT, "design": "tool", "scene": scene.name, "seed": seed,
            "samples": int(len(d.counts)), "poses": int(len(d.reads)),
            "candidates": int(len(qe)), "free": names, "level": settings.level,
            "counts": d.counts.tolist(), "plates": d.plates.tolist(),
            "approach": d.approach.tolist(), "reads_per_pose": d.reads.tolist(),
            "max_reads": max_reads, "dropped": d.dropped,
            "tour": {"travel_ticks": d.tour.travel_ticks, "detours": d.tour.detours,
                     "excluded": d.tour.excluded, "paths_checked": d.tour.paths_checked},
            "robot_time_s": {"planned": d.time_s, "budget": budget, "random": t_r,
                             "read_ticks_per_sample": int(_read_ticks())},
            "random_samples": n_r,
            "predicted_tool_mm": {"planned": d.tool_mm, "random": tool_r,
                                  "where": TOOL_WHERE + "; the noise model's, tempered "
                                  "prior and known lengths as the fit weighs them"},
            "aimed_with": None if model is None else "params",
            "design_clearance_m": DESIGN_CLEARANCE_M,
            "noise": {"sample_sigma_m": rd.sigma_m}}


def _read_ticks() -> int:
    from planecal.sampling.tour import READ_TICKS_MEAN
    return READ_TICKS_MEAN


def random_minutes(scene, samples: int, seed: int = 0, model=None) -> float:
    """Robot minutes of the sampling run's own random run of ``samples`` (its poses from
    ``seed``, every laser read succeeding, reads at ``tour.READ_TICKS_MEAN``): the default
    budget of a tool design, the random run it is compared with."""
    from planecal.safety.collision import CollisionWorld
    from planecal.sampling import tour
    from planecal.studies.planning import run_design
    _, _, visits = run_design(scene, samples, seed, CollisionWorld(scene, clearance_m=0.01),
                              with_visits=True, model=model)
    return tour.robot_time_s(visits, _start(scene), scene.robot,
                             read_ticks=tour.READ_TICKS_MEAN) / 60.0
