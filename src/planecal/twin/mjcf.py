"""MuJoCo models built in code (``mujoco.MjSpec``) from the robot description and a scene.

Robot (``robot_spec``; written to ``models/<robot>/<robot>.xml`` by scripts/build_mjcf.py)
------------------------------------------------------------------------------------------
Built from the robot's whole geometric model (``kinematics.Kinematics``: robot.json's, or
the twin's true robot):
* body ``base`` carries the shapes of link frame 0, at the model's base frame;
* body ``link<i>`` (i = 1..6) is the model's frame i: its pos/quat relative to its parent
  is joint i's fixed part ``Rx(alpha) Tx(a) Ry(beta) Rz(theta) Tz(d)`` and its hinge
  ``joint<i>`` turns about local z through the origin. So with ``qpos = q + delta``
  (joint angles from the encoder model plus joint offsets) the sites ``frame<i>`` (at
  ``dh_site(robot, i)`` = ``kinematics.link_site``: Tx(a_i) Rx(alpha_i) of a standard
  DH table's row i) are the link frames (``kinematics.link_frames``; a DH table's
  standard DH frames) of the nominal model; site ``flange`` is the model's flange frame.
* geoms: ``v_<piece>`` visual (group 1, contype = conaffinity = 0, massless: the model
  of the real link), ``c_<piece>`` collision (group 3: the checker's envelope around
  it), meshes from ``planecal.model.geometry`` (the robot's shapes.json; convex but a
  visual mesh drawn as it is), one or more pieces per body.
* inertials: each body's mass and centre of mass (and inertia, where robot.json gives
  one) are robot.json's ``masses`` of its link (the tool's: the payload); the geoms
  carry none. The twin's gravity model reads them back from the compiled model.
  Sites of the link frames are in group 4.

Scene (``scene_spec``): the robot, a ``tool`` body on the flange (adapter + ZS-LD80 head,
groups 1/3), a ``laser`` site whose +z is the beam at the sensor origin, and the cell's
plates, stands, floor and obstacles as box geoms on the world body (group 0: the only
group the laser sees).

MuJoCo's ``to_xml`` writes 6 significant digits; ``to_xml_exact`` rewrites the pose,
size and range attributes of named elements with 17 digits, so a model loaded from the
file has the same kinematics as the one built in code (to 1e-15).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.geometry import robot_link_meshes, scene_meshes, sensor_pose, tool_meshes
from planecal.model.kinematics import Kinematics, link_site
from planecal.model.gravity import inertia_matrix, lumped
from planecal.model.robot import Robot

GROUP_ENV = 0  # plates, stands, floor, obstacles: visible and seen by the laser
GROUP_VISUAL = 1
GROUP_SENSOR = 2  # laser site
GROUP_COLLISION = 3
GROUP_FRAMES = 4
BASE_BODY = "base"
TOOL_BODY = "tool"
LASER_SITE = "laser"
FLANGE_SITE = "flange"

_RGBA = {
    "visual": [0.95, 0.75, 0.10, 1.0],
    "tool": [0.25, 0.25, 0.28, 1.0],
    "collision": [0.8, 0.2, 0.2, 0.3],
    "plate": [0.55, 0.62, 0.70, 1.0],
    "stand": [0.35, 0.35, 0.38, 1.0],
    "floor": [0.80, 0.80, 0.78, 1.0],
    "obstacle": [0.70, 0.35, 0.25, 1.0],
}


def link_body_name(i: int) -> str:
    return f"link{i}"


def dh_site(robot: Robot, i: int) -> np.ndarray:
    """Link frame i in the model's frame i (``kinematics.link_site`` of the nominal
    chain; for a standard DH table Tx(a_i) Rx(alpha_i) of row i, identity for 0 when the
    chain starts at its base). The link shapes (``geometry``, in link frames) hang off
    their body by it."""
    return link_site(robot.kinematics, i)


MIN_MASS_KG = 1e-9  # MuJoCo needs a moving body to have some mass


def set_inertial(body, masses) -> None:
    """The body's inertial from masses ``(position in the body frame, mass[, inertia about
    their centre (3, 3) in the body's axes, or None])``: their total mass at their centre
    of mass and their inertia about it (point masses but for the inertias given);
    MIN_MASS_KG when there are none. The body's geoms add nothing."""
    M, c, I = lumped(masses)
    body.explicitinertial = True
    if not M:
        body.mass, body.ipos, body.inertia = MIN_MASS_KG, [0, 0, 0], [MIN_MASS_KG] * 3
        return
    body.mass, body.ipos = M, c.tolist()
    body.fullinertia = (np.array([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])
                        + np.array([1, 1, 1, 0, 0, 0]) * 1e-6 * M).tolist()


def _inertia_in(R: np.ndarray, six) -> np.ndarray | None:
    """robot.json's inertia (ixx iyy izz ixy ixz iyz, link frame axes) in axes R x."""
    J = inertia_matrix(six)
    return None if J is None else R @ J @ R.T


def _clean(T: np.ndarray) -> np.ndarray:
    T = np.array(T, float)
    T[np.abs(T) < 1e-15] = 0.0
    return T


def mat_to_quat(R: np.ndarray) -> np.ndarray:
    """Rotation matrix -> MuJoCo quaternion (w, x, y, z)."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, float).ravel())
    q[np.abs(q) < 1e-16] = 0.0
    return q


def _pose_kwargs(T: np.ndarray) -> dict:
    return {"pos": T[:3, 3].tolist(), "quat": mat_to_quat(T[:3, :3]).tolist()}


def _add_mesh_geom(spec, body, name, mesh, vertices_in_body, kind, group):
    spec.add_mesh(name=f"m_{name}", uservert=np.round(vertices_in_body, 6).ravel().tolist(),
                  userface=mesh.faces.ravel().tolist())
    g = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"m_{name}",
                      group=group, rgba=_RGBA[kind])
    _set_collision_flags(g, kind)
    return g


def _add_box_geom(body, name, extents, T, kind, group):
    g = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=(np.asarray(extents, float) / 2).tolist(), group=group,
                      rgba=_RGBA[kind], **_pose_kwargs(T))
    _set_collision_flags(g, kind)
    return g


def _set_collision_flags(g, kind):
    if kind in ("visual", "tool"):  # visual only: never collides, no mass
        g.contype, g.conaffinity, g.density = 0, 0, 0.0
    else:
        g.contype, g.conaffinity = 1, 1


def robot_spec(robot: Robot, kin: Kinematics | None = None) -> mujoco.MjSpec:
    """The robot alone (see the module docstring for the body/joint/geom layout), built
    from ``kin`` (default: robot.json's nominal model)."""
    kin = robot.kinematics if kin is None else kin
    spec = mujoco.MjSpec()
    spec.modelname = robot.name.replace(" ", "_")
    spec.compiler.degree = False
    base = spec.worldbody.add_body(name=BASE_BODY, **_pose_kwargs(_clean(kin.base)))
    set_inertial(base, [])
    bodies = [base]
    parent = base
    for i in range(robot.n_joints):
        b = parent.add_body(name=link_body_name(i + 1),
                            **_pose_kwargs(_clean(kin.joint_transform(i))))
        X = dh_site(robot, i + 1)
        set_inertial(b, [(X[:3, :3] @ com + X[:3, 3], m, _inertia_in(X[:3, :3], J))
                         for frame, com, m, J in robot.masses if frame == i + 1])
        b.add_joint(name=f"joint{i + 1}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1],
                    range=robot.limits[i].tolist(), limited=mujoco.mjtLimited.mjLIMITED_TRUE,
                    damping=100.0, armature=1.0)
        site = {"name": f"frame{i + 1}", "group": GROUP_FRAMES, "size": [0.02, 0, 0],
                **_pose_kwargs(dh_site(robot, i + 1))}
        b.add_site(**site)
        bodies.append(b)
        parent = b
    n = robot.n_joints
    bodies[n].add_site(name=FLANGE_SITE, group=GROUP_FRAMES, size=[0.01, 0, 0],
                       **_pose_kwargs(_clean(kin.flange)))
    for kind, group in (("visual", GROUP_VISUAL), ("collision", GROUP_COLLISION)):
        for lm in robot_link_meshes(robot, kind):
            # body k holds standard DH frame k's shapes, which sits at dh_site(k) on it
            T = dh_site(robot, lm.body)
            v = lm.mesh.vertices @ T[:3, :3].T + T[:3, 3]
            _add_mesh_geom(spec, bodies[lm.body], f"{kind[0]}_{lm.name}", lm.mesh, v, kind, group)
    # MuJoCo filters parent-child contacts, but not for a body welded to the world
    spec.add_exclude(bodyname1=BASE_BODY, bodyname2=link_body_name(1))
    key = spec.add_key(name="home")
    key.qpos = [0.0] * n
    return spec


def add_tool(spec: mujoco.MjSpec, robot: Robot, scene, sensor: CellParams | None = None,
             kin: Kinematics | None = None, payload=None):
    """Adapter, laser head and the ``laser`` site on the flange (``kin``'s flange frame,
    default robot.json's); ``payload`` (mass kg, centre of mass in the flange frame) is
    the tool body's inertial.

    ``sensor`` (a CellParams) places the head and the site (the twin's truth); default:
    the scene's nominal sensor pose."""
    n = robot.n_joints
    kin = robot.kinematics if kin is None else kin
    flange_body = spec.body(link_body_name(n))
    tool = flange_body.add_body(name=TOOL_BODY, **_pose_kwargs(_clean(kin.flange)))
    set_inertial(tool, [] if payload is None else [(payload[1], payload[0])])
    for kind, group, rgba_kind in (("visual", GROUP_VISUAL, "tool"),
                                   ("collision", GROUP_COLLISION, "collision")):
        for lm in tool_meshes(scene, kind, sensor):
            name = f"{kind[0]}_{lm.name}"
            if lm.box_extents is not None:
                _add_box_geom(tool, name, lm.box_extents, lm.box_pose, rgba_kind, group)
            else:
                _add_mesh_geom(spec, tool, name, lm.mesh, lm.mesh.vertices, rgba_kind, group)
    if sensor is None:
        T = sensor_pose(scene.sensor_origin, scene.phi_y, scene.phi_z)
    else:
        T = sensor_pose(sensor.sensor_origin, sensor.phi_y, sensor.phi_z)
    tool.add_site(name=LASER_SITE, group=GROUP_SENSOR, type=mujoco.mjtGeom.mjGEOM_SPHERE,
                  size=[0.002, 0, 0], rgba=[1, 0, 0, 1], **_pose_kwargs(T))
    return tool


def cell_geom_names(scene, planes: np.ndarray | None = None) -> list[tuple[str, object]]:
    """(unique geom name, StaticMesh) for the cell's shapes, in scene_meshes order."""
    out, seen = [], set()
    for sm in scene_meshes(scene, planes):
        name, k = sm.name, 1
        while name in seen:
            k += 1
            name = f"{sm.name}_{k}"
        seen.add(name)
        out.append((name, sm))
    return out


def plate_geom_names(scene) -> list[str]:
    """The geom name of each of scene.plates, in order."""
    return [name for name, sm in cell_geom_names(scene) if sm.kind == "plate"]


def add_cell(spec: mujoco.MjSpec, scene, planes: np.ndarray | None = None) -> list[str]:
    """Plates (on ``planes`` n~ (k,3), default nominal), stands, floor, obstacles as box
    geoms on the world body, group 0. Returns the geom names in scene_meshes order."""
    names = []
    for name, sm in cell_geom_names(scene, planes):
        _add_box_geom(spec.worldbody, name, sm.box_extents, sm.box_pose, sm.kind, GROUP_ENV)
        names.append(name)
    return names


def scene_spec(scene, truth: CellParams | None = None, calibration_qpos=None,
               kin: Kinematics | None = None, payload=None) -> mujoco.MjSpec:
    """Robot + tool + cell. ``truth`` places the sensor and the plates (default nominal),
    ``kin`` is the robot's geometry (default robot.json's), ``payload`` the tool's mass;
    the joint offsets go into qpos at run time, not into the model."""
    robot = scene.robot
    spec = robot_spec(robot, kin)
    spec.modelname = f"{spec.modelname}_{scene.name}"
    spec.option.gravity = [0.0, 0.0, 0.0]  # kinematic twin: keep a viewer's simulation still
    add_tool(spec, robot, scene, truth, kin, payload)
    add_cell(spec, scene, None if truth is None else truth.planes)
    if calibration_qpos is not None:
        key = spec.add_key(name="calibration")
        key.qpos = np.asarray(calibration_qpos, float).tolist()
    return spec


_EXACT_ATTRS = ("pos", "quat", "size", "range", "axis")


def to_xml_exact(spec: mujoco.MjSpec) -> str:
    """``spec.to_xml()`` with pos/quat/size/range/axis of named bodies, sites, joints and
    geoms written at full double precision."""
    root = ET.fromstring(spec.to_xml())
    lookup = {"body": spec.body, "site": spec.site, "joint": spec.joint, "geom": spec.geom}
    for el in root.iter():
        find = lookup.get(el.tag)
        name = el.get("name")
        if find is None or name is None:
            continue
        obj = find(name)
        for attr in _EXACT_ATTRS:
            text = el.get(attr)
            if text is None:
                continue
            k = len(text.split())
            vals = np.asarray(getattr(obj, attr), float).ravel()[:k]
            el.set(attr, " ".join(_fmt(v) for v in vals))
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def _fmt(v: float) -> str:
    s = repr(float(v))
    return s[:-2] if s.endswith(".0") else s


GENERATED_HEADER = ("<!-- Generated by scripts/build_mjcf.py from models/{name}/robot.json "
                    "and planecal.model.geometry; do not edit. -->\n")


def robot_xml(robot: Robot) -> str:
    """The robot-only MJCF text (what models/<robot>/<robot>.xml holds)."""
    return GENERATED_HEADER.format(name=robot.source.parent.name if robot.source else robot.name) \
        + to_xml_exact(robot_spec(robot))


def robot_xml_path(robot: Robot):
    folder = robot.source.parent
    return folder / f"{folder.name}.xml"


_VIEW_SCENE = """<!-- Generated by scripts/build_mjcf.py; do not edit. A bare view of the robot:
     python -m mujoco.viewer --mjcf {path}
     (the twin's cells: planecal mjcf --scene SCENE --out OUT.xml) -->
<mujoco model="{name} scene">
  <include file="{robot_file}" />
  <option gravity="0 0 0" />
  <visual>
    <headlight diffuse="0.6 0.6 0.6" ambient="0.3 0.3 0.3" specular="0 0 0" />
    <global azimuth="150" elevation="-20" />
  </visual>
  <asset>
    <texture type="skybox" builtin="gradient" rgb1="0.3 0.5 0.7" rgb2="0 0 0" width="512" height="3072" />
    <texture type="2d" name="groundplane" builtin="checker" mark="edge" rgb1="0.2 0.3 0.4" rgb2="0.1 0.2 0.3" markrgb="0.8 0.8 0.8" width="300" height="300" />
    <material name="groundplane" texture="groundplane" texuniform="true" texrepeat="5 5" reflectance="0.2" />
  </asset>
  <worldbody>
    <light pos="0 0 3.5" dir="0 0 -1" directional="true" />
    <geom name="floor" size="0 0 0.05" type="plane" material="groundplane" />
  </worldbody>
</mujoco>
"""


def view_scene_xml(robot: Robot) -> str:
    """models/<robot>/scene.xml: floor, light and sky around an <include> of the robot
    file (the Menagerie layout)."""
    folder = robot.source.parent
    return _VIEW_SCENE.format(path=f"models/{folder.name}/scene.xml", name=folder.name,
                              robot_file=robot_xml_path(robot).name)


def view_scene_path(robot: Robot):
    return robot.source.parent / "scene.xml"
