"""Validation on the twin: ISO 9283 pose accuracy AP and repeatability RP (seed 3.2-3.3),
and the gauge-block test of seed 9.3, each with the nominal and the calibrated model, in a
world of the twin's error profile (``twin.profile``: the truth, the robot's true geometry,
the joint errors, the laser's), over several truths, and with each error source switched
off in turn (``breakdown``) to measure what an offsets-only calibration leaves of it.

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
position, then ``joints_to_counts``. The twin drives there as the robot does (the sampling
run's step path, ``sampling.driver``, each path collision-checked; a joint's backlash
follows the direction it came from) and settles (a fresh repeatability draw), and the
*true* attained position of the TCP (flange origin, or ``tcp`` in the flange frame) is read
from MuJoCo. ``cycles`` (30) cycles P1 -> P5. Per pose:
  AP = |barycentre of the attained positions - commanded position|
  RP = l_bar + 3 S_l,  l_j = |x_j - barycentre|, S_l their sample std.
Only the joint offsets enter AP: the sensor and planes are not part of the robot.

Two frames. ISO 9283 measures in the robot's base coordinate system: the measurement is
registered to the robot as it stands (``robot_frame``: the frame of joint 1 at its zero,
i.e. J1's axis, J1's zero direction and the height of that frame, which a laser tracker
finds from the robot's own first axis). AP (``ap_mm``) is in that frame. The cell frame
(``ap_cell_mm``) is the twin's world: what a program written in the nominal cell
coordinates reaches; it adds the robot's placement (the base frame error of a realistic
world) and J1's zero offset delta1, which no plane calibration can see (a turn about J1 or
a shift of the whole robot moves the plates with it). In the ideal world the two agree
unless delta1 is drawn (``offsets_all``).

Gauge block (9.3): a block of length L (default 100 mm) stands on the (true) plate at its
centre, its two measuring faces perpendicular to the plate and to the plate's x edge.
Four points on each face (a 20 x 20 mm square around the face centre, ``face_height``
above the plate) are measured by the laser with the beam pointing into the face, tilted
down towards the plate by ``tilt`` (sensor above the plate); the pose is chosen with the
nominal model (IK within limits, collision-free target in ``CollisionWorld``, which does
not know the block) and the twin measures: the true sensor pose (MuJoCo site, with the
repeatability draw of that pose) and a ray to the analytic face plane, plus the laser
noise of a 100-reading mean and the laser's linearity error of the world (``twin.ticks``'s
laser model). Each model turns (counts, distance) into a point
``o_b + d z_b``; a plane is fitted to each face's four points; the length is the mean
distance of each face's points from the other face's plane (both ways, averaged); its
error against L is reported for the nominal model (scene nominal sensor pose, zero
offsets), the calibrated model, and the calibrated sensor pose with nominal offsets
(to separate the offsets' share). ``gauge_repeats`` repetitions give mean and std.
The block is modelled analytically, not as MuJoCo geometry (that would need the scene
builder, owned elsewhere).

Over truths (``validate_truth``, a pure function of a ``TruthJob``): draw the world
(``studies.montecarlo.world_for``), sample a calibration set on that world's twin
(``twin_samples``: the sampling run's planner, collision checks and laser reads), calibrate
offsets-only from the nominal values (``fit.solve``), validate on the same world.
``calibrate_run`` is the one place the fit is called (``level`` 'offsets' today).
``summarize`` gives median and worst; ``breakdown`` repeats one truth with each error
family of ``montecarlo.SOURCES`` on alone (or switched off in turn) and reports AP after
calibration per variant: what each source leaves. The truths and the variants run on
``studies.distributed.Engine`` (``run_jobs``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from planecal.model.cell import CellParams, sensor_in_base, sensor_rotation
from planecal.model.encoder import counts_to_joints, joints_to_counts
from planecal.base.errors import InputError
from planecal.model.robot import fk, ik_nearest
from planecal.studies.common import BUFFER_LEN, table
from planecal.studies.montecarlo import SOURCES

FORMAT = "planecal-validate/1"
# the published figures the twin's are read against (docs/STUDIES.md, ERROR-MODEL.md 2.9)
ANCHORS = ("published after calibration: SCALAR 0.09 mm (simulation, three planes); KUKA "
           "Absolute Accuracy 1-3 mm -> 0.1-0.3 mm (vendor, secondary source); RoboDK "
           "0.05-0.15 mm with a laser tracker (not verified). The real MC70 (seed Table 9): "
           "max model error 0.10-0.19 mm on the plate after calibration (not an AP).")


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
    clearance_m: float = 0.01
    gauge: bool = True  # the gauge-block test too (the demo and the breakdown skip it)

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
    from planecal.model.kinematics import from_robot
    kin = world.kinematics if world.kinematics is not None else from_robot(robot)
    return registered_frame(robot, kin.with_offsets(world.params.joint_offsets))


def _commanded_counts(robot, T, q_ref, model):
    """Joint angles and counts that put the flange at T by ``model``: joint offsets (6,)
    (robot.json's model with them), or a level-2 ``CellParams`` (the whole calibrated
    model: its offsets' IK, then ``compensate.solve_poses`` on the full model)."""
    if isinstance(model, CellParams):
        from planecal.estimation.compensate import FullModel, solve_poses
        q0 = ik_nearest(robot, T, q_ref, delta=model.joint_offsets, weights=np.abs(robot.gains))
        if q0 is None:
            return None, None
        full = FullModel(robot, model)
        # T is in the robot's frame (J1's axis and zero): the model's own base frame is
        # registered to it, as compensate does
        q, _, ok, _, _ = solve_poses(full, (full.robot_frame() @ T)[None], q0[None])
        if not ok[0]:
            return None, None
        q = q[0]
    else:
        q = ik_nearest(robot, T, q_ref, delta=model, weights=np.abs(robot.gains))
        if q is None:
            return None, None
    return q, joints_to_counts(robot, q)


def iso9283(twin, scene, delta_models: dict, center, edge, R, st: ValidationSettings,
            checker=None, frame: np.ndarray | None = None, mover: Mover | None = None) -> dict:
    """AP and RP per pose for each model in ``delta_models`` (name -> offsets (6,), or a
    level-2 ``CellParams``: ``_commanded_counts``): AP in
    the robot's frame ``frame`` (a 4x4 in the cell frame, ``robot_frame``; None: the cell
    frame) and in the cell frame."""
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
    mover = mover or Mover(twin, robot, checker)
    prev = mover.drv.commanded_counts  # every path of the cycles, before any is driven
    for name in delta_models:
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
    for name in delta_models:
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
                linearity: np.ndarray | None = None) -> dict:
    """The gauge-block test (module docstring); ``models``: name -> CellParams;
    ``linearity``: the laser's linearity error (``LaserNoise.lin``; None: none)."""
    rng = rng or np.random.default_rng(st.seed)
    lin = np.zeros(4) if linearity is None else np.asarray(linearity, float)
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
                                 "laser range")
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
    from planecal.model.robot import jacobian
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

def validate(scene, world, calibrated: CellParams, sample_counts: np.ndarray,
             st: ValidationSettings | None = None, checker=None, fit=None,
             options=None) -> dict:
    """ISO 9283 AP/RP and the gauge block, nominal vs calibrated, on a twin of ``world``
    (a ``twin.truth.Truth``; a ``CellParams`` is robot.json's geometry) with ``options``
    (``TwinOptions``: the profile's joint and laser errors, noise; None: ``TwinOptions()``,
    the ideal world's). ``sample_counts``: the calibration samples (they place the ISO
    cube); ``fit``: the calibration's ``fit.Result``, whose covariance predicts the spread
    (None: no prediction)."""
    from planecal.model.scene import nominal_params
    from planecal.twin import Twin, TwinOptions
    from planecal.twin.laser import LaserNoise
    from planecal.twin.truth import Truth

    options = TwinOptions() if options is None else options
    st = st or ValidationSettings()
    st.check()
    world = world if isinstance(world, Truth) else Truth(world)
    truth = world.params
    robot = scene.robot
    twin = Twin(scene, truth=world, seed=st.seed, options=options)
    mover = Mover(twin, robot, checker)
    flanges = fk(robot, counts_to_joints(robot, sample_counts))[:, :3, 3]
    center, edge = cube_from_flanges(flanges, st.cube_edge_m)
    q_cal = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    R = fk(robot, q_cal)[:3, :3]
    frame = robot_frame(robot, world)
    models = {"nominal": np.zeros(6),
              "calibrated": calibrated.joint_offsets if calibrated.is_level1 else calibrated}
    for attempt in range(6):  # a cube of our own choosing shrinks until all poses are clear
        try:
            iso = iso9283(twin, scene, models, center, edge, R, st, checker, frame, mover)
            break
        except InputError:
            if st.cube_edge_m is not None or attempt == 5:
                raise
            edge *= 0.75
    ap_b, ap_a = iso["models"]["nominal"]["ap_mm"], iso["models"]["calibrated"]["ap_mm"]
    rp = np.maximum(iso["models"]["nominal"]["rp_mm"], iso["models"]["calibrated"]["rp_mm"])
    d_err = calibrated.joint_offsets - truth.joint_offsets
    # what is left: delta1 turns everything about the base axis, delta6 turns a TCP off axis 6
    r_xy = np.hypot(iso["points_m"][:, 0], iso["points_m"][:, 1])
    left = {"offset_error_rad": d_err, "delta1_error_rad": float(d_err[0]),
            "delta6_error_rad": float(d_err[5]),
            "delta1_share_mm": float(abs(d_err[0]) * r_xy.max() * 1e3),
            "delta6_share_mm": float(abs(d_err[5]) * np.hypot(*np.asarray(st.tcp_m)[:2]) * 1e3)}
    out = {
        "ap_before_mm": float(ap_b.max()), "ap_after_mm": float(ap_a.max()),
        "ap_ratio": float(ap_b.max() / ap_a.max()) if ap_a.max() > 0 else float("inf"),
        "ap_before_cell_mm": float(iso["models"]["nominal"]["ap_cell_mm"].max()),
        "ap_after_cell_mm": float(iso["models"]["calibrated"]["ap_cell_mm"].max()),
        "rp_mm": float(rp.max()),
        "rp_before_mm": float(iso["models"]["nominal"]["rp_mm"].max()),
        "rp_after_mm": float(iso["models"]["calibrated"]["rp_mm"].max()),
        "gauge_error_before_mm": None, "gauge_error_after_mm": None,
        "gauge_error_offsets_only_mm": None, "predicted_from_fit": None,
        "iso": iso, "gauge": None, "residual_offset_error": left,
        "settings": {k: getattr(st, k) for k in st.__dataclass_fields__},
    }
    if not st.gauge:
        return out
    nominal = nominal_params(scene)
    mixed = calibrated.copy()
    mixed.joint_offsets = nominal.joint_offsets.copy()
    lin = LaserNoise(scene.laser_range_mm, 0.0, None, None, options.laser_linearity_mm,
                     world.laser_phases).lin
    gb = gauge_block(twin, scene, truth, {"nominal": nominal, "calibrated": calibrated,
                                          "calibrated_sensor_nominal_offsets": mixed}, st,
                     checker, mover=mover, laser_noise_mm=options.laser_noise_mm,
                     linearity=lin)
    if fit is not None:
        out["predicted_from_fit"] = predicted_spread(
            robot, gb["measurements"], calibrated, fit.layout, fit.covariance,
            iso["points_m"], R, np.asarray(st.tcp_m, float), q_cal)
    gb.pop("measurements")
    out.update(gauge=gb, gauge_error_before_mm=gb["models"]["nominal"]["error_mm"],
               gauge_error_after_mm=gb["models"]["calibrated"]["error_mm"],
               gauge_error_offsets_only_mm=gb["models"]["calibrated_sensor_nominal_offsets"]
               ["error_mm"])
    return out


# ----- over truths, and what each error source leaves -----------------------------------------

LEVELS = ("offsets", "full")  # what ``calibrate_run`` fits (planecal.estimation.calibrate)


def calibrate_run(scene, qe: np.ndarray, d: np.ndarray, plate: np.ndarray,
                  level: str = "offsets", compliance: bool = False):
    """The calibration of one rehearsed set (``fit.Result``): from the scene's nominal
    values, at ``level`` (``LEVELS``) as ``planecal calibrate --level`` does (offsets: the
    joint offsets, the sensor pose and the planes; full: the whole kinematic model's
    identifiable base set, the arm's scale kept; ``compliance``: J2/J3's compliance too)."""
    from planecal.estimation.calibrate import calibrate
    from planecal.model.scene import nominal_params
    if level not in LEVELS:
        raise InputError(f"--level: one of {', '.join(LEVELS)}, got {level!r}")
    return calibrate(scene.robot, qe, d, nominal_params(scene), plate, level=level,
                     compliance=compliance).result


def run_jobs(fn, items: list, engine=1, label: str = "validate", quiet: bool = True) -> list:
    """``[fn(item) for item in items]`` on ``engine`` (an open ``studies.distributed.Engine``
    or a job count: ``studies.common.parallel_map``)."""
    from planecal.studies.common import Progress, parallel_map
    items = list(items)
    return parallel_map(fn, items, engine, Progress(label, len(items), quiet=quiet))


@dataclass(frozen=True)
class TruthJob:
    """One truth of ``validate_truth``: the world (scene, error profile, truth seed, the
    error families switched ``off``), the calibration set (rehearsal ``samples`` and
    ``seed``, or a planned pose list ``poses``) and the validation settings."""
    scene: str
    errors: str
    truth_seed: int
    samples: int = 150
    seed: int = 0
    offsets_all: bool = False
    poses: tuple | None = None
    settings: ValidationSettings = field(default_factory=ValidationSettings)
    off: tuple = ()
    level: str = "offsets"
    compliance: bool = False


def validate_truth(job: TruthJob) -> dict:
    """Draw the world, sample a calibration set on its twin, calibrate offsets-only from
    the nominal values, validate on the same world (module docstring). A set the sampling
    run gives up on: ``{"truth_seed", "failed"}``."""
    return truth_run(job)[0]


def truth_run(job: TruthJob) -> tuple[dict, object, tuple | None]:
    """``validate_truth``'s result, the calibration (``fit.Result``, None if the sampling
    gave up) and its samples ``(qe, d_m, plate)``: what a recording of the run draws."""
    from planecal.studies.common import cached_scene, cached_world
    from planecal.studies.montecarlo import (MCSettings, pose_list_samples,
                                             sources_on, twin_samples, without, world_for)

    st = job.settings
    mc = MCSettings(scene=job.scene, samples=len(job.poses) if job.poses else job.samples,
                    seed=job.seed, errors=job.errors, truth_seed=job.truth_seed,
                    offsets_all=job.offsets_all, poses=job.poses, clearance_m=st.clearance_m)
    scene = cached_scene(job.scene)
    world, opts = without(*world_for(mc, 0), job.off)
    try:
        sample = pose_list_samples if job.poses else twin_samples
        qe, d, plate, rejected = sample(scene, world, mc, job.seed, opts)
    except RuntimeError as e:
        return {"truth_seed": job.truth_seed, "off": list(job.off), "failed": str(e)}, None, None
    fit = calibrate_run(scene, qe, d, plate, job.level, job.compliance)
    v = validate(scene, world, fit.params, qe, st, cached_world(job.scene, st.clearance_m), fit,
                 opts)
    v["truth_seed"] = job.truth_seed
    v["level"] = job.level
    v["compliance"] = job.compliance
    v["off"] = list(job.off)
    v["sources"] = sources_on(scene.robot, world, opts)
    v["calibration"] = {"samples": len(d), "rejected": rejected, "fit_rms_mm": fit.rms_mm(),
                        "max_model_error_mm": float(np.abs(fit.residuals_m).max() * 1e3),
                        "converged": bool(fit.converged),
                        "offsets_std_rad": fit.std[fit.layout.slice("joint_offsets")]}
    v["truth_offsets_rad"] = world.params.joint_offsets
    v["calibrated_offsets_rad"] = fit.params.joint_offsets
    return v, fit, (qe, d, plate)


TRUTH_KEYS = ("truth_seed", "ap_before_mm", "ap_after_mm", "ap_before_cell_mm",
              "ap_after_cell_mm", "rp_mm", "rp_before_mm", "rp_after_mm",
              "gauge_error_before_mm", "gauge_error_after_mm")


def truth_row(v: dict) -> dict:
    """The per-truth entry of a validation over truths (``truths`` in its JSON)."""
    row = {k: v.get(k) for k in TRUTH_KEYS}
    cal = v.get("calibration") or {}
    row["max_model_error_mm"] = cal.get("max_model_error_mm")
    row["samples"] = cal.get("samples")
    row["offset_error_rad"] = (v.get("residual_offset_error") or {}).get("offset_error_rad")
    return row


def summarize(results: list[dict]) -> tuple[dict, dict, dict]:
    """(summary, the median truth's result, the worst truth's): median and worst over the
    truths of each figure (the worst truth: the largest AP after calibration; the median
    truth: the one whose AP after is the median, the lower one of an even count)."""
    ok = [v for v in results if "failed" not in v]
    if not ok:
        raise InputError("no truth could be validated: "
                         + "; ".join(f"truth {v['truth_seed']}: {v['failed']}" for v in results))
    after = np.array([v["ap_after_mm"] for v in ok])
    order = np.argsort(after, kind="stable")
    med = ok[int(order[(len(ok) - 1) // 2])]
    worst = ok[int(order[-1])]

    def stat(key, f):
        vals = [v[key] for v in ok if v.get(key) is not None]
        return float(f(vals)) if vals else None
    out = {"truths": [truth_row(v) for v in results if "failed" not in v],
           "failed_truths": [{"truth_seed": v["truth_seed"], "reason": v["failed"]}
                             for v in results if "failed" in v],
           "median_truth_seed": med["truth_seed"], "worst_truth_seed": worst["truth_seed"]}
    for key in ("ap_before_mm", "ap_after_mm", "ap_before_cell_mm", "ap_after_cell_mm", "rp_mm",
                "rp_before_mm", "rp_after_mm"):
        base = key[:-3]
        out[f"{base}_median_mm"] = stat(key, np.median)
        out[f"{base}_worst_mm"] = stat(key, np.max)
    for key in ("gauge_error_before_mm", "gauge_error_after_mm"):
        base = key[:-3]
        out[f"{base}_median_mm"] = stat(key, np.median)
        out[f"{base}_worst_mm"] = stat(key, lambda x: max(x, key=abs))
    return out, med, worst


def breakdown_variants(sources: list[str], mode: str = "alone") -> list[tuple[str, tuple]]:
    """(label, families switched off): 'off' each family switched off in turn, 'alone'
    each family alone; both with all sources and none of them."""
    if mode not in ("off", "alone"):
        raise InputError(f"--breakdown: 'off', 'alone' or 'none', got {mode!r}")
    rows = [("all sources", ())]
    if mode == "off":
        rows += [(f"without {f}", (f,)) for f in sources]
    else:
        rows += [(f"{f} alone", tuple(g for g in sources if g != f)) for f in sources]
    rows.append(("none (cell only)", tuple(sources)))
    return rows


def breakdown(job: TruthJob, mode: str = "alone", engine=1, quiet: bool = True) -> dict:
    """``job``'s truth repeated with each error family switched off (``mode`` 'off') or on
    alone ('alone'), the gauge block skipped: AP after calibration per variant (the same
    rehearsal seed: the same pose draws)."""
    from dataclasses import replace

    from planecal.studies.common import cached_scene
    from planecal.studies.montecarlo import MCSettings, sources_on, world_for
    mc = MCSettings(scene=job.scene, errors=job.errors, truth_seed=job.truth_seed,
                    offsets_all=job.offsets_all)
    on = sources_on(cached_scene(job.scene).robot, *world_for(mc, 0))
    variants = breakdown_variants(on, mode)
    st = replace(job.settings, gauge=False)
    res = run_jobs(validate_truth, [replace(job, off=off, settings=st)
                                    for _, off in variants], engine, "breakdown", quiet)
    rows = []
    for (label, off), v in zip(variants, res):
        row = {"variant": label, "off": list(off)}
        if "failed" in v:
            row["failed"] = v["failed"]
        else:
            row.update({k: v[k] for k in ("ap_before_mm", "ap_after_mm", "ap_after_cell_mm",
                                          "rp_mm")})
            row["max_model_error_mm"] = v["calibration"]["max_model_error_mm"]
        rows.append(row)
    return {"truth_seed": job.truth_seed, "mode": mode, "sources": on, "variants": rows}


def cannot_remove(bd: dict) -> list[dict]:
    """From a breakdown: per error family, what it leaves in AP after calibration (with
    all on minus with it off; or, alone, with it alone minus with none), largest first."""
    rows = {r["variant"]: r for r in bd["variants"] if "failed" not in r}
    allr, none = rows.get("all sources"), rows.get("none (cell only)")
    out = []
    for f in bd["sources"]:
        if bd["mode"] == "off":
            r = rows.get(f"without {f}")
            if r is None or allr is None:
                continue
            share = allr["ap_after_mm"] - r["ap_after_mm"]
        else:
            r = rows.get(f"{f} alone")
            if r is None or none is None:
                continue
            share = r["ap_after_mm"] - none["ap_after_mm"]
        out.append({"source": f, "what": SOURCES[f], "ap_after_share_mm": float(share),
                    "ap_after_variant_mm": r["ap_after_mm"]})
    return sorted(out, key=lambda x: -x["ap_after_share_mm"])


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
           f"(x{v['ap_ratio']:.1f} smaller); RP {v['rp_mm']:.4f} mm (the robot's frame)",
           f"in the cell frame (with the robot's placement and delta1, which no plane "
           f"calibration sees): AP before {v['ap_before_cell_mm']:.4f} mm, after "
           f"{v['ap_after_cell_mm']:.4f} mm", ""]
    g = v["gauge"]
    if g is not None:
        rows = [[name, f"{m['error_mm']:+.4f}", f"{m['error_std_mm']:.4f}",
                 f"{m['max_abs_error_mm']:.4f}"] for name, m in g["models"].items()]
        out.append(f"gauge block {g['length_m'] * 1e3:.0f} mm, 4 points per face, "
                   f"{g['repeats']} repeats (largest incidence {g['max_incidence_deg']:.0f} deg)")
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
                   f"to {r['delta1_share_mm']:.3f} mm at these poses in the cell frame (none in "
                   f"the robot's frame, which J1's zero defines); delta6 (a roll of the sensor) "
                   f"leaves {r['delta6_share_mm']:.3f} mm at the TCP. Neither changes a distance "
                   f"the laser measures, so the gauge length does not see them.")
    return "\n".join(out)


def _mm(x, fmt=".3f"):
    return "-" if x is None else format(x, fmt)


def format_truths(summary: dict, world: str) -> str:
    """The per-truth table, the median and the worst truth."""
    rows = [[str(t["truth_seed"]), _mm(t["ap_before_mm"], ".2f"), _mm(t["ap_after_mm"]),
             _mm(t["ap_after_cell_mm"]), _mm(t["rp_mm"]), _mm(t["gauge_error_before_mm"], "+.3f"),
             _mm(t["gauge_error_after_mm"], "+.3f"), _mm(t["max_model_error_mm"])]
            for t in summary["truths"]]
    out = [f"ISO 9283 and gauge block on the twin, {world} world, {len(rows)} truth(s); "
           "offsets-only calibration from the nominal values; AP in the robot's frame "
           "(cell: in the cell frame)",
           table(["truth", "AP before", "AP after", "AP after cell", "RP", "gauge before",
                  "gauge after", "max model err"], rows),
           "(mm; AP, RP: worst of P1..P5; max model err: the fit's largest |residual|, seed "
           "Table 9's figure)", ""]
    by_seed = {t["truth_seed"]: t for t in summary["truths"]}
    for what, key in (("median", "median_truth_seed"), ("worst", "worst_truth_seed")):
        t = by_seed[summary[key]]
        out.append(f"{what} truth (seed {t['truth_seed']}): AP {t['ap_before_mm']:.2f} -> "
                   f"{t['ap_after_mm']:.3f} mm (cell frame {t['ap_before_cell_mm']:.2f} -> "
                   f"{t['ap_after_cell_mm']:.3f}), RP {t['rp_before_mm']:.3f} -> "
                   f"{t['rp_after_mm']:.3f} mm, gauge block "
                   f"{_mm(t['gauge_error_before_mm'], '+.3f')} -> "
                   f"{_mm(t['gauge_error_after_mm'], '+.3f')} mm")
    out.append(f"over the truths: AP after median {summary['ap_after_median_mm']:.3f} mm, "
               f"worst {summary['ap_after_worst_mm']:.3f} mm; in the cell frame median "
               f"{summary['ap_after_cell_median_mm']:.3f}, worst "
               f"{summary['ap_after_cell_worst_mm']:.3f} mm")
    for f in summary["failed_truths"]:
        out.append(f"truth {f['truth_seed']} left out: {f['reason']}")
    return "\n".join(out)


def format_breakdown(bd: dict) -> str:
    """What each error source leaves after calibration (``breakdown``), and the sources
    the calibration cannot remove."""
    rows = []
    for r in bd["variants"]:
        if "failed" in r:
            rows.append([r["variant"], "failed", "", "", ""])
            continue
        rows.append([r["variant"], f"{r['ap_before_mm']:.2f}", f"{r['ap_after_mm']:.3f}",
                     f"{r['ap_after_cell_mm']:.3f}", f"{r['max_model_error_mm']:.3f}"])
    how = "switched off in turn" if bd["mode"] == "off" else "each alone"
    out = [f"what each error source leaves (truth {bd['truth_seed']}, the same poses; sources "
           f"{how}; no gauge block)",
           table(["world", "AP before", "AP after", "AP after cell", "max model err"], rows),
           "(mm)"]
    cr = cannot_remove(bd)
    noise = [c for c in cr if c["source"] == "noise"]
    cr = [c for c in cr if c["source"] != "noise"]
    big = [c for c in cr if c["ap_after_share_mm"] >= 0.005]
    if big:
        what = ("AP after calibration drops by" if bd["mode"] == "off"
                else "alone it adds")
        out.append("an offsets-only calibration cannot remove: " + "; ".join(
            f"{c['what']} ({what} {c['ap_after_share_mm']:.3f} mm)" for c in big)
            + ". None of them is in the fit's model; the offsets absorb only the part that "
              "looks like a joint zero in the calibrated region.")
    small = [c for c in cr if c["ap_after_share_mm"] < 0.005]
    if small:
        out.append("less than 5 um of AP here (a negative share: without it AP is larger, "
                   "the sources partly cancel in the fit): " + ", ".join(
                       f"{c['source']} {c['ap_after_share_mm'] * 1e3:+.0f} um" for c in small))
    for c in noise:
        out.append(f"the noise ({c['what']}) is the floor no calibration removes: alone it "
                   f"adds {c['ap_after_share_mm'] * 1e3:.0f} um of AP (and sets RP)")
    return "\n".join(out)
