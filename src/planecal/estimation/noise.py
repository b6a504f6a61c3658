"""The one noise model of a sample, used by the weighted fit, the studies' bounds, planning
and the twin's synthetic samples (SI units).

A sample's distance error is
  e_i = sum_j (dd/dq_j)_i eps_j + laser_i
with eps ~ N(0, s^2 I) the repeatability perturbation of the six joints drawn each time the
robot comes to rest (``repeatability_sigma``: a 3-sigma flange spread of the robot's
repeatability, +-0.07 mm for the MC70, s ~ 1.1e-5 rad) and laser_i the laser noise of the
sample value, the mean of a ``BUFFER_LEN``-reading buffer (``sample_sigma_m``: the
reading's std / sqrt(100)). dd/dq_j equals the Jacobian column of delta_j. So e_i is
Gaussian, independent between samples, zero mean, with a variance that depends on the pose
(heteroscedastic):
  v_i = s^2 |J_delta,i|^2 + sigma_L^2          (``noise_variance``)
and with the encoder's quantisation (uniform +-1/2 count per motor, through the wrist
coupling) a term sum_j (dd/dx_j)^2 / (12 g_j^2) (``sample_variance``).
"""
from __future__ import annotations

import numpy as np

from planecal.model.kinematics import fk_jacobian
from planecal.model.layout import ParamLayout
from planecal.model.robot import Robot

BUFFER_LEN = 100  # laser readings averaged into one sample (sampling.laserread)


def sample_sigma_m(laser_noise_mm: float, buffer_len: int = BUFFER_LEN) -> float:
    """The std [m] of a sample's distance from the laser alone: the mean of ``buffer_len``
    readings of std ``laser_noise_mm``."""
    return float(laser_noise_mm) * 1e-3 / np.sqrt(buffer_len)


def repeatability_sigma(robot: Robot, repeatability_m: float | None = None) -> float:
    """Joint-angle std [rad] that gives a flange 3-sigma spread of ``repeatability_m``
    (default: the robot's, robot.json ``repeatability_mm``): each joint perturbed
    independently by N(0, s^2), s = (r / 3) / ||J_v(q = 0)||_F. For the MC70 (+-0.07 mm)
    s ~ 1.1e-5 rad."""
    r = robot.repeatability_m if repeatability_m is None else repeatability_m
    Jv = fk_jacobian(robot.kinematics, np.zeros(robot.n_joints))[1][:3]
    return float(r / 3.0 / np.linalg.norm(Jv))


def noise_variance(J_delta: np.ndarray, joint_sigma: float, distance_sigma_m: float) -> np.ndarray:
    """Per-sample distance noise variance [m^2]: J_delta (N, 6) the Jacobian columns of the
    six joint offsets (= dd/dq), joint_sigma the joint-angle std of the robot's
    repeatability [rad], distance_sigma_m the std of a sample from the sensor [m]."""
    return joint_sigma ** 2 * np.sum(J_delta ** 2, axis=1) + distance_sigma_m ** 2


def sample_variance(robot: Robot, J_delta: np.ndarray, joint_sigma_rad: float,
                    distance_sigma_m: float, quantization: bool) -> np.ndarray:
    """``noise_variance``, and with ``quantization`` the motors' uniform +-1/2 count
    (through the wrist coupling)."""
    v = noise_variance(J_delta, joint_sigma_rad, distance_sigma_m)
    if quantization:
        Jx = J_delta @ robot.coupling  # dd/dx (actuator angles)
        v = v + np.sum(Jx ** 2 / (12.0 * robot.gains ** 2), axis=1)
    return v


def row_weights(J_delta: np.ndarray, joint_sigma_rad: float | None,
                distance_sigma_m: float) -> np.ndarray | None:
    """The weighted fit's row weights 1/sqrt(v_i) from the joint offsets' columns, or None
    for an unweighted fit (``joint_sigma_rad`` None)."""
    if joint_sigma_rad is None:
        return None
    return 1.0 / np.sqrt(noise_variance(J_delta, joint_sigma_rad, distance_sigma_m))


def offsets_columns(layout: ParamLayout) -> slice:
    """Where the six joint offsets' columns (dd/dq) sit in a layout's Jacobian."""
    return layout.slice("joint_offsets")
