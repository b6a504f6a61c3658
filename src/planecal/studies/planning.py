"""Pose planning for identifiability: choose N sample poses among M collision-free
candidates to maximise det(J^T J) (D-optimal) before the robot moves.

Candidates (``candidate_pool``): the sampling run's own pose distribution
(``PoseGenerator``: spot on the plate, beam in the cone, distance, roll; round robin over
plates), half with IK nearest to the scene's calibration position within the limits, counts
in range, target configuration collision-free (``CollisionWorld.check_config``), half the
poses the run's own planner visits. Rows: the distance Jacobian at the scene's *nominal*
parameters (all we know before calibrating) over the free parameters, columns scaled to
unit RMS over the candidates (so units do not matter; D-optimality is invariant to column
scaling anyway, the scaling only conditions the arithmetic).

Algorithm and prediction: ``studies.design`` (D-optimal choice, greedy + Fedorov exchange).

Prediction: the offsets' std of the unweighted fit, sandwich covariance with the twin's
noise model (``studies.common``: repeatability projected per pose + laser buffer mean), for
the planned set and for the set the sampling run itself would visit with the same seed
(its ``Planner``: IK nearest to the *previous* pose, target and path checked; without a
checker: the first N candidates), of equal size. That baseline matters: on thesis_final
the run's path checks keep the wrist in one branch (q5 > 0 in 99 % of the samples), which
leaves delta5 ~10x less determined than poses mixing both wrist branches.

Sample count from a target (``choose_count``): the smallest n whose D-optimal design's
predicted figure meets it -- ``target_std_urad``: the largest predicted (sandwich) std of
the free joint offsets (delta2..delta5 by default); ``target_ap_mm``: the predicted
position error at the tool point (the laser's beam point at the scene's standoff, robot
frame, 1 sigma, RMS over the candidate poses: ``estimation.accuracy``'s figure, the
sandwich covariance of every free parameter carried there), with in quadrature the model's
mismatch an earlier calibration of the cell showed (``Mismatch``: its estimate's share
beyond the noise, held: systematic, not averaged down by more poses; without one, the
noise alone), times ``TARGET_MARGIN``. Bisection over n (the prediction falls with n; the result is checked,
never assumed).

Aiming (``model``, ``plan --params R.json``): the candidates are drawn, solved and
predicted with an earlier calibration's cell (its sensor pose, planes and joint offsets:
``sampling.poses.CommandModel``, what ``rehearse``/``sample --params`` aim with), so the
planned distances are the true cell's to that calibration's accuracy, not to the nominal
sensor pose's millimetres: a plan made from the nominal model of a real cell put 4 of 13
poses out of the laser's range (issue 22).

Robot time (``sampling.tour``): the planned poses are ordered into the tour from the
calibration position that minimises the robot's ticks under the step limit (``tour.order``:
each move costs the ticks of the joint that needs the most, collision-checked moves, a
blocked one by its detour), and the plan reports the robot time of the run that visits
them (``tour.visit_list``: the run's own ``ListPlanner``, then ``tour.robot_time_s`` at the
robot's step and tick; laser reads at ``tour.READ_TICKS``, the twin's median) before
ordering (the design's order), after it, and for the random run of equal size. A pose
that run cannot reach from the others (straight or by a detour) is dropped from the list
and the plan says so (``dropped``), its prediction then of the poses listed: the run
visits a plan's list whole.

The sampling run takes the list through ``SamplingRun(..., planner=ListPlanner(...))``
(foreground planning only: the list planner keeps state);
``studies.rehearsal.rehearse_planned`` does that on the twin; ``planecal rehearse --poses
POSES.json`` (and ``sample``) does it from the command line.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from planecal.base.errors import InputError
from planecal.base.progress import report
from planecal.formats.base import read_json, validate
from planecal.formats.poses import POSES_FORMAT, PosesFile
from planecal.model.encoder import counts_in_range, counts_to_joints, joints_to_counts
from planecal.studies.design import (TARGET_MARGIN, TOOL_WHERE, Mismatch, Predictor,
                                     choose_count, d_optimal, design_covariances, scaled_rows,
                                     tool_rows)


def candidates(scene, m: int, seed: int, checker=None, max_draws: int | None = None,
               model=None):
    """Up to m collision-free candidate poses: (qe (k,6) int64, q (k,6), plate (k,)). Each
    drawn sensor pose offers its solution in each wrist branch (the nearest to the
    calibration position in that branch), so the design can mix the branches. ``model``:
    what the poses are aimed with (``sampling.poses.CommandModel``; default nominal)."""
    from planecal.sampling.poses import PoseGenerator, PoseSettings

    gen = PoseGenerator(scene, PoseSettings(cone_deg=scene.cone_deg,
                                            distance_mm=tuple(scene.distance_mm)), model)
    rng = np.random.default_rng(seed)
    q_ref = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    qe, qs, plate = [], [], []
    draws = 0
    max_draws = max_draws or 20 * m
    while len(qe) < m and draws < max_draws:
        report(len(qe), m, "candidate poses")
        k = gen.plate_for(draws, rng)  # by draw: a draw gives up to two candidates
        pose = gen.draw(rng, k)
        draws += 1
        for q in gen.branch_targets(pose, q_ref):
            c = joints_to_counts(scene.robot, q)
            if len(qe) >= m or not counts_in_range(scene.robot, c):
                continue
            if checker is not None and not checker.check_config(q).ok:
                continue
            qe.append(c)
            qs.append(q)
            plate.append(k)
    if len(qe) < 2:
        raise InputError(f"only {len(qe)} collision-free candidate poses in {draws} draws")
    return np.array(qe), np.array(qs), np.array(plate, int)


RUN_POOL_SEED = 7_919  # added to the seed: the run-planner half of the candidate pool


def candidate_pool(scene, m: int, seed: int, checker=None, model=None):
    """The candidates of a plan: (qe, q, plate). Half from ``candidates`` (each drawn pose
    in both wrist branches, IK nearest to the calibration position), half the poses the
    sampling run's own planner visits (``run_design``, seed + ``RUN_POOL_SEED``: IK
    nearest to the previous pose, so the joints wander over their range). On thesis_final
    the second half is far richer (log det of 150 chosen of 1500: 22.8 from the first
    kind alone, 31.5 from both); without a checker, ``candidates`` only."""
    if checker is None:
        return candidates(scene, m, seed, checker, model=model)
    qe, q, plate = candidates(scene, m - m // 2, seed, checker, model=model)
    qe2, pl2 = run_design(scene, m // 2, seed + RUN_POOL_SEED, checker, model=model)
    return (np.vstack([qe, qe2]), np.vstack([q, counts_to_joints(scene.robot, qe2)]),
            np.concatenate([plate, pl2]))


def run_design(scene, n: int, seed: int, checker, clearance_m: float = 0.01,
               with_visits: bool = False, model=None):
    """The poses the sampling run itself would visit (its ``Planner``: IK from the
    previous pose, target and path collision-checked) for ``seed``, if every laser read
    succeeded: (qe, plate), and with ``with_visits`` its moves (``tour.Visit``s, for the
    robot time)."""
    from planecal.sampling import tour
    from planecal.sampling.planner import Planner
    from planecal.sampling.run import RunSettings
    rs = RunSettings.for_scene(scene, samples=n, seed=seed)
    q0 = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    try:
        visits = tour.visit(Planner(scene, rs.pose, checker, model), q0, n, seed,
                            rs.max_attempts)
    except RuntimeError as e:
        raise InputError(f"the sampling run's planner gave up: {e}") from None
    qe = np.array([v.goal for v in visits], np.int64).reshape(-1, 6)
    plate = np.array([v.plate for v in visits], int)
    return (qe, plate, visits) if with_visits else (qe, plate)


PLAN_STAGES = 6  # progress steps of ``plan``


@dataclass
class _Design:
    """A plan's candidates, the D-optimal choice among them and its prediction."""
    qe: np.ndarray
    plate: np.ndarray
    layout: object
    free: np.ndarray
    J: np.ndarray  # the candidates' distance Jacobian over ``layout``
    predictor: Predictor
    n: int  # the sample count: asked for, or chosen for a target
    chosen: np.ndarray
    passes: int
    swaps: int
    logdet: float
    std: np.ndarray  # sandwich std of the free parameters
    white: np.ndarray  # white-noise std of the free parameters
    ap_mm: float  # predicted tool-point position error
    model: object | None = None  # what the poses are aimed with (None: nominal)
    mismatch: Mismatch | None = None


@dataclass
class _RandomRun:
    """The baseline: the sampling run's own poses, its robot time and its prediction."""
    qe: np.ndarray
    plate: np.ndarray
    time_s: float
    logdet: float
    std: np.ndarray
    white: np.ndarray
    ap_mm: float


@dataclass
class _Tour:
    """The planned poses in the order listed; the robot time before and after ordering;
    ``dropped``: why the run cannot visit the rest of the design (None: it can)."""
    chosen: np.ndarray
    order: object | None  # ``tour.order``'s result, None when not ordered
    time_unordered_s: float
    time_s: float
    dropped: str | None = None


def plan(scene, n: int, m: int, seed: int = 0, settings=None, checker=None,
         repeatability_mm: float | None = None, laser_noise_mm: float = 0.001,
         target_std_urad: float | None = None, target_ap_mm: float | None = None,
         ordered: bool = True, progress=None, model=None,
         mismatch: Mismatch | None = None) -> dict:
    """The planning study (module docstring). Returns the planned pose list (ordered for
    robot time unless ``ordered=False``), the random set of equal size, both predictions
    and the robot times. With a target (``target_std_urad`` or ``target_ap_mm``) ``n`` is
    the most samples it may choose. ``settings``: how the poses will be calibrated
    (``estimation.calibrate.CalibrationSettings``; default level offsets): the design is
    D-optimal for the base set the candidates can identify (``calibrate.base_set``).
    ``progress``: a ``Progress`` of ``PLAN_STAGES`` steps (released once a target is met).
    ``model``: what the poses are aimed with (``sampling.poses.CommandModel``: an earlier
    calibration's cell; default nominal); ``mismatch``: that calibration's (``Mismatch``),
    which scales every prediction (module docstring)."""
    target = plan_target(n, m, target_std_urad, target_ap_mm)
    design = _design(scene, n, m, seed, settings, checker, repeatability_mm, laser_noise_mm,
                     target, progress, model, mismatch)
    start = joints_to_counts(scene.robot, scene.calibration_q if scene.calibration_q is not
                             None else np.zeros(6))
    _say(progress, f"the random run's {design.n} poses")
    random = _random_run(scene, design, seed, checker, start)
    tour = _tour(scene, design, checker, counts_to_joints(scene.robot, start), start, ordered,
                 progress)
    if tour.dropped is not None:  # the prediction of the poses listed
        design = _keep(design, tour.chosen)
    return _result(scene, seed, design, random, tour, ordered, target)


def _say(progress, note: str) -> None:
    if progress is not None:
        progress.update(note=note)


def plan_target(n: int, m: int, target_std_urad, target_ap_mm) -> tuple[str, float] | None:
    """The plan's sizes checked, and its target: ("std" | "ap", value), or None."""
    if n < 13:
        raise InputError(f"--samples must be at least 13, got {n}")
    if m < n:
        raise InputError(f"--candidates ({m}) must be at least --samples ({n})")
    if target_std_urad is not None and target_ap_mm is not None:
        raise InputError("--target-std-urad and --target-ap-mm exclude each other")
    for name, t in (("--target-std-urad", target_std_urad), ("--target-ap-mm", target_ap_mm)):
        if t is not None and not (np.isfinite(t) and t > 0):
            raise InputError(f"{name} must be a finite number > 0, got {t}")
    if target_std_urad is not None:
        return "std", target_std_urad
    return None if target_ap_mm is None else ("ap", target_ap_mm)


def _design(scene, n: int, m: int, seed: int, settings, checker, repeatability_mm,
            laser_noise_mm: float, target, progress, model=None, mismatch=None) -> _Design:
    """The candidates (``candidate_pool``) and the D-optimal choice of n among them (or of
    the fewest that meet ``target``: ``choose_count``), with its prediction (the twin's
    noise model)."""
    from planecal.estimation.calibrate import CalibrationSettings, base_set
    from planecal.estimation.noise import repeatability_sigma, sample_sigma_m
    from planecal.model.scene import nominal_params
    if target is not None and target[0] == "ap" and mismatch is not None \
            and mismatch.mismatch_mm * TARGET_MARGIN > target[1]:
        raise InputError(f"--target-ap-mm {target[1]:g}: not reachable by any poses: the "
                         f"model's mismatch {mismatch.source} showed leaves "
                         f"{mismatch.mismatch_mm:.3g} mm at the tool point on its own "
                         f"(x{TARGET_MARGIN:g} margin: {mismatch.mismatch_mm * TARGET_MARGIN:.3g}"
                         "); calibrate at a higher --level and plan from that result")
    settings = settings or CalibrationSettings()
    _say(progress, f"drawing {m} candidate poses")
    qe, q, plate = candidate_pool(scene, m, seed, checker, model)
    if len(qe) < n:
        raise InputError(f"only {len(qe)} collision-free candidates for {n} samples")
    params = nominal_params(scene) if model is None else model.params
    layout, bs = base_set(scene.robot, qe, params, plate, settings)
    free = bs.mask(layout)
    J, A = scaled_rows(scene, qe, plate, layout, free, params)
    rep = scene.robot.repeatability_m if repeatability_mm is None else repeatability_mm * 1e-3
    s = repeatability_sigma(scene.robot, rep) if rep > 0 else 0.0
    sig_l = sample_sigma_m(laser_noise_mm)
    predictor = Predictor(scene, J, layout, free, s, sig_l,
                          tool_rows(scene, q, params, layout, free),
                          0.0 if mismatch is None else mismatch.mismatch_mm)
    if target is not None:
        _say(progress, f"choosing the sample count for the target ({target[0]} <= {target[1]:g})")
        n, (chosen, _, passes, swaps) = choose_count(A, predictor, *target,
                                                          max(13, int(free.sum()) + 1), n,
                                                          progress)
    else:
        _say(progress, f"choosing {n} D-optimal poses")
        chosen, _, passes, swaps = d_optimal(A, n)
    return _Design(qe, plate, layout, free, J, predictor, n, chosen, passes, swaps,
                   *_prediction(predictor, J, J[chosen]), model, mismatch)


def _random_run(scene, d: _Design, seed: int, checker, start: np.ndarray) -> _RandomRun:
    """What the sampling run itself would sample (same seed; without a checker the first
    candidates), scaled as the design's candidates, and its robot time from ``start``."""
    from planecal.sampling import tour
    n, robot = d.n, scene.robot
    if checker is not None:
        qe_r, plate_r, visits_r = run_design(scene, n, seed, checker, with_visits=True,
                                             model=d.model)
        time_r = tour.robot_time_s(visits_r, start, robot)
    else:
        qe_r, plate_r, time_r = d.qe[:n], d.plate[:n], tour.robot_time_s(d.qe[:n], start, robot)
    J_r, _ = scaled_rows(scene, qe_r, plate_r, d.layout, d.free,
                         None if d.model is None else d.model.params)
    return _RandomRun(qe_r, plate_r, time_r, *_prediction(d.predictor, d.J, J_r))


def _prediction(p: Predictor, J_all: np.ndarray, J: np.ndarray):
    """(log det of the design scaled as the candidates J_all, sandwich and white std of the
    free parameters, predicted position error [mm]) of the poses whose Jacobian rows are J."""
    A = J[:, p.free] / np.sqrt(np.mean(J_all[:, p.free] ** 2, axis=0))
    cov = design_covariances(J, p.layout, p.free, p.s, p.sig_l)
    std, ap = p.of_covariances(cov)
    return float(np.linalg.slogdet(A.T @ A)[1]), std, np.sqrt(np.diag(cov["white"])), ap


def _tour(scene, d: _Design, checker, q0: np.ndarray, start: np.ndarray, ordered: bool,
          progress) -> _Tour:
    """The run's robot time through the design's poses in the design's order and, with
    ``ordered``, ordered into the tour that minimises it (``tour.order``), without any
    pose the run's own ``ListPlanner`` cannot reach from the others, straight or by a
    detour (``tour.visit_list``; ``_Tour.dropped`` says why)."""
    from planecal.sampling import tour
    robot = scene.robot

    def run(idx):
        """(robot time, the poses of idx the run takes in idx's order, why not the rest)."""
        if checker is None:
            return tour.robot_time_s(d.qe[idx], start, robot), idx, None
        vs, taken, why = tour.visit_list(scene, d.qe[idx], d.plate[idx], checker, q0)
        return tour.robot_time_s(vs, start, robot), idx[np.sort(taken)], why

    _say(progress, "robot time of the design's order")
    time_before, chosen, why = run(d.chosen)
    time_s, tr = time_before, None
    _say(progress, "ordering the poses for robot time" if ordered else "keeping the design's order")
    if ordered:
        tr = tour.order(d.qe[d.chosen], start, checker, scene if checker is not None else None,
                        nominal=robot.step_counts)
    _say(progress, "robot time of the tour" if ordered else "not ordered")
    if ordered:
        time_s, chosen, why = run(d.chosen[np.array(tr.order, int)])
    why = None if why is None else (f"{d.n - len(chosen)} of the {d.n} planned poses dropped "
                                    f"(the sampling run's list planner: {why})")
    return _Tour(chosen, tr, time_before, time_s, why)


def _keep(d: _Design, rows: np.ndarray) -> _Design:
    """The design reduced to the candidates ``rows`` of its choice, its prediction anew."""
    logdet, std, white, ap = _prediction(d.predictor, d.J, d.J[rows])
    return replace(d, n=len(rows), chosen=rows, logdet=logdet, std=std, white=white, ap_mm=ap)


def _result(scene, seed: int, d: _Design, r: _RandomRun, t: _Tour, ordered: bool,
            target) -> dict:
    """The plan's document (format ``POSES_FORMAT``)."""
    from planecal.sampling import tour
    n, p, fn = d.n, int(d.free.sum()), d.layout.names_of(d.free)
    tr, read_s = t.order, (tour.READ_TICKS + tour.DWELL_TICKS) * scene.robot.tick_s
    res = {
        "format": POSES_FORMAT, "scene": scene.name, "seed": seed, "samples": n,
        "candidates": int(len(d.qe)), "free": fn,
        "counts": d.qe[t.chosen].tolist(), "plates": d.plate[t.chosen].tolist(),
        "random_counts": r.qe.tolist(), "random_plates": r.plate.tolist(),
        "logdet_planned": d.logdet, "logdet_random": r.logdet,
        "d_efficiency_gain": float(np.exp((d.logdet - r.logdet) / p)),
        "exchange_passes": d.passes, "exchange_swaps": d.swaps,
        "ordered": bool(ordered), "dropped": t.dropped,
        "tour": None if tr is None else {"travel_ticks": tr.travel_ticks, "detours": tr.detours,
                                         "excluded": tr.excluded,
                                         "paths_checked": tr.paths_checked},
        "robot_time_s": {"random": r.time_s, "planned_unordered": t.time_unordered_s,
                         "planned": t.time_s, "read_ticks_per_sample": tour.READ_TICKS},
        "robot_time_per_sample_s": {"random": r.time_s / n, "planned": t.time_s / n},
        "travel_per_sample_s": {"random": r.time_s / n - read_s, "planned": t.time_s / n - read_s},
        "predicted_std_planned": dict(zip(fn, d.std.tolist())),
        "predicted_std_random": dict(zip(fn, r.std.tolist())),
        "predicted_white_std_planned": dict(zip(fn, d.white.tolist())),
        "predicted_white_std_random": dict(zip(fn, r.white.tolist())),
        "predicted_tool_mm": {"planned": d.ap_mm, "random": r.ap_mm, "where": TOOL_WHERE},
        "aimed_with": None if d.model is None else "params",
        "mismatch": None if d.mismatch is None else {
            "tool_point_mm": d.mismatch.tool_point_mm,
            "noise_only_mm": d.mismatch.noise_only_mm,
            "mismatch_mm": d.mismatch.mismatch_mm, "source": d.mismatch.source},
        "noise": {"joint_sigma_rad": d.predictor.s, "laser_sample_sigma_m": d.predictor.sig_l},
    }
    if target is not None:
        res["target"] = {"kind": target[0], "value": target[1],
                         "unit": "urad" if target[0] == "std" else "mm",
                         "margin": TARGET_MARGIN}
    return res


def approach_of(doc: dict, n: int) -> np.ndarray:
    """(n,) int8: the approach side of each entry of a pose list read by ``load_poses``
    (0, straight in, where the plan chose none)."""
    a = doc.get("approach")
    return np.zeros(n, np.int8) if a is None else np.array(a, np.int8).reshape(n)


def load_poses(path) -> tuple[np.ndarray, np.ndarray, dict]:
    """(counts (n, 6) int64, plates (n,), the whole document) of a pose list, validated by
    ``planecal.formats.poses.PosesFile``; one-line InputError otherwise."""
    d = read_json(path, "pose list")
    pf = validate(PosesFile, d, path, "pose list")
    return np.array(pf.counts, np.int64).reshape(-1, 6), np.array(pf.plates, int), d
