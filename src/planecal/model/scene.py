"""Scenes: one JSON file per cell under scenes/ (robot, sensor, plates, obstacles).

A scene holds *nominal* values (what the cell engineer measured). The twin draws its
hidden truth around them; calibration starts from them (``nominal_params``).

Plate geometry: the measured face lies in the plane n~ . p = 1. ``corner_m`` is projected
onto that plane; the plate spans ``size_m`` along its in-plane x axis (``x_axis`` projected
onto the plane) and y = facing x x. ``face`` (+1 or -1) says whether the measured side
looks along +n~ or -n~ (the side the sensor is on); the plate's body (``thickness_m``)
lies behind the face. A stand, if any, is a box from the floor to the plate's lowest point.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.planes import point_normal_from_n_tilde
from planecal.base.errors import InputError
from planecal.formats.base import read_json, validate
from planecal.formats.scene import RobotBounds, SceneFile
from planecal.base.paths import DEFAULT_SCENE, scene_path  # noqa: F401 (also named here)
from planecal.model.kinematics import reach_m
from planecal.model.robot import DEFAULT_ROBOT, Robot, load_robot


@dataclass
class Plate:
    name: str
    n_tilde: np.ndarray
    corner: np.ndarray
    x_hint: np.ndarray
    size: np.ndarray  # (2,) m
    thickness: float
    face: int = 1
    stand: bool = True

    def frame(self, n_tilde: np.ndarray | None = None) -> np.ndarray:
        """Plate frame (4x4) in the base frame: origin at the corner on the measured face,
        z the facing normal, x and y along the plate's edges. With ``n_tilde`` the plate
        is placed on that plane instead (the twin's hidden truth)."""
        n_tilde = self.n_tilde if n_tilde is None else np.asarray(n_tilde, float)
        _, nhat = point_normal_from_n_tilde(n_tilde)
        z = self.face * nhat
        corner = self.corner - (n_tilde @ self.corner - 1.0) / (n_tilde @ nhat) * nhat
        x = self.x_hint - (self.x_hint @ z) * z
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        T = np.eye(4)
        T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, corner
        return T

    def center(self, n_tilde: np.ndarray | None = None) -> np.ndarray:
        T = self.frame(n_tilde)
        return T[:3, 3] + T[:3, :2] @ (self.size / 2)


@dataclass
class Box:
    name: str
    center: np.ndarray
    size: np.ndarray  # full extents (3,) m
    rpy: np.ndarray  # (3,) rad, R = Rz(yaw) Ry(pitch) Rx(roll)


@dataclass(frozen=True)
class LengthReference:
    """A known length in the cell (issue 22): plate ``plates[1]`` parallel to plate
    ``plates[0]`` (0-based), ``separation_m`` further from the base origin along its normal
    (negative: nearer; a stepped artefact, measured), with the measurement's std and the
    faces' parallelism std. The fit takes it as prior rows (``planes.parallel_rows``), and
    the arm's scale, which a laser on planes cannot see otherwise, is then free."""
    plates: tuple[int, int]
    separation_m: float
    std_m: float
    parallel_std_rad: float
    source: str = ""


@dataclass(frozen=True)
class NamedTcp:
    """A TCP a scene names (``tools``): its position in the flange frame [m]."""
    name: str
    tcp: np.ndarray  # (3,)


@dataclass
class Scene:
    name: str
    path: Path
    description: str
    robot: Robot
    sensor_origin: np.ndarray
    phi_y: float
    phi_z: float
    laser_range_mm: tuple[float, float]
    plates: list[Plate]
    obstacles: list[Box] = field(default_factory=list)
    floor_z: float = 0.0
    home_counts: np.ndarray | None = None
    calibration_q: np.ndarray | None = None  # rad, a configuration near the plates
    cone_deg: float = 30.0
    distance_mm: tuple[float, float] = (70.0, 90.0)
    references: tuple[LengthReference, ...] = ()
    tools: list[NamedTcp] = field(default_factory=list)
    allowed_pairs: tuple[tuple[str, str], ...] = ()  # (tool piece, arm piece): not checked

    @property
    def standoff_m(self) -> float:
        """The laser's measuring centre [m]: the middle of its window (``sensor.range_mm``;
        80 mm for the ZS-LD80's 65-95 mm, the distance its serial field counts from). The
        tool point is the beam point there (``measurement.beam_point``)."""
        return 0.5e-3 * (self.laser_range_mm[0] + self.laser_range_mm[1])


def load_scene(name_or_path: str | Path = DEFAULT_SCENE) -> Scene:
    """A scene by name (scenes/<name>.json) or path, validated by
    ``planecal.formats.scene.SceneFile`` against its robot (home counts within the
    encoder's bits, plates within reach); one-line InputError otherwise."""
    path = scene_path(name_or_path)
    raw = read_json(path, "scene")
    robot = bounds = None
    ref = raw.get("robot", DEFAULT_ROBOT) if isinstance(raw, dict) else None
    if isinstance(ref, str) and ref:  # otherwise validation names the problem
        try:
            robot = load_robot(ref, relative_to=path.parent)
        except InputError as e:
            raise InputError(f"{path}: robot: {e}") from None
        bounds = RobotBounds(robot.name, reach_m(robot.kinematics), robot.encoder_bits)
    sf = validate(SceneFile, raw, path, "scene", {"robot": bounds})
    plates = [Plate(name=p.name or f"plate{i + 1}", n_tilde=np.array(p.n_tilde),
                    corner=np.array(p.corner_m), x_hint=np.array(p.x_axis),
                    size=np.array(p.size_m), thickness=p.thickness_m, face=p.face,
                    stand=p.stand)
              for i, p in enumerate(sf.plates)]
    obstacles = [Box(o.name or f"obstacle{i + 1}", np.array(o.center_m), np.array(o.size_m),
                     np.array(o.rpy_rad)) for i, o in enumerate(sf.obstacles)]
    pos, s = sf.positions, sf.sensor
    home = robot.home_counts if pos.home_counts is None else pos.home_counts
    return Scene(
        name=sf.name or path.stem, path=path, description=sf.description, robot=robot,
        sensor_origin=np.array(s.origin_m), phi_y=s.phi_y_rad, phi_z=s.phi_z_rad,
        laser_range_mm=tuple(s.range_mm), plates=plates, obstacles=obstacles,
        floor_z=sf.floor_z_m, home_counts=np.asarray(home, np.int64),
        calibration_q=(None if pos.calibration_deg is None
                       else np.deg2rad(np.array(pos.calibration_deg))),
        cone_deg=sf.sampling.cone_deg, distance_mm=tuple(sf.sampling.distance_mm),
        references=tuple(_reference(path, i, r, plates) for i, r in enumerate(sf.references)),
        tools=[NamedTcp(t.name, np.array(t.tcp_m, float)) for t in sf.tools],
        allowed_pairs=tuple(tuple(p.pieces) for p in sf.allowed_pairs),
    )


# a reference's nominal planes agree with it within these (a scene's drawing)
REFERENCE_TILT_RAD = 1e-3
REFERENCE_GAP_M = 0.001


def _reference(path: Path, i: int, r, plates: list[Plate]) -> LengthReference:
    """A scene file's reference, its plates' nominal planes checked against it: parallel
    and as far apart as it says, within a drawing's rounding."""
    from planecal.model.planes import parallel_rows
    ia, ib = r.plate_indices([p for p in plates])
    g, _, _ = parallel_rows(plates[ia].n_tilde, plates[ib].n_tilde, r.separation_m)
    where = f"{path}: references.{i}"
    if abs(r.separation_m) < REFERENCE_GAP_M:
        raise InputError(f"{where}.separation_m: {r.separation_m:g} m: two faces of a stepped "
                         "block are more than a millimetre apart")
    if np.linalg.norm(g[:3]) > REFERENCE_TILT_RAD:
        raise InputError(f"{where}: {r.plates[0]} and {r.plates[1]} are "
                         f"{np.linalg.norm(g[:3]):.3g} rad from parallel: not one stepped "
                         "artefact")
    if abs(g[3]) > REFERENCE_GAP_M:
        raise InputError(f"{where}.separation_m: the plates' n~ put them "
                         f"{g[3] + r.separation_m:.6g} m apart, not {r.separation_m:g} m")
    return LengthReference((ia, ib), r.separation_m, r.std_m, r.parallel_std_rad,
                           r.source or "")


def nominal_params(scene: Scene) -> CellParams:
    """The scene's nominal parameters: zero offsets, the measured sensor pose and planes,
    and the laser's measuring range (what its linearity error is a function of)."""
    return CellParams(np.zeros(6), scene.sensor_origin, scene.phi_y, scene.phi_z,
                      np.array([p.n_tilde for p in scene.plates]),
                      laser_range_m=tuple(v * 1e-3 for v in scene.laser_range_mm))
