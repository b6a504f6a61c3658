"""The measurement model: the laser's distance to a plate from the encoder counts and the
cell's parameters (seed 6.14), and its analytic Jacobian, for every parameter layout.

    q       = encoder model (counts -> joint angles; ``planecal.model.encoder``)
    q'      = q + sum_f (s_f sin(f q) + c_f cos(f q))     gear harmonics (level 3)
              - b/2 side                     backlash: the flank each joint rests on
              + c tau(q)                     gravity deflection (compliance c, torque tau)
    chain   = robot.json's nominal chain with the parameters' corrections
              (``kinematics_of``): theta_j += delta_j (joint offsets), alpha_j, a_j,
              beta_j, d_j += geometry[j], base = frame_error(base) nominal base
    o_b,z_b = the beam's origin and direction in the cell frame: the flange pose at q'
              times the sensor origin o and z_f = Rz(phi_z) Ry(phi_y) e_z (flange frame)
    d       = (1 - n~ . o_b) / (n~ . z_b)     for the sample's plate n~ (n~ . p = 1)

Which parameters are free is a layout (``planecal.model.layout``), never a branch here: the
same chain and kernel serve the joint offsets alone (level 1) and the whole model.
Jacobian: every parameter moves the part of the chain after it rigidly, by a rotation
about a line (axis w through c) or a translation t; with p_m = o_b + d z_b the hit point
and s = n~ . z_b,

    rotation:     dd = -(p_m - c) . (n~ x w) / s
    translation:  dd = -n~ . t / s
    n~:           dd = -p_m / s
    o:            dd = -(R^T n~) / s
    phi:          dd = -d (R^T n~) . dz_f/dphi / s
    c_j:          the theta_j column times tau_j(q)
    h{j}_{f}s/c:  the theta_j column times sin(f q_j) / cos(f q_j)
    b_j:          the theta_j column times -side_j / 2

(``planecal.model.chain.distance``; checked against central differences in the tests.)
The kernel takes the joint angles as their cosines and sines (``Joints``): a fit holds
them once and evaluates the model at the same joints every iteration.
The laser does not see a roll about its own beam, so o, phi_y, phi_z are the whole
flange-to-sensor frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

from planecal.model import chain as _chain
from planecal.model.cell_params import CellParams
from planecal.model.encoder import counts_to_joints
from planecal.model.gravity import joint_torques
from planecal.model.kinematics import Kinematics, fk, frame_error
from planecal.model.layout import ParamLayout, gear_term, laser_term, level1_layout
from planecal.model.robot import Robot

def beam_direction(phi_y: float, phi_z: float) -> np.ndarray:
    sy, cy, sz, cz = np.sin(phi_y), np.cos(phi_y), np.sin(phi_z), np.cos(phi_z)
    return np.array([cz * sy, sz * sy, cy])


def beam_direction_derivative(phi_y: float, phi_z: float) -> np.ndarray:
    """d z_f / d(phi_y, phi_z): (3, 2)."""
    sy, cy, sz, cz = np.sin(phi_y), np.cos(phi_y), np.sin(phi_z), np.cos(phi_z)
    return np.array([[cz * cy, -sz * sy], [sz * cy, cz * sy], [-sy, 0.0]])


def beam_point(sensor_origin, phi_y: float, phi_z: float, standoff_m: float) -> np.ndarray:
    """The tool point of a laser (3,): the point on its beam at ``standoff_m`` from its
    origin (the measuring centre, ``Scene.standoff_m``), in the flange frame."""
    return np.asarray(sensor_origin, float) + standoff_m * beam_direction(phi_y, phi_z)


def sensor_rotation(phi_y: float, phi_z: float) -> np.ndarray:
    """Flange->sensor rotation Rz(phi_z) Ry(phi_y) (seed 6.7); its z column is the beam."""
    sy, cy, sz, cz = np.sin(phi_y), np.cos(phi_y), np.sin(phi_z), np.cos(phi_z)
    return np.array([[cz * cy, -sz, cz * sy], [sz * cy, cz, sz * sy], [-sy, 0.0, cy]])


@dataclass(frozen=True, eq=False)
class Joints:
    """Joint angles ``q`` (N, n) [rad] with their cosines and sines, taken once
    (``Joints.of``): what the distance kernel reads; ``side`` (N, n), the flank each
    joint's backlash rests on (``backlash_sides``; None: unknown, the middle)."""
    q: np.ndarray
    cos: np.ndarray
    sin: np.ndarray
    side: np.ndarray | None = None

    @classmethod
    def of(cls, q, side=None) -> "Joints":
        q = np.ascontiguousarray(np.atleast_2d(np.asarray(q, float)))
        c, s = np.empty_like(q), np.empty_like(q)
        _chain.trig(q, c, s)
        if side is not None:
            side = np.asarray(side, float).reshape(q.shape)
        return cls(q, c, s, side)

    def rows(self, rows) -> "Joints":
        """The rows ``rows`` (a bool mask or indices); itself for a mask of every row."""
        rows = np.asarray(rows)
        if rows.dtype == bool and rows.all():
            return self
        return Joints(self.q[rows], self.cos[rows], self.sin[rows],
                      None if self.side is None else self.side[rows])

    def __len__(self) -> int:
        return len(self.q)


def kinematics_of(robot: Robot, params: CellParams) -> Kinematics:
    """robot.json's nominal chain with params' joint offsets, geometry and base frame
    (compliance is pose-dependent: ``effective_joints``)."""
    nom = robot.kinematics
    g = params.geometry
    return Kinematics(nom.alpha + g[:, 0], nom.a + g[:, 1], nom.beta + g[:, 2],
                      nom.theta + params.joint_offsets, nom.d + g[:, 3],
                      frame_error(params.base) @ nom.base, nom.flange)


def base_error_axes(base: np.ndarray) -> np.ndarray:
    """The rotation axes (rows rx, ry, rz) of a base frame error (x, y, z, rx, ry, rz;
    ``kinematics.frame_error``: T(t) Rz Ry Rx): rx about Rz Ry e_x, ry about Rz e_y, rz about
    e_z, each through t."""
    cy, sy, cz, sz = math.cos(base[4]), math.sin(base[4]), math.cos(base[5]), math.sin(base[5])
    return np.array([[cz * cy, sz * cy, -sy], [-sz, cz, 0.0], [0.0, 0.0, 1.0]])


def backlash_sides(robot: Robot, q: np.ndarray, direction: np.ndarray | None) -> np.ndarray:
    """(N, n): the flank each joint's backlash rests on at joint angles q (the output
    trails its motor: -b/2 after a positive motion). A joint whose gravity torque is at
    least its preload (robot.json's ``transmission.backlash_preload_nm``) rests on the
    flank the torque pushes it to, whichever way it came: side = -sign(tau); any other
    joint on the flank its last motion left it on, the recorded ``direction`` (a sample
    file's direction columns; 0 where not known, and everywhere without ``direction``)."""
    q = np.atleast_2d(np.asarray(q, float))
    side = np.zeros_like(q) if direction is None else \
        np.sign(np.atleast_2d(np.asarray(direction, float))).reshape(q.shape).copy()
    pre = np.asarray(robot.backlash_preload_nm, float)
    if np.isfinite(pre).any():
        tau = joint_torques(robot, q)
        held = np.abs(tau) >= pre
        side[held] = -np.sign(tau[held])
    return side


def effective_joints(robot: Robot, q: np.ndarray, params: CellParams,
                     side: np.ndarray | None = None):
    """(q', tau (N, 6) or None): the joint angles with every joint error the parameters
    hold (module docstring): gear harmonics at q, backlash on ``side`` (``backlash_sides``;
    None: the middle) and the gravity deflection c tau(q)."""
    q = np.atleast_2d(np.asarray(q, float))
    if not params.joint_errors:
        return q, None
    qd = q.copy()
    for (j, f), (a_s, a_c) in zip(params.gear_terms, params.gear):
        if a_s or a_c:
            qd[:, j] += a_s * np.sin(f * q[:, j]) + a_c * np.cos(f * q[:, j])
    if side is not None and params.backlash.any():
        qd -= 0.5 * params.backlash * side
    tau = None
    if params.compliance.any():
        tau = joint_torques(robot, q)
        qd += params.compliance * tau
    return qd, tau


def flange_pose(robot: Robot, q: np.ndarray, params: CellParams,
                side: np.ndarray | None = None) -> np.ndarray:
    """The model's flange (robot.json's standard DH frame 6) in the cell frame at joint
    angles q (N, 6) or (6,), every joint error included (``effective_joints``; ``side``
    the backlash flanks): (N, 4, 4) or (4, 4)."""
    qd, _ = effective_joints(robot, q, params, side)
    T = fk(kinematics_of(robot, params), qd)
    return T[0] if np.ndim(q) == 1 else T


def sensor_in_base(robot: Robot, q: np.ndarray, params: CellParams,
                   side: np.ndarray | None = None):
    """Beam origin o_b and direction z_b in the cell frame, (N, 3) each ((3,) for one pose)."""
    T = flange_pose(robot, q, params, side)
    R, p = T[..., :3, :3], T[..., :3, 3]
    return R @ params.sensor_origin + p, R @ beam_direction(params.phi_y, params.phi_z)


def plane_distance(n_tilde: np.ndarray, o_b: np.ndarray, z_b: np.ndarray) -> np.ndarray:
    """Distance along the beam from o_b to the plane n~ . p = 1 (seed 6.14)."""
    return (1.0 - np.sum(n_tilde * o_b, -1)) / np.sum(n_tilde * z_b, -1)


def joints_of_counts(robot: Robot, qe: np.ndarray, direction: np.ndarray | None = None,
                     sides: bool = True) -> Joints:
    """The ``Joints`` of encoder counts qe (N, 6), with the backlash flanks of the recorded
    approach ``direction`` (N, 6) or None (``backlash_sides``) where ``sides`` (a model
    with a backlash; the flanks cost a gravity torque per sample)."""
    q = counts_to_joints(robot, np.atleast_2d(qe))
    return Joints.of(q, backlash_sides(robot, q, direction) if sides else None)


def has_backlash(layout: ParamLayout) -> bool:
    """Whether a layout's model has a backlash (its Jacobian needs the flanks)."""
    return bool(layout.groups_of("backlash"))


def predict(robot: Robot, qe: np.ndarray, params: CellParams,
            plane_index: np.ndarray | None = None,
            direction: np.ndarray | None = None) -> np.ndarray:
    """Model distance [m] for encoder counts qe (N, 6) (or (6,)) on plane_index (default 0),
    with the samples' recorded approach ``direction`` (level 3's backlash; None: not
    recorded): ``predict_with_jacobian``'s distance, bit for bit, without the Jacobian."""
    one = np.ndim(qe) == 1
    d, _ = _evaluate(robot, joints_of_counts(robot, qe, direction, bool(params.backlash.any())),
                     params, 0 if plane_index is None else plane_index, None)
    return d[0] if one else d


def predict_with_jacobian(robot: Robot, qe: np.ndarray, params: CellParams,
                          plane_index: np.ndarray | None = None,
                          layout: ParamLayout | None = None, free: np.ndarray | None = None,
                          direction: np.ndarray | None = None):
    """Model distance d (N,) [m] and its Jacobian w.r.t. the parameters in ``layout``'s
    order (default: the level-1 layout of ``params``' planes): (N, len(layout)), or only
    the columns of the ``free`` mask (N, free.sum()) in their order."""
    layout = layout or level1_layout(params.n_planes)
    sides = bool(params.backlash.any()) or has_backlash(layout)
    return _evaluate(robot, joints_of_counts(robot, qe, direction, sides), params,
                     0 if plane_index is None else plane_index,
                     column_map(layout, robot.n_joints, free))


def predict_joints_with_jacobian(robot: Robot, q: np.ndarray | Joints, params: CellParams,
                                 plane_index, layout: ParamLayout, free=None):
    """``predict_with_jacobian`` at joint angles q (N, 6), or their ``Joints``, instead of
    counts (the fit converts its counts and takes their sines once)."""
    return _evaluate(robot, q if isinstance(q, Joints) else Joints.of(q), params,
                     plane_index, column_map(layout, robot.n_joints, free))


@dataclass(frozen=True, eq=False)
class ColumnMap:
    """Where each elementary derivative goes in the Jacobian (-1: not wanted); built once
    per (layout, free) by ``column_map``."""
    width: int
    joint: np.ndarray  # (n, 5): alpha, a, beta, theta, d of each joint
    base: np.ndarray  # (6,)
    origin: np.ndarray  # (3,)
    angles: np.ndarray  # (2,)
    plane: np.ndarray  # (k, 3)
    extra_joint: np.ndarray  # (m,): joint of a theta-scaled column
    extra_col: np.ndarray  # (m,)
    extra_kind: tuple  # (m,) what scales it: ("compliance",), ("gear", f, "s"|"c"),
    # ("backlash",)
    laser_col: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # the
    # laser linearity's columns
    laser_kind: tuple = ()  # (order, "s"|"c") of each


_JOINT_SLOT = {"alpha": 0, "a": 1, "beta": 2, "d": 4}


@lru_cache(maxsize=256)
def _column_map(layout: ParamLayout, n: int, free_key: bytes | None) -> ColumnMap:
    free = (np.ones(len(layout), bool) if free_key is None
            else np.frombuffer(free_key, bool))
    pos = np.where(free, np.cumsum(free) - 1, -1)
    joint = np.full((n, 5), -1, np.int64)
    base, origin, angles = (np.full(k, -1, np.int64) for k in (6, 3, 2))
    plane = np.full((layout.n_planes, 3), -1, np.int64)
    ej, ec, ek, lc, lk = [], [], [], [], []
    for g in layout.groups:
        cols = pos[layout.slice(g.name)]
        if g.kind == "joint_offsets":
            joint[:, 3] = cols
        elif g.kind == "joint_geometry":
            for p, c in zip(g.params, cols):
                joint[g.index, _JOINT_SLOT[p.name.rstrip("0123456789")]] = c
        elif g.kind == "base_frame":
            base[:] = cols
        elif g.kind == "sensor_origin":
            origin[:] = cols
        elif g.kind == "sensor_angles":
            angles[:] = cols
        elif g.kind == "plane":
            plane[g.index] = cols
        elif g.kind in ("compliance", "backlash"):
            for j, c in enumerate(cols):
                if c >= 0:
                    ej.append(j), ec.append(c), ek.append((g.kind,))
        elif g.kind == "gear":
            for name, c in zip(g.names, cols):
                if c >= 0:
                    j, f, t = gear_term(name)
                    ej.append(j - 1), ec.append(c), ek.append(("gear", f, t))
        elif g.kind == "laser":
            for name, c in zip(g.names, cols):
                if c >= 0:
                    lc.append(c), lk.append(laser_term(name))
        else:
            raise ValueError(f"the measurement model has no parameters of kind {g.kind!r}")
    return ColumnMap(int(free.sum()), joint, base, origin, angles, plane,
                     np.array(ej, np.int64), np.array(ec, np.int64), tuple(ek),
                     np.array(lc, np.int64), tuple(lk))


def column_map(layout: ParamLayout, n_joints: int, free=None) -> ColumnMap:
    """The Jacobian's column map of a layout (every column, or the ``free`` mask's)."""
    key = None if free is None else np.ascontiguousarray(free, bool).tobytes()
    return _column_map(layout, n_joints, key)


_NO_COLUMNS = ColumnMap(0, np.full((6, 5), -1, np.int64), *(np.full(k, -1, np.int64)
                                                             for k in (6, 3, 2)),
                        np.full((0, 3), -1, np.int64), np.zeros(0, np.int64),
                        np.zeros(0, np.int64), ())


def _laser_reading(params: CellParams, d: np.ndarray, J, cm: ColumnMap) -> np.ndarray:
    """The laser's reading of the distances d: d + e(d), e the linearity error over the
    measuring range (``layout.laser_group``); J's columns scaled by 1 + e'(d) and the
    linearity's own columns filled in."""
    lo, hi = params.laser_range_m
    x = (d - lo) / (hi - lo)
    e, de = np.zeros_like(d), np.zeros_like(d)
    for k, (a_s, a_c) in zip(params.laser_orders, params.laser):
        w = 2.0 * np.pi * k
        s, c = np.sin(w * x), np.cos(w * x)
        e += a_s * s + a_c * c
        de += (a_s * c - a_c * s) * w / (hi - lo)
    if J is not None and J.shape[1]:
        J *= (1.0 + de)[:, None]
        for col, (k, t) in zip(cm.laser_col, cm.laser_kind):
            J[:, col] = (np.sin if t == "s" else np.cos)(2.0 * np.pi * k * x)
    return d + e


def _extra_factors(robot: Robot, joints: Joints, tau, cm: ColumnMap) -> np.ndarray:
    """(N, m): what scales joint ``extra_joint``'s theta column into each extra column, at
    the measured joints (module docstring): tau_j(q) (compliance), sin/cos(f q_j) (gear),
    -side_j / 2 (backlash)."""
    q = joints.q
    factor = np.empty((len(q), len(cm.extra_col)))
    for e, (j, kind) in enumerate(zip(cm.extra_joint, cm.extra_kind)):
        if kind[0] == "compliance":
            tau = joint_torques(robot, q) if tau is None else tau
            factor[:, e] = tau[:, j]
        elif kind[0] == "gear":
            factor[:, e] = (np.sin if kind[2] == "s" else np.cos)(kind[1] * q[:, j])
        else:
            factor[:, e] = 0.0 if joints.side is None else -0.5 * joints.side[:, j]
    return factor


def _evaluate(robot: Robot, joints: Joints, params: CellParams, plane_index,
              cmap: ColumnMap | None):
    """The distances at the joints and, with a column map, the Jacobian."""
    tau = None
    measured = joints
    if params.joint_errors:  # the deflected joints' own sines
        qd, tau = effective_joints(robot, joints.q, params, joints.side)
        joints = Joints.of(qd)
    kin = kinematics_of(robot, params)
    N, n = joints.q.shape
    cm = cmap or _NO_COLUMNS
    if cm.joint.shape[0] != n:
        cm = replace(cm, joint=np.full((n, 5), -1, np.int64))
    factor = _extra_factors(robot, measured, tau, cm)
    d, hit = np.empty(N), np.empty((N, 3))
    J = np.zeros((N if cmap is not None else 0, cm.width))
    pidx = np.ascontiguousarray(np.broadcast_to(np.asarray(plane_index, np.int64), (N,)))
    _chain.distance(kin.packed, kin.base, kin.flange, joints.cos, joints.sin,
                    params.sensor_origin, beam_direction(params.phi_y, params.phi_z),
                    beam_direction_derivative(params.phi_y, params.phi_z),
                    np.ascontiguousarray(params.planes), pidx, base_error_axes(params.base),
                    params.base[:3].copy(), d, hit, J, cm.joint, cm.base, cm.origin,
                    cm.angles, cm.plane, cm.extra_joint, cm.extra_col, factor)
    if params.laser.any() or cm.laser_col.size:
        d = _laser_reading(params, d, J if cmap is not None else None, cm)
    return d, (J if cmap is not None else None)
