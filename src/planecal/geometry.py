"""Link, tool and cell shapes: one source for the MuJoCo twin, the FCL checker and Rerun.

Conventions
-----------
* Metres, watertight ``trimesh.Trimesh`` objects.
* ``LinkMesh.body`` is the index of the DH frame the mesh is rigidly attached to
  (0 = base, i = frame after joint i, 6 = flange; the flange adapter and laser head are
  attached to frame 6). ``mesh.vertices`` are already expressed in that DH frame:
  ``T_body_mesh`` is always the identity here (kept for the contract).
* ``StaticMesh.mesh`` vertices are in the robot base frame.
* When a shape is exactly a box, ``box_extents`` (full extents, m) and ``box_pose``
  (4x4 pose of the box centre in the body / base frame) say so, so that MuJoCo and FCL
  can use an exact box primitive (ray vs box is exact; vs a float32 mesh only ~1e-10 m).

Robot envelope (``kind="collision"``)
-------------------------------------
Each link is one or two convex pieces (``name`` unique), the convex hull of a few cylinders placed from
the DH dimensions of the MC70 (base column to 0.6 m, shoulder offset 0.15 m, upper arm
0.9 m, elbow 0.15 m, forearm 0.99 m, wrist to flange 0.175 m). The collision pieces use
polygons circumscribed about the nominal radius plus ``COLLISION_MARGIN`` and cylinder
ends pushed out by the same margin, so they contain the nominal envelope: conservative.
``kind="visual"`` uses finer, slightly smaller (inscribed, 0.92 r) shapes that lie
inside the collision shapes.

Tool (flange adapter + ZS-LD80 head)
------------------------------------
The head is a box ``HEAD_EXTENTS`` = 30 x 20 x 60 mm (x, y, z of the sensor frame); the
beam leaves the centre of its z = 0 face at the sensor origin ``o`` and runs along the
sensor z axis (``cell.sensor_rotation(phi_y, phi_z)``, the head body lies at z < 0).
The adapter is the convex hull of a disc on the flange face and the head's back face.

Cell
----
Plates are boxes: the measured face on the plane, the body (``thickness``) behind it
(``Plate.frame``). A stand is a ``STAND_SIDE`` square column under the plate's centre,
from the floor up to the plate's lower face (it touches the plate, never enters it). The floor is a ``FLOOR_SIZE`` slab whose
top is at ``scene.floor_z``. Obstacles are the scene's boxes (R = Rz(yaw) Ry(pitch) Rx(roll)).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from planecal.cell import sensor_rotation
from planecal.errors import InputError

COLLISION_MARGIN = 0.010  # m added around the nominal robot envelope
TOOL_MARGIN = 0.003  # m added around the adapter and head
VISUAL_SCALE = 0.92
COLLISION_SECTIONS = 12
VISUAL_SECTIONS = 32
HEAD_EXTENTS = np.array([0.030, 0.020, 0.060])  # ZS-LD80 head, sensor frame x, y, z [m]
ADAPTER_RADIUS = 0.050  # m, disc on the flange face
ADAPTER_THICKNESS = 0.012
STAND_SIDE = 0.08  # m
FLOOR_SIZE = (6.0, 6.0, 0.05)  # m
KINDS = ("collision", "visual")


@dataclass
class LinkMesh:
    name: str
    body: int
    mesh: trimesh.Trimesh
    T_body_mesh: np.ndarray = field(default_factory=lambda: np.eye(4))
    box_extents: np.ndarray | None = None
    box_pose: np.ndarray | None = None


@dataclass
class StaticMesh:
    name: str
    mesh: trimesh.Trimesh
    kind: str  # 'plate' | 'stand' | 'floor' | 'obstacle'
    box_extents: np.ndarray | None = None
    box_pose: np.ndarray | None = None


# ----- building blocks -----

@dataclass(frozen=True)
class _Cyl:
    """Cylinder between p0 and p1 (DH-frame coordinates of its body) with radius r."""
    p0: tuple
    p1: tuple
    r: float


_MC70_D = (0.600, 0.0, 0.0, 0.990, 0.0, 0.175)
_MC70_A = (0.150, 0.900, 0.150, 0.0, 0.0, 0.0)

# (name, body, [cylinders whose convex hull is the piece]) in the body's DH frame.
# Frame notes at q = 0: frame 1 has y1 = base up, z1 = joint-2 axis; frame 2 has x2 from
# shoulder to elbow; frame 3 has z3 along the forearm, y3 = joint-3 axis; frame 4 sits at
# the wrist centre with the forearm along +y4; frame 5 has z5 to the flange, y5 = joint-5
# axis; frame 6 is the flange face.
_LINKS = [
    ("base", 0, [_Cyl((0, 0, 0.0), (0, 0, 0.30), 0.30)]),
    ("turret", 1, [_Cyl((-0.15, -0.30, 0), (-0.15, -0.05, 0), 0.26),
                   _Cyl((0, 0, -0.24), (0, 0, 0.24), 0.20)]),
    ("upper_arm", 2, [_Cyl((-0.90, 0, -0.17), (-0.90, 0, 0.17), 0.19),
                      _Cyl((0, 0, -0.15), (0, 0, 0.15), 0.16)]),
    ("elbow", 3, [_Cyl((-0.15, -0.16, 0), (-0.15, 0.16, 0), 0.17),
                  _Cyl((0, 0, -0.30), (0, 0, 0.35), 0.15)]),
    ("forearm", 4, [_Cyl((0, 0.64, 0), (0, 0.22, 0), 0.12)]),
    ("wrist_fork", 4, [_Cyl((0, 0, -0.10), (0, 0, 0.10), 0.08),
                       _Cyl((0, 0.05, 0), (0, 0.22, 0), 0.08)]),
    ("wrist", 5, [_Cyl((0, -0.09, 0), (0, 0.09, 0), 0.09),
                  _Cyl((0, 0, 0), (0, 0, 0.14), 0.085)]),
    ("flange", 6, [_Cyl((0, 0, -0.035), (0, 0, 0.0), 0.0625)]),
]


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise InputError(f"geometry: kind must be 'collision' or 'visual', got {kind!r}")


def _cylinder_points(c: _Cyl, kind: str) -> np.ndarray:
    p0, p1 = np.asarray(c.p0, float), np.asarray(c.p1, float)
    axis = p1 - p0
    length = np.linalg.norm(axis)
    u = axis / length
    if kind == "collision":
        n = COLLISION_SECTIONS
        r = (c.r + COLLISION_MARGIN) / np.cos(np.pi / n)  # circumscribed polygon
        p0, p1 = p0 - COLLISION_MARGIN * u, p1 + COLLISION_MARGIN * u
    else:
        n = VISUAL_SECTIONS
        r = VISUAL_SCALE * c.r
    helper = np.array([1.0, 0, 0]) if abs(u[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    ang = 2 * np.pi * np.arange(n) / n
    ring = r * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    return np.concatenate([p0 + ring, p1 + ring])


def _hull(points: np.ndarray) -> trimesh.Trimesh:
    mesh = trimesh.convex.convex_hull(np.asarray(points, float))
    if not mesh.is_watertight:  # pragma: no cover - qhull hulls are closed
        raise RuntimeError("geometry: convex hull is not watertight")
    return mesh


def box_mesh(extents, pose=None) -> trimesh.Trimesh:
    """A watertight box (full extents) at pose (4x4, centre)."""
    return trimesh.creation.box(extents=np.asarray(extents, float),
                                transform=np.eye(4) if pose is None else np.asarray(pose, float))


def _rpy_matrix(rpy) -> np.ndarray:
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return Rz @ Ry @ Rx


# ----- public API -----

def robot_link_meshes(robot=None, kind: str = "collision") -> list[LinkMesh]:
    """Convex link pieces of the MC70 envelope, one per DH frame 0..6.

    The shapes are drawn for the MC70's DH dimensions (module docstring); a ``robot``
    whose DH differs gets an InputError rather than wrong shapes."""
    _check_kind(kind)
    if robot is not None and (robot.n_joints != 6 or not (
            np.allclose(robot.d, _MC70_D) and np.allclose(robot.a, _MC70_A))):
        raise InputError(f"geometry: no link shapes for {robot.name} (drawn for the MC70's DH)")
    out = []
    for name, body, cyls in _LINKS:
        pts = np.concatenate([_cylinder_points(c, kind) for c in cyls])
        out.append(LinkMesh(name, body, _hull(pts)))
    return out


def sensor_pose(origin, phi_y: float, phi_z: float) -> np.ndarray:
    """Flange -> sensor frame (4x4): origin o, rotation Rz(phi_z) Ry(phi_y); z = beam."""
    T = np.eye(4)
    T[:3, :3] = sensor_rotation(phi_y, phi_z)
    T[:3, 3] = np.asarray(origin, float)
    return T


def tool_meshes(scene, kind: str = "collision", sensor=None) -> list[LinkMesh]:
    """Flange adapter and laser head, attached to DH frame 6 (the flange).

    Built from the scene's nominal sensor pose, or from ``sensor`` = (origin, phi_y,
    phi_z) (e.g. the twin's hidden truth) or a ``CellParams``."""
    _check_kind(kind)
    if sensor is None:
        o, py, pz = scene.sensor_origin, scene.phi_y, scene.phi_z
    elif hasattr(sensor, "sensor_origin"):
        o, py, pz = sensor.sensor_origin, sensor.phi_y, sensor.phi_z
    else:
        o, py, pz = sensor
    T_fs = sensor_pose(o, py, pz)
    m = TOOL_MARGIN if kind == "collision" else -0.001
    ext = HEAD_EXTENTS + 2 * m
    T_head = T_fs @ _translation((0.0, 0.0, -HEAD_EXTENTS[2] / 2))
    head = LinkMesh("laser_head", 6, box_mesh(ext, T_head), box_extents=ext, box_pose=T_head)
    # adapter: hull of a disc on the flange face and the head's back face (sensor z = -60 mm)
    n = COLLISION_SECTIONS if kind == "collision" else VISUAL_SECTIONS
    ang = 2 * np.pi * np.arange(n) / n
    r = ADAPTER_RADIUS + m
    disc = np.stack([r * np.cos(ang), r * np.sin(ang), np.zeros(n)], -1)
    disc = np.concatenate([disc, disc + [0, 0, ADAPTER_THICKNESS]])
    hx, hy = ext[0] / 2, ext[1] / 2
    back = np.array([[sx * hx, sy * hy, -HEAD_EXTENTS[2] + dz]
                     for sx in (-1, 1) for sy in (-1, 1) for dz in (0.0, 0.01)])
    back = back @ T_fs[:3, :3].T + T_fs[:3, 3]
    adapter = LinkMesh("flange_adapter", 6, _hull(np.concatenate([disc, back])))
    return [adapter, head]


def _translation(t) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = t
    return T


def plate_box(plate, n_tilde=None) -> tuple[np.ndarray, np.ndarray]:
    """(full extents, centre pose) of a plate's box: face on the plane, body behind it."""
    F = plate.frame(n_tilde)
    ext = np.array([plate.size[0], plate.size[1], plate.thickness])
    return ext, F @ _translation((plate.size[0] / 2, plate.size[1] / 2, -plate.thickness / 2))


def _stand_top(pose: np.ndarray, ext: np.ndarray) -> float:
    """Height of a stand's top under a plate box (centre pose, extents): the plate's lower
    large face above the column's four top corners, lowest of them (the column touches
    the plate without entering it); for a steep plate (|n_z| < 0.3) its lowest point."""
    z = pose[:3, 2]
    corners = pose[:3, 3] + (np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                                       for sz in (-1, 1)]) * ext / 2) @ pose[:3, :3].T
    low = float(corners[:, 2].min())
    if abs(z[2]) < 0.3:
        return low
    p0 = pose[:3, 3] - np.sign(z[2]) * z * ext[2] / 2  # a point of the lower large face
    xy = pose[:2, 3] + STAND_SIDE / 2 * np.array([[sx, sy] for sx in (-1, 1) for sy in (-1, 1)])
    heights = p0[2] - ((xy - p0[:2]) @ z[:2]) / z[2]
    return max(low, float(heights.min()))


def scene_meshes(scene, plates_n_tilde=None) -> list[StaticMesh]:
    """Plates (on ``plates_n_tilde`` (k,3) if given, else the nominal planes), their
    stands, the floor and the obstacles, in the base frame."""
    if plates_n_tilde is not None:
        plates_n_tilde = np.asarray(plates_n_tilde, float).reshape(-1, 3)
        if len(plates_n_tilde) != len(scene.plates):
            raise InputError(f"geometry: {len(plates_n_tilde)} planes given for "
                             f"{len(scene.plates)} plates")
    out = []
    for i, plate in enumerate(scene.plates):
        ext, pose = plate_box(plate, None if plates_n_tilde is None else plates_n_tilde[i])
        mesh = box_mesh(ext, pose)
        out.append(StaticMesh(plate.name, mesh, "plate", ext, pose))
        if plate.stand:
            top = _stand_top(pose, ext)
            h = top - scene.floor_z
            if h > 1e-3:
                c = pose[:3, 3]
                sp = _translation((c[0], c[1], scene.floor_z + h / 2))
                se = np.array([STAND_SIDE, STAND_SIDE, h])
                out.append(StaticMesh(f"{plate.name}_stand", box_mesh(se, sp), "stand", se, sp))
    fe = np.array(FLOOR_SIZE)
    fp = _translation((0.0, 0.0, scene.floor_z - fe[2] / 2))
    out.append(StaticMesh("floor", box_mesh(fe, fp), "floor", fe, fp))
    for ob in scene.obstacles:
        pose = np.eye(4)
        pose[:3, :3] = _rpy_matrix(ob.rpy)
        pose[:3, 3] = ob.center
        out.append(StaticMesh(ob.name, box_mesh(ob.size, pose), "obstacle",
                              np.asarray(ob.size, float), pose))
    return out
