"""The robot's one kinematic chain: per joint modified DH (Craig) with Hayati's beta, a
base frame and a flange frame. The nominal robot (robot.json), a calibration's model at
any level and the twin's true robot are all one of these; what differs is the values.

    T_flange(q) = B  prod_i [ Rx(alpha_i) Tx(a_i) Ry(beta_i) Rz(theta_i + q_i) Tz(d_i) ]  F

``theta_i`` is the joint's zero (``theta0_i + delta_i``: the joint offsets that level-1
calibration identifies), q the joint angles from the encoder model. Frame i (after joint
i) has joint i's axis as its z axis, through its origin. Standard DH, which robot.json
holds, turns into this form exactly (``from_standard_dh``): alpha_i = alpha_{i-1}^std,
a_i = a_{i-1}^std (0 for joint 1), theta and d unchanged, F = Tx(a_n^std) Rx(alpha_n^std),
beta = 0, B = I. A link's own frame (``link_frames``: where its shapes hang) is frame i
times the fixed part of the next joint, Rx(alpha_{i+1}) Tx(a_{i+1}): the standard DH frame
i of the nominal robot.

Why modified DH and beta: where consecutive axes are parallel (J2-J3 on the MC70,
alpha_3 = 0), standard DH's common normal is ill-defined under a small misalignment (a tiny
tilt moves d by metres); modified DH puts the twist and length before the joint, and
Hayati's beta (a rotation about y) carries the tilt within the plane of the parallel
axes, so every small geometric error has a small parameter.

The chain is computed by compiled kernels (``planecal.model.chain``): one pose's flange and
geometric Jacobian in a few microseconds (IK, planning and compensation pay it per pose),
N poses in one call. Every function here takes q of shape (n,) or (N, n).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from planecal.model import chain as _chain

JOINT_PARAMS = ("alpha", "a", "beta", "theta", "d")  # per joint, in the product's order
FRAME_PARAMS = ("x", "y", "z", "rx", "ry", "rz")  # a frame error: translation, small rotation


def rot(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    R = np.eye(3)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[i, i] = R[j, j] = c
    R[i, j], R[j, i] = -s, s
    return R


def rpy_angles(R) -> list[float]:
    """URDF's roll, pitch, yaw of a rotation R = Rz(yaw) Ry(pitch) Rx(roll) (at gimbal lock,
    pitch +-90 deg: roll 0, the rest in yaw)."""
    R = np.asarray(R, float)
    c = float(np.hypot(R[0, 0], R[1, 0]))
    pitch = float(np.arctan2(-R[2, 0], c))
    if c < 1e-12:
        return [0.0, pitch, float(np.arctan2(-R[0, 1], R[1, 1]))]
    return [float(np.arctan2(R[2, 1], R[2, 2])), pitch, float(np.arctan2(R[1, 0], R[0, 0]))]


def frame_error(e) -> np.ndarray:
    """4x4 of a frame error (x, y, z [m], rx, ry, rz [rad]): T(x,y,z) Rz(rz) Ry(ry) Rx(rx)."""
    x, y, z, rx, ry, rz = np.asarray(e, float).reshape(6)
    cx, sx, cy, sy, cz, sz = (math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry),
                              math.cos(rz), math.sin(rz))
    return np.array([[cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx, x],
                     [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx, y],
                     [-sy, cy * sx, cy * cx, z],
                     [0.0, 0.0, 0.0, 1.0]])


@dataclass(frozen=True, eq=False)
class Kinematics:
    """The geometric model (module docstring). Arrays (n,) per joint; ``base`` and
    ``flange`` 4x4. ``packed`` (n, 11): alpha, a, beta, theta, d per joint and the cosines
    and sines of alpha, beta and theta, contiguous, for the kernels (``chain``)."""
    alpha: np.ndarray
    a: np.ndarray
    beta: np.ndarray
    theta: np.ndarray
    d: np.ndarray
    base: np.ndarray = field(default_factory=lambda: np.eye(4))
    flange: np.ndarray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self):
        set_ = object.__setattr__
        columns = (self.alpha, self.a, self.beta, self.theta, self.d)
        packed = np.empty((np.size(self.alpha), 11))
        for k, (name, v) in enumerate(zip(JOINT_PARAMS, columns)):
            packed[:, k] = v
            set_(self, name, packed[:, k].copy())
        for name, v in (("base", self.base), ("flange", self.flange)):
            set_(self, name, np.ascontiguousarray(v, float))
        for k, c in ((0, 5), (2, 7), (3, 9)):  # cos, sin of alpha, beta and theta
            np.cos(packed[:, k], out=packed[:, c])
            np.sin(packed[:, k], out=packed[:, c + 1])
        packed.flags.writeable = False
        object.__setattr__(self, "packed", packed)

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
        """The model with joint offsets delta added to the joint zeros (None: itself)."""
        if delta is None:
            return self
        return replace(self, theta=self.theta + np.asarray(delta, float))


def from_standard_dh(theta0, d, a, alpha) -> Kinematics:
    """The chain of a standard DH table (``T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``,
    robot.json's convention; module docstring)."""
    theta0, d, a, alpha = (np.asarray(v, float) for v in (theta0, d, a, alpha))
    n = len(d)
    F = np.eye(4)
    F[:3, :3] = rot(0, alpha[-1])
    F[:3, 3] = [a[-1], 0.0, 0.0]
    return Kinematics(np.concatenate([[0.0], alpha[:-1]]), np.concatenate([[0.0], a[:-1]]),
                      np.zeros(n), theta0.copy(), d.copy(), np.eye(4), F)


def link_site(kin: Kinematics, i: int) -> np.ndarray:
    """Link frame i in frame i (4x4, 0-based i in 0..n): the next joint's fixed
    Rx(alpha_{i+1}) Tx(a_{i+1}), or the flange F for i = n (``link_frames``). For a chain
    made from a standard DH table it is Tx(a_i) Rx(alpha_i) of the table's row i: the
    standard DH frame i in the modified-DH frame i."""
    if i == kin.n_joints:
        return kin.flange.copy()
    return tx_rx(kin.a[i], kin.alpha[i])


def tx_rx(a: float, alpha: float) -> np.ndarray:
    """Tx(a) Rx(alpha) (= Rx(alpha) Tx(a)), entries below 1e-15 set to 0."""
    c, s = np.cos(alpha), np.sin(alpha)
    T = np.array([[1.0, 0.0, 0.0, a], [0.0, c, -s, 0.0], [0.0, s, c, 0.0],
                  [0.0, 0.0, 0.0, 1.0]])
    T[np.abs(T) < 1e-15] = 0.0
    return T


def joint_between_links(kin: Kinematics, j: int) -> tuple[np.ndarray, np.ndarray]:
    """Joint j (1-based) between the link frames it joins: (P, A) with

        link_j = link_{j-1} P Rz(theta_j + q_j) A,   P = Ry(beta_j),   A = Tz(d_j) link_site(j)

    so joint j's axis is P's z through link frame j-1's origin (which lies on it), and a
    point x of link j sits at A x in the frame that turns with the joint. For a standard
    DH chain P = I and A = Tz(d_j) Tx(a_j) Rx(alpha_j) (the table's row j). The collision
    checker's bounds, the URDF's joint origins and the gravity model read joints so."""
    i = j - 1
    P = np.eye(4)
    P[:3, :3] = rot(1, kin.beta[i])
    P[np.abs(P) < 1e-15] = 0.0
    A = link_site(kin, j)
    Tz = np.eye(4)
    Tz[2, 3] = kin.d[i]
    return P, Tz @ A


def reach_m(kin: Kinematics) -> float:
    """An upper bound of the flange's distance from the base origin: link frame 0's origin
    plus each joint's |A| translation (consecutive link frames' origins are that far
    apart, whatever the joint angles: ``joint_between_links``)."""
    r = float(np.linalg.norm((kin.base @ link_site(kin, 0))[:3, 3]))
    return r + sum(float(np.linalg.norm(joint_between_links(kin, j)[1][:3, 3]))
                   for j in range(1, kin.n_joints + 1))


def parallel_pairs(kin: Kinematics, tol: float = 1e-9) -> list[int]:
    """Joints i (0-based) whose axis is parallel to the previous one's (alpha_i = 0,
    i >= 1): where Hayati's beta_i is a parameter of its own."""
    return [i for i in range(1, kin.n_joints) if abs(np.sin(kin.alpha[i])) < tol]


def _rows(kin: Kinematics, q) -> tuple[np.ndarray, tuple]:
    q = np.asarray(q, float)
    if q.shape[-1] != kin.n_joints:
        raise ValueError(f"joint angles of shape {q.shape} for a {kin.n_joints}-joint chain")
    lead = q.shape[:-1]
    return np.ascontiguousarray(q.reshape(-1, kin.n_joints)), lead


def _homogeneous(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def frames(kin: Kinematics, q) -> np.ndarray:
    """Frames 0..n (base, after joint 1, ..., after joint n) in the cell frame:
    (..., n+1, 4, 4)."""
    Q, lead = _rows(kin, q)
    R, p = _chain.frames(kin.packed, kin.base, Q)
    return _homogeneous(R, p).reshape(lead + (kin.n_joints + 1, 4, 4))


def link_frames(kin: Kinematics, q) -> np.ndarray:
    """Each link's own frame, base to flange (..., n+1, 4, 4): frame i times the next
    joint's fixed Rx(alpha) Tx(a), and the flange last; robot.json's standard DH frames
    0..n for the nominal robot. The link shapes (``planecal.model.geometry``) hang off these."""
    Q, lead = _rows(kin, q)
    R, p = _chain.link_frames(kin.packed, kin.base, kin.flange, Q)
    return _homogeneous(R, p).reshape(lead + (kin.n_joints + 1, 4, 4))


_NO_JACOBIAN = np.empty((0, 6, 0))


def fk(kin: Kinematics, q) -> np.ndarray:
    """Flange pose in the cell frame, (..., 4, 4)."""
    Q, lead = _rows(kin, q)
    T = np.empty((len(Q), 4, 4))
    _chain.flange_jacobian(kin.packed, kin.base, kin.flange, Q, T, _NO_JACOBIAN)
    return T.reshape(lead + (4, 4))


def jacobian(kin: Kinematics, q) -> np.ndarray:
    """Geometric Jacobian of the flange in the cell frame, rows (v, w): (..., 6, n)."""
    return fk_jacobian(kin, q)[1]


def fk_jacobian(kin: Kinematics, q) -> tuple[np.ndarray, np.ndarray]:
    """The flange pose (..., 4, 4) and its geometric Jacobian (..., 6, n) in one pass."""
    Q, lead = _rows(kin, q)
    T = np.empty((len(Q), 4, 4))
    J = np.empty((len(Q), 6, kin.n_joints))
    _chain.flange_jacobian(kin.packed, kin.base, kin.flange, Q, T, J)
    return T.reshape(lead + (4, 4)), J.reshape(lead + (6, kin.n_joints))


PARALLEL_SIN = 1e-3  # axes closer to parallel than this take Hayati's beta, not a normal


def from_axes(points, axes, tip) -> Kinematics:
    """The chain of joint axes given at q = 0 in the base frame (a point on each (n, 3),
    its direction (n, 3), turning right-handed about it) and the flange's pose ``tip``
    there (4x4): exactly the same forward kinematics (how a URDF becomes the model,
    ``planecal.io.urdf_import``; docs/ROBOTS.md).

    Frame by frame, frame i-1 may still turn about and slide along its own axis (its
    theta and d are not fixed until the next axis is known; frame 0 is the base frame
    B, which may do the same). Axis i:
    * not parallel to axis i-1 (|sin| > PARALLEL_SIN): the common normal from axis i-1 to
      axis i fixes frame i-1's x and origin (theta_{i-1}, d_{i-1}), then alpha_i is the
      twist about it and a_i its length, beta_i = 0 (modified DH);
    * parallel or nearly (Hayati): axis i meets frame i-1's xy plane at a point c; x turns
      towards c (theta_{i-1}), a_i = |c|, and Rx(alpha_i) Ry(beta_i) tilts z onto axis i
      (beta_i = 0 for exactly parallel axes, alpha_i = pi for opposite ones);
    frame i starts at that point of axis i, z along it. After the last axis, theta_n and
    d_n put frame n's origin at the foot of the flange's origin on axis n and its x
    towards the flange's x; the flange frame F is what remains. Tolerances are 1e-12 m."""
    P, U = np.asarray(points, float), np.asarray(axes, float)
    U = U / np.linalg.norm(U, axis=1, keepdims=True)
    n = len(P)
    alpha, a, beta, theta, d = (np.zeros(n) for _ in range(5))
    C = np.eye(4)  # frame i-1 at q = 0 (frame 0: the base, B = I so far)
    B = np.eye(4)
    for i in range(n):
        z, o, u = C[:3, 2], C[:3, 3], U[i]
        s = np.linalg.norm(np.cross(z, u))
        if s > PARALLEL_SIN:
            w0 = o - P[i]
            b, dd, e = z @ u, z @ w0, u @ w0
            slide = (b * e - dd) / (1 - b * b)
            c1 = P[i] + ((e - b * dd) / (1 - b * b)) * u
            c0 = o + slide * z
            x = c1 - c0
            x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-12 else np.cross(z, u) / s
        else:
            slide = 0.0
            c1 = P[i] + (-((P[i] - o) @ z) / (u @ z)) * u
            x = c1 - o
            x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-12 else C[:3, 0]
        phi = float(np.arctan2(x @ C[:3, 1], x @ C[:3, 0]))
        C = _turn_slide(C, phi, slide)
        if i == 0:
            B = _turn_slide(B, phi, slide)
        else:
            theta[i - 1] += phi
            d[i - 1] += slide
        a[i] = float(np.linalg.norm(c1 - C[:3, 3]))
        uc = C[:3, :3].T @ u  # axis i in frame i-1 (turned)
        if s > PARALLEL_SIN:
            alpha[i] = float(np.arctan2(np.cross([0.0, 0.0, 1.0], uc)[0], uc[2]))
        else:
            beta[i] = float(np.arcsin(np.clip(uc[0], -1.0, 1.0)))
            alpha[i] = float(np.arctan2(-uc[1], uc[2]))
        C = C @ Kinematics([alpha[i]], [a[i]], [beta[i]], [0.0], [0.0]).joint_transform(0)
    T = np.asarray(tip, float)
    slide = float((T[:3, 3] - C[:3, 3]) @ C[:3, 2])
    xt = T[:3, 0] - (T[:3, 0] @ C[:3, 2]) * C[:3, 2]
    phi = float(np.arctan2(xt @ C[:3, 1], xt @ C[:3, 0])) if np.linalg.norm(xt) > 1e-6 else 0.0
    C = _turn_slide(C, phi, slide)
    theta[n - 1] += phi
    d[n - 1] += slide
    return Kinematics(alpha, a, beta, theta, d, B, np.linalg.inv(C) @ T)


def _turn_slide(C: np.ndarray, phi: float, slide: float) -> np.ndarray:
    """C Rz(phi) Tz(slide)."""
    T = np.eye(4)
    T[:3, :3] = rot(2, phi)
    T[2, 3] = slide
    return C @ T
