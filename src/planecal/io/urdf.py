"""URDF of the robot, nominal or calibrated, for ROS/MoveIt, FIGAROH and any URDF tool.

Tree: ``base`` (the robot base frame, DH frame 0) -> ``joint1`` .. ``joint6`` (revolute,
links ``link1`` .. ``link6``) -> ``flange`` (fixed, DH frame 6) -> ``laser`` (fixed, the
sensor frame: origin o in the flange frame, rotation Rz(phi_z) Ry(phi_y), z = the beam).

A URDF joint's value is planecal's joint angle q (what ``encoder.counts_to_joints``
gives), so a URDF consumer's forward kinematics at q is ``kinematics.fk(robot.kinematics.with_offsets(delta), q)``.
Standard DH, ``T_i = Rz(q_i + c_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`` with
``c_i = theta0_i + delta_i``. A URDF joint turns its child about an axis after a fixed
origin; since Rz(q + c) = Rz(q) Rz(c), joint i turns by q_i about z and the constant part
of link i, ``Rz(c_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``, is the origin of the next joint (of
the fixed ``flange`` joint after link 6):

    xyz = (a_i cos c_i, a_i sin c_i, d_i),   rpy = (alpha_i, 0, c_i)

(URDF's rpy is R = Rz(yaw) Ry(pitch) Rx(roll)). Every origin is exact in xyz/rpy form:
no matrix-to-angles conversion, no gimbal lock. The calibrated joint offsets delta sit in
those yaws. Joint limits are robot.json's (on q). robot.json holds no joint speeds or
torques; URDF requires both attributes, so they are written as 0 with a comment saying
they are unknown (a motion planner needs its own).

Shapes are optional: ``MeshRef`` entries (a mesh file whose vertices are in DH frame
``body``, as ``planecal.model.geometry`` builds them) become ``<visual>``/``<collision>``
elements; frame 0 goes to ``base``, frames 1..5 to ``link1..5`` (origin: the constant part
above), frame 6 (the wrist's last link and the tool) to ``flange``.

This module reads a ``Robot`` and ``CellParams``; it knows nothing of files above them.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from planecal.model.cell_params import CellParams
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
    """(xyz, rpy) of the constant part of DH link i (0-based): Rz(c) Tz(d) Tx(a) Rx(alpha),
    c = theta0_i + delta_i (module docstring)."""
    c = float(robot.theta0[i] + delta[i])
    a, d, alpha = float(robot.a[i]), float(robot.d[i]), float(robot.alpha[i])
    return [a * np.cos(c), a * np.sin(c), d], [alpha, 0.0, c]


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
            by_link.setdefault("base", []).append((m, None))
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
    for i in range(6):
        j = ET.SubElement(root, "joint", name=f"joint{i + 1}", type="revolute")
        ET.SubElement(j, "parent", link=parent)
        ET.SubElement(j, "child", link=f"link{i + 1}")
        if i == 0:
            xyz, rpy = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        else:
            xyz, rpy = link_constant(robot, delta, i - 1)
        ET.SubElement(j, "origin", xyz=_vec(xyz), rpy=_vec(rpy))
        ET.SubElement(j, "axis", xyz="0 0 1")
        lo, hi = robot.limits[i]
        ET.SubElement(j, "limit", lower=_num(lo), upper=_num(hi), effort="0", velocity="0")
        parent = f"link{i + 1}"
    j = ET.SubElement(root, "joint", name="flange_joint", type="fixed")
    ET.SubElement(j, "parent", link="link6")
    ET.SubElement(j, "child", link="flange")
    xyz, rpy = link_constant(robot, delta, 5)
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
