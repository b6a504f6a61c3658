"""The robot's whole geometric model: per joint modified DH (Craig) with Hayati's beta, a
base frame and a flange frame. The twin's true robot is one of these (its errors drawn
from an error profile); level-2 calibration identifies its parameters.

    T_flange(q) = B  prod_i [ Rx(alpha_i) Tx(a_i) Ry(beta_i) Rz(theta_i + q_i) Tz(d_i) ]  F

``theta_i`` is the joint's zero (``theta0_i + delta_i``: the joint offsets that level-1
calibration identifies), q the joint angles from the encoder model. Frame i (after joint
i) has joint i's axis as its z axis, through its origin. Standard DH, which robot.json
holds, turns into this form exactly: alpha_i = alpha_{i-1}^std, a_i = a_{i-1}^std (0 for
joint 1), theta and d unchanged, F = Tx(a_6^std) Rx(alpha_6^std), beta = 0, B = I; and
the standard DH frame i is frame i times Tx(a_i^std) Rx(alpha_i^std) (``dh_frame``).

Why modified DH and beta: where consecutive axes are parallel (J2-J3 on the MC70,
alpha_3 = 0), standard DH's common normal is ill-defined under a small misalignment (a tiny
tilt moves d by metres); modified DH puts the twist and length before the joint, and
Hayati's beta (a rotation about y) carries the tilt within the plane of the parallel
axes, so every small geometric error has a small parameter.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from planecal.model.robot import Robot

JOINT_PARAMS = ("alpha", "a", "beta", "theta", "d")  # per joint, in the product's order
FRAME_PARAMS = ("x", "y", "z", "rx", "ry", "rz")  # a frame error: translation, small rotation


def rot(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    R = np.eye(3)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[i, i] = R[j, j] = c
    R[i, j], R[j, i] = -s, s
    return R


def frame_error(e) -> np.ndarray:
    """4x4 of a frame error (x, y, z [m], rx, ry, rz [rad]): T(x,y,z) Rz(rz) Ry(ry) Rx(rx)."""
    x, y, z, rx, ry, rz = np.asarray(e, float).reshape(6)
    T = np.eye(4)
    T[:3, :3] = rot(2, rz) @ rot(1, ry) @ rot(0, rx)
    T[:3, 3] = (x, y, z)
    return T


@dataclass(frozen=True)
class Kinematics:
    """The geometric model (module docstring). Arrays (n,) per joint; ``base`` and
    ``flange`` 4x4."""
    alpha: np.ndarray
    a: np.ndarray
    beta: np.ndarray
    theta: np.ndarray
    d: np.ndarray
    base: np.ndarray = field(default_factory=lambda: np.eye(4))
    flange: np.ndarray = field(default_factory=lambda: np.eye(4))

    @property
    def n_joints(self) -> int:
        return len(self.alpha)

    def joint_transform(self, i: int, q: float = 0.0) -> np.ndarray:
        """Rx(alpha_i) Tx(a_i) Ry(beta_i) Rz(theta_i + q) Tz(d_i) (0-based i)."""
        T = np.eye(4)
        T[:3, :3] = R = rot(0, self.alpha[i]) @ rot(1, self.beta[i]) @ rot(2, self.theta[i] + q)
        T[:3, 3] = np.array([self.a[i], 0.0, 0.0]) + R[:, 2] * self.d[i]  # Rx keeps x
        return T

    def with_offsets(self, delta) -> "Kinematics":
        """The model with joint offsets delta added to the joint zeros."""
        return replace(self, theta=self.theta + np.asarray(delta, float))


def from_robot(robot: Robot, delta=None) -> "Kinematics":
    """The nominal model of robot.json's standard DH (module docstring), with joint offsets
    ``delta`` (default none)."""
    n = robot.n_joints
    alpha = np.concatenate([[0.0], robot.alpha[:-1]])
    a = np.concatenate([[0.0], robot.a[:-1]])
    theta = robot.theta0.copy() if delta is None else robot.theta0 + np.asarray(delta, float)
    F = np.eye(4)
    F[:3, :3] = rot(0, robot.alpha[-1])
    F[:3, 3] = [robot.a[-1], 0.0, 0.0]
    return Kinematics(alpha, a, np.zeros(n), theta, robot.d.copy(), np.eye(4), F)


def parallel_pairs(kin: Kinematics, tol: float = 1e-9) -> list[int]:
    """Joints i (0-based) whose axis is parallel to the previous one's (alpha_i = 0,
    i >= 1): where Hayati's beta_i is a parameter of its own."""
    return [i for i in range(1, kin.n_joints) if abs(np.sin(kin.alpha[i])) < tol]


def chain(kin: Kinematics, q: np.ndarray):
    """Frames 0..n, component first: lists x, y, z, p of (3, ...) arrays (axes and origin
    of each frame in the cell frame; frame 0 is the base, frame i is after joint i), and
    the flange frame (x, y, z, p). Vectorized over the leading axes of q; each elementary
    rotation is skipped where its angle is zero for the whole model."""
    q = np.asarray(q, float)
    theta = np.moveaxis(q + kin.theta, -1, 0)  # (n, ...)
    ct, st = np.cos(theta), np.sin(theta)
    shape = (3,) + theta.shape[1:]
    B = kin.base

    def col(v):
        return np.broadcast_to(np.asarray(v, float).reshape((3,) + (1,) * (len(shape) - 1)), shape)

    x, y, z, p = col(B[:3, 0]), col(B[:3, 1]), col(B[:3, 2]), col(B[:3, 3])
    xs, ys, zs, ps = [x], [y], [z], [p]
    for i in range(kin.n_joints):
        al, be = kin.alpha[i], kin.beta[i]
        if al != 0.0:  # Rx(alpha)
            ca, sa = np.cos(al), np.sin(al)
            y, z = ca * y + sa * z, ca * z - sa * y
        if kin.a[i] != 0.0:  # Tx(a)
            p = p + kin.a[i] * x
        if be != 0.0:  # Ry(beta)
            cb, sb = np.cos(be), np.sin(be)
            x, z = cb * x - sb * z, sb * x + cb * z
        c, s_ = ct[i], st[i]  # Rz(theta + q)
        x, y = x * c + y * s_, y * c - x * s_
        if kin.d[i] != 0.0:  # Tz(d)
            p = p + kin.d[i] * z
        xs.append(x)
        ys.append(y)
        zs.append(z)
        ps.append(p)
    F = kin.flange
    fx = x * F[0, 0] + y * F[1, 0] + z * F[2, 0]
    fy = x * F[0, 1] + y * F[1, 1] + z * F[2, 1]
    fz = x * F[0, 2] + y * F[1, 2] + z * F[2, 2]
    fp = p + x * F[0, 3] + y * F[1, 3] + z * F[2, 3]
    return xs, ys, zs, ps, (fx, fy, fz, fp)


def _stack(x, y, z, p) -> np.ndarray:
    lead = x.shape[1:]
    T = np.zeros(lead + (4, 4))
    for c, v in enumerate((x, y, z, p)):
        T[..., :3, c] = np.moveaxis(v, 0, -1)
    T[..., 3, 3] = 1.0
    return T


def frames(kin: Kinematics, q: np.ndarray) -> np.ndarray:
    """Frames 0..n (base, after joint 1, ..., after joint n) in the cell frame: (..., n+1, 4, 4)."""
    xs, ys, zs, ps, _ = chain(kin, q)
    return np.stack([_stack(*v) for v in zip(xs, ys, zs, ps)], axis=-3)


def fk(kin: Kinematics, q: np.ndarray) -> np.ndarray:
    """Flange pose in the cell frame, (..., 4, 4)."""
    return _stack(*chain(kin, q)[4])
