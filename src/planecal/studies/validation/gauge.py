"""The gauge-block test of seed 9.3 on the twin (the package docstring describes it), and
the spread the fit's covariance predicts for it and for the ISO poses."""
from __future__ import annotations

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.noise import BUFFER_LEN
from planecal.model.cell_params import CellParams
from planecal.model.encoder import counts_to_joints, joints_to_counts
from planecal.model.ik import ik_nearest
from planecal.model.measurement import sensor_in_base, sensor_rotation
from planecal.studies.validation.iso9283 import Mover
from planecal.studies.validation.settings import ValidationSettings


def gauge_block_geometry(scene, truth: CellParams, st: ValidationSettings, plate: int = 0):
    """Faces of the block in the base frame: list of (point on face centre line, outward
    normal, in-face axes (2,3)) for faces A and B, and the plate normal."""
    F = scene.plates[plate].frame(truth.planes[plate])
    x, y, z = F[:3, 0], F[:3, 1], F[:3, 2]
    c = F[:3, 3] + F[:3, :2] @ (scene.plates[plate].size / 2) + st.face_height_m * z
    L = st.block_length_m
    faces = [(c - L / 2 * x, -x, np.array([y, z])), (c + L / 2 * x, x, np.array([y, z]))]
    return faces, z


def _measure_pose(scene, face, plate_normal, offset, st, checker, q_ref, aim):
    """Joint target putting the beam onto the face point ``face centre + offset`` from
    ``st.distance_m`` away, tilted down by st.tilt_deg, by the aiming model ``aim`` (a
    ``compensate.CalibratedModel``: its sensor pose, the closed-form IK with its offsets
    for the branch and the roll, then Newton on its whole model; the face in its base
    frame); tries rolls about the beam and a few tilts; None if nothing reachable and
    collision-free."""
    robot = scene.robot
    p0, n, _ = face
    p = p0 + offset
    T_fs = np.eye(4)
    T_fs[:3, :3] = sensor_rotation(aim.params.phi_y, aim.params.phi_z)
    T_fs[:3, 3] = aim.params.sensor_origin
    T_sf = np.linalg.inv(T_fs)
    best = None
    for tilt in (st.tilt_deg, st.tilt_deg + 10, st.tilt_deg - 10, st.tilt_deg + 20):
        t = np.deg2rad(tilt)
        beam = -np.cos(t) * n - np.sin(t) * plate_normal
        beam /= np.linalg.norm(beam)
        x0 = np.cross(plate_normal, beam)
        x0 /= np.linalg.norm(x0)
        y0 = np.cross(beam, x0)
        for psi in np.deg2rad(np.arange(0, 360, 15)):
            Ts = np.eye(4)
            Ts[:3, 0] = np.cos(psi) * x0 + np.sin(psi) * y0
            Ts[:3, 1] = np.cross(beam, Ts[:3, 0])
            Ts[:3, 2] = beam
            Ts[:3, 3] = p - st.distance_m * beam
            q = ik_nearest(robot, Ts @ T_sf, q_ref, delta=aim.params.joint_offsets,
                           weights=np.abs(robot.gains))
            if q is None:
                continue
            cost = np.max(np.abs(q - q_ref) * np.abs(robot.gains))
            if best is not None and cost >= best[0]:
                continue
            q = _on_model(aim, Ts @ T_sf, q)
            if q is None or (checker is not None and not checker.check_config(q).ok):
                continue
            best = (cost, q)
        if best is not None:
            return best[1]
    return None


def _on_model(aim, T, q0):
    """The joints at which ``aim``'s whole model puts its flange at T (its base frame),
    from q0 (``compensate.solve_poses``); None where Newton does not converge."""
    from planecal.estimation.compensate import solve_poses
    q, _, ok, _, _ = solve_poses(aim, T[None], q0[None])
    return q[0] if ok[0] else None


def _plane_fit(P):
    c = P.mean(0)
    _, _, Vt = np.linalg.svd(P - c)
    return c, Vt[-1]


def gauge_length(points_a, points_b) -> float:
    ca, na = _plane_fit(points_a)
    cb, nb = _plane_fit(points_b)
    la = np.mean(np.abs((points_b - ca) @ na))
    lb = np.mean(np.abs((points_a - cb) @ nb))
    return float((la + lb) / 2)


def laser_reading_mm(d_m: float, window_mm, lin: np.ndarray) -> float:
    """The twin's laser model (``twin.ticks.laser``) without noise: the reading [mm] of a
    true distance ``d_m`` with the linearity error ``lin`` (``twin.laser.LaserNoise.lin``);
    NaN outside the window."""
    from planecal.twin import ticks
    out = np.empty(1)
    ticks.laser(np.zeros(1, np.int64), np.array([float(d_m)]), -1.0, 0, np.zeros(0), 0,
                False, 0.0, float(window_mm[0]), float(window_mm[1]), lin, out,
                np.zeros(3, np.int64))
    return float(out[0])


def gauge_block(twin, scene, truth, models: dict, st: ValidationSettings, checker=None,
                rng=None, mover: Mover | None = None, laser_noise_mm: float = 0.001,
                linearity: np.ndarray | None = None, aim=None) -> dict:
    """The gauge-block test (module docstring); ``models``: name -> CellParams;
    ``linearity``: the laser's linearity error (``LaserNoise.lin``; None: none); ``aim``:
    the model that aims the laser at the block (a ``compensate.CalibratedModel``: the block
    where its plate is, the poses by its model; None: the nominal model and the scene's
    nominal plate). The block stands on the true plate; the twin measures it there."""
    from planecal.estimation.compensate import CalibratedModel
    from planecal.model.scene import nominal_params
    rng = rng or np.random.default_rng(st.seed)
    lin = np.zeros(4) if linearity is None else np.asarray(linearity, float)
    robot = scene.robot
    aim = aim or CalibratedModel(robot, nominal_params(scene), "nominal")
    faces, zp = gauge_block_geometry(scene, truth, st)
    aimed, za = gauge_block_geometry(scene, aim.params, st)
    q_ref = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    a = st.point_spacing_m / 2
    offsets = [(u, v) for u in (-a, a) for v in (-a, a)]
    plan = []
    for fi, face in enumerate(aimed):
        for u, v in offsets:
            off = u * face[2][0] + v * face[2][1]
            q = _measure_pose(scene, face, za, off, st, checker, q_ref, aim)
            if q is None:
                raise InputError(f"gauge block: no reachable, collision-free pose for a point on "
                                 f"face {'AB'[fi]}; change --block-mm or the tilt")
            plan.append((fi, joints_to_counts(robot, q)))
    mover = mover or Mover(twin, robot, checker)
    prev = mover.drv.commanded_counts
    for k, (fi, c) in enumerate(plan + plan[:1]):  # every path, before any is driven
        if not mover.path_ok(prev, c):
            raise InputError(f"gauge block: no collision-free path to point {k % 4 + 1} of "
                             f"face {'AB'[fi]}; change --block-mm or the tilt")
        prev = c
    sig_l = laser_noise_mm * 1e-3 / np.sqrt(BUFFER_LEN)
    lengths = {name: [] for name in models}
    worst_incidence = 0.0
    first = None
    for _ in range(st.gauge_repeats):
        meas = []
        for fi, c in plan:
            mover.go(c, "gauge block pose")
            Ts = twin.sensor_pose()
            o, zb = Ts[:3, 3], Ts[:3, 2]
            p0, n, _ = faces[fi]
            cosi = -(n @ zb)
            worst_incidence = max(worst_incidence, float(np.degrees(np.arccos(min(1.0, cosi)))))
            d_true = (n @ (p0 - o)) / (n @ zb)
            mm = laser_reading_mm(d_true, scene.laser_range_mm, lin)
            if not np.isfinite(mm):
                raise InputError(f"gauge block: reading {d_true * 1e3:.1f} mm out of the "
                                 f"laser range (aimed with the {aim.level} model)")
            d = (mm * 1e-3 if lin.any() else d_true) + rng.normal(0.0, sig_l)
            meas.append((fi, c, d))
        first = first or meas
        for name, params in models.items():
            pts = {0: [], 1: []}
            for fi, c, d in meas:
                ob, zb = sensor_in_base(robot, counts_to_joints(robot, c)[None], params)
                pts[fi].append(ob[0] + d * zb[0])
            lengths[name].append(gauge_length(np.array(pts[0]), np.array(pts[1])))
    out = {"length_m": st.block_length_m, "repeats": st.gauge_repeats,
           "max_incidence_deg": worst_incidence, "models": {}, "measurements": first}
    for name, ls in lengths.items():
        e = np.array(ls) - st.block_length_m
        out["models"][name] = {"error_mm": float(e.mean() * 1e3),
                               "error_std_mm": float(e.std(ddof=1) * 1e3) if len(e) > 1 else 0.0,
                               "max_abs_error_mm": float(np.max(np.abs(e)) * 1e3)}
    return out


def length_from(robot, meas, params: CellParams) -> float:
    pts = {0: [], 1: []}
    for fi, c, d in meas:
        ob, zb = sensor_in_base(robot, counts_to_joints(robot, c)[None], params)
        pts[fi].append(ob[0] + d * zb[0])
    return gauge_length(np.array(pts[0]), np.array(pts[1]))


def predicted_spread(robot, meas, calibrated: CellParams, layout, covariance, points, R, tcp,
                     q_ref) -> dict:
    """What the fit's own covariance (``fit.Covariance``, by name, over the fit's
    ``layout``) predicts (1 sigma) for the gauge-length error and for the TCP position
    error at the ISO poses (offsets' covariance through the flange Jacobian), by linear
    propagation."""
    from planecal.model.kinematics import jacobian
    cov = covariance.matrix
    x0 = calibrated.to_vector(layout)
    idx = layout.indices(covariance.names)
    ok = np.all(np.isfinite(cov), axis=1)
    g = np.zeros(len(idx))
    L0 = length_from(robot, meas, calibrated)
    for k, i in enumerate(idx):
        if not ok[k]:
            continue
        h = 1e-7 * max(1.0, abs(x0[i]))
        x = x0.copy()
        x[i] += h
        g[k] = (length_from(robot, meas, CellParams.from_vector(x, layout)) - L0) / h
    C = np.where(np.isfinite(cov), cov, 0.0)
    sig_len = float(np.sqrt(max(g @ C @ g, 0.0)))
    # offsets block of the covariance (free offsets only)
    offsets = layout.group("joint_offsets").names
    off = [k for k, n in enumerate(covariance.names) if n in offsets and ok[k]]
    Co = C[np.ix_(off, off)]
    cols = [offsets.index(covariance.names[k]) for k in off]  # joint of each offset
    sig_pos = []
    for p in points:
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = p - R @ tcp
        q = ik_nearest(robot, T, q_ref, delta=calibrated.joint_offsets)
        Jg = jacobian(robot.kinematics.with_offsets(calibrated.joint_offsets), q)
        r = R @ tcp
        Jv = Jg[:3] - np.cross(r, Jg[3:].T).T  # TCP velocity: v + w x r
        Jo = Jv[:, cols]
        sig_pos.append(float(np.sqrt(np.trace(Jo @ Co @ Jo.T))))
    return {"gauge_length_std_mm": sig_len * 1e3, "tcp_position_rms_mm": np.array(sig_pos) * 1e3}
