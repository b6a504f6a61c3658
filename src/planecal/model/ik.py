"""Closed-form inverse kinematics of the robot's nominal chain (robot.json), with joint
offsets: every solution within the joint limits, and the one nearest a given pose.

Only the spherical-wrist geometry of the MC70 family is solved in closed form (a6 = a5 =
a4 = 0, d2 = d3 = 0, alpha = (+90, 0, +90, -90, +90, 0) deg; ``inverse_kinematics:
spherical_wrist`` in robot.json).
"""
from __future__ import annotations

import numpy as np

from planecal.base.errors import InputError
from planecal.model.robot import Robot


def _wrap(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


def _rot_z_x(theta: float, alpha: float) -> np.ndarray:
    """Rotation part of one DH link, Rz(theta) Rx(alpha)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st * ca, st * sa], [st, ct * ca, -ct * sa], [0.0, sa, ca]])


def _expand_turns(robot: Robot, Q: np.ndarray) -> np.ndarray:
    """Every 2*pi-equivalent of each joint of each row of Q (wrapped to [-pi, pi)) that
    lies within the joint limits (joints such as J4 +-360 deg have several)."""
    turns = 2 * np.pi * np.arange(-3, 4)
    for j in range(Q.shape[1]):
        vals = Q[:, j, None] + turns  # (m, 7)
        lo, hi = robot.limits[j]
        ok = (vals >= lo - 1e-12) & (vals <= hi + 1e-12)
        rows, k = np.nonzero(ok)
        Q = Q[rows].copy()
        Q[:, j] = vals[rows, k]
    return Q


def ik_all(robot: Robot, T: np.ndarray, delta: np.ndarray | None = None,
           within: bool = True) -> np.ndarray:
    """All closed-form IK solutions (k, 6) for one flange pose T (4x4).

    Only the spherical-wrist geometry of the MC70 family (a6 = a5 = a4 = 0, d2 = d3 = 0,
    alpha = (+90, 0, +90, -90, +90, 0) deg) is supported. With ``within`` (default) every
    2*pi-equivalent solution inside the joint limits is listed (J4 +-360, J6 +-450 deg);
    without it, the up to 8 solutions wrapped to [-pi, pi).
    """
    if robot.ik_kind != "spherical_wrist":
        raise InputError(f"{robot.name}: no closed-form inverse kinematics for this robot")
    T = np.asarray(T, float)
    d1, d4, d6 = robot.d[0], robot.d[3], robot.d[5]
    a1, a2, a3 = robot.a[0], robot.a[1], robot.a[2]
    th0, al = robot.theta0, robot.alpha
    off = th0 + (0.0 if delta is None else np.asarray(delta, float))
    R, p = T[:3, :3], T[:3, 3]
    w = p - d6 * R[:, 2]
    L = np.hypot(a3, d4)
    beta = np.arctan2(d4, a3)
    sols = []
    rho = np.hypot(w[0], w[1])
    for front in (True, False):
        th1 = np.arctan2(w[1], w[0]) if front else np.arctan2(-w[1], -w[0])
        r = (rho if front else -rho) - a1
        s = w[2] - d1
        c = (r * r + s * s - a2 * a2 - L * L) / (2 * a2 * L)
        if abs(c) > 1 + 1e-12:
            continue
        c = min(max(c, -1.0), 1.0)
        R01 = _rot_z_x(th1, al[0])
        for phi in {np.arccos(c), -np.arccos(c)}:
            th3 = phi + beta
            th2 = np.arctan2(s, r) - np.arctan2(L * np.sin(phi), a2 + L * np.cos(phi))
            R03 = R01 @ _rot_z_x(th2, al[1]) @ _rot_z_x(th3, al[2])
            R36 = R03.T @ R
            s5 = np.hypot(R36[0, 2], R36[1, 2])
            for sign in (1.0, -1.0):
                th5 = np.arctan2(sign * s5, R36[2, 2])
                if s5 < 1e-12:  # wrist singularity: only th4 + th6 is defined; keep th4 = 0
                    th4 = 0.0
                    th6 = np.arctan2(R36[1, 0], R36[0, 0])
                else:
                    th4 = np.arctan2(sign * R36[1, 2], sign * R36[0, 2])
                    th6 = np.arctan2(sign * R36[2, 1], -sign * R36[2, 0])
                sols.append([th1, th2, th3, th4, th5, th6])
    if not sols:
        return np.zeros((0, 6))
    Q = _wrap(np.array(sols) - off)
    return _expand_turns(robot, Q) if within else Q


def ik_nearest(robot: Robot, T: np.ndarray, q_near: np.ndarray,
               delta: np.ndarray | None = None, weights: np.ndarray | None = None):
    """The IK solution within limits nearest to q_near (weighted max-norm), or None."""
    Q = ik_all(robot, T, delta)
    if len(Q) == 0:
        return None
    w = np.ones(6) if weights is None else weights
    cost = np.max(np.abs(Q - q_near) * w, axis=1)
    return Q[np.argmin(cost)]
