"""The cell: sensor on the flange, plane(s) in the base frame, the distance model
d(qe; params) (seed 6.14) and its analytic parameter Jacobian.

Parameters (SI):
  joint_offsets  delta (6,) rad, theta_i = q_i + delta_i + theta0_i
  sensor_origin  o (3,) m in the flange frame
  phi_y, phi_z   beam z_f = Rz(phi_z) Ry(phi_y) e_z = (cz sy, sz sy, cy) in the flange frame
  planes         n~ (k, 3) 1/m in the base frame, n~ . p = 1 on plane k

The parameter vector and its names come from a ``planecal.model.layout.ParamLayout`` (level 1:
[delta1..6, o_x, o_y, o_z, phi_y, phi_z, n1_x, n1_y, n1_z, n2_x, ...], robot and sensor
shared, one n~ per plane, seed 6.3); ``CellParams.to_vector``/``from_vector`` and the
Jacobian's columns go through it, by group, so no code here knows an offset.

Jacobian (derived here, equal to the seed's 6.20-6.23): with p_m = o_b + d z_b the hit
point and s = n~ . z_b,
  dd/dn~      = -p_m / s
  dd/do       = -(R^T n~) / s
  dd/dphi     = -d (R^T n~) . dz_f/dphi / s
  dd/ddelta_i = -n~ . (z_{i-1} x (p_m - o_{i-1})) / s
"""
from __future__ import annotations

import numpy as np

from planecal.model import model_full
from planecal.model.cell_params import CellParams
from planecal.model.encoder import counts_to_joints
from planecal.model.layout import ParamLayout, level1_layout
from planecal.model.robot import Robot, chain, fk

__all__ = ["CellParams", "beam_direction", "beam_direction_derivative", "sensor_rotation",
           "sensor_in_base", "plane_distance", "predict", "predict_with_jacobian",
           "n_tilde_from_point_normal", "point_normal_from_n_tilde", "transform_n_tilde"]


def beam_direction(phi_y: float, phi_z: float) -> np.ndarray:
    sy, cy, sz, cz = np.sin(phi_y), np.cos(phi_y), np.sin(phi_z), np.cos(phi_z)
    return np.array([cz * sy, sz * sy, cy])


def beam_direction_derivative(phi_y: float, phi_z: float) -> np.ndarray:
    """d z_f / d(phi_y, phi_z): (3, 2)."""
    sy, cy, sz, cz = np.sin(phi_y), np.cos(phi_y), np.sin(phi_z), np.cos(phi_z)
    return np.array([[cz * cy, -sz * sy], [sz * cy, cz * sy], [-sy, 0.0]])


def sensor_rotation(phi_y: float, phi_z: float) -> np.ndarray:
    """Flange->sensor rotation Rz(phi_z) Ry(phi_y) (seed 6.7); its z column is the beam."""
    sy, cy, sz, cz = np.sin(phi_y), np.cos(phi_y), np.sin(phi_z), np.cos(phi_z)
    return np.array([[cz * cy, -sz, cz * sy], [sz * cy, cz, sz * sy], [-sy, 0.0, cy]])


def sensor_in_base(robot: Robot, q: np.ndarray, params: CellParams):
    """Sensor origin o_b (N,3) and beam z_b (N,3) in the base frame for joint angles q."""
    T = fk(robot, q, params.joint_offsets)
    R, p = T[..., :3, :3], T[..., :3, 3]
    o_b = R @ params.sensor_origin + p
    z_b = R @ beam_direction(params.phi_y, params.phi_z)
    return o_b, z_b


def plane_distance(n_tilde: np.ndarray, o_b: np.ndarray, z_b: np.ndarray) -> np.ndarray:
    """Distance along the beam from o_b to the plane n~ . p = 1 (seed 6.14)."""
    return (1.0 - np.sum(n_tilde * o_b, -1)) / np.sum(n_tilde * z_b, -1)


def predict(robot: Robot, qe: np.ndarray, params: CellParams,
            plane_index: np.ndarray | None = None) -> np.ndarray:
    """Model distance [m] for encoder counts qe (N,6) on plane_index (N,) (default 0)."""
    q = counts_to_joints(robot, qe)
    if params.is_level1:
        o_b, z_b = sensor_in_base(robot, q, params)
    else:  # the whole kinematic model (level 2)
        o_b, z_b = model_full.sensor_in_base(robot, np.atleast_2d(q), params)
        if np.ndim(qe) == 1:
            o_b, z_b = o_b[0], z_b[0]
    n = params.planes[0 if plane_index is None else np.asarray(plane_index)]
    return plane_distance(n, o_b, z_b)


def predict_with_jacobian(robot: Robot, qe: np.ndarray, params: CellParams,
                          plane_index: np.ndarray | None = None,
                          layout: ParamLayout | None = None):
    """Model distance d (N,) [m] and its Jacobian (N, len(layout)) w.r.t. the parameters in
    ``layout``'s order (default: the level-1 layout of ``params``' planes)."""
    layout = layout or level1_layout(params.n_planes)
    qe = np.atleast_2d(qe)
    N = len(qe)
    pidx = np.zeros(N, int) if plane_index is None else np.asarray(plane_index, int)
    q = counts_to_joints(robot, qe)
    if not params.is_level1 or any(g.kind in model_full.LEVEL2_KINDS for g in layout.groups):
        return model_full.distance_with_jacobian(robot, q, params, pidx, layout)
    xs, ys, zs, ps = chain(robot, q, params.joint_offsets)  # component first: (3, N)
    x6, y6, z6, p6 = xs[-1], ys[-1], zs[-1], ps[-1]
    o, zf = params.sensor_origin, beam_direction(params.phi_y, params.phi_z)
    o_b = x6 * o[0] + y6 * o[1] + z6 * o[2] + p6
    z_b = x6 * zf[0] + y6 * zf[1] + z6 * zf[2]
    n = np.ascontiguousarray(params.planes[pidx].T)  # (3, N)
    s = np.einsum("kn,kn->n", n, z_b)
    d = (1.0 - np.einsum("kn,kn->n", n, o_b)) / s
    p_m = o_b + d * z_b
    J = np.zeros((N, len(layout)))
    # joint offsets: rotation about z_{i-1} through o_{i-1}:
    # n~ . (z x (p_m - o)) = (p_m - o) . (n~ x z)
    Jd = J[:, layout.slice("joint_offsets")]  # a view: its columns are J's
    for i in range(6):
        z, w = zs[i], p_m - ps[i]
        Jd[:, i] = -(w[0] * (n[1] * z[2] - n[2] * z[1]) + w[1] * (n[2] * z[0] - n[0] * z[2])
                     + w[2] * (n[0] * z[1] - n[1] * z[0])) / s
    nf = np.stack([np.einsum("kn,kn->n", n, v) for v in (x6, y6, z6)], -1)  # R^T n~, (N, 3)
    J[:, layout.slice("sensor_origin")] = -nf / s[:, None]
    J[:, layout.slice("sensor_angles")] = -(d / s)[:, None] * (
        nf @ beam_direction_derivative(params.phi_y, params.phi_z))
    J[np.arange(N)[:, None], layout.columns("plane")[pidx]] = -(p_m / s).T
    return d, J


# ----- plane representations (seed 6.4.2, appendix D) -----

def n_tilde_from_point_normal(point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """n~ = n (p.n)/|p.n|^2 for the plane through ``point`` with unit ``normal``."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    h = float(np.dot(point, n))
    if abs(h) < 1e-9:
        raise ValueError("plane passes through the base origin: n~ cannot describe it")
    return n / h


def point_normal_from_n_tilde(n_tilde: np.ndarray):
    """Closest plane point to the origin and the unit normal pointing away from the origin."""
    n_tilde = np.asarray(n_tilde, float)
    nn = float(n_tilde @ n_tilde)
    return n_tilde / nn, n_tilde / np.sqrt(nn)


def transform_n_tilde(T: np.ndarray, n_tilde: np.ndarray) -> np.ndarray:
    """Express a plane given in frame P by n~ in frame B, with T = B_T_P (appendix D)."""
    p, nhat = point_normal_from_n_tilde(n_tilde)
    return n_tilde_from_point_normal(T[:3, :3] @ p + T[:3, 3], T[:3, :3] @ nhat)
