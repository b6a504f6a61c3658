"""Random sensor poses on the calibration plate(s) and their joint targets (seed 7.1.2).

A pose is drawn in the plate's frame (``Plate.frame()``: origin at a corner on the measured
face, x and y along the edges, z the facing normal, pointing to the side the sensor is on):

- the laser spot p: uniform over the plate shrunk by ``margin_m`` on every edge;
- the beam b (the sensor's +z, pointing from the sensor towards the plate): uniform over the
  *solid angle* of a cone of half-angle ``cone_deg`` about -z (the plate's inward normal):
  cos(theta) ~ U[cos(cone), 1], azimuth ~ U[0, 2 pi). (The seed adds +-30 deg independently
  to roll, pitch and yaw; that spreads unevenly over the cone, and its cone is 60 deg wide,
  i.e. a 30 deg half-angle, the default here.)
- the distance d along the beam: U[lo, hi] mm (the scene's ``sampling.distance_mm``) or a
  fixed value; the sensor origin is o = p - d b, so the beam hits p after d;
- a rotation psi about the beam: U[-roll, +roll] (``roll_deg``, default 180: any roll)
  measured from the plate's x edge projected normal to the beam.

The sensor pose T_base_sensor = [x y b o] is turned into a flange pose with the model's
flange->sensor transform (``cell.sensor_rotation(phi_y, phi_z)``, sensor origin):
T_base_flange = T_base_sensor inv(T_flange_sensor). Only the beam of the sensor frame
matters to the distance model; the sensor's own x axis is arbitrary but fixed.

The model the loop aims with (``CommandModel``) is the scene's nominal cell and robot.json's
encoder zeros for a first calibration run; after a calibration (live validation, seed 8.2
and 8.4) it is the result: its sensor pose, its planes (the plates' frames) and its joint
offsets (in the IK, or loaded into the encoder zeros as the controller would hold them).

The joint target is an IK solution within the joint limits, with the nominal (zero) joint
offsets, chosen by ``ik_choice``:

- ``wrist`` (default; seed 7.1.2: "try to achieve maximum joint change between the random
  poses, in order to get good identifiability"): the wrist branch (the sign of q5, which
  turns the wrist over) changes at random, with probability ``WRIST_SWITCH`` per pose,
  then the solution of that branch nearest to the current configuration; the other branch
  when the chosen one has no solution. A run so spends about half its samples in each
  branch, turning the wrist over some 15 times in 150 samples (each a detour: the switch
  probability trades identifiability for robot time). Without it the nearest solution
  keeps the wrist in one branch for a whole run, and delta5, which the wrist branch is the
  lever of, is determined 5-10x worse (docs/STUDIES.md).
- ``nearest``: the solution nearest to the current configuration.

Nearest means the fewest 10 ms ticks: the largest number of encoder counts any joint must
travel (weights = |gains|).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.measurement import sensor_rotation
from planecal.model.encoder import counts_in_range, counts_to_joints, joints_to_counts
from planecal.base.errors import InputError
from planecal.formats.run import IK_CHOICES, PLATE_CHOICES  # the sidecar's allowed values
from planecal.model.ik import ik_all
from planecal.model.scene import Scene



WRIST_SWITCH = 0.1  # chance per pose that the wrist branch changes (ik_choice wrist)


@dataclass
class PoseSettings:
    cone_deg: float = 30.0
    distance_mm: tuple[float, float] = (70.0, 90.0)
    fixed_distance_mm: float | None = None
    margin_m: float = 0.025
    roll_deg: float = 180.0
    plate_choice: str = "round_robin"
    ik_choice: str = "wrist"

    def check(self, scene: Scene) -> None:
        """Raise InputError for settings the scene cannot use."""
        if not 0.0 <= self.cone_deg < 90.0:
            raise InputError(f"cone half-angle must be in [0, 90) deg, got {self.cone_deg}")
        if not 0.0 <= self.roll_deg <= 180.0:
            raise InputError(f"roll range must be in [0, 180] deg, got {self.roll_deg}")
        lo_r, hi_r = scene.laser_range_mm
        if self.fixed_distance_mm is not None:
            if not lo_r <= self.fixed_distance_mm <= hi_r:
                raise InputError(f"fixed distance {self.fixed_distance_mm} mm is outside the "
                                 f"laser range {lo_r}-{hi_r} mm")
        else:
            lo, hi = self.distance_mm
            if not (lo_r <= lo <= hi <= hi_r):
                raise InputError(f"distance range {lo}-{hi} mm is not within the laser range "
                                 f"{lo_r}-{hi_r} mm")
        if self.ik_choice not in IK_CHOICES:
            raise InputError(f"IK choice must be one of {', '.join(IK_CHOICES)}, "
                             f"got {self.ik_choice!r}")
        if self.plate_choice not in PLATE_CHOICES:
            raise InputError(f"plate choice must be one of {', '.join(PLATE_CHOICES)}, "
                             f"got {self.plate_choice!r}")
        for i, plate in enumerate(scene.plates):
            if np.any(plate.size <= 2 * self.margin_m):
                raise InputError(f"plate {i + 1} ({plate.name}) is smaller than twice the "
                                 f"margin {self.margin_m * 1e3:.0f} mm")


@dataclass(frozen=True)
class CommandModel:
    """What the loop aims with (module docstring): the cell's parameters (sensor pose,
    planes, joint offsets) and the encoder zeros that turn joint angles into counts."""
    params: CellParams
    qe0: np.ndarray

    @classmethod
    def nominal(cls, scene: Scene) -> "CommandModel":
        from planecal.model.scene import nominal_params
        return cls(nominal_params(scene), scene.robot.qe0.copy())


@dataclass
class SensorPose:
    plate: int  # 0-based plate index
    point: np.ndarray  # (3,) laser spot on the nominal plane, base frame [m]
    beam: np.ndarray  # (3,) unit beam direction, base frame
    distance_m: float
    T_sensor: np.ndarray  # (4,4) base <- sensor
    T_flange: np.ndarray  # (4,4) base <- flange (nominal sensor mounting)
    theta: float  # beam angle from the plate's inward normal [rad]


class PoseGenerator:
    """Draws random sensor poses on a scene's plates; see the module docstring."""

    def __init__(self, scene: Scene, settings: PoseSettings | None = None,
                 model: CommandModel | None = None):
        self.scene = scene
        self.robot = scene.robot
        self.settings = settings or PoseSettings(cone_deg=scene.cone_deg,
                                                 distance_mm=tuple(scene.distance_mm))
        self.settings.check(scene)
        self.model = model = model or CommandModel.nominal(scene)
        p = model.params
        if p.n_planes != len(scene.plates):
            raise InputError(f"the commanding model has {p.n_planes} plane(s), the scene "
                             f"{len(scene.plates)} plate(s)")
        self.frames = [pl.frame(n) for pl, n in zip(scene.plates, p.planes)]
        T_fs = np.eye(4)
        T_fs[:3, :3] = sensor_rotation(p.phi_y, p.phi_z)
        T_fs[:3, 3] = p.sensor_origin
        self.T_sf = np.linalg.inv(T_fs)  # sensor <- flange
        self.delta = p.joint_offsets.copy()
        self.weights = np.abs(self.robot.gains)

    @property
    def n_plates(self) -> int:
        return len(self.frames)

    def plate_for(self, index: int, rng: np.random.Generator) -> int:
        """Plate for sample ``index``: round robin over the plates, or uniformly random."""
        if self.n_plates == 1:
            return 0
        if self.settings.plate_choice == "random":
            return int(rng.integers(self.n_plates))
        return index % self.n_plates

    def draw(self, rng: np.random.Generator, plate: int = 0,
             shift_m: float = 0.0) -> SensorPose:
        """A random pose on ``plate`` (module docstring), placed ``shift_m`` nearer the
        plate than the drawn distance: where the laser reads that much beyond the
        commanding model there, it reads the drawn distance (``sampling.aim``). A fixed
        distance is not shifted: it is what the run measures the cell's error at (live
        validation, seed 8.2)."""
        s = self.settings
        F = self.frames[plate]
        size = self.scene.plates[plate].size
        u = rng.uniform(s.margin_m, size[0] - s.margin_m)
        v = rng.uniform(s.margin_m, size[1] - s.margin_m)
        cos_t = rng.uniform(np.cos(np.deg2rad(s.cone_deg)), 1.0)
        az = rng.uniform(0.0, 2 * np.pi)
        psi = rng.uniform(-np.deg2rad(s.roll_deg), np.deg2rad(s.roll_deg))
        if s.fixed_distance_mm is not None:
            d = s.fixed_distance_mm * 1e-3
        else:
            d = rng.uniform(*s.distance_mm) * 1e-3 - shift_m
        x_p, y_p, z_p, c = F[:3, 0], F[:3, 1], F[:3, 2], F[:3, 3]
        sin_t = np.sqrt(max(0.0, 1.0 - cos_t * cos_t))
        beam = -cos_t * z_p + sin_t * (np.cos(az) * x_p + np.sin(az) * y_p)
        point = c + u * x_p + v * y_p
        x0 = x_p - (x_p @ beam) * beam
        x0 /= np.linalg.norm(x0)
        y0 = np.cross(beam, x0)
        T = np.eye(4)
        T[:3, 0] = np.cos(psi) * x0 + np.sin(psi) * y0
        T[:3, 1] = np.cross(beam, T[:3, 0])
        T[:3, 2] = beam
        T[:3, 3] = point - d * beam
        return SensorPose(plate, point, beam, d, T, T @ self.T_sf, float(np.arccos(min(cos_t, 1.0))))

    def joint_target(self, pose: SensorPose, q_near: np.ndarray,
                     rng: np.random.Generator | None = None):
        """Joint angles (6,) reaching ``pose`` within the limits (``ik_choice``, module
        docstring; ``wrist`` draws the branch from ``rng``; without one, the nearest), or
        None when unreachable."""
        Q = ik_all(self.robot, pose.T_flange, self.delta)
        if len(Q) == 0:
            return None
        if self.settings.ik_choice == "wrist" and rng is not None:
            up = (q_near[4] >= 0) != (rng.uniform() < WRIST_SWITCH)
            branch = (Q[:, 4] >= 0) == up
            if branch.any():
                Q = Q[branch]
        cost = np.max(np.abs(Q - q_near) * self.weights, axis=1)
        return Q[np.argmin(cost)]

    def branch_targets(self, pose: SensorPose, q_near: np.ndarray) -> list[np.ndarray]:
        """For each wrist branch (q5 >= 0, q5 < 0) the solution reaching ``pose`` nearest
        to ``q_near``: the candidates a pose offers a planner that chooses among them."""
        Q = ik_all(self.robot, pose.T_flange, self.delta)
        out = []
        for up in (True, False):
            B = Q[(Q[:, 4] >= 0) == up]
            if len(B):
                out.append(B[np.argmin(np.max(np.abs(B - q_near) * self.weights, axis=1))])
        return out

    def counts_target(self, q: np.ndarray) -> np.ndarray:
        """The encoder counts of joint angles q, with the model's encoder zeros."""
        return joints_to_counts(self.robot, q, self.model.qe0)


def aim_counts(scene: Scene, counts: np.ndarray, plates: np.ndarray,
               source: CommandModel | None, target: CommandModel):
    """A pose list made with ``source``'s cell (None: the nominal one) aimed with
    ``target``'s (an earlier calibration of the cell): each pose's sensor placed where
    ``target`` puts the same sensor pose relative to the same plate (the spot on the
    plate, the beam's incidence and the distance as the list was made), its joints the IK
    solution nearest to the listed ones (their wrist branch), its counts with ``target``'s
    encoder zeros. Returns (counts (n, 6) int64, aimed (n,) bool): a pose ``target``
    cannot reach within the limits keeps its listed counts (aimed False)."""
    from planecal.model.kinematics import fk
    src = PoseGenerator(scene, model=source)
    dst = PoseGenerator(scene, model=target)
    counts = np.asarray(counts, np.int64).reshape(-1, 6)
    plates = np.asarray(plates, int).reshape(-1)
    out, ok = counts.copy(), np.zeros(len(counts), bool)
    q_src = counts_to_joints(scene.robot, counts, src.model.qe0)
    T_fs = np.linalg.inv(src.T_sf)  # flange <- sensor, as the list was made
    kin = scene.robot.kinematics.with_offsets(src.delta)
    for i, (q, k) in enumerate(zip(q_src, plates)):
        T_s = fk(kin, q) @ T_fs
        rel = np.linalg.inv(src.frames[k]) @ T_s  # the sensor in its plate's frame
        T_f = dst.frames[k] @ rel @ dst.T_sf
        Q = ik_all(scene.robot, T_f, dst.delta)
        if len(Q) == 0:
            continue
        Q = Q[(Q[:, 4] >= 0) == (q[4] >= 0)] if np.any((Q[:, 4] >= 0) == (q[4] >= 0)) else Q
        best = Q[np.argmin(np.max(np.abs(Q - q) * dst.weights, axis=1))]
        c = dst.counts_target(best)
        if counts_in_range(scene.robot, c):
            out[i], ok[i] = c, True
    return out, ok
