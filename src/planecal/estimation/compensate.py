"""Compensation ("filtering a program", RoboDK's term; issue 13 item 4): joint targets the
controller can play so that the *calibrated* model puts the flange where the *nominal*
model says it should be.

The FD11 keeps robot.json's kinematics and its encoder offsets (qe0); it cannot take a new
kinematic model. A program's target is a flange pose T in the base frame, or a joint target
whose pose the nominal model gives (``robot.fk``). Its corrected target q_c solves

    calibrated_flange(q_c) = T

by Newton's method on the pose error (position [m], rotation vector [rad], both in the base
frame) with the calibrated model's geometric Jacobian (``CalibratedModel.jacobian``),
started from the nominal solution (the closed-form IK nearest the previous target, or the
joint target itself). The calibrated model differs from the
nominal by milliradians: 2-3 steps, 5-6 near the elbow's stretched singularity (Jacobian
condition ~6e3). Every target's convergence is checked (``Compensation.converged``). The corrected joints
are written as counts with robot.json's encoder model (``encoder.joints_to_counts``): the
controller is left as it is. Rounding to whole counts leaves a residual of its own
(``rounded_residual_m``, tens of um at the MC70's ~2.3e-5 rad per count).

The calibrated model (``CalibratedModel``) is the one model of every level
(``planecal.model.measurement``: robot.json's chain with the result's joint offsets and, at
level full, its geometry, base frame and compliance); ``load_calibrated`` reads it from a
result made for the same robot.

Frames. A plane calibration cannot see where the robot stands among the plates nor J1's
zero: a turn about J1 (delta1) or a shift of the base moves the plates with it. A level-1
fit fixes delta1 at 0; a full model may carry that freedom in delta1 or its base frame
(a 20 mrad delta1 seen on three plates). Targets are therefore registered, by default, in
the robot's own frame: the model's frame of joint 1 at q = 0 mapped onto the nominal
model's (``robot_frame``; ``planecal validate``'s AP frame), so ``calibrated_flange(q_c) =
robot_frame T``. ``frame="cell"`` takes T in the calibration's base frame instead.

The calibrated region (``Region``): where the calibration's samples are, the convex hull of
their flange positions grown by 50 mm and the range of each joint they visited grown by 2
deg. A model fitted there is only known there; a target beyond either is outside, by how
far (mm from the hull, rad per joint).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from planecal.model.cell_params import CellParams
from planecal.model.encoder import counts_to_joints, joints_to_counts
from planecal.base.errors import InputError
from planecal.formats.base import read_json
from planecal.model.robot import Robot, within_limits
from planecal.io.targets import Targets
from planecal.model.kinematics import fk
from planecal.model.ik import ik_nearest

COMPENSATED_FORMAT = "planecal-compensated/1"
TOL_M = 1e-9  # a target is solved when the calibrated flange is within 1 nm ...
TOL_RAD = 1e-9  # ... and 1 nrad of it
MAX_ITER = 30


# ----- the calibrated model ---------------------------------------------------------------------

def registered_frame(robot: Robot, kin) -> np.ndarray:
    """``kin``'s frame of joint 1 at q = 0 mapped onto robot.json's (``robot_frame``): how
    a model's base frame sits in the frame a robot is measured in (ISO 9283's)."""
    from planecal.model.kinematics import frames
    z = np.zeros(robot.n_joints)
    return frames(kin, z)[1] @ np.linalg.inv(frames(robot.kinematics, z)[1])


@dataclass(frozen=True, eq=False)
class CalibratedModel:
    """A calibration at any level: robot.json's chain with the parameters' joint offsets,
    geometry, base frame and joint compliance (``planecal.model.measurement``), the one
    model every level is. ``level`` labels the result it came from (reports)."""
    robot: Robot
    params: CellParams
    level: str = "offsets"

    def flange(self, q: np.ndarray, side: np.ndarray | None = None) -> np.ndarray:
        """q (N, 6) rad (joint angles from the encoder model) -> (N, 4, 4) flange (standard
        DH frame 6) in the base frame; ``side`` (N, 6) the backlash flanks (level 3:
        ``measurement.backlash_sides``; None: the middle)."""
        from planecal.model.measurement import flange_pose
        return flange_pose(self.robot, np.atleast_2d(q), self.params, side)

    def jacobian(self, q: np.ndarray, side: np.ndarray | None = None) -> np.ndarray:
        """The geometric Jacobian (N, 6, 6) of the flange at q, rows (v, w) in the base
        frame (the joint errors' own derivatives -- the gravity deflection's ~1e-4, a gear
        harmonic's f A ~4e-3 -- left out: Newton's steps converge all the same)."""
        from planecal.model.kinematics import jacobian
        from planecal.model.measurement import effective_joints, kinematics_of
        qd, _ = effective_joints(self.robot, np.atleast_2d(q), self.params, side)
        return jacobian(kinematics_of(self.robot, self.params), qd)

    def sides(self, q: np.ndarray, direction: np.ndarray | None) -> np.ndarray:
        """(N, 6): the backlash flanks at q after motions of ``direction`` (N, 6) in -1, 0,
        +1 (``measurement.backlash_sides``)."""
        from planecal.model.measurement import backlash_sides
        return backlash_sides(self.robot, np.atleast_2d(q), direction)

    def robot_frame(self) -> np.ndarray:
        """4x4: the model's frame of joint 1 at q = 0 in its base frame, times the inverse
        of the nominal model's (identity for the nominal model)."""
        from planecal.model.measurement import kinematics_of
        return registered_frame(self.robot, kinematics_of(self.robot, self.params))


def load_calibrated(robot: Robot, path) -> tuple[CalibratedModel, dict]:
    """The calibrated model of a result (or parameter) file, and the parsed file; the
    result must have been made for ``robot`` (``io.params.check_robot``)."""
    from planecal.io.params import check_robot, load_params
    doc = read_json(path, "calibration result")
    check_robot(doc, robot, path)
    params = load_params(path)
    level = doc.get("level") if isinstance(doc, dict) and isinstance(doc.get("level"), str) \
        else ("full" if isinstance(doc, dict) and doc.get("kinematics") is not None
              else "offsets")
    return CalibratedModel(robot, params, level), doc


# ----- the calibrated region ------------------------------------------------------------------

REGION_MARGIN_M = 0.05  # how far beyond the samples' flange positions a target may lie
REGION_MARGIN_RAD = np.radians(2.0)  # ... and beyond the joint ranges they visited


@dataclass(frozen=True, eq=False)
class Region:
    """Where a calibration's samples are: the convex hull of their flange positions
    (nominal model, base frame) grown by ``margin_m``, and the range of each joint they
    visited grown by ``margin_rad``. A model fitted there is only known there."""
    lower: np.ndarray  # (6,) rad
    upper: np.ndarray
    facets: np.ndarray  # (F, 4): unit outward normals n and offsets b, n . p + b <= 0 inside
    samples: int
    source: str
    margin_m: float = REGION_MARGIN_M
    margin_rad: float = REGION_MARGIN_RAD

    @classmethod
    def from_counts(cls, robot: Robot, qe: np.ndarray, source: str,
                    margin_m: float = REGION_MARGIN_M,
                    margin_rad: float = REGION_MARGIN_RAD) -> "Region":
        from scipy.spatial import ConvexHull, QhullError
        q = counts_to_joints(robot, np.asarray(qe))
        if len(q) < 5:
            raise InputError(f"{source}: a calibrated region needs at least 5 samples")
        p = fk(robot.kinematics, q)[:, :3, 3]
        try:
            hull = ConvexHull(p, qhull_options="QJ")
        except QhullError:
            raise InputError(f"{source}: the samples' flange positions span no volume: no "
                             "calibrated region") from None
        return cls(q.min(0), q.max(0), hull.equations, len(q), source, margin_m, margin_rad)

    def distance_m(self, q: np.ndarray, robot: Robot) -> np.ndarray:
        """How far (m, >= 0) the nominal flange at q (N, 6) lies outside the hull grown by
        the margin (the largest facet distance beyond it)."""
        p = fk(robot.kinematics, np.atleast_2d(q))[:, :3, 3]
        d = p @ self.facets[:, :3].T + self.facets[:, 3]
        return np.maximum(0.0, d.max(1) - self.margin_m)

    def outside(self, q: np.ndarray) -> np.ndarray:
        """How far (rad, >= 0) each joint of q (N, 6) lies outside its range grown by the
        margin: (N, 6)."""
        q = np.atleast_2d(q)
        m = self.margin_rad
        return np.maximum(0.0, np.maximum(self.lower - m - q, q - self.upper - m))

    def to_dict(self) -> dict:
        return {"kind": "flange_hull_and_joint_ranges", "margin_mm": self.margin_m * 1e3,
                "margin_deg": float(np.degrees(self.margin_rad)),
                "lower_deg": np.degrees(self.lower).tolist(),
                "upper_deg": np.degrees(self.upper).tolist(), "hull_facets": len(self.facets),
                "samples": self.samples, "source": self.source}


# ----- the solve ---------------------------------------------------------------------------------

def pose_error(T: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(N, 6): position T - F [m] and the rotation vector of R_T R_F^T [rad], base frame."""
    dp = T[:, :3, 3] - F[:, :3, 3]
    dw = Rotation.from_matrix(T[:, :3, :3] @ np.swapaxes(F[:, :3, :3], -1, -2)).as_rotvec()
    return np.hstack([dp, dw])


def solve_poses(model: CalibratedModel, T: np.ndarray, q0: np.ndarray,
                tol_m: float = TOL_M, tol_rad: float = TOL_RAD, max_iter: int = MAX_ITER,
                direction: np.ndarray | None = None):
    """Joint angles q (N, 6) with model.flange(q) = T (N, 4, 4), by Newton from q0 with the
    model's own Jacobian (``CalibratedModel.jacobian``), each target approached with
    ``direction`` (N, 6) in -1, 0, +1 (level 3's backlash; None: not known, the middle):
    (q, iterations (N,), converged (N,), position residual [m] (N,), rotation residual
    [rad] (N,))."""
    q = np.array(q0, float, copy=True)
    n = len(q)
    its = np.zeros(n, int)
    d = None if direction is None else np.broadcast_to(np.asarray(direction), (n, 6))
    for _ in range(max_iter + 1):
        side = model.sides(q, d)
        e = pose_error(T, model.flange(q, side))
        rp, rw = np.linalg.norm(e[:, :3], axis=1), np.linalg.norm(e[:, 3:], axis=1)
        todo = ~((rp < tol_m) & (rw < tol_rad))
        if not todo.any() or its.max() >= max_iter:
            break
        J = model.jacobian(q[todo], side[todo])
        q[todo] += np.einsum("nij,nj->ni", np.linalg.pinv(J, rcond=1e-12), e[todo])
        its[todo] += 1
    return q, its, ~todo, rp, rw


@dataclass(frozen=True)
class Compensation:
    """Each target's nominal and corrected joints and counts, the solve's convergence and
    residuals, and how far outside the calibrated region it lies (module docstring)."""
    names: list
    where: list
    pose: np.ndarray  # (N, 4, 4) the flange pose the nominal model commands
    q_nominal: np.ndarray  # (N, 6) rad
    q_corrected: np.ndarray  # (N, 6) rad
    counts_nominal: np.ndarray  # (N, 6) int64
    counts_corrected: np.ndarray  # (N, 6) int64
    iterations: np.ndarray
    converged: np.ndarray
    residual_m: np.ndarray  # the solve's, continuous joints
    residual_rad: np.ndarray
    rounded_residual_m: np.ndarray  # the calibrated flange at the integer counts
    rounded_residual_rad: np.ndarray
    outside_rad: np.ndarray  # (N, 6), 0 within the region's joint ranges
    outside_m: np.ndarray  # (N,), 0 within the region's flange hull

    @property
    def correction_rad(self) -> np.ndarray:
        return self.q_corrected - self.q_nominal

    @property
    def correction_counts(self) -> np.ndarray:
        return self.counts_corrected - self.counts_nominal

    @property
    def outside(self) -> np.ndarray:
        return (self.outside_rad.max(1) > 0) | (self.outside_m > 0)

    def summary(self) -> dict:
        out = self.outside_rad.max(1)
        worst = int(np.argmax(out))
        far = int(np.argmax(self.outside_m))
        return {
            "targets": len(self.names),
            "converged": int(self.converged.sum()),
            "max_iterations": int(self.iterations.max()),
            "max_correction_counts": np.abs(self.correction_counts).max(0).tolist(),
            "max_correction_mrad": (np.abs(self.correction_rad).max(0) * 1e3).tolist(),
            "max_residual_mm": float(self.residual_m.max() * 1e3),
            "max_residual_mrad": float(self.residual_rad.max() * 1e3),
            "max_rounded_residual_mm": float(self.rounded_residual_m.max() * 1e3),
            "max_rounded_residual_mrad": float(self.rounded_residual_rad.max() * 1e3),
            "outside": int(self.outside.sum()),
            "max_outside_deg": float(np.degrees(out[worst])),
            "max_outside_target": self.names[worst] if out[worst] > 0 else None,
            "max_outside_joint": int(np.argmax(self.outside_rad[worst]) + 1) if out[worst] > 0 else None,
            "max_outside_mm": float(self.outside_m[far] * 1e3),
            "max_outside_mm_target": self.names[far] if self.outside_m[far] > 0 else None,
        }


def nominal_solutions(robot: Robot, targets: Targets, q_start: np.ndarray):
    """Each target's nominal joints and pose: a joint target's pose by ``robot.fk``; a
    Cartesian target's joints by the closed-form IK nearest to the previous target's
    (the first: nearest ``q_start``), as the controller would play the program.
    InputError naming a target no solution within the joint limits reaches."""
    q = targets.q.copy()
    T = targets.pose.copy()
    prev = np.asarray(q_start, float)
    w = np.abs(robot.gains)
    for i in range(len(targets)):
        if np.isfinite(T[i, 0, 0]):
            qi = ik_nearest(robot, T[i], prev, weights=w)
            if qi is None:
                raise InputError(f"{targets.where[i]}: target {targets.names[i]} is out of "
                                 "reach of the nominal model (no IK solution within the "
                                 "joint limits)")
            q[i] = qi
        else:
            if not within_limits(robot, q[i]):
                raise InputError(f"{targets.where[i]}: target {targets.names[i]} is outside "
                                 "the joint limits")
            T[i] = fk(robot.kinematics, q[i])
        prev = q[i]
    return q, T


FRAMES = ("robot", "cell")


def approach_directions(q: np.ndarray, q_start: np.ndarray | None = None) -> np.ndarray:
    """(N, 6) in -1, 0, +1: the sign of each joint's motion into each of the poses q (N, 6)
    played in order from ``q_start`` (None: the first pose's is not known, 0); a joint that
    does not move keeps the side its last motion left it on (level 3's backlash)."""
    q = np.atleast_2d(np.asarray(q, float))
    prev = q[:1] if q_start is None else np.atleast_2d(q_start)
    step = np.sign(np.diff(np.vstack([prev, q]), axis=0))
    out = np.zeros_like(step)
    side = np.zeros(q.shape[1])
    for i, s in enumerate(step):
        side = np.where(s != 0, s, side)
        out[i] = side
    return out.astype(np.int8)


def compensate(model: CalibratedModel, targets: Targets, region: Region,
               q_start: np.ndarray | None = None, frame: str = "robot") -> Compensation:
    """Corrected joint targets (module docstring). ``q_start``: where the first Cartesian
    target's IK branch is chosen (default: the region's centre). ``frame``: what the
    targets' coordinates are relative to: ``robot`` (default) the robot's own frame, joint
    1's axis and zero (the model's ``robot_frame``: a calibration's turn about J1 or shift
    of the base that no plate sees stays out); ``cell`` the calibration's base frame (the
    frame its planes are in)."""
    if frame not in FRAMES:
        raise InputError(f"--frame must be one of {', '.join(FRAMES)}, got {frame!r}")
    robot = model.robot
    q_start = (region.lower + region.upper) / 2 if q_start is None else q_start
    q_nom, T = nominal_solutions(robot, targets, q_start)
    Tm = model.robot_frame() @ T if frame == "robot" else T  # in the model's base frame
    direction = approach_directions(q_nom)  # the program's motions into its targets
    q_c, its, ok, rp, rw = solve_poses(model, Tm, q_nom, direction=direction)
    bad = np.flatnonzero(ok & ~within_limits(robot, q_c))
    if len(bad):
        i = bad[0]
        raise InputError(f"{targets.where[i]}: target {targets.names[i]}: the corrected "
                         "joints leave the joint limits")
    c_nom = joints_to_counts(robot, q_nom)
    c_cor = joints_to_counts(robot, np.where(ok[:, None], q_c, q_nom))
    qr = counts_to_joints(robot, c_cor)
    e = pose_error(Tm, model.flange(qr, model.sides(qr, direction)))
    return Compensation(list(targets.names), list(targets.where), T, q_nom, q_c, c_nom, c_cor,
                        its, ok, rp, rw, np.linalg.norm(e[:, :3], axis=1),
                        np.linalg.norm(e[:, 3:], axis=1), region.outside(q_c),
                        region.distance_m(q_c, robot))
