"""ISO 9283 pose accuracy AP and repeatability RP on the twin (seed 3.2-3.3; the
package docstring says where the cube goes, how each model commands it and in which frame
AP is measured)."""
from __future__ import annotations

import numpy as np

from planecal.base.errors import InputError
from planecal.model.cell_params import CellParams
from planecal.model.encoder import counts_to_joints, joints_to_counts
from planecal.model.ik import ik_nearest
from planecal.studies.validation.settings import ValidationSettings


def iso_points(center: np.ndarray, edge: float) -> np.ndarray:
    """P1..P5 (5, 3): centre and 0.8 of the way to the four corners of the diagonal plane."""
    h = edge / 2
    corners = np.array([[-h, -h, -h], [h, h, -h], [h, h, h], [-h, -h, h]])
    return np.vstack([center, center + 0.8 * corners])


def cube_from_flanges(flange_pos: np.ndarray, edge: float | None) -> tuple[np.ndarray, float]:
    c = flange_pos.mean(0)
    if edge is None:
        rng = np.percentile(flange_pos, 90, axis=0) - np.percentile(flange_pos, 10, axis=0)
        edge = float(min(0.25, 0.8 * rng.min()))
    return c, edge


class Mover:
    """Moves the twin to counts as the robot moves there: the sampling run's step path
    (``sampling.driver``), each path collision-checked once (``checker``; None: not
    checked), then held until the robot is at rest on the counts (it settles: a fresh
    repeatability draw). A joint's backlash follows the direction it came from."""

    def __init__(self, twin, robot, checker=None):
        from planecal.links.base import AlwaysEnabled
        from planecal.sampling.driver import Driver
        self.twin, self.robot, self.checker = twin, robot, checker
        self.drv = Driver(twin, twin, AlwaysEnabled(), robot)
        self.drv.start()
        self._clear: dict = {}

    def path_ok(self, c0, c1) -> bool:
        if self.checker is None:
            return True
        key = (np.asarray(c0, np.int64).tobytes(), np.asarray(c1, np.int64).tobytes())
        if key not in self._clear:
            q0, q1 = counts_to_joints(self.robot, np.array([c0, c1]))
            self._clear[key] = bool(self.checker.check_path(q0, q1).ok)
        return self._clear[key]

    def go(self, counts, what: str = "pose") -> None:
        from planecal.sampling.driver import plan_move
        c = np.asarray(counts, np.int64)
        if not self.path_ok(self.drv.commanded_counts, c):
            raise InputError(f"{what}: the path there is not collision-free")
        rows = plan_move(self.drv, c)
        if rows is None:
            raise InputError(f"{what}: counts outside the encoder range")
        self.drv.follow(rows)
        for _ in range(1000):  # the servo's lag: a few tens of ticks at most
            if np.array_equal(self.drv.current, c):
                break
            self.drv.hold()
        else:
            raise RuntimeError(f"{what}: the twin did not come to rest on its counts")


def robot_frame(robot, world) -> np.ndarray:
    """The frame ISO 9283 measures in, in the cell frame (module docstring): the true
    robot's frame of joint 1 at its zero, mapped onto the nominal one's. Identity in the
    ideal world with delta1 = 0."""
    from planecal.estimation.compensate import registered_frame
    kin = world.kinematics if world.kinematics is not None else robot.kinematics
    return registered_frame(robot, kin.with_offsets(world.params.joint_offsets))


def commanded_counts(robot, T, q_ref, model: CellParams):
    """Joint angles and counts that put the flange at T (in the robot's frame) by
    ``model`` (any level: the calibrated model, ``compensate.CalibratedModel``): the
    closed-form IK with its joint offsets nearest ``q_ref``, then Newton on the whole model
    (``compensate.solve_poses``; no step where the model is robot.json's with offsets).
    (None, None) where the pose is not reachable."""
    from planecal.estimation.compensate import CalibratedModel, solve_poses
    q0 = ik_nearest(robot, T, q_ref, delta=model.joint_offsets, weights=np.abs(robot.gains))
    if q0 is None:
        return None, None
    full = CalibratedModel(robot, model)
    # T is in the robot's frame (J1's axis and zero): the model's own base frame is
    # registered to it, as compensate does
    q, _, ok, _, _ = solve_poses(full, (full.robot_frame() @ T)[None], q0[None])
    if not ok[0]:
        return None, None
    return q[0], joints_to_counts(robot, q[0])


def iso9283(twin, scene, models: dict, center, edge, R, st: ValidationSettings,
            checker=None, frame: np.ndarray | None = None, mover: Mover | None = None) -> dict:
    """AP and RP per pose for each model in ``models`` (name -> ``CellParams``, any level:
    ``commanded_counts``): AP in the robot's frame ``frame`` (a 4x4 in the cell frame,
    ``robot_frame``; None: the cell frame) and in the cell frame."""
    robot = scene.robot
    q_ref = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    tcp = np.asarray(st.tcp_m, float)
    P = iso_points(center, edge)
    targets = []
    for i, p in enumerate(P):
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = p - R @ tcp  # the TCP at p
        targets.append(T)
    counts = {}
    for name, model in models.items():
        cs = []
        for i, T in enumerate(targets):
            q, c = commanded_counts(robot, T, q_ref, model)
            if q is None:
                raise InputError(f"ISO pose P{i + 1} is not reachable; give a smaller --cube-mm")
            if checker is not None and not checker.check_config(q).ok:
                raise InputError(f"ISO pose P{i + 1} is not collision-free; give a smaller --cube-mm")
            cs.append(c)
        counts[name] = cs
    mover = mover or Mover(twin, robot, checker)
    prev = mover.drv.commanded_counts  # every path of the cycles, before any is driven
    for name in models:
        cs = counts[name]
        for i, c in enumerate([cs[0]] + list(cs[1:]) + [cs[0]]):
            if not mover.path_ok(prev, c):
                raise InputError(f"ISO pose P{i % 5 + 1} ({name} model): the path there is "
                                 "not collision-free; give a smaller --cube-mm")
            prev = c
        prev = cs[-1]
    F = np.eye(4) if frame is None else np.asarray(frame, float)
    Finv = np.linalg.inv(F)
    out = {"points_m": P, "edge_m": edge, "center_m": center, "robot_frame": F, "models": {}}
    for name in models:
        att = np.zeros((st.cycles, 5, 3))
        for j in range(st.cycles):
            for i in range(5):
                mover.go(counts[name][i], f"ISO pose P{i + 1}")
                Tt = twin.flange_pose()
                att[j, i] = Tt[:3, :3] @ tcp + Tt[:3, 3]
        bary = att.mean(0)
        lj = np.linalg.norm(att - bary[None], axis=2)
        rp = lj.mean(0) + 3 * lj.std(0, ddof=1)
        ap_cell_xyz = bary - P
        ap_xyz = (Finv[:3, :3] @ bary.T).T + Finv[:3, 3] - P
        out["models"][name] = {
            "ap_mm": np.linalg.norm(ap_xyz, axis=1) * 1e3, "ap_xyz_mm": ap_xyz * 1e3,
            "rp_mm": rp * 1e3, "ap_cell_mm": np.linalg.norm(ap_cell_xyz, axis=1) * 1e3,
            "ap_xyz_cell_mm": ap_cell_xyz * 1e3}
    return out
