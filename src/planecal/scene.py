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

from planecal.cell import CellParams, point_normal_from_n_tilde
from planecal.errors import InputError
from planecal.params import load_json
from planecal.paths import data_path
from planecal.robot import Robot, load_robot

DEFAULT_SCENE = "thesis_final"


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


def scene_path(name_or_path: str | Path = DEFAULT_SCENE) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".json" or p.exists():
        return p
    return data_path("scenes") / f"{name_or_path}.json"


def _vec(path, obj, key, n, default=None):
    v = obj.get(key, default)
    try:
        a = np.asarray(v, float)
    except (TypeError, ValueError):
        raise InputError(f"{path}: '{key}' must be {n} numbers") from None
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise InputError(f"{path}: '{key}' must be {n} finite numbers, got {v!r}")
    return a


def load_scene(name_or_path: str | Path = DEFAULT_SCENE) -> Scene:
    path = scene_path(name_or_path)
    raw = load_json(path)
    try:
        robot = load_robot(raw.get("robot", "mc70"))
        s = raw["sensor"]
        plates = []
        for i, p in enumerate(raw["plates"]):
            where = f"{path}: plates[{i}]"
            n_tilde = _vec(where, p, "n_tilde", 3)
            plates.append(Plate(
                name=p.get("name", f"plate{i + 1}"), n_tilde=n_tilde,
                corner=_vec(where, p, "corner_m", 3), x_hint=_vec(where, p, "x_axis", 3, [1, 0, 0]),
                size=_vec(where, p, "size_m", 2), thickness=float(p.get("thickness_m", 0.01)),
                face=int(p.get("face", 1)), stand=bool(p.get("stand", True))))
            if plates[-1].face not in (1, -1):
                raise InputError(f"{where}: 'face' must be +1 or -1")
        if not plates:
            raise InputError(f"{path}: a scene needs at least one plate")
        obstacles = [Box(o.get("name", f"obstacle{i + 1}"), _vec(path, o, "center_m", 3),
                         _vec(path, o, "size_m", 3), _vec(path, o, "rpy_rad", 3, [0, 0, 0]))
                     for i, o in enumerate(raw.get("obstacles", []))]
        pos = raw.get("positions", {})
        samp = raw.get("sampling", {})
        cal = pos.get("calibration_deg")
        scene = Scene(
            name=raw.get("name", path.stem), path=path, description=raw.get("description", ""),
            robot=robot, sensor_origin=_vec(path, s, "origin_m", 3),
            phi_y=float(s["phi_y_rad"]), phi_z=float(s["phi_z_rad"]),
            laser_range_mm=tuple(s.get("range_mm", [65.0, 95.0])),
            plates=plates, obstacles=obstacles, floor_z=float(raw.get("floor_z_m", 0.0)),
            home_counts=np.asarray(pos.get("home_counts", robot.home_counts), np.int64),
            calibration_q=None if cal is None else np.deg2rad(_vec(path, pos, "calibration_deg", 6)),
            cone_deg=float(samp.get("cone_deg", 30.0)),
            distance_mm=tuple(samp.get("distance_mm", [70.0, 90.0])),
        )
    except KeyError as e:
        raise InputError(f"{path}: missing key {e}") from None
    except (TypeError, ValueError) as e:
        raise InputError(f"{path}: {e}") from None
    return scene


def nominal_params(scene: Scene) -> CellParams:
    """The scene's nominal parameters: zero offsets, the measured sensor pose and planes."""
    return CellParams(np.zeros(6), scene.sensor_origin, scene.phi_y, scene.phi_z,
                      np.array([p.n_tilde for p in scene.plates]))
