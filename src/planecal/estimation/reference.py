"""The reference a calibration's figures at the tool are judged against (issues 30 and 31).

A calibration's covariance says how far its parameters move with the samples' noise; it
does not say what the model leaves out. An offsets-only fit of a robot whose links are off
absorbs their effect into the offsets and the sensor pose, right on the plate and wrong
elsewhere: a bias no covariance of that fit shows (measured on the realistic UR5, truths
100-101: with the noise switched off the estimate of 0.54-0.94 mm stays for an error of
1.8-2.4 mm at the tool; with the geometry switched off the error falls to 0.50-0.60 mm;
with everything but the noise off the estimate is right). And a level-3 fit holds its
weakly determined geometry at its prior: where the robot's geometry is larger than the
prior says (the UR5's 0.3 mm / 0.5 mrad and 1 mrad between its parallel axes against
level 3's 0.2 mm / 0.2 mrad), the fit's covariance reports the prior's std for an error
several times it (0.33 mm said, 1.9 mm true).

The reference is level 3's whole model (``model.levels``: the geometry, the base frame,
J2/J3's compliance, the gear harmonics, backlash and laser linearity), linearised at the
calibration's solution, with a prior of the robot class's magnitude on each of those
terms (``levels.class_std``) and the noise model's variance on each sample
(``estimation.noise``: the repeatability on the beam, the laser, the counts). Two scales
are left to the samples, found by maximising the evidence (MacKay's fixed point): the
prior's ``scale`` (how large this robot's errors are against the class: the realistic
MC70's come out 0.5-0.7, the realistic UR5's 1.9-3.4) and the ``noise_factor`` (the
residuals' variance over the noise model's). Its posterior, a mean correction and a
covariance, is where the truth is as far as these samples say.

A model's error at the tool is then, pose by pose, its tool point minus the reference's
posterior: a mean (the model's bias against the reference: zero only where the model
agrees with it) and the posterior's spread. Its rms over the poses is the estimate
(``rms_mm``); draws of it give a band (``quantiles``). The same reference judges every
model on the same samples: the calibration itself, and the simpler levels
(``estimation.verdict``). Measured (150 samples, realistic, truths 100-104 against the
twin's true model, rms over the samples' poses): thesis_final offsets 0.66-1.05 mm for
0.71-0.89 true, full 1.2-3.7 for 2.1-3.6; ur5_table offsets 1.3-2.3 for 1.1-2.4, level 3
0.65-1.7 for 0.55-1.9; three_plates level 3 0.21-0.22 for 0.11-0.23.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace

import numpy as np

from planecal.estimation.evidence import evidence_step
from planecal.estimation.fit import FitPrior
from planecal.estimation.identifiability import DEFAULT_TOL, select_base
from planecal.estimation.noise import repeatability_sigma, sample_sigma_m, sample_variance
from planecal.estimation.tool import standoff_m, tool_jacobian, tool_point
from planecal.model.gravity import joint_torques
from planecal.model.layout import ParamLayout
from planecal.model.levels import class_std, layout_for
from planecal.model.measurement import joints_of_counts, predict_joints_with_jacobian

MAX_POSES = 100  # the tool point is judged at up to this many of the samples' poses
EVIDENCE_PASSES = 60  # Gauss-Newton with MacKay's fixed point: each pass one Jacobian
SETTLED = 1e-2  # both scales within 1 % and the step within 1 % of its std
LASER_NOISE_MM = 0.001  # a reading's noise in the noise model (the ZS-LD80's resolution)


@dataclass(frozen=True, eq=False)
class Reference:
    """The reference posterior (module docstring): its mean ``params`` (level 3's layout
    ``layout``; free: its base set on these samples, ``names``) and covariance ``cov``
    over ``names``; the tool point at the samples ``poses`` (joint angles ``q``, backlash
    flanks ``side``): the mean's ``points`` (M, 3) and its Jacobian ``T`` (M, 3, q)."""
    robot: object
    layout: ParamLayout
    names: tuple[str, ...]
    params: object  # CellParams
    cov: np.ndarray
    T: np.ndarray
    points: np.ndarray
    poses: np.ndarray
    q: np.ndarray
    side: np.ndarray | None
    standoff_m: float
    scale: dict  # the class prior's scale per kind of term (geometry, gear, ...)
    noise_factor: float
    gamma: float  # how many of the class terms the samples determine (MacKay's gamma)
    system: tuple = ()  # the whitened linear system at the mean (``widened``)

    def widened(self, k: float) -> "Reference":
        """The same reference with every class prior k times wider (to first order about
        its mean): what its figures would be were the robot's errors larger than the
        samples' evidence puts them. Where a conclusion holds in both, the samples carry
        it, not the prior's scale."""
        X, y, std, x, G, g, s2, f, groups = self.system
        dx, cov, *_ = evidence_step(X, y, std, x, G, g, np.asarray(s2) * k * k, f, groups)
        return replace(self, cov=cov, points=self.points + np.einsum("nik,k->ni", self.T, dx))

    def error(self, params) -> tuple[np.ndarray, np.ndarray]:
        """A model's (``params``) error at the tool: the mean (M, 3) [m], its tool points
        minus the reference's, and the spread's square root S (M*3, q): the error is mean
        + (S z).reshape(M, 3), z standard normal."""
        mean = tool_point(self.robot, self.q, params, self.side, self.standoff_m) - self.points
        lam, V = np.linalg.eigh(0.5 * (self.cov + self.cov.T))
        S = self.T.reshape(-1, len(self.names)) @ (V * np.sqrt(np.clip(lam, 0.0, None)))
        return mean, S

    def rms_mm(self, params) -> float:
        """A model's expected tool-point error, rms over the poses [mm]."""
        mean, S = self.error(params)
        return float(np.sqrt(np.mean(np.sum(mean ** 2, 1)) + np.sum(S ** 2) / len(mean))
                     * 1e3)

    def draws(self, params, n: int = 4000, seed: int = 0) -> np.ndarray:
        """(n, M, 3) draws of a model's error at the tool [m] (a fixed seed: the same
        figures each run)."""
        mean, S = self.error(params)
        z = np.random.default_rng(seed).standard_normal((n, S.shape[1]))
        return mean[None] + (z @ S.T).reshape(n, *mean.shape)


def pose_subset(n: int, k: int = MAX_POSES) -> np.ndarray:
    """Up to k of n samples, evenly spread over the run: where the tool point is judged."""
    return np.unique(np.linspace(0, n - 1, min(n, k)).round().astype(int))


BUILT: dict = {}  # the last few references, by their samples (every level of one run shares one)


def _key(res, laser_noise_mm: float) -> str:
    pb = res.problem
    h = hashlib.sha256()
    for a in (pb.qe, pb.d_m, pb.plate, res.used, res.initial.to_vector(res.layout),
              np.zeros(0) if pb.direction is None else pb.direction):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr((pb.robot.digest, pb.references, laser_noise_mm)).encode())
    return h.hexdigest()


def build(res, laser_noise_mm: float = LASER_NOISE_MM) -> Reference:
    """``reference`` of a fit's samples, kept for the next fit of the same samples (the
    levels a validation or a verdict compares)."""
    key = _key(res, laser_noise_mm)
    if key not in BUILT:
        if len(BUILT) >= 4:
            BUILT.pop(next(iter(BUILT)))
        BUILT[key] = reference(res, laser_noise_mm)
    return BUILT[key]


def reference(res, laser_noise_mm: float = LASER_NOISE_MM) -> Reference:
    """The reference (module docstring) on the samples of a fit ``res`` (``fit.Result``),
    found from the fit's initial values (the same reference for every level calibrated
    from them; from a level-2 fit's solution, whose weakly determined geometry can sit
    millimetres off, Gauss-Newton may settle in another, worse minimum): Gauss-Newton on
    the posterior, the prior's scale and the noise factor updated at each step (MacKay),
    until the step and both scales settle."""
    pb = res.problem
    robot, used = pb.robot, res.used
    qe, plate, d_m = pb.qe[used], pb.plate[used], pb.d_m[used]
    direction = None if pb.direction is None else pb.direction[used]
    W = layout_for(robot, res.params.n_planes, "nonkinematic")
    joints = joints_of_counts(robot, qe, direction, True)
    params = res.initial
    _, J = predict_joints_with_jacobian(robot, joints, params, plate, W)
    # every joint's compliance, not only the level's J2 and J3 (a UR5's wrist yields too)
    candidates = W.free_mask(None) | W.mask(W.group("compliance").names)
    cols = select_base(J, W, candidates, DEFAULT_TOL).mask(W)
    names = W.names_of(cols)
    offsets = W.mask(W.group("joint_offsets").names)
    sd = np.sqrt(sample_variance(robot, J[:, offsets], repeatability_sigma(robot),
                                 sample_sigma_m(laser_noise_mm), True))
    tau = np.abs(joint_torques(robot, joints.q)).max(0)
    std = np.array([class_std(W, n, tau) for n in names])
    x_all = params.to_vector(W)
    groups = _groups(W, names)
    s2, f = np.ones(groups.max() + 1), 1.0
    for _ in range(EVIDENCE_PASSES):
        d, J = predict_joints_with_jacobian(robot, joints, params, plate, W, cols)
        G, g = (FitPrior.of(W, x_all, cols, pb.references, 1.0).rows(x_all[cols], len(names))
                if pb.references else (np.zeros((0, len(names))), np.zeros(0)))
        step, cov, s2_new, f_new, gamma = evidence_step(J / sd[:, None], (d_m - d) / sd, std,
                                                        x_all[cols], G, g, s2, f, groups)
        x_all[cols] += step
        params = params.with_vector(x_all, W)
        settled = (np.all(np.abs(np.log(s2_new / s2)) < SETTLED)
                   and abs(np.log(f_new / f)) < SETTLED
                   and np.all(np.abs(step) <= SETTLED * np.sqrt(np.diag(cov))))
        s2, f = s2_new, f_new
        if settled:
            break
    poses = pose_subset(len(qe))
    q, side, h = joints.q[poses], joints.side[poses], standoff_m(params)
    T = tool_jacobian(robot, q, side, W, params, names, h)
    kinds = [W.group(W.param(n).group).kind for n in names]
    scales = {k: float(np.sqrt(s2[groups[kinds.index(k)]])) for k in dict.fromkeys(kinds)
              if np.isfinite(std[kinds.index(k)])}
    system = (J / sd[:, None], (d_m - d) / sd, std, x_all[cols], G, g, s2, f, groups)
    return Reference(robot, W, tuple(names), params, cov, T,
                     tool_point(robot, q, params, side, h), poses, q, side, h,
                     scales, f, gamma, system)


def _groups(layout: ParamLayout, names) -> np.ndarray:
    """Each name's prior group: its parameter group's kind (the joint geometry, the base
    frame, the compliance, the gear harmonics, the backlash, the laser: each class has its
    own scale)."""
    kinds = [layout.group(layout.param(n).group).kind for n in names]
    order = list(dict.fromkeys(kinds))
    return np.array([order.index(k) for k in kinds], int)
