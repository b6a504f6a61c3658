"""Gravity torque on each joint from robot.json's link masses, for the calibration's
compliance parameters (level 3, seed 5.4: theta_j += c_j tau_j(q)).

One formula: ``planecal.model.gravity_kernel.gravity_torque``, which also deflects the realistic
twin's joints (``twin.ticks``); this module builds its world ``W`` from
robot.json without MuJoCo, the way ``twin.mjcf`` builds the twin's bodies and
``twin.errors.gravity_model`` reads them back: body j's pose before its hinge is the
nominal model's joint transform (``kinematics.Kinematics.joint_transform``), each point
mass of ``robot.masses`` sits in its link frame, ``kinematics.link_site`` on its body
(for a standard DH table: the standard DH frame j, Tx(a_j) Rx(alpha_j) of row j), and gravity is the twin's (-9.81 m/s^2
along the base z). A payload (mass, centre of mass in the flange frame) is optional; the
calibration model leaves it out (the sensor's ~1 kg against the arm's ~265 kg carried by
J2: ~1 % of tau, absorbed by c_j).

The torque is evaluated at the encoder's joint angles q (without the joint offsets, a few
mrad: < 1e-8 rad of deflection), so it depends on no parameter and the compliance columns
of the Jacobian are exact.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from planecal.model.kinematics import link_site
from planecal.model.robot import Robot

GRAVITY = np.array([0.0, 0.0, -9.81])  # the twin's (twin.errors.GRAVITY)


def gravity_world(robot: Robot, payload=None) -> tuple:
    """The tick's world tuple (harmonics unused, base, body poses (n,4,4), mass bodies,
    centres of mass in their bodies (m,3), masses (m,), gravity) of robot.json's nominal
    model; ``payload`` = (mass kg, centre of mass (3,) in the flange frame) or None."""
    kin = robot.kinematics
    P = np.array([kin.joint_transform(i) for i in range(robot.n_joints)])
    body, com, kg = [], [], []
    for frame, c, m, _ in robot.masses:
        X = link_site(kin, frame)
        body.append(frame)
        com.append(X[:3, :3] @ np.asarray(c, float) + X[:3, 3])
        kg.append(float(m))
    if payload is not None:
        F = kin.flange
        body.append(robot.n_joints)
        com.append(F[:3, :3] @ np.asarray(payload[1], float) + F[:3, 3])
        kg.append(float(payload[0]))
    return (np.zeros((6, 1, 3)), kin.base.copy(), P, np.array(body, np.int64),
            np.array(com, float).reshape(-1, 3), np.array(kg, float), GRAVITY.copy())


def inertia_matrix(six) -> np.ndarray | None:
    """robot.json's inertia (ixx iyy izz ixy ixz iyz) as a symmetric 3x3 (None: none)."""
    if six is None:
        return None
    xx, yy, zz, xy, xz, yz = (float(v) for v in six)
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def lumped(masses) -> tuple[float, np.ndarray, np.ndarray]:
    """One body's masses ``(position (3,), mass[, inertia about its centre (3, 3) or
    None])`` (all in the body's frame) as one: (total mass, its centre of mass, the
    inertia about that centre: each mass's own, point masses none, plus m (|r|^2 I - r r^T)
    for its offset r). (0, 0, 0) for none. The twin's bodies and the URDF's inertials."""
    pts = [(np.asarray(p[0], float), float(p[1]), p[2] if len(p) > 2 else None)
           for p in masses if p[1] > 0]
    M = sum(m for _, m, _ in pts)
    if not M:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    c = sum(m * p for p, m, _ in pts) / M
    I = sum(m * (np.dot(p - c, p - c) * np.eye(3) - np.outer(p - c, p - c))
            + (np.zeros((3, 3)) if J is None else J) for p, m, J in pts)
    return float(M), c, I


@lru_cache(maxsize=1)
def _compiled():
    """The twin's gravity_torque over many rows, compiled with numba (cached)."""
    from numba import njit

    from planecal.base.paths import numba_cache
    from planecal.model.gravity_kernel import gravity_torque
    numba_cache()  # in planecal's cache folder, not beside this file in site-packages

    @njit(cache=True)
    def rows(Q, W, out):
        tau = np.empty(Q.shape[1])
        for i in range(Q.shape[0]):
            gravity_torque(Q[i], W, tau)
            out[i, :] = tau

    return rows


def joint_torques(robot: Robot, q: np.ndarray, payload=None) -> np.ndarray:
    """Gravity torque [N m] on each joint (N, 6) at joint angles q (N, 6) (the encoder's:
    theta = q + theta0 is in the nominal model)."""
    q = np.ascontiguousarray(np.atleast_2d(np.asarray(q, float)))
    out = np.empty_like(q)
    if not robot.masses and payload is None:
        out[:] = 0.0
        return out
    _compiled()(q, gravity_world(robot, payload), out)
    return out
