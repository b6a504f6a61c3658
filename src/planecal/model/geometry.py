"""Link, tool and cell shapes: one source for the MuJoCo twin, the FCL checker and Rerun.

Conventions
-----------
* Metres, watertight convex ``mesh.Mesh`` objects (convex hulls, cached: ``planecal.model.mesh``).
* ``LinkMesh.body`` is the index of the link frame the mesh is rigidly attached to
  (0 = base, i = the link joint i turns, 6 = flange; the flange adapter and laser head
  are attached to frame 6). ``mesh.vertices`` are already expressed in that frame:
  ``T_body_mesh`` is always the identity here (kept for the contract).
* ``StaticMesh.mesh`` vertices are in the robot base frame.
* When a shape is exactly a box, ``box_extents`` (full extents, m) and ``box_pose``
  (4x4 pose of the box centre in the body / base frame) say so, so that MuJoCo and FCL
  can use an exact box primitive (ray vs box is exact; vs a float32 mesh only ~1e-10 m).

Robot shapes: ``kind="visual"`` is the model of the real links, ``"collision"`` its envelope
----------------------------------------------------------------------------------------
They come from the robot's description: ``shapes.json`` beside its robot.json (format
``planecal-shapes/1``, ``planecal.formats.shapes``; docs/ROBOTS.md), a list of pieces, each
in one link frame (``kinematics.link_frames``: the standard DH frames of a DH table) and
each the convex hull of a few cylinders, boxes, spheres or STL meshes (``_Cyl``, ``_Box``,
``_Sphere``, ``_MeshPts``). The MC70's pieces are placed from its DH dimensions and sized
from its datasheet and estimates (docs/ROBOTS.md, "The MC70's shapes"); an imported
robot's are its URDF's <visual> and <collision> elements (``planecal robot import``).

A piece used for ``both`` (the MC70's) is the visual shape, its polygons circumscribing
the nominal circles (``VISUAL_SECTIONS`` sides; they exceed a true cylinder by < 0.22 % of
its radius, nothing is cut off), and, grown by the margin, the collision shape. A piece
used for ``visual`` only is drawn as given (one mesh: the mesh itself, which may be
concave); one used for ``collision`` only is the convex hull of its primitives, grown.
``kind="collision"`` contains each piece grown by ``margin_m`` in every direction
(default: the file's ``collision_margin_m``, else ``COLLISION_MARGIN``): each cylinder's
radius (the visual polygon's circumradius) and ends, each box's half extents grow by the
margin, and the polygon of ``COLLISION_SECTIONS`` sides circumscribes the grown circle; a
sphere's or a mesh's hull is summed with a polyhedron that holds the ball of the margin
(a geodesic sphere, scaled to circumscribe it). Since conv(A) + ball = conv(A + ball),
the collision piece contains every point within the margin of the piece: any distance
between collision pieces is at most the visual distance minus margins, so the checker's
verdicts are conservative for the visual shapes (where a URDF's collision elements
enclose its visual ones).

``COLLISION_MARGIN`` = 4 mm: joint offsets of the size the seed identified (Table 10:
0.76, 1.24, 0.73, 0.05 mrad on joints 2-5) move no link or tool point of the MC70
farther than 3.5 mm, whatever their signs, anywhere in the workspace (1.5 mm with Table
10's own signs; test_geometry measures it); a smaller arm moves less. The planner poses
the links with nominal kinematics; the real arm sits up to that far off. The rest (the
twin's larger offset tolerance, sensor and plate poses, servo lag, the sizes' own
uncertainty) is for the run's clearance (10 mm by default) to cover. The envelope is
measured against the visual shapes by scripts/bench_collision.py.

Tool (flange adapter + ZS-LD80 head)
------------------------------------
The head is a box ``HEAD_EXTENTS`` = 30 x 20 x 60 mm (x, y, z of the sensor frame); the
beam leaves the centre of its z = 0 face at the sensor origin ``o`` and runs along the
sensor z axis (``cell.sensor_rotation(phi_y, phi_z)``, the head body lies at z < 0).
The adapter is the convex hull of a disc on the flange face and the head's back face
(the last 10 mm of the head). Visual and collision shapes as for the links.

Cell
----
Plates are boxes: the measured face on the plane, the body (``thickness``) behind it
(``Plate.frame``). A stand is a ``STAND_SIDE`` square column under the plate's centre,
from the floor up to the plate's lower face (it touches the plate, never enters it). The floor is a ``FLOOR_SIZE`` slab whose
top is at ``scene.floor_z``. Obstacles are the scene's boxes (R = Rz(yaw) Ry(pitch) Rx(roll)).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.measurement import sensor_rotation
from planecal.base.errors import InputError
from planecal.model.mesh import Mesh, box, convex_hull, read_stl

COLLISION_MARGIN = 0.004  # m around the visual shapes (module docstring)
TOOL_MARGIN = COLLISION_MARGIN  # the tool's envelope: the same margin
COLLISION_SECTIONS = 32  # sides of the collision polygons
VISUAL_SECTIONS = 48  # sides of the visual polygons
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
    mesh: Mesh
    T_body_mesh: np.ndarray = field(default_factory=lambda: np.eye(4))
    box_extents: np.ndarray | None = None
    box_pose: np.ndarray | None = None


@dataclass
class StaticMesh:
    name: str
    mesh: Mesh
    kind: str  # 'plate' | 'stand' | 'floor' | 'obstacle'
    box_extents: np.ndarray | None = None
    box_pose: np.ndarray | None = None


# ----- building blocks -----

@dataclass(frozen=True)
class _Cyl:
    """Cylinder between p0 and p1 (coordinates in its body's frame) with radius r."""
    p0: tuple
    p1: tuple
    r: float


@dataclass(frozen=True)
class _Box:
    """Box of half extents ``half`` at ``pose`` (4x4, centre) in its body's frame."""
    pose: np.ndarray
    half: tuple


@dataclass(frozen=True)
class _Sphere:
    centre: tuple
    r: float


@dataclass(frozen=True, eq=False)
class _MeshPts:
    """An STL mesh's vertices (in its body's frame) and the mesh itself."""
    mesh: Mesh


def _geodesic(level: int) -> tuple[np.ndarray, float]:
    """Vertices of a geodesic sphere (an icosahedron, its faces split ``level`` times) on
    the unit sphere, and the scale that makes their hull circumscribe the unit ball."""
    t = (1 + 5 ** 0.5) / 2
    V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
                 float)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    for _ in range(level):
        F = convex_hull(V).faces
        mids = np.concatenate([V[F[:, [0, 1]]].mean(1), V[F[:, [1, 2]]].mean(1),
                               V[F[:, [2, 0]]].mean(1)])
        V = np.unique(np.round(np.concatenate([V, mids / np.linalg.norm(mids, axis=1,
                                                                         keepdims=True)]), 15),
                      axis=0)
    hull = convex_hull(V)
    inradius = float(np.min(np.einsum("fk,fk->f", hull.face_normals, hull.triangles_center)))
    return V, 1.0 / inradius


SPHERE_LEVEL = 1  # 42 vertices: a sphere's polyhedron exceeds it by < 9 % of its radius


@dataclass(frozen=True)
class ShapePiece:
    name: str
    link: int
    use: str  # 'both' | 'visual' | 'collision'
    primitives: tuple


@dataclass(frozen=True)
class RobotShapes:
    """A robot's shapes.json, its primitives read (meshes loaded)."""
    path: Path
    pieces: tuple[ShapePiece, ...]
    margin_m: float | None
    allowed_pairs: tuple[tuple[str, str], ...] = ()  # not checked: the robot keeps them apart
    unchecked: str | None = None  # why the arm has no collision pieces (formats.shapes)


def shapes_path(robot) -> Path:
    """shapes.json beside the robot's robot.json."""
    if robot.folder is None:
        raise InputError(f"geometry: {robot.name} has no folder, so no shapes.json")
    return robot.folder / "shapes.json"


def robot_shapes(robot) -> RobotShapes:
    """The robot's link shapes (``shapes.json``, validated; InputError when it has none)."""
    path = shapes_path(robot)
    if not path.exists():
        raise InputError(f"{path}: no link shapes for {robot.name}: the twin, the collision "
                         "checker and the views need them (docs/ROBOTS.md: shapes.json, or "
                         "planecal robot import)")
    return load_shapes(path)


_SHAPES: dict = {}  # (path, content) -> RobotShapes: read once per process, meshes included


def load_shapes(path) -> RobotShapes:
    """A shapes.json file, validated and its meshes read (one-line InputError otherwise)."""
    import json

    from planecal.formats.base import read_json, validate
    from planecal.formats.shapes import ShapesFile
    path = Path(path)
    raw = read_json(path, "robot shapes")
    key = (str(path.resolve()), json.dumps(raw, sort_keys=True))
    hit = _SHAPES.get(key)
    if hit is None:
        doc = validate(ShapesFile, raw, path, "robot shapes")
        pieces = []
        for i, p in enumerate(doc.pieces):
            prims = tuple(_primitive(path, i, k, prim) for k, prim in enumerate(p.primitives))
            pieces.append(ShapePiece(p.name, p.link, p.use, prims))
        hit = RobotShapes(path, tuple(pieces), doc.collision_margin_m,
                          tuple(tuple(p.pieces) for p in doc.allowed_pairs), doc.unchecked)
        if len(_SHAPES) > 16:
            _SHAPES.clear()
        _SHAPES[key] = hit
    return hit


def _primitive(path: Path, i: int, k: int, prim):
    if prim.cylinder is not None:
        c = prim.cylinder
        return _Cyl(tuple(c.from_m), tuple(c.to_m), c.radius_m)
    if prim.box is not None:
        b = prim.box
        pose = np.eye(4)
        pose[:3, :3] = _rpy_matrix(b.rpy_rad)
        pose[:3, 3] = b.center_m
        return _Box(pose, tuple(np.asarray(b.size_m, float) / 2))
    if prim.sphere is not None:
        return _Sphere(tuple(prim.sphere.center_m), prim.sphere.radius_m)
    f = path.parent / prim.mesh.file
    try:
        mesh = read_stl(f)
    except (OSError, ValueError) as e:
        raise InputError(f"{path}: pieces[{i}].primitives[{k}].mesh.file: "
                         f"{getattr(e, 'strerror', None) or e}") from None
    if len(mesh.vertices) < 4:
        raise InputError(f"{path}: pieces[{i}].primitives[{k}].mesh.file: {f.name} has "
                         f"{len(mesh.vertices)} vertices: no solid")
    return _MeshPts(mesh)


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise InputError(f"geometry: kind must be 'collision' or 'visual', got {kind!r}")


def _margin(kind: str, margin_m: float | None) -> float:
    _check_kind(kind)
    if kind == "visual":
        return 0.0
    m = COLLISION_MARGIN if margin_m is None else float(margin_m)
    if not (np.isfinite(m) and m >= 0):
        raise InputError(f"geometry: margin must be a finite distance >= 0 m, got {margin_m}")
    return m


def _points(prim, kind: str, m: float) -> np.ndarray:
    """Vertices of one primitive: the visual polygon (a cylinder's polygon circumscribes
    its circle), or for the collision envelope the primitive grown by m (module docstring)."""
    if isinstance(prim, _Box):
        half = np.asarray(prim.half, float) + m
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                            for sz in (-1, 1)]) * half
        return corners @ prim.pose[:3, :3].T + prim.pose[:3, 3]
    if isinstance(prim, _Sphere):
        U, scale = _geodesic(SPHERE_LEVEL)
        return np.asarray(prim.centre, float) + U * (prim.r + m) * scale
    if isinstance(prim, _MeshPts):
        V = prim.mesh.vertices
        if kind == "visual" or m == 0:
            return V
        U, scale = _geodesic(0)
        H = convex_hull(V).vertices
        return (H[:, None, :] + U[None] * m * scale).reshape(-1, 3)
    p0, p1 = np.asarray(prim.p0, float), np.asarray(prim.p1, float)
    axis = p1 - p0
    u = axis / np.linalg.norm(axis)
    r = prim.r / np.cos(np.pi / VISUAL_SECTIONS)  # the visual polygon's circumradius
    if kind == "collision":
        n = COLLISION_SECTIONS
        r = (r + m) / np.cos(np.pi / n)
        p0, p1 = p0 - m * u, p1 + m * u
    else:
        n = VISUAL_SECTIONS
    helper = np.array([1.0, 0, 0]) if abs(u[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    ang = 2 * np.pi * np.arange(n) / n
    ring = r * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    return np.concatenate([p0 + ring, p1 + ring])


def _piece(prims, kind: str, m: float) -> Mesh:
    return convex_hull(np.concatenate([_points(p, kind, m) for p in prims]))


def box_mesh(extents, pose=None) -> Mesh:
    """A watertight box (full extents) at pose (4x4, centre)."""
    return box(extents, pose)


def _rpy_matrix(rpy) -> np.ndarray:
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return Rz @ Ry @ Rx


# ----- public API -----

def robot_link_meshes(robot=None, kind: str = "collision",
                      margin_m: float | None = None) -> list[LinkMesh]:
    """The robot's link pieces (its ``shapes.json``, module docstring), one or more per
    link frame 0..6: the visual shapes (the model of the real links) or the collision
    envelope around them, ``margin_m`` (default: the file's, else ``COLLISION_MARGIN``)
    out. ``robot`` defaults to the MC70. A robot without shapes.json: InputError."""
    _check_kind(kind)
    if robot is None:
        from planecal.model.robot import load_robot
        robot = load_robot()
    shapes = robot_shapes(robot)
    if kind == "collision" and margin_m is None and shapes.margin_m is not None:
        margin_m = shapes.margin_m
    m = _margin(kind, margin_m)
    out = []
    for piece in shapes.pieces:
        if piece.use not in ("both", kind):
            continue
        prims = piece.primitives
        if kind == "visual" and len(prims) == 1 and isinstance(prims[0], _MeshPts):
            out.append(LinkMesh(piece.name, piece.link, prims[0].mesh))  # drawn as it is
        else:
            out.append(LinkMesh(piece.name, piece.link, _piece(prims, kind, m)))
    return out


def sensor_pose(origin, phi_y: float, phi_z: float) -> np.ndarray:
    """Flange -> sensor frame (4x4): origin o, rotation Rz(phi_z) Ry(phi_y); z = beam."""
    T = np.eye(4)
    T[:3, :3] = sensor_rotation(phi_y, phi_z)
    T[:3, 3] = np.asarray(origin, float)
    return T


def tool_meshes(scene, kind: str = "collision", sensor=None,
                margin_m: float | None = None) -> list[LinkMesh]:
    """Flange adapter and laser head, attached to DH frame 6 (the flange): visual, or the
    collision envelope ``margin_m`` (default ``TOOL_MARGIN``) around it.

    Built from the scene's nominal sensor pose, or from ``sensor`` = (origin, phi_y,
    phi_z) (e.g. the twin's hidden truth) or a ``CellParams``."""
    m = _margin(kind, TOOL_MARGIN if margin_m is None else margin_m)
    if sensor is None:
        o, py, pz = scene.sensor_origin, scene.phi_y, scene.phi_z
    elif isinstance(sensor, CellParams):
        o, py, pz = sensor.sensor_origin, sensor.phi_y, sensor.phi_z
    else:
        o, py, pz = sensor
    T_fs = sensor_pose(o, py, pz)
    ext = HEAD_EXTENTS + 2 * m
    T_head = T_fs @ _translation((0.0, 0.0, -HEAD_EXTENTS[2] / 2))
    head = LinkMesh("laser_head", 6, box_mesh(ext, T_head), box_extents=ext, box_pose=T_head)
    # adapter: hull of a disc on the flange face and the head's last 10 mm (sensor z -60..-50 mm)
    disc = _Cyl((0.0, 0.0, 0.0), (0.0, 0.0, ADAPTER_THICKNESS), ADAPTER_RADIUS)
    back = _Box(T_fs @ _translation((0.0, 0.0, -HEAD_EXTENTS[2] + 0.005)),
                (HEAD_EXTENTS[0] / 2, HEAD_EXTENTS[1] / 2, 0.005))
    adapter = LinkMesh("flange_adapter", 6, _piece([disc, back], kind, m))
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
