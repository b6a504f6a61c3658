"""How accurate the calibrated robot is, estimated from its own samples (issues 22, 31):
the position error a calibration leaves at the tool, with the model's mismatch in it,
beside the noise-only figure the covariance alone gives.

Where: the calibrated tool's point, the laser's beam point at its nominal standoff (the
middle of the scene's measuring range, 80 mm for the ZS-LD80), in the robot's own frame
(J1's axis and zero: ``compensate.registered_frame``, what ``planecal validate`` measures
AP in), at the calibration samples' poses (up to 100 of them).

**The estimate** (``tool_point_mm``) and its band (``one_calibration_p10_mm``..``p90_mm``)
are the verdict's (``estimation.verdict``): the calibration's tool points against the
reference model (``estimation.reference``: level 3's whole model with the robot class's
errors, scaled by the samples' evidence), its bias against it and the reference's spread.
Before issue 31 the estimate was the calibration's own covariance at the fit's residual
level (``covariance_mm`` here): right on average on three plates at level 3 (truths 0-19:
rms 0.181 against a true 0.191 mm), 1.6-4.1x low on the realistic UR5 and 6-7x on the
UR10e, where an offsets fit absorbs the geometry's and the compliance's errors (a bias no
covariance of that fit holds) and a level-3 fit holds its weak geometry at a prior smaller
than the robot's errors.

* **noise only** (``noise_only_mm``): the covariance scaled by the noise model's level
  (``estimation.noise``: the repeatability and the laser, as the robot's datasheet gives
  them), what a model that fitted the robot exactly would leave;
* ``error_directions``: the effective number of independent directions of the
  covariance's error at the tool (``draw_band``);
* the held-out residual (``cv_residual_rms_mm``): ``FOLDS``-fold cross-validation of the
  distances, each fold predicted by the calibration refitted without it (in closed form,
  ``estimation.selection``; ``cross_validate`` refits for real). Its rms against the fit's
  own residual rms says how much of the fit is the samples' noise. A plane sees a position
  error only along its normal, so neither residual alone is a position error.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from planecal.base.errors import InputError
from planecal.base.progress import report
from planecal.estimation.calibrate import Calibration, calibrate
from planecal.estimation.noise import repeatability_sigma, sample_sigma_m, sample_variance
from planecal.model.encoder import counts_to_joints
from planecal.estimation.reference import pose_subset
from planecal.estimation.tool import tool_jacobian, tool_point  # noqa: F401 (re-exported)
from planecal.estimation.verdict import verdict_of
from planecal.model.measurement import (Joints, backlash_sides, predict,
                                        predict_joints_with_jacobian)
from planecal.model.robot import Robot

FOLDS = 10


@dataclass(frozen=True)
class Accuracy:
    """The accuracy figures of one calibration (module docstring), mm."""
    tool_point_mm: float  # the verdict's estimate, the model's mismatch in it
    noise_only_mm: float  # predicted from the noise model alone
    residual_sigma_mm: float  # the fit's own (unbiased) residual std
    noise_sigma_mm: float  # the noise model's rms sample std
    cv_residual_rms_mm: float | None  # held-out residuals of the cross-validation
    in_sample_rms_mm: float
    held_out: int  # samples the cross-validation predicted
    folds: int
    standoff_mm: float
    # the verdict's 10-90 % band of the error validate measures as AP near the samples
    # (``estimation.verdict``), and the covariance's effective directions (``draw_band``)
    one_calibration_p10_mm: float = 0.0
    one_calibration_p90_mm: float = 0.0
    error_directions: float = 0.0
    covariance_mm: float = 0.0  # the fit's covariance alone at its residual level
    where: str = ("the laser's beam point at its nominal standoff, in the robot's frame, rms "
                  "over the calibration samples' poses; the band: AP near the samples")

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


def of_samples(scene, cal: Calibration, samples) -> Accuracy:
    """``accuracy`` of a calibration of a sample file's ``Samples`` in ``scene`` (its laser
    range and known lengths)."""
    return accuracy(scene.robot, cal, samples.qe, samples.d_mm * 1e-3, samples.plate,
                    samples.direction, scene.references, scene.laser_range_mm)


def accuracy(robot: Robot, cal: Calibration, qe, d_m, plate=None, direction=None,
             references: tuple = (), laser_range_mm=(65.0, 95.0),
             laser_noise_mm: float = 0.001) -> Accuracy:
    """The accuracy figures of ``cal``, a calibration of these samples (module docstring).
    ``laser_noise_mm``: a reading's noise (the noise model's; the repeatability is
    robot.json's)."""
    res, verdict = cal.result, verdict_of(cal)
    qe = np.asarray(qe)
    n = len(qe)
    plate = np.zeros(n, int) if plate is None else np.asarray(plate, int)
    standoff = 0.5e-3 * (laser_range_mm[0] + laser_range_mm[1])
    q = counts_to_joints(robot, qe)
    side = backlash_sides(robot, q, direction)
    idx = pose_subset(n)
    C = np.nan_to_num(res.covariance.matrix)
    T = tool_jacobian(robot, q[idx], None if side is None else side[idx], res.layout,
                      res.params, list(res.covariance.names), standoff)
    per_pose = np.einsum("nik,kl,nil->n", T, C, T)
    tool_rms = float(np.sqrt(max(per_pose.mean(), 0.0)))
    directions = draw_band(T, C)[2]
    # the noise model at these poses: the repeatability on the beam, the laser, the counts
    offsets = res.layout.mask(res.layout.group("joint_offsets").names)
    _, J = predict_joints_with_jacobian(robot, Joints.of(q, side), res.params, plate,
                                        res.layout, offsets)
    v = sample_variance(robot, J, repeatability_sigma(robot), sample_sigma_m(laser_noise_mm),
                        True)
    noise_sigma = float(np.sqrt(v.mean()))
    scale = noise_sigma / res.sigma_m if res.sigma_m > 0 else 0.0
    return Accuracy(tool_point_mm=verdict.tool_mm, noise_only_mm=tool_rms * scale * 1e3,
                    residual_sigma_mm=res.sigma_m * 1e3, noise_sigma_mm=noise_sigma * 1e3,
                    cv_residual_rms_mm=verdict.held_out_mm, held_out=int(res.used.sum()),
                    in_sample_rms_mm=res.rms_mm(), folds=FOLDS, standoff_mm=standoff * 1e3,
                    one_calibration_p10_mm=verdict.band_mm[0],
                    one_calibration_p90_mm=verdict.band_mm[1], error_directions=directions,
                    covariance_mm=tool_rms * 1e3)
