"""Link, tool and cell shapes: one source for the MuJoCo twin, the FCL checker and Rerun.

Conventions
-----------
* Metres, watertight convex ``mesh.Mesh`` objects (convex hulls, cached: ``planecal.model.mesh``).
* ``LinkMesh.body`` is the index of the DH frame the mesh is rigidly attached to
  (0 = base, i = frame after joint i, 6 = flange; the flange adapter and laser head are
  attached to frame 6). ``mesh.vertices`` are already expressed in that DH frame:
  ``T_body_mesh`` is always the identity here (kept for the contract).
* ``StaticMesh.mesh`` vertices are in the robot base frame.
* When a shape is exactly a box, ``box_extents`` (full extents, m) and ``box_pose``
  (4x4 pose of the box centre in the body / base frame) say so, so that MuJoCo and FCL
  can use an exact box primitive (ray vs box is exact; vs a float32 mesh only ~1e-10 m).

Robot shapes: ``kind="visual"`` is the model of the real links, ``"collision"`` its envelope
----------------------------------------------------------------------------------------
Every piece (``name`` unique) is convex: the convex hull of a few cylinders and boxes
(``_Cyl``, ``_Box``) in the DH frame of its body, placed from the robot description's DH
dimensions (models/mc70/robot.json: d1 = 0.600, a1 = 0.150, a2 = 0.900, a3 = 0.150,
d4 = 0.990, d6 = 0.175 m) and sized by the constants below. What each size comes from:

* DH (robot.json, the seed's Table 2): where every joint axis, hub and link end is.
* Datasheet (seed H.1): J5 +-125 deg: the flange and the J6 housing must clear the
  forearm's end up to the limit, which places the fork's crotch (``FORK_CROTCH``: bent
  to 125 deg the flange reaches 152 mm from the J5 axis towards the forearm, the J6
  housing 150 mm; the crotch is at 170 mm). The wrist sits between two prongs
  (``wrist_fork_p``, ``wrist_fork_n``), not in front of a block.
  J3 +260/-146 deg (406 deg of travel): the forearm swings past the upper arm, so the
  upper arm is a beam beside the forearm's plane (``UPPER_ARM_Z``, on the +z2 side, the
  robot's right at q = 0; the side is not documented), not centred on it; issue 11
  records the offset arm of the real MC70 as well.
* Estimates (no public MC70 drawing was found: the datasheet's exterior-dimension figure
  is not in the seed's text, and the stored web pages, docs and code hold no MC70
  drawing, CAD or URDF): the radii and widths, sized for a 640 kg, 70 kg-payload arm
  of this reach (datasheet mass and payload) and kept from the first envelope where
  nothing better is known: base 300, turret column 260, J2 housing 200, shoulder hub
  190, elbow hub 160, elbow housing 150/170, forearm 120, J5 hub 90, J6 housing 85,
  flange 62.5 mm radius (a 125 mm flange), prongs 35 mm thick.

``kind="visual"`` polygons circumscribe the nominal circles (``VISUAL_SECTIONS`` sides;
they exceed a true cylinder by < 0.22 % of its radius, nothing is cut off).
``kind="collision"`` contains the visual piece grown by ``margin_m`` in every direction
(default ``COLLISION_MARGIN``): each cylinder's radius (the visual polygon's circumradius)
and ends, each box's half extents grow by the margin, and the polygon of
``COLLISION_SECTIONS`` sides circumscribes the grown circle. Since conv(A) + ball =
conv(A + ball), the collision piece contains every point within the margin of the visual
piece: any distance between collision pieces is at most the visual distance minus
margins, so the checker's verdicts are conservative for the visual shapes.

``COLLISION_MARGIN`` = 4 mm: joint offsets of the size the seed identified (Table 10:
0.76, 1.24, 0.73, 0.05 mrad on joints 2-5) move no link or tool point farther than
3.5 mm, whatever their signs, anywhere in the workspace (1.5 mm with Table 10's own
signs; test_geometry measures it). The planner poses the links with nominal kinematics;
the real arm sits up to that far off. The rest (the twin's larger offset tolerance,
sensor and plate poses, servo lag, the sizes' own uncertainty) is for the run's
clearance (10 mm by default) to cover. The envelope is measured against the visual
shapes by scripts/bench_collision.py.

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

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.measurement import sensor_rotation
from planecal.base.errors import InputError
from planecal.model.mesh import Mesh, box, convex_hull

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

# MC70 link sizes [m] (module docstring says where each comes from)
BASE_RADIUS, BASE_HEIGHT = 0.300, 0.300
TURRET_RADIUS, TURRET_TOP = 0.260, 0.050  # J1 column; its top 50 mm below the J2 axis
J2_HOUSING_RADIUS = 0.200
J2_HOUSING_Z = (-0.240, 0.160)  # along the J2 axis; the upper arm sits beside it
UPPER_ARM_Z = (0.160, 0.320)  # the upper arm beam, beside the forearm's plane (+z2)
SHOULDER_HUB_RADIUS, ELBOW_HUB_RADIUS = 0.190, 0.160
ELBOW_J3_RADIUS, ELBOW_J3_HALF = 0.170, 0.160  # elbow housing round the J3 axis
ELBOW_RADIUS, ELBOW_BACK, ELBOW_FRONT = 0.150, 0.300, 0.350  # round the forearm axis
FOREARM_RADIUS = 0.120
FORK_CROTCH = 0.170  # forearm end between the prongs, from the J5 axis
FORK_INNER, FORK_OUTER, FORK_RADIUS, FORK_ROOT = 0.095, 0.130, 0.090, 0.250
J5_HUB_RADIUS, J5_HUB_HALF = 0.090, 0.090
J6_HOUSING_RADIUS = 0.085
FLANGE_RADIUS, FLANGE_THICKNESS = 0.0625, 0.035


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


def _mc70_pieces(robot) -> list[tuple[str, int, list]]:
    """(name, body, primitives) of the MC70's link pieces, in the DH frames; positions
    from the robot's DH (module docstring). Frames at q = 0: frame 1 has y1 = base up and
    z1 = the J2 axis; frame 2 (at the J3 axis) has x2 from shoulder to elbow; frame 3 has
    z3 along the forearm and y3 = the J3 axis; frame 4 sits at the wrist centre with the
    forearm along +y4 and z4 = the J5 axis; frame 5 has z5 to the flange and y5 = the J5
    axis; frame 6 is the flange face."""
    d1, d4, d6 = robot.d[0], robot.d[3], robot.d[5]
    a1, a2, a3 = robot.a[0], robot.a[1], robot.a[2]
    z0, z1 = UPPER_ARM_Z
    prongs = [(f"wrist_fork_{side}", 4,
               [_Cyl((0, 0, s * FORK_INNER), (0, 0, s * FORK_OUTER), FORK_RADIUS),
                _Cyl((0, FORK_ROOT, s * FORK_INNER), (0, FORK_ROOT, s * FORK_OUTER), FORK_RADIUS)])
              for side, s in (("p", 1), ("n", -1))]
    return [
        ("base", 0, [_Cyl((0, 0, 0), (0, 0, BASE_HEIGHT), BASE_RADIUS)]),
        ("turret", 1, [_Cyl((-a1, BASE_HEIGHT - d1, 0), (-a1, -TURRET_TOP, 0), TURRET_RADIUS),
                       _Cyl((0, 0, J2_HOUSING_Z[0]), (0, 0, J2_HOUSING_Z[1]), J2_HOUSING_RADIUS)]),
        ("upper_arm", 2, [_Cyl((-a2, 0, z0), (-a2, 0, z1), SHOULDER_HUB_RADIUS),
                          _Cyl((0, 0, z0), (0, 0, z1), ELBOW_HUB_RADIUS)]),
        ("elbow", 3, [_Cyl((-a3, -ELBOW_J3_HALF, 0), (-a3, ELBOW_J3_HALF, 0), ELBOW_J3_RADIUS),
                      _Cyl((0, 0, -ELBOW_BACK), (0, 0, ELBOW_FRONT), ELBOW_RADIUS)]),
        ("forearm", 4, [_Cyl((0, FORK_CROTCH, 0), (0, d4 - ELBOW_FRONT, 0), FOREARM_RADIUS)]),
        *prongs,
        ("wrist", 5, [_Cyl((0, -J5_HUB_HALF, 0), (0, J5_HUB_HALF, 0), J5_HUB_RADIUS),
                      _Cyl((0, 0, 0), (0, 0, d6 - FLANGE_THICKNESS), J6_HOUSING_RADIUS)]),
        ("flange", 6, [_Cyl((0, 0, -FLANGE_THICKNESS), (0, 0, 0.0), FLANGE_RADIUS)]),
    ]


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
    """Convex link pieces of the MC70, one or more per DH frame 0..6: the visual shapes
    (the model of the real links) or the collision envelope around them, ``margin_m``
    (default ``COLLISION_MARGIN``) out (module docstring). ``robot`` (default the MC70
    description) places them by its DH; the sizes are the MC70's, so another robot gets
    an InputError rather than wrong shapes."""
    m = _margin(kind, margin_m)
    if robot is None:
        from planecal.model.robot import load_robot
        robot = load_robot()
    if robot.n_joints != 6 or "MC70" not in robot.name:
        raise InputError(f"geometry: no link shapes for {robot.name} (sizes are the MC70's)")
    return [LinkMesh(name, body, _piece(prims, kind, m)) for name, body, prims in _mc70_pieces(robot)]


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
