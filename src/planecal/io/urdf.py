"""URDF of the robot, nominal or calibrated, for ROS/MoveIt, FIGAROH and any URDF tool.

Tree: ``base`` (the robot base frame: planecal's cell frame) -> ``joint1`` .. ``joint6``
(revolute; robot.json's ``joint_names`` where it has them; links ``link1`` .. ``link6``)
-> ``flange`` (fixed, the flange frame) -> ``laser`` (fixed, the sensor frame: origin o in
the flange frame, rotation Rz(phi_z) Ry(phi_y), z = the beam).

A URDF joint's value is planecal's joint angle q (what ``encoder.counts_to_joints``
gives), so a URDF consumer's forward kinematics at q is ``kinematics.fk(robot.kinematics.with_offsets(delta), q)``.
The chain (``kinematics``) joins link frames by ``link_j = link_{j-1} P_j Rz(c_j + q_j) A_j``
(``kinematics.joint_between_links``; c_j = theta0_j + delta_j). A URDF joint turns its
child about an axis after a fixed origin; since Rz(c + q) = Rz(q) Rz(c), URDF link j is
``link_{j-1} P_j Rz(q_j)`` (turned by q_j about z) and the constant rest of joint j,
``Rz(c_j) A_j``, is the next joint's origin up to its own P_{j+1}:

    origin of joint 1 = B link_site(0) P_1,   origin of joint j+1 = Rz(c_j) A_j P_{j+1},
    origin of the fixed ``flange`` joint = Rz(c_6) A_6.

For a standard DH table (P = I, A_j = Tz(d_j) Tx(a_j) Rx(alpha_j), B = I) that is
``xyz = (a_j cos c_j, a_j sin c_j, d_j), rpy = (alpha_j, 0, c_j)`` (URDF's rpy is
R = Rz(yaw) Ry(pitch) Rx(roll)), written so without a matrix-to-angles conversion; any
other origin (a Hayati beta, an imported robot's base and flange) is converted from its
matrix (to ~1e-16). The calibrated joint offsets delta sit in those yaws. Joint limits
are robot.json's (on q); joint names are robot.json's ``joint_names`` where it has them.
robot.json holds no joint speeds or torques; URDF requires both attributes, so they are
written as 0 with a comment saying they are unknown (a motion planner needs its own).

Shapes are optional: ``MeshRef`` entries (a mesh file whose vertices are in link frame
``body``, as ``planecal.model.geometry`` builds them) become ``<visual>``/``<collision>``
elements; frame 0 goes to ``base`` (origin B link_site(0)), frames 1..5 to ``link1..5``
(origin: Rz(c_k) A_k), frame 6 (the wrist's last link and the tool) to ``flange``.

This module reads a ``Robot`` and ``CellParams``; it knows nothing of files above them.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.kinematics import joint_between_links, link_site, rot, rpy_angles, tx_rx
from planecal.model.robot import Robot

LINKS = ("base", "link1", "link2", "link3", "link4", "link5", "link6", "flange", "laser")


@dataclass(frozen=True)
class MeshRef:
    """A mesh file for the URDF: vertices in DH frame ``body`` (0 base .. 6 flange)."""
    body: int
    kind: str  # "visual" or "collision"
    filename: str  # as written into the URDF (relative path or URI)
    name: str = ""


def _num(v: float) -> str:
    """Shortest text that reads back as the same double (exact round trip)."""
    v = float(v)
    return "0" if v == 0 else repr(v)


def _vec(v) -> str:
    return " ".join(_num(x) for x in v)


def link_constant(robot: Robot, delta, i: int) -> tuple[list[float], list[float]]:
    """(xyz, rpy) of the constant part of joint i+1 (0-based i): Rz(c) A, c = theta0 +
    delta (module docstring); for a standard DH row Rz(c) Tz(d) Tx(a) Rx(alpha)."""
    return _xyz_rpy(_constant(robot, delta, i + 1), *_std_form(robot, delta, i + 1, False))


def _constant(robot: Robot, delta, j: int) -> np.ndarray:
    kin = robot.kinematics
    _, A = joint_between_links(kin, j)
    Rz = np.eye(4)
    Rz[:3, :3] = rot(2, float(kin.theta[j - 1] + delta[j - 1]))
    return Rz @ A


def joint_origin(robot: Robot, delta, j: int) -> np.ndarray:
    """The origin (4x4) of URDF joint j (1-based; j = n + 1: the fixed flange joint) in its
    parent link (module docstring)."""
    kin = robot.kinematics
    n = kin.n_joints
    T = kin.base @ link_site(kin, 0) if j == 1 else _constant(robot, delta, j - 1)
    return T if j > n else T @ joint_between_links(kin, j)[0]


def _std_form(robot: Robot, delta, j: int, with_next: bool):
    """(a, d, alpha, c) where joint j's constant part (with the next joint's P when
    ``with_next``) has the standard DH form Rz(c) Tz(d) Tx(a) Rx(alpha), else ()."""
    kin = robot.kinematics
    n = kin.n_joints
    if j < 1 or (with_next and j < n and kin.beta[j] != 0.0):
        return ()
    site = link_site(kin, j)
    if j == n:  # the flange: F = Tx(a) Rx(alpha)?
        a, alpha = site[0, 3], float(np.arctan2(site[2, 1], site[1, 1]))
        if not np.array_equal(site, tx_rx(a, alpha)):
            return ()
    else:
        a, alpha = kin.a[j], kin.alpha[j]
    return (float(a), float(kin.d[j - 1]), float(alpha), float(kin.theta[j - 1] + delta[j - 1]))


def _xyz_rpy(T: np.ndarray, *std) -> tuple[list[float], list[float]]:
    """URDF xyz and rpy of T: exactly (a cos c, a sin c, d), (alpha, 0, c) for the standard
    DH form ``std`` = (a, d, alpha, c), else from the matrix."""
    if std:
        a, d, alpha, c = std
        return [a * np.cos(c), a * np.sin(c), d], [alpha, 0.0, c]
    return [float(v) for v in T[:3, 3]], rpy_angles(T[:3, :3])


def origin_xyz_rpy(robot: Robot, delta, j: int) -> tuple[list[float], list[float]]:
    """(xyz, rpy) of URDF joint j's origin (``joint_origin``)."""
    std = ()
    if j == 1:
        if np.array_equal(joint_origin(robot, delta, 1), np.eye(4)):
            return [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    else:
        std = _std_form(robot, delta, j - 1, True)
    return _xyz_rpy(joint_origin(robot, delta, j), *std)


def joint_names(robot: Robot) -> list[str]:
    """The URDF's joint names: robot.json's ``joint_names`` where it has them (an imported
    robot keeps its URDF's), else joint1..joint6."""
    return list(robot.joint_names) if robot.joint_names else [f"joint{i}" for i in range(1, 7)]


def robot_name(robot: Robot) -> str:
    return re.sub(r"[^a-z0-9]+", "_", robot.name.lower()).strip("_") or "robot"


def urdf_tree(robot: Robot, params: CellParams, name: str | None = None,
              meshes: list[MeshRef] | None = None, source: str = "") -> ET.ElementTree:
    """The URDF document (module docstring) for ``robot`` with ``params``' joint offsets and
    sensor pose."""
    if robot.n_joints != 6:
        raise ValueError(f"{robot.name}: URDF export is written for six joints")
    delta = np.asarray(params.joint_offsets, float)
    root = ET.Element("robot", name=name or robot_name(robot))
    from planecal import __version__
    root.append(ET.Comment(
        f" written by planecal {__version__}: {robot.name}"
        + (f"; {source}" if source else "")
        + ". Joint values are planecal's joint angles q [rad]; the joint offsets are in the "
          "joint origins' yaw. "))
    links = {n: ET.SubElement(root, "link", name=n) for n in LINKS}
    by_link: dict[str, list[tuple[MeshRef, tuple | None]]] = {}
    for m in meshes or []:
        if m.kind not in ("visual", "collision"):
            raise ValueError(f"mesh kind {m.kind!r}: visual or collision")
        if m.body == 0:
            T0 = robot.kinematics.base @ link_site(robot.kinematics, 0)
            by_link.setdefault("base", []).append(
                (m, None if np.array_equal(T0, np.eye(4)) else _xyz_rpy(T0)))
        elif 1 <= m.body <= 5:
            by_link.setdefault(f"link{m.body}", []).append((m, link_constant(robot, delta, m.body - 1)))
        elif m.body == 6:
            by_link.setdefault("flange", []).append((m, None))
        else:
            raise ValueError(f"mesh {m.filename}: body {m.body} is not a DH frame 0..6")
    for link, refs in by_link.items():
        for m, origin in sorted(refs, key=lambda r: r[0].kind == "collision"):
            el = ET.SubElement(links[link], m.kind, **({"name": m.name} if m.name else {}))
            if origin is not None:
                ET.SubElement(el, "origin", xyz=_vec(origin[0]), rpy=_vec(origin[1]))
            ET.SubElement(ET.SubElement(el, "geometry"), "mesh", filename=m.filename)
    if any(m.kind == "visual" for m in meshes or []):
        # one grey for every visual (a URDF colour is declared once, by name)
        mat = ET.Element("material", name="planecal_grey")
        ET.SubElement(mat, "color", rgba="0.75 0.75 0.78 1")
        root.insert(1, mat)
        for v in root.iter("visual"):
            ET.SubElement(v, "material", name="planecal_grey")

    root.append(ET.Comment(" robot.json holds no joint speeds or torques: velocity and "
                           "effort are 0 (unknown), give a planner its own limits "))
    parent = "base"
    names = joint_names(robot)
    for i in range(6):
        j = ET.SubElement(root, "joint", name=names[i], type="revolute")
        ET.SubElement(j, "parent", link=parent)
        ET.SubElement(j, "child", link=f"link{i + 1}")
        xyz, rpy = origin_xyz_rpy(robot, delta, i + 1)
        ET.SubElement(j, "origin", xyz=_vec(xyz), rpy=_vec(rpy))
        ET.SubElement(j, "axis", xyz="0 0 1")
        lo, hi = robot.limits[i]
        ET.SubElement(j, "limit", lower=_num(lo), upper=_num(hi), effort="0", velocity="0")
        parent = f"link{i + 1}"
    j = ET.SubElement(root, "joint", name="flange_joint", type="fixed")
    ET.SubElement(j, "parent", link="link6")
    ET.SubElement(j, "child", link="flange")
    xyz, rpy = origin_xyz_rpy(robot, delta, 7)
    ET.SubElement(j, "origin", xyz=_vec(xyz), rpy=_vec(rpy))
    j = ET.SubElement(root, "joint", name="laser_joint", type="fixed")
    ET.SubElement(j, "parent", link="flange")
    ET.SubElement(j, "child", link="laser")
    ET.SubElement(j, "origin", xyz=_vec(params.sensor_origin),
                  rpy=_vec([0.0, params.phi_y, params.phi_z]))
    tree = ET.ElementTree(root)
    ET.indent(tree)
    return tree


def urdf_text(robot: Robot, params: CellParams, name: str | None = None,
              meshes: list[MeshRef] | None = None, source: str = "") -> str:
    tree = urdf_tree(robot, params, name, meshes, source)
    return '<?xml version="1.0"?>\n' + ET.tostring(tree.getroot(), encoding="unicode") + "\n"
