"""The whole kinematic model's distance (level 2, issue 13) and its analytic Jacobian.

The chain is ``planecal.model.kinematics``' (modified DH with Hayati's beta, base frame, flange
frame): robot.json's nominal model (``kinematics.from_robot``, the one source) plus the
corrections a ``cell.CellParams`` carries,

    alpha_j, a_j, beta_j, d_j  += params.geometry[j]        (per joint, modified DH)
    theta_j                    += params.joint_offsets[j]  (level 1's delta_j)
    base                        = kinematics.frame_error(params.base)
    theta_j                    += params.compliance[j] * tau_j(q)   (level 3, seed 5.4)

with tau the gravity torque of robot.json's link masses at the joint angles q
(``gravity.joint_torques``: the twin's formula). The sensor (origin o and beam angles
phi_y, phi_z in the flange frame = standard DH frame 6) and the planes are level 1's: a
laser distance does not see a roll about its own beam, so o, phi_y, phi_z are the whole
flange-to-sensor frame. At zero corrections this is ``planecal.model.robot``'s standard-DH
model (tests/test_level2_model.py: 1e-12 m on the seed's real samples).

Jacobian. Every parameter moves the part of the chain after it rigidly: by a rotation
about a line (unit axis w through a point c) or a translation t, both in the base frame.
With p_m = o_b + d z_b the hit point and s = n~ . z_b,

    rotation:     dd = -(p_m - c) . (n~ x w) / s
    translation:  dd = -n~ . t / s

Joint j (frame j-1 with axes x, y, z and origin p; Rx(alpha) Tx(a) Ry(beta) Rz(theta+q)
Tz(d)): alpha about x through p; a along x; beta about y' (y after Rx(alpha)) through
p + a x; theta (and delta) about z_j through p + a x; d along z_j; c_j: the theta column
times tau_j. Base T(t) Rz Ry Rx: x, y, z along the base axes; rz about e_z, ry about
Rz e_y, rx about Rz Ry e_x, each through t. Exact at any parameter value (the chain is
recomputed there): checked against central differences in the tests.
"""
from __future__ import annotations

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.gravity import joint_torques
from planecal.model.kinematics import Kinematics, frame_error, from_robot, rot
from planecal.model.layout import ParamLayout
from planecal.model.robot import Robot

LEVEL2_KINDS = ("joint_geometry", "base_frame", "compliance")


def kinematics_of(robot: Robot, params: CellParams) -> Kinematics:
    """robot.json's nominal model with params' joint offsets, geometry and base frame
    (compliance is pose-dependent: ``effective_joints``)."""
    nom = from_robot(robot, params.joint_offsets)
    g = params.geometry
    return Kinematics(nom.alpha + g[:, 0], nom.a + g[:, 1], nom.beta + g[:, 2], nom.theta,
                      nom.d + g[:, 3], frame_error(params.base), nom.flange)


def effective_joints(robot: Robot, q: np.ndarray, params: CellParams):
    """(q + c tau(q), tau (N, 6) or None): the joint angles with the gravity deflection."""
    q = np.atleast_2d(np.asarray(q, float))
    if not params.compliance.any():
        return q, None
    tau = joint_torques(robot, q)
    return q + params.compliance * tau, tau


def _chain(kin: Kinematics, q: np.ndarray):
    """Component-first chain (3, N) arrays: per joint j the frame j-1 axes x, y, origin p,
    the beta axis y', the joint's point c = p + a x and axis z_j; and the last frame."""
    theta = (q + kin.theta).T  # (n, N)
    ct, st = np.cos(theta), np.sin(theta)
    N = q.shape[0]
    B = kin.base

    def col(v):
        return np.repeat(np.asarray(v, float).reshape(3, 1), N, axis=1)

    x, y, z, p = col(B[:3, 0]), col(B[:3, 1]), col(B[:3, 2]), col(B[:3, 3])
    per = []
    for i in range(kin.n_joints):
        xa, pa = x, p
        ca, sa = np.cos(kin.alpha[i]), np.sin(kin.alpha[i])
        y, z = ca * y + sa * z, ca * z - sa * y
        c = p + kin.a[i] * x
        cb, sb = np.cos(kin.beta[i]), np.sin(kin.beta[i])
        yb = y
        x, z = cb * x - sb * z, sb * x + cb * z
        x, y = x * ct[i] + y * st[i], y * ct[i] - x * st[i]
        p = c + kin.d[i] * z
        per.append((xa, pa, yb, c, z))
    return per, (x, y, z, p)


def _flange(kin: Kinematics, last):
    x, y, z, p = last
    F = kin.flange
    fx = x * F[0, 0] + y * F[1, 0] + z * F[2, 0]
    fy = x * F[0, 1] + y * F[1, 1] + z * F[2, 1]
    fz = x * F[0, 2] + y * F[1, 2] + z * F[2, 2]
    fp = p + x * F[0, 3] + y * F[1, 3] + z * F[2, 3]
    return fx, fy, fz, fp


def flange_pose(robot: Robot, q: np.ndarray, params: CellParams) -> np.ndarray:
    """The calibrated model's flange (standard DH frame 6) in the base (cell) frame,
    (N, 4, 4), gravity deflection included. Equal to ``robot.fk(robot, q, delta)`` when
    params carry no level-2 correction."""
    qe, _ = effective_joints(robot, q, params)
    kin = kinematics_of(robot, params)
    _, last = _chain(kin, qe)
    fx, fy, fz, fp = _flange(kin, last)
    T = np.zeros((qe.shape[0], 4, 4))
    for c, v in enumerate((fx, fy, fz, fp)):
        T[:, :3, c] = v.T
    T[:, 3, 3] = 1.0
    return T


def sensor_in_base(robot: Robot, q: np.ndarray, params: CellParams):
    """Beam origin o_b (N, 3) and direction z_b (N, 3) in the base frame."""
    T = flange_pose(robot, q, params)
    zf = _beam(params)
    return (T[:, :3, :3] @ params.sensor_origin + T[:, :3, 3], T[:, :3, :3] @ zf)


def _beam(params) -> np.ndarray:
    return (rot(2, params.phi_z) @ rot(1, params.phi_y))[:, 2]


def _beam_derivative(params) -> np.ndarray:
    sy, cy, sz, cz = (np.sin(params.phi_y), np.cos(params.phi_y), np.sin(params.phi_z),
                      np.cos(params.phi_z))
    return np.array([[cz * cy, -sz * sy], [sz * cy, cz * sy], [-sy, 0.0]])


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _rotation_column(n, w, c, p_m, s):
    """dd for a rotation about axis w (3, N or 3,) through c: -(p_m - c) . (n x w) / s."""
    w = np.broadcast_to(np.asarray(w, float).reshape(3, -1), n.shape)
    nxw = (n[1] * w[2] - n[2] * w[1], n[2] * w[0] - n[0] * w[2], n[0] * w[1] - n[1] * w[0])
    r = p_m - np.asarray(c, float).reshape(3, -1)
    return -_dot(r, nxw) / s


def distance_with_jacobian(robot: Robot, q: np.ndarray, params: CellParams,
                           plane_index: np.ndarray, layout: "ParamLayout"):
    """Distance d (N,) [m] along the beam to each sample's plane for joint angles q (N, 6)
    and its Jacobian (N, len(layout)) w.r.t. the layout's parameters (module docstring);
    groups of any level (level 1's kinds and LEVEL2_KINDS)."""
    q = np.atleast_2d(np.asarray(q, float))
    N = q.shape[0]
    pidx = np.asarray(plane_index, int)
    qd, tau = effective_joints(robot, q, params)
    kin = kinematics_of(robot, params)
    per, last = _chain(kin, qd)
    fx, fy, fz, fp = _flange(kin, last)
    o, zf = params.sensor_origin, _beam(params)
    o_b = fx * o[0] + fy * o[1] + fz * o[2] + fp
    z_b = fx * zf[0] + fy * zf[1] + fz * zf[2]
    n = np.ascontiguousarray(params.planes[pidx].T)  # (3, N)
    s = _dot(n, z_b)
    d = (1.0 - _dot(n, o_b)) / s
    p_m = o_b + d * z_b
    J = np.zeros((N, len(layout)))
    kinds = {g.kind for g in layout.groups}
    dtheta = np.empty((N, 6))
    for j, (x, p, yb, c, z) in enumerate(per):
        dtheta[:, j] = _rotation_column(n, z, c, p_m, s)
    if "joint_offsets" in kinds:
        J[:, layout.slice("joint_offsets")] = dtheta
    if "sensor_origin" in kinds:
        nf = np.stack([_dot(n, v) for v in (fx, fy, fz)], -1)  # R^T n~
        J[:, layout.slice("sensor_origin")] = -nf / s[:, None]
        J[:, layout.slice("sensor_angles")] = -(d / s)[:, None] * (nf @ _beam_derivative(params))
    if "plane" in kinds:
        J[np.arange(N)[:, None], layout.columns("plane")[pidx]] = -(p_m / s).T
    if "joint_geometry" in kinds:
        cols = layout.columns("joint_geometry")  # (6, 4): alpha, a, beta, d
        for j, (x, p, yb, c, z) in enumerate(per):
            J[:, cols[j, 0]] = _rotation_column(n, x, p, p_m, s)
            J[:, cols[j, 1]] = -_dot(n, x) / s
            J[:, cols[j, 2]] = _rotation_column(n, yb, c, p_m, s)
            J[:, cols[j, 3]] = -_dot(n, z) / s
    if "base_frame" in kinds:
        t, (ry, rz) = params.base[:3], params.base[4:]
        cols = layout.columns("base_frame")[0]
        for k in range(3):
            J[:, cols[k]] = -n[k] / s
        Rz, Ry = rot(2, rz), rot(1, ry)
        for k, w in ((3, Rz @ Ry[:, 0]), (4, Rz[:, 1]), (5, np.array([0.0, 0.0, 1.0]))):
            J[:, cols[k]] = _rotation_column(n, w, t, p_m, s)
    if "compliance" in kinds:
        tq = joint_torques(robot, q) if tau is None else tau
        J[:, layout.slice("compliance")] = dtheta * tq
    return d, J
