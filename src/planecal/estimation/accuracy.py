"""How accurate the calibrated robot is, estimated from its own samples (issue 22): the
position error a calibration leaves at the tool, with the model's mismatch in it, beside
the noise-only figure the covariance alone gives.

Where: the calibrated tool's point, the laser's beam point at its nominal standoff (the
middle of the scene's measuring range, 80 mm for the ZS-LD80), in the robot's own frame
(J1's axis and zero: ``compensate.registered_frame``, what ``planecal validate`` measures
AP in), at the calibration samples' poses.

    tool-point error  = sqrt(mean over the poses of tr(T_i C T_i^T))

with T_i the tool point's derivative by the calibrated parameters at pose i (central
differences of ``measurement.sensor_in_base``) and C the calibration's covariance: the
posterior one of the fit (its priors, the scene's known lengths, the base set), scaled

* by the noise level the fit's own residuals show (``Result.sigma_m``: what the model does
  not explain, the robot's mismatch with it included): **the estimate**;
* by the noise model's (``estimation.noise``: the repeatability and the laser, as the
  robot's datasheet gives them): **noise only**, what a model that fitted the robot exactly
  would leave.

One calibration's own error is one draw of the parameters' error, and it lies mostly
along a few directions, so it scatters about the predicted rms: ``draw_band`` gives the
10-90 % band of that draw (``one_calibration_p10_mm``..``p90_mm``) and the effective number
of directions. Measured (three_plates, realistic, level 3, 150 samples, truths 0-19): the
estimate 0.160-0.207 mm, the calibrations' actual tool-point error (calibrated against the
twin's true model, rms over the samples' poses) 0.079-0.406 mm, rms over the twenty 0.191
against the estimates' 0.181: right on average, with 1.8-2.4 directions, so one
calibration is within 1.5x of a perfect estimate with probability 0.54-0.61 (all five:
0.06).

Beside them, the held-out residual: ``folds``-fold cross-validation over the samples, each
fold's distances predicted by a calibration (the same settings) of the other samples. Its
rms against the fit's own residual rms says how much of the fit is the samples' noise.
A plane sees a position error only along its normal, so neither residual alone is a
position error; the covariance carries it to the tool in every direction, and a direction
no sample sees (J1's angle at a plate, the arm's scale without a known length) keeps its
prior's uncertainty.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from planecal.base.errors import InputError
from planecal.base.progress import report
from planecal.estimation.calibrate import Calibration, calibrate
from planecal.estimation.noise import repeatability_sigma, sample_sigma_m, sample_variance
from planecal.model.encoder import counts_to_joints
from planecal.model.measurement import (Joints, backlash_sides, kinematics_of, predict,
                                        predict_joints_with_jacobian, sensor_in_base)
from planecal.model.robot import Robot

FOLDS = 10
FD_STEP = 1e-7  # central differences (SI units: rad, m, 1/m; compliance scaled below)


@dataclass(frozen=True)
class Accuracy:
    """The accuracy figures of one calibration (module docstring), mm."""
    tool_point_mm: float  # predicted, the model's mismatch in it
    noise_only_mm: float  # predicted from the noise model alone
    residual_sigma_mm: float  # the fit's own (unbiased) residual std
    noise_sigma_mm: float  # the noise model's rms sample std
    cv_residual_rms_mm: float | None  # held-out residuals of the cross-validation (None:
    # no fold had enough other samples to calibrate)
    in_sample_rms_mm: float
    held_out: int  # samples the cross-validation predicted
    folds: int
    standoff_mm: float
    # one calibration's own error is one draw: its rms over the poses lies between these
    # (10 % and 90 % of the draws; ``draw_band``), with this many directions in it
    one_calibration_p10_mm: float = 0.0
    one_calibration_p90_mm: float = 0.0
    error_directions: float = 0.0
    where: str = ("the laser's beam point at its nominal standoff, in the robot's frame, rms "
                  "over the calibration samples' poses")

    def to_dict(self) -> dict:
        return asdict(self)


DRAWS = 20_000  # Monte Carlo draws of ``draw_band`` (a fixed seed: the same band each run)


def draw_band(T: np.ndarray, C: np.ndarray) -> tuple[float, float, float]:
    """What one calibration's error at the tool is, against the rms the covariance
    predicts: (10 %, 90 % quantiles of its rms over the poses, as fractions of that rms;
    the effective number of independent directions in it). A calibration's parameter
    error is one draw delta ~ N(0, C); its tool-point error's mean square over the poses is
    delta^T G delta with G = mean_i T_i^T T_i, a sum of chi-square(1) terms weighted by the
    eigenvalues of C^1/2 G C^1/2. With few of them (a plane calibration's tool error lies
    mostly along one or two directions: 1.8-2.4 on three_plates at level 3) one
    calibration's error scatters widely about the rms: a perfect estimate is within 1.5x
    of it only 54-61 % of the time there."""
    G = np.einsum("nik,nil->kl", T, T) / len(T)
    w, V = np.linalg.eigh(C)
    S = V * np.sqrt(np.clip(w, 0.0, None))
    lam = np.clip(np.linalg.eigvalsh(S.T @ G @ S), 0.0, None)
    if lam.sum() <= 0:
        return 0.0, 0.0, 0.0
    lam = lam / lam.sum()
    z = np.random.default_rng(0).standard_normal((DRAWS, len(lam)))
    r = np.sqrt((z ** 2) @ lam)
    lo, hi = np.quantile(r, [0.1, 0.9])
    return float(lo), float(hi), float(1.0 / (lam ** 2).sum())


def tool_point(robot: Robot, q: np.ndarray, params, side, standoff_m: float) -> np.ndarray:
    """(N, 3): the beam point at ``standoff_m`` in the model's robot frame (its frame of
    joint 1 at q = 0 mapped onto robot.json's: ``compensate.registered_frame``)."""
    from planecal.estimation.compensate import registered_frame
    o, z = sensor_in_base(robot, q, params, side)
    F = np.linalg.inv(registered_frame(robot, kinematics_of(robot, params)))
    return (o + standoff_m * z) @ F[:3, :3].T + F[:3, 3]


def tool_jacobian(robot: Robot, q: np.ndarray, side, layout, params, names,
                  standoff_m: float) -> np.ndarray:
    """(N, 3, p): the tool point's derivative by the parameters ``names`` of ``layout`` at
    ``params``, by central differences (a calibration's free ones: its ``Covariance.names``;
    a plan's: the base set it designs for)."""
    x0 = params.to_vector(layout)
    T = np.empty((len(q), 3, len(names)))
    for k, name in enumerate(names):
        i = layout.index(name)
        h = FD_STEP * (1e-3 if layout.param(name).unit == "rad/(N m)" else 1.0)
        xp, xm = x0.copy(), x0.copy()
        xp[i] += h
        xm[i] -= h
        T[:, :, k] = (tool_point(robot, q, params.with_vector(xp, layout), side, standoff_m)
                      - tool_point(robot, q, params.with_vector(xm, layout), side, standoff_m)) \
            / (2 * h)
    return T


def cross_validate(robot: Robot, qe, d_m, initial, plate, settings, direction=None,
                   references: tuple = (), folds: int = FOLDS, seed: int = 0) -> np.ndarray:
    """(N,) held-out residuals [m] (predicted - measured): each of ``folds`` folds (a
    random partition, ``seed``) predicted by a calibration of the other samples; NaN for a
    fold whose other samples are too few to calibrate."""
    qe, d_m = np.asarray(qe), np.asarray(d_m, float)
    n = len(d_m)
    plate = np.zeros(n, int) if plate is None else np.asarray(plate, int)
    out = np.full(n, np.nan)
    for k, f in enumerate(np.array_split(np.random.default_rng(seed).permutation(n), folds)):
        report(k + 1, folds, "cross-validation: fold")
        keep = np.setdiff1d(np.arange(n), f)
        dk = None if direction is None else np.asarray(direction)[keep]
        try:
            cal = calibrate(robot, qe[keep], d_m[keep], initial, plate[keep], settings, dk,
                            references)
        except InputError:  # too few samples left to fit: this fold is not predicted
            continue
        df = None if direction is None else np.asarray(direction)[f]
        out[f] = predict(robot, qe[f], cal.params, plate[f], df) - d_m[f]
    return out


def of_samples(scene, cal: Calibration, samples, folds: int = FOLDS) -> Accuracy:
    """``accuracy`` of a calibration of a sample file's ``Samples`` in ``scene`` (its laser
    range and known lengths)."""
    return accuracy(scene.robot, cal, samples.qe, samples.d_mm * 1e-3, samples.plate,
                    samples.direction, scene.references, scene.laser_range_mm, folds=folds)


def accuracy(robot: Robot, cal: Calibration, qe, d_m, plate=None, direction=None,
             references: tuple = (), laser_range_mm=(65.0, 95.0), laser_noise_mm: float = 0.001,
             folds: int = FOLDS) -> Accuracy:
    """The accuracy figures of ``cal``, a calibration of these samples (module docstring).
    ``laser_noise_mm``: a reading's noise (the noise model's; the repeatability is
    robot.json's)."""
    res = cal.result
    qe = np.asarray(qe)
    n = len(qe)
    plate = np.zeros(n, int) if plate is None else np.asarray(plate, int)
    standoff = 0.5e-3 * (laser_range_mm[0] + laser_range_mm[1])
    q = counts_to_joints(robot, qe)
    side = backlash_sides(robot, q, direction)
    C = np.nan_to_num(res.covariance.matrix)
    T = tool_jacobian(robot, q, side, res.layout, res.params, list(res.covariance.names),
                      standoff)
    per_pose = np.einsum("nik,kl,nil->n", T, C, T)
    tool_rms = float(np.sqrt(max(per_pose.mean(), 0.0)))
    lo, hi, directions = draw_band(T, C)
    # the noise model at these poses: the repeatability on the beam, the laser, the counts
    offsets = res.layout.mask(res.layout.group("joint_offsets").names)
    _, J = predict_joints_with_jacobian(robot, Joints.of(q, side), res.params, plate,
                                        res.layout, offsets)
    v = sample_variance(robot, J, repeatability_sigma(robot), sample_sigma_m(laser_noise_mm),
                        True)
    noise_sigma = float(np.sqrt(v.mean()))
    scale = noise_sigma / res.sigma_m if res.sigma_m > 0 else 0.0
    cv = cross_validate(robot, qe, d_m, res.initial, plate, cal.settings, direction,
                        references, folds)
    held = cv[np.isfinite(cv)]
    return Accuracy(tool_point_mm=tool_rms * 1e3, noise_only_mm=tool_rms * scale * 1e3,
                    residual_sigma_mm=res.sigma_m * 1e3, noise_sigma_mm=noise_sigma * 1e3,
                    cv_residual_rms_mm=(float(np.sqrt(np.mean(held ** 2)) * 1e3)
                                        if len(held) else None),
                    held_out=len(held),
                    in_sample_rms_mm=res.rms_mm(), folds=folds, standoff_mm=standoff * 1e3,
                    one_calibration_p10_mm=lo * tool_rms * 1e3,
                    one_calibration_p90_mm=hi * tool_rms * 1e3, error_directions=directions)
