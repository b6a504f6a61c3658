"""Robot description (loaded from models/<robot>/robot.json), forward kinematics,
geometric Jacobian and closed-form inverse kinematics.

Convention (MODEL-NOTES): standard DH, ``T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``
with ``theta_i = q_i + delta_i + theta0_i``; ``q`` are joint angles from the encoder
model and ``delta`` the joint offsets that calibration identifies. SI units (m, rad).
Every function is vectorized over leading axes of ``q``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError
from planecal.formats.base import read_json, validate
from planecal.formats.robot import RobotFile
from planecal.base.paths import data_folder

DEFAULT_ROBOT = "mc70"


@dataclass(frozen=True)
class Robot:
    name: str
    theta0: np.ndarray  # (6,) rad
    d: np.ndarray  # (6,) m
    a: np.ndarray  # (6,) m
    alpha: np.ndarray  # (6,) rad
    limits: np.ndarray  # (6, 2) rad, [lower, upper]
    gains: np.ndarray  # (6,) counts/rad
    qe0: np.ndarray  # (6,) counts at the zero reference
    coupling: np.ndarray  # (6, 6) C with q = C x
    encoder_bits: int
    ik_kind: str | None
    repeatability_m: float
    tick_s: float
    max_step_counts: int
    trip_step_counts: int
    home_counts: np.ndarray  # (6,) int64
    source: Path | None = None
    # (standard DH frame, centre of mass in it [m] (3,), mass [kg]): the arm's masses
    masses: tuple = ()

    @property
    def n_joints(self) -> int:
        return len(self.d)

def load_robot(name_or_path: str | Path = DEFAULT_ROBOT) -> Robot:
    """Load a robot description: a name under models/ (``mc70``) or a path to robot.json.
    Validated by ``planecal.formats.robot.RobotFile``; one-line InputError otherwise."""
    p = Path(name_or_path)
    if not p.suffix and len(p.parts) == 1:  # a name, not a path
        p = data_folder("models") / str(name_or_path) / "robot.json"
    rf = validate(RobotFile, read_json(p, "robot description"), p, "robot description")
    enc, ctrl = rf.encoder, rf.controller
    return Robot(
        name=rf.name,
        theta0=np.array([j.theta0_rad for j in rf.dh]),
        d=np.array([j.d_m for j in rf.dh]),
        a=np.array([j.a_m for j in rf.dh]),
        alpha=np.array([j.alpha_rad for j in rf.dh]),
        limits=np.deg2rad(np.array(rf.joint_limits_deg, float)),
        gains=np.array(enc.gain_counts_per_rad, float),
        qe0=np.array(enc.offset_counts, float),
        coupling=enc.coupling_matrix(),
        encoder_bits=enc.bits,
        ik_kind=rf.inverse_kinematics,
        repeatability_m=rf.repeatability_mm * 1e-3,
        tick_s=ctrl.tick_s,
        max_step_counts=ctrl.max_step_counts,
        trip_step_counts=ctrl.trip_step_counts,
        home_counts=np.array(ctrl.home_counts, np.int64),
        source=p,
        masses=tuple((m.frame, np.array(m.com_m, float), m.mass_kg) for m in rf.masses),
    )


def full_angles(robot: Robot, q: np.ndarray, delta: np.ndarray | None = None) -> np.ndarray:
    theta = np.asarray(q, float) + robot.theta0
    return theta if delta is None else theta + delta


def chain(robot: Robot, q: np.ndarray, delta: np.ndarray | None = None):
    """Frames 0..n, component first: lists x, y, z, p of (3, ...) arrays (axes and origin
    of each frame in the base frame; the leading axis is the x/y/z component, so every
    operation below runs on contiguous rows). The DH product is done column-wise: with
    u = x ct + y st and v = y ct - x st, the next frame is x' = u, y' = ca v + sa z,
    z' = ca z - sa v, p' = p + a u + d z — 6x cheaper than chaining 4x4 matrices."""
    theta = np.moveaxis(full_angles(robot, q, delta), -1, 0)  # (n, ...)
    ct, st = np.cos(theta), np.sin(theta)
    shape = (3,) + theta.shape[1:]
    x, y, z = (np.broadcast_to(e.reshape((3,) + (1,) * (len(shape) - 1)), shape)
               for e in np.eye(3))
    p = np.zeros(shape)
    xs, ys, zs, ps = [x], [y], [z], [p]
    for i in range(robot.n_joints):
        c, s_ = ct[i], st[i]
        ca, sa = np.cos(robot.alpha[i]), np.sin(robot.alpha[i])
        u = x * c + y * s_
        v = y * c - x * s_
        p = p + robot.a[i] * u + robot.d[i] * z
        x, y, z = u, ca * v + sa * z, ca * z - sa * v
        xs.append(x)
        ys.append(y)
        zs.append(z)
        ps.append(p)
    return xs, ys, zs, ps


def fk_frames(robot: Robot, q: np.ndarray, delta: np.ndarray | None = None) -> np.ndarray:
    """Frames 0..n (base, after joint 1, ..., flange) in the base frame: (..., n+1, 4, 4)."""
    xs, ys, zs, ps = chain(robot, q, delta)
    lead = xs[0].shape[1:]
    F = np.zeros(lead + (len(xs), 4, 4))
    for col, vs in enumerate((xs, ys, zs, ps)):
        F[..., :3, col] = np.moveaxis(np.stack(vs, 0), (0, 1), (-2, -1))
    F[..., 3, 3] = 1.0
    return F


def fk(robot: Robot, q: np.ndarray, delta: np.ndarray | None = None) -> np.ndarray:
    """Flange pose in the base frame, (..., 4, 4)."""
    return fk_frames(robot, q, delta)[..., -1, :, :]


def jacobian(robot: Robot, q: np.ndarray, delta: np.ndarray | None = None) -> np.ndarray:
    """Geometric Jacobian of the flange in the base frame, rows (v, w): (..., 6, n)."""
    F = fk_frames(robot, q, delta)
    z = F[..., :-1, :3, 2]  # axes z_{i-1}
    o = F[..., :-1, :3, 3]
    p = F[..., -1:, :3, 3]
    Jv = np.cross(z, p - o)
    return np.concatenate([np.swapaxes(Jv, -1, -2), np.swapaxes(z, -1, -2)], axis=-2)


def repeatability_sigma(robot: Robot, repeatability_m: float | None = None) -> float:
    """Joint-angle std [rad] that gives a flange 3-sigma spread of ``repeatability_m``
    (default: the robot's, robot.json ``repeatability_mm``): each joint perturbed
    independently by N(0, s^2), s = (r / 3) / ||J_v(q = 0)||_F. For the MC70 (+-0.07 mm)
    s ~ 1.1e-5 rad. The twin's repeatability and the weighted fit's noise model."""
    r = robot.repeatability_m if repeatability_m is None else repeatability_m
    Jv = jacobian(robot, np.zeros(robot.n_joints))[:3]
    return float(r / 3.0 / np.linalg.norm(Jv))


def within_limits(robot: Robot, q: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    q = np.asarray(q, float)
    return np.all((q >= robot.limits[:, 0] - tol) & (q <= robot.limits[:, 1] + tol), axis=-1)


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
