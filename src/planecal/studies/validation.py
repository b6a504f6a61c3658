"""Validation on the twin: ISO 9283 pose accuracy AP and repeatability RP (seed 3.2-3.3),
and the gauge-block test of seed 9.3, each with the nominal and the calibrated model.

ISO 9283 (position part). A cube with edges parallel to the base axes is placed over the
calibrated region: centred on the mean flange position of the calibration samples, edge
``cube_edge`` (default: 80 % of the samples' smallest flange-position range between the
10th and 90th percentiles, at most 0.25 m, shrunk by 0.75 until P1..P5 are reachable
and collision-free). Its diagonal plane through corners
(-,-,-), (+,+,-), (+,+,+), (-,-,+) holds P1 (the centre) and P2..P5, on the diagonals
at a tenth of the diagonal from the corners. The commanded orientation is the flange's at
the scene's calibration position. For each model (nominal: zero offsets; calibrated:
the fitted offsets) the controller converts the commanded pose to counts: IK with the
model's offsets (equivalently encoder.offsets_to_qe0) nearest to the calibration
position, then ``joints_to_counts``. The twin goes to those counts (``set_counts``: the
robot settles, with a fresh repeatability draw) and the *true* attained position of the
TCP (flange origin, or ``tcp`` in the flange frame) is read from MuJoCo. ``cycles`` (30)
cycles P1 -> P5. Per pose:
  AP = |barycentre of the attained positions - commanded position|
  RP = l_bar + 3 S_l,  l_j = |x_j - barycentre|, S_l their sample std.
Only the joint offsets enter AP: the sensor and planes are not part of the robot.

Gauge block (9.3): a block of length L (default 100 mm) stands on the (true) plate at its
centre, its two measuring faces perpendicular to the plate and to the plate's x edge.
Four points on each face (a 20 x 20 mm square around the face centre, ``face_height``
above the plate) are measured by the laser with the beam pointing into the face, tilted
down towards the plate by ``tilt`` (sensor above the plate); the pose is chosen with the
nominal model (IK within limits, collision-free target in ``CollisionWorld``, which does
not know the block) and the twin measures: the true sensor pose (MuJoCo site, with the
repeatability draw of that pose) and a ray to the analytic face plane, plus the laser
noise of a 100-reading mean. Each model turns (counts, distance) into a point
``o_b + d z_b``; a plane is fitted to each face's four points; the length is the mean
distance of each face's points from the other face's plane (both ways, averaged); its
error against L is reported for the nominal model (scene nominal sensor pose, zero
offsets), the calibrated model, and the calibrated sensor pose with nominal offsets
(to separate the offsets' share). ``gauge_repeats`` repetitions give mean and std.
The block is modelled analytically, not as MuJoCo geometry (that would need the scene
builder, owned elsewhere).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.cell import CellParams, sensor_in_base, sensor_rotation
from planecal.encoder import counts_to_joints, joints_to_counts
from planecal.errors import InputError
from planecal.robot import fk, ik_nearest
from planecal.studies.common import BUFFER_LEN, table


@dataclass(frozen=True)
class ValidationSettings:
    cycles: int = 30
    cube_edge_m: float | None = None
    tcp_m: tuple = (0.0, 0.0, 0.0)
    block_length_m: float = 0.100
    face_height_m: float = 0.040
    point_spacing_m: float = 0.020
    tilt_deg: float = 30.0
    distance_m: float = 0.080
    gauge_repeats: int = 10
    seed: int = 0
    laser_noise_mm: float = 0.001
    repeatability_mm: float | None = None
    clearance_m: float = 0.01

    def check(self):
        if self.cycles < 2:
            raise InputError(f"--cycles must be at least 2, got {self.cycles}")
        if self.cube_edge_m is not None and not 0 < self.cube_edge_m <= 1.0:
            raise InputError(f"--cube-mm must be in (0, 1000], got {self.cube_edge_m * 1e3}")
        if not 0 < self.block_length_m <= 0.3:
            raise InputError(f"--block-mm must be in (0, 300], got {self.block_length_m * 1e3}")
        if self.gauge_repeats < 1:
            raise InputError("--gauge-repeats must be at least 1")


# ----- ISO 9283 ------------------------------------------------------------------------------

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


def _commanded_counts(robot, T, q_ref, delta):
    q = ik_nearest(robot, T, q_ref, delta=delta, weights=np.abs(robot.gains))
    if q is None:
        return None, None
    return q, joints_to_counts(robot, q)


def iso9283(twin, scene, delta_models: dict, center, edge, R, st: ValidationSettings,
            checker=None) -> dict:
    """AP and RP per pose for each model in ``delta_models`` (name -> offsets (6,))."""
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
    for name, delta in delta_models.items():
        cs = []
        for i, T in enumerate(targets):
            q, c = _commanded_counts(robot, T, q_ref, delta)
            if q is None:
                raise InputError(f"ISO pose P{i + 1} is not reachable; give a smaller --cube-mm")
            if checker is not None and not checker.check_config(q).ok:
                raise InputError(f"ISO pose P{i + 1} is not collision-free; give a smaller --cube-mm")
            cs.append(c)
        counts[name] = cs
    out = {"points_m": P, "edge_m": edge, "center_m": center, "models": {}}
    for name in delta_models:
        att = np.zeros((st.cycles, 5, 3))
        for j in range(st.cycles):
            for i in range(5):
                twin.set_counts(counts[name][i])
                Tt = twin.flange_pose()
                att[j, i] = Tt[:3, :3] @ tcp + Tt[:3, 3]
        bary = att.mean(0)
        ap_xyz = bary - P
        ap = np.linalg.norm(ap_xyz, axis=1)
        lj = np.linalg.norm(att - bary[None], axis=2)
        rp = lj.mean(0) + 3 * lj.std(0, ddof=1)
        out["models"][name] = {"ap_mm": ap * 1e3, "ap_xyz_mm": ap_xyz * 1e3, "rp_mm": rp * 1e3}
    return out


# ----- gauge block -----------------------------------------------------------------------------

def gauge_block_geometry(scene, truth: CellParams, st: ValidationSettings, plate: int = 0):
    """Faces of the block in the base frame: list of (point on face centre line, outward
    normal, in-face axes (2,3)) for faces A and B, and the plate normal."""
    F = scene.plates[plate].frame(truth.planes[plate])
    x, y, z = F[:3, 0], F[:3, 1], F[:3, 2]
    c = F[:3, 3] + F[:3, :2] @ (scene.plates[plate].size / 2) + st.face_height_m * z
    L = st.block_length_m
    faces = [(c - L / 2 * x, -x, np.array([y, z])), (c + L / 2 * x, x, np.array([y, z]))]
    return faces, z


def _measure_pose(scene, face, plate_normal, offset, st, checker, q_ref):
    """Joint target (nominal model) putting the beam onto the face point ``face centre +
    offset`` from ``st.distance_m`` away, tilted down by st.tilt_deg; tries rolls about the
    beam and a few tilts; None if nothing reachable and collision-free."""
    robot = scene.robot
    p0, n, _ = face
    p = p0 + offset
    T_fs = np.eye(4)
    T_fs[:3, :3] = sensor_rotation(scene.phi_y, scene.phi_z)
    T_fs[:3, 3] = scene.sensor_origin
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
            q = ik_nearest(robot, Ts @ T_sf, q_ref, weights=np.abs(robot.gains))
            if q is None:
                continue
            cost = np.max(np.abs(q - q_ref) * np.abs(robot.gains))
            if best is not None and cost >= best[0]:
                continue
            if checker is not None and not checker.check_config(q).ok:
                continue
            best = (cost, q)
        if best is not None:
            return best[1]
    return None


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


def gauge_block(twin, scene, truth, models: dict, st: ValidationSettings, checker=None,
                rng=None) -> dict:
    """The gauge-block test (module docstring); ``models``: name -> CellParams."""
    rng = rng or np.random.default_rng(st.seed)
    robot = scene.robot
    faces, zp = gauge_block_geometry(scene, truth, st)
    q_ref = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    a = st.point_spacing_m / 2
    offsets = [(u, v) for u in (-a, a) for v in (-a, a)]
    plan = []
    for fi, face in enumerate(faces):
        for u, v in offsets:
            off = u * face[2][0] + v * face[2][1]
            q = _measure_pose(scene, face, zp, off, st, checker, q_ref)
            if q is None:
                raise InputError(f"gauge block: no reachable, collision-free pose for a point on "
                                 f"face {'AB'[fi]}; change --block-mm or the tilt")
            plan.append((fi, joints_to_counts(robot, q)))
    sig_l = st.laser_noise_mm * 1e-3 / np.sqrt(BUFFER_LEN)
    lengths = {name: [] for name in models}
    worst_incidence = 0.0
    first = None
    for _ in range(st.gauge_repeats):
        meas = []
        for fi, c in plan:
            twin.set_counts(c)
            Ts = twin.sensor_pose()
            o, zb = Ts[:3, 3], Ts[:3, 2]
            p0, n, _ = faces[fi]
            cosi = -(n @ zb)
            worst_incidence = max(worst_incidence, float(np.degrees(np.arccos(min(1.0, cosi)))))
            d = (n @ (p0 - o)) / (n @ zb) + rng.normal(0.0, sig_l)
            if not (scene.laser_range_mm[0] <= d * 1e3 <= scene.laser_range_mm[1]):
                raise InputError(f"gauge block: reading {d * 1e3:.1f} mm out of the laser range")
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
    from planecal.robot import jacobian
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
        Jg = jacobian(robot, q, calibrated.joint_offsets)
        r = R @ tcp
        Jv = Jg[:3] - np.cross(r, Jg[3:].T).T  # TCP velocity: v + w x r
        Jo = Jv[:, cols]
        sig_pos.append(float(np.sqrt(np.trace(Jo @ Co @ Jo.T))))
    return {"gauge_length_std_mm": sig_len * 1e3, "tcp_position_rms_mm": np.array(sig_pos) * 1e3}


# ----- whole validation ---------------------------------------------------------------------------

def validate(scene, truth: CellParams, calibrated: CellParams, sample_counts: np.ndarray,
             st: ValidationSettings | None = None, checker=None, fit=None) -> dict:
    """ISO 9283 AP/RP and the gauge block, nominal vs calibrated, on a twin with ``truth``.
    ``sample_counts``: the calibration samples (they place the ISO cube); ``fit``: the
    calibration's ``fit.Result``, whose covariance predicts the spread (None: no
    prediction)."""
    from planecal.scene import nominal_params
    from planecal.twin import Twin, TwinOptions

    st = st or ValidationSettings()
    st.check()
    robot = scene.robot
    twin = Twin(scene, truth=truth, seed=st.seed,
                options=TwinOptions(laser_noise_mm=st.laser_noise_mm,
                                    repeatability_mm=st.repeatability_mm))
    flanges = fk(robot, counts_to_joints(robot, sample_counts))[:, :3, 3]
    center, edge = cube_from_flanges(flanges, st.cube_edge_m)
    q_cal = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    R = fk(robot, q_cal)[:3, :3]
    models = {"nominal": np.zeros(6), "calibrated": calibrated.joint_offsets}
    for attempt in range(6):  # a cube of our own choosing shrinks until all poses are clear
        try:
            iso = iso9283(twin, scene, models, center, edge, R, st, checker)
            break
        except InputError:
            if st.cube_edge_m is not None or attempt == 5:
                raise
            edge *= 0.75
    nominal = nominal_params(scene)
    mixed = calibrated.copy()
    mixed.joint_offsets = nominal.joint_offsets.copy()
    gb = gauge_block(twin, scene, truth, {"nominal": nominal, "calibrated": calibrated,
                                          "calibrated_sensor_nominal_offsets": mixed}, st, checker)
    pred = None
    if fit is not None:
        pred = predicted_spread(robot, gb["measurements"], calibrated, fit.layout,
                                fit.covariance, iso["points_m"], R,
                                np.asarray(st.tcp_m, float), q_cal)
    gb.pop("measurements")
    ap_b, ap_a = iso["models"]["nominal"]["ap_mm"], iso["models"]["calibrated"]["ap_mm"]
    rp = np.maximum(iso["models"]["nominal"]["rp_mm"], iso["models"]["calibrated"]["rp_mm"])
    d_err = calibrated.joint_offsets - truth.joint_offsets
    # what is left: delta1 turns everything about the base axis, delta6 turns a TCP off axis 6
    r_xy = np.hypot(iso["points_m"][:, 0], iso["points_m"][:, 1])
    left = {"offset_error_rad": d_err, "delta1_error_rad": float(d_err[0]),
            "delta6_error_rad": float(d_err[5]),
            "delta1_share_mm": float(abs(d_err[0]) * r_xy.max() * 1e3),
            "delta6_share_mm": float(abs(d_err[5]) * np.hypot(*np.asarray(st.tcp_m)[:2]) * 1e3)}
    return {
        "ap_before_mm": float(ap_b.max()), "ap_after_mm": float(ap_a.max()),
        "ap_ratio": float(ap_b.max() / ap_a.max()) if ap_a.max() > 0 else float("inf"),
        "rp_mm": float(rp.max()),
        "gauge_error_before_mm": gb["models"]["nominal"]["error_mm"],
        "gauge_error_after_mm": gb["models"]["calibrated"]["error_mm"],
        "gauge_error_offsets_only_mm": gb["models"]["calibrated_sensor_nominal_offsets"]["error_mm"],
        "predicted_from_fit": pred,
        "iso": iso, "gauge": gb, "residual_offset_error": left,
        "settings": {k: getattr(st, k) for k in st.__dataclass_fields__},
    }


def format_validation(v: dict) -> str:
    iso = v["iso"]
    rows = []
    for i in range(5):
        nb, ca = iso["models"]["nominal"], iso["models"]["calibrated"]
        p = iso["points_m"][i]
        rows.append([f"P{i + 1}", f"{p[0]:.3f} {p[1]:.3f} {p[2]:.3f}", f"{nb['ap_mm'][i]:.4f}",
                     f"{ca['ap_mm'][i]:.4f}", f"{nb['rp_mm'][i]:.4f}", f"{ca['rp_mm'][i]:.4f}"])
    out = [f"ISO 9283 pose accuracy on the twin: cube edge {iso['edge_m'] * 1e3:.0f} mm centred "
           f"at {np.round(np.asarray(iso['center_m']), 3).tolist()} m, "
           f"{v['settings']['cycles']} cycles, TCP {list(v['settings']['tcp_m'])} m in the flange frame",
           table(["pose", "position [m]", "AP nominal mm", "AP calibrated mm", "RP nominal mm",
                  "RP calibrated mm"], rows), "",
           f"AP before {v['ap_before_mm']:.4f} mm, after {v['ap_after_mm']:.4f} mm "
           f"(x{v['ap_ratio']:.1f} smaller); RP {v['rp_mm']:.4f} mm", ""]
    g = v["gauge"]
    rows = [[name, f"{m['error_mm']:+.4f}", f"{m['error_std_mm']:.4f}", f"{m['max_abs_error_mm']:.4f}"]
            for name, m in g["models"].items()]
    out.append(f"gauge block {g['length_m'] * 1e3:.0f} mm, 4 points per face, {g['repeats']} "
               f"repeats (largest incidence {g['max_incidence_deg']:.0f} deg)")
    out.append(table(["model", "length error mm", "std mm", "max |error| mm"], rows))
    r = v["residual_offset_error"]
    pr = v.get("predicted_from_fit")
    if pr:
        out.append("")
        out.append(f"the fit's covariance predicts (1 sigma): gauge length "
                   f"{pr['gauge_length_std_mm']:.4f} mm (sensor pose and offsets); TCP position "
                   f"error from the offsets at P1..P5 "
                   + " ".join(f"{x:.4f}" for x in pr["tcp_position_rms_mm"]) + " mm (rms)")
    out.append("")
    out.append("offset error left after calibration [urad]: "
               + " ".join(f"{e * 1e6:+.1f}" for e in r["offset_error_rad"]))
    if abs(r["delta1_error_rad"]) > 1e-9 or abs(r["delta6_error_rad"]) > 1e-9:
        out.append(f"delta1 (not identifiable: a turn of the plates about the base axis) leaves up "
                   f"to {r['delta1_share_mm']:.3f} mm at these poses; delta6 (a roll of the sensor) "
                   f"leaves {r['delta6_share_mm']:.3f} mm at the TCP. Neither changes a distance the "
                   f"laser measures, so the gauge length does not see them.")
    return "\n".join(out)
