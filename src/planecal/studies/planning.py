"""Pose planning for identifiability: choose N sample poses among M collision-free
candidates to maximise det(J^T J) (D-optimal) before the robot moves.

Candidates: the sampling run's own pose distribution (``PoseGenerator``: spot on the plate,
beam in the cone, distance, roll; round robin over plates), IK nearest to the scene's
calibration position within the limits, counts in range, target configuration
collision-free (``CollisionWorld.check_config``). Rows: the distance Jacobian at the
scene's *nominal* parameters (all we know before calibrating) over the free parameters,
columns scaled to unit RMS over the candidates (so units do not matter; D-optimality is
invariant to column scaling anyway, the scaling only conditions the arithmetic).

Algorithm: greedy forward selection (each step adds the candidate with the largest
prediction variance a^T M^-1 a, Sherman-Morrison updates, M0 = 1e-6 I), then Fedorov
exchange passes (swap a chosen and a free candidate when it raises det M:
(1 + d_j)(1 - d_i) + d_ij^2 > 1 + tol) until no swap helps. Each candidate is used at most
once (a repeated pose only averages noise, the real run samples each pose once).

Prediction: the offsets' std of the unweighted fit, sandwich covariance with the twin's
noise model (``studies.common``: repeatability projected per pose + laser buffer mean), for
the planned set and for the set the sampling run itself would visit with the same seed
(its ``Planner``: IK nearest to the *previous* pose, target and path checked; without a
checker: the first N candidates), of equal size. That baseline matters: on thesis_final
the run's path checks keep the wrist in one branch (q5 > 0 in 99 % of the samples), which
leaves delta5 ~10x less determined than poses mixing both wrist branches. ``order_poses`` sorts the planned poses into a tour from
the calibration position (nearest in the largest count difference, straight joint paths
collision-checked; a pose whose path is blocked is tried later).

The sampling run takes the list through ``SamplingRun(..., planner=ListPlanner(...))``
(foreground planning only: the list planner keeps state); ``rehearse_planned`` does that
on the twin; ``planecal rehearse --poses POSES.json`` (and ``sample``) does it from the
command line.
"""
from __future__ import annotations

import numpy as np

from planecal.cell import predict_with_jacobian
from planecal.encoder import counts_in_range, joints_to_counts
from planecal.errors import InputError
from planecal.fit import noise_variance
from planecal.formats.base import read_json, validate
from planecal.formats.poses import POSES_FORMAT, PosesFile
from planecal.studies.common import BUFFER_LEN, covariances


def candidates(scene, m: int, seed: int, checker=None, max_draws: int | None = None):
    """Up to m collision-free candidate poses: (qe (k,6) int64, q (k,6), plate (k,)). Each
    drawn sensor pose offers its solution in each wrist branch (the nearest to the
    calibration position in that branch), so the design can mix the branches."""
    from planecal.sampling.poses import PoseGenerator, PoseSettings

    gen = PoseGenerator(scene, PoseSettings(cone_deg=scene.cone_deg,
                                            distance_mm=tuple(scene.distance_mm)))
    rng = np.random.default_rng(seed)
    q_ref = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    qe, qs, plate = [], [], []
    draws = 0
    max_draws = max_draws or 20 * m
    while len(qe) < m and draws < max_draws:
        k = gen.plate_for(len(qe), rng)
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


def run_design(scene, n: int, seed: int, checker, clearance_m: float = 0.01):
    """The poses the sampling run itself would visit (its ``Planner``: IK from the
    previous pose, target and path collision-checked) for ``seed``, if every laser read
    succeeded: (qe, plate)."""
    from planecal.sampling.collect import Cursor, MemoryRecorder, PlansOnly, Tally, collect
    from planecal.sampling.planner import Planner
    from planecal.sampling.run import RunSettings
    rs = RunSettings.for_scene(scene, samples=n, seed=seed)
    rec, tally = MemoryRecorder(), Tally()
    q0 = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    collect(Planner(scene, rs.pose, checker), PlansOnly(), rec, n,
            Cursor(q0, np.random.default_rng(seed).bit_generator.state), tally,
            rs.max_attempts)
    if tally.status != "complete":
        raise InputError(f"the sampling run's planner gave up: {tally.reason}")
    qe, _, plate = rec.arrays()
    return qe, plate


def d_optimal(A: np.ndarray, n: int, max_passes: int = 20, tol: float = 1e-9):
    """Indices of n rows of A (M, p) maximising det(A_S^T A_S): greedy + Fedorov exchange.
    Returns (indices, log det, passes, swaps)."""
    M, p = A.shape
    if n > M:
        raise InputError(f"cannot choose {n} poses from {M} candidates")
    Minv = np.eye(p) * 1e6
    chosen = []
    free = np.ones(M, bool)
    for _ in range(n):
        d = np.einsum("ij,jk,ik->i", A, Minv, A)
        d[~free] = -np.inf
        j = int(np.argmax(d))
        a = A[j]
        Ma = Minv @ a
        Minv -= np.outer(Ma, Ma) / (1.0 + a @ Ma)
        chosen.append(j)
        free[j] = False
    chosen = np.array(chosen)
    swaps = 0
    passes = 0
    for passes in range(1, max_passes + 1):
        improved = False
        for pos in range(n):
            G = A[chosen].T @ A[chosen]
            Minv = np.linalg.inv(G)
            i = chosen[pos]
            ai = A[i]
            MA = A @ Minv  # (M, p)
            d_all = np.einsum("ij,ij->i", MA, A)
            d_ij = MA @ ai
            gain = (1 + d_all) * (1 - d_all[i]) + d_ij ** 2
            gain[~free] = -np.inf
            j = int(np.argmax(gain))
            if gain[j] > 1 + tol:
                chosen[pos] = j
                free[i], free[j] = True, False
                swaps += 1
                improved = True
        if not improved:
            break
    sign, logdet = np.linalg.slogdet(A[chosen].T @ A[chosen])
    return chosen, float(logdet), passes, swaps


def scaled_rows(scene, qe, plate, layout, free):
    """The Jacobian (over ``layout``) at the scene's nominal parameters, and its free
    columns scaled to unit RMS."""
    from planecal.scene import nominal_params
    nominal = nominal_params(scene)
    _, J = predict_with_jacobian(scene.robot, qe, nominal, plate, layout)
    Jf = J[:, free]
    S = 1.0 / np.sqrt(np.mean(Jf ** 2, axis=0))
    return J, Jf * S


def predicted_std(J: np.ndarray, layout, free, joint_sigma: float, laser_sigma_m: float):
    """Sandwich and white-noise std of the free parameters for the Jacobian J (over
    ``layout``) and the twin's noise model."""
    v = noise_variance(J[:, layout.slice("joint_offsets")], joint_sigma, laser_sigma_m)
    cov = covariances(J[:, free], v)
    return np.sqrt(np.diag(cov["sandwich"])), np.sqrt(np.diag(cov["white"]))


def order_poses(scene, q: np.ndarray, checker=None) -> tuple[list[int], int]:
    """A tour through the poses from the calibration position: each step goes to the
    nearest remaining pose (largest count difference) whose straight path is clear.
    Returns (order, paths that were blocked and skipped)."""
    robot = scene.robot
    w = np.abs(robot.gains)
    cur = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    left = list(range(len(q)))
    order, blocked = [], 0
    while left:
        cost = np.max(np.abs(q[left] - cur) * w, axis=1)
        for idx in np.argsort(cost):
            j = left[idx]
            if checker is None or checker.check_path(cur, q[j]).ok:
                break
            blocked += 1
        else:
            j = left[int(np.argmin(cost))]  # nothing clear from here: take the nearest anyway
        order.append(j)
        left.remove(j)
        cur = q[j]
    return order, blocked


def plan(scene, n: int, m: int, seed: int = 0, free_names=None, checker=None,
         repeatability_mm: float | None = None, laser_noise_mm: float = 0.001) -> dict:
    """The planning study (module docstring). Returns the planned pose list (ordered),
    the random set of equal size and both predictions."""
    from planecal.layout import level1_layout
    from planecal.studies.montecarlo import MCSettings, joint_sigma

    if n < 13:
        raise InputError(f"--samples must be at least 13, got {n}")
    if m < n:
        raise InputError(f"--candidates ({m}) must be at least --samples ({n})")
    layout = level1_layout(len(scene.plates))
    free = layout.free_from_names(free_names)
    qe, q, plate = candidates(scene, m, seed, checker)
    if len(qe) < n:
        raise InputError(f"only {len(qe)} collision-free candidates for {n} samples")
    J, A = scaled_rows(scene, qe, plate, layout, free)
    chosen, logdet, passes, swaps = d_optimal(A, n)
    # the baseline: what the sampling run itself would sample (same seed), scaled alike
    if checker is not None:
        qe_r, plate_r = run_design(scene, n, seed, checker)
    else:
        qe_r, plate_r = qe[:n], plate[:n]
    J_r, _ = scaled_rows(scene, qe_r, plate_r, layout, free)
    A_r = J_r[:, free] / np.sqrt(np.mean(J[:, free] ** 2, axis=0))
    _, logdet_rand = np.linalg.slogdet(A_r.T @ A_r)
    s = joint_sigma(scene.robot, MCSettings(repeatability_mm=repeatability_mm))
    sig_l = laser_noise_mm * 1e-3 / np.sqrt(BUFFER_LEN)
    std_p, white_p = predicted_std(J[chosen], layout, free, s, sig_l)
    std_r, white_r = predicted_std(J_r, layout, free, s, sig_l)
    order, blocked = order_poses(scene, q[chosen], checker)
    chosen = chosen[order]
    p = int(free.sum())
    fn = layout.names_of(free)
    return {
        "format": POSES_FORMAT, "scene": scene.name, "seed": seed, "samples": n,
        "candidates": int(len(qe)), "free": fn,
        "counts": qe[chosen].tolist(), "plates": plate[chosen].tolist(),
        "random_counts": qe_r.tolist(), "random_plates": plate_r.tolist(),
        "logdet_planned": logdet, "logdet_random": float(logdet_rand),
        "d_efficiency_gain": float(np.exp((logdet - logdet_rand) / p)),
        "exchange_passes": passes, "exchange_swaps": swaps, "paths_blocked_in_ordering": blocked,
        "predicted_std_planned": dict(zip(fn, std_p.tolist())),
        "predicted_std_random": dict(zip(fn, std_r.tolist())),
        "predicted_white_std_planned": dict(zip(fn, white_p.tolist())),
        "predicted_white_std_random": dict(zip(fn, white_r.tolist())),
        "noise": {"joint_sigma_rad": s, "laser_sample_sigma_m": sig_l},
    }


def load_poses(path) -> tuple[np.ndarray, np.ndarray, dict]:
    """(counts (n, 6) int64, plates (n,), the whole document) of a pose list, validated by
    ``planecal.formats.poses.PosesFile``; one-line InputError otherwise."""
    d = read_json(path, "pose list")
    pf = validate(PosesFile, d, path, "pose list")
    return np.array(pf.counts, np.int64).reshape(-1, 6), np.array(pf.plates, int), d


# ----- consuming a pose list in the sampling run ---------------------------------------------

def rehearse_planned(scene, counts, plates, out, twin, checker, seed: int = 0):
    """A sampling run on ``twin`` through the planned poses (``ListPlanner``)."""
    from planecal.links.base import AlwaysEnabled
    from planecal.sampling.driver import Driver
    from planecal.sampling.planner import ListPlanner
    from planecal.sampling.run import RunSettings, SamplingRun

    rs = RunSettings(scene=str(scene.path), samples=len(counts), seed=seed)
    drv = Driver(twin, twin, AlwaysEnabled(), scene.robot)
    return SamplingRun(drv, scene, rs, out, checker,
                       planner=ListPlanner(scene, counts, plates, checker)).run()
