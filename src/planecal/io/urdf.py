"""URDF of the robot, nominal or calibrated, for ROS/MoveIt, FIGAROH and any URDF tool.

Tree: ``base`` (the robot base frame: planecal's cell frame) -> ``joint1`` .. ``joint6``
(revolute; robot.json's ``joint_names`` where it has them; links ``link1`` .. ``link6``)
-> ``flange`` (fixed, the flange frame) -> ``laser`` (fixed, the sensor frame: origin o in
the flange frame, rotation Rz(phi_z) Ry(phi_y), z = the beam).

The chain written is the model's: ``measurement.kinematics_of(robot, params)``, robot.json's
nominal chain with the parameters' joint offsets, joint geometry (alpha, a, beta, d) and
base frame (the nominal model for the scene's nominal parameters). A URDF joint's value
is planecal's joint angle q (what ``encoder.counts_to_joints`` gives), so a URDF
consumer's forward kinematics at q is that model's flange (``measurement.flange_pose``).
What a URDF cannot hold is left out (``not_in_urdf``): joint compliance (the deflection
depends on the pose) and level 3's gear harmonics, backlash and laser linearity.

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
other origin (a Hayati beta, a base frame, an imported robot's base and flange) is
converted from its matrix (to ~1e-16). The joint offsets delta sit in those yaws. Joint
limits are robot.json's (on q); ``velocity`` is the fastest the controller link lets a
joint move: robot.json's ``trip_step_counts`` a tick over the joint's encoder gain (the
UR5's 180 deg/s; for the MC70's FD11 link 0.11-0.24 rad/s, far below the arm's own);
robot.json has no torques, so ``effort`` is 0 (unknown; a comment says so).

Masses: each link frame's masses (robot.json's ``masses``, lumped by
``gravity.lumped``: total mass, centre of mass, inertia about it, point masses none) are
the ``<inertial>`` of the URDF link that carries the frame (``link1..5``, ``flange`` for
frame 6), so ``planecal robot import`` of the file reads them back.

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
from planecal.model.gravity import inertia_matrix, lumped
from planecal.model.kinematics import (Kinematics, joint_between_links, link_site, rot,
                                       rpy_angles, tx_rx)
from planecal.model.measurement import kinematics_of
from planecal.model.robot import Robot

LINKS = ("base", "link1", "link2", "link3", "link4", "link5", "link6", "flange", "laser")


@dataclass(frozen=True)
class MeshRef:
    """A mesh file for the URDF: vertices in DH frame ``body`` (0 base .. 6 flange)."""
    body: int
    kind: str  # "visual" or "collision"
    filename: str  # as written into the URDF (relative path or URI)
    name: str = ""


def not_in_urdf(params: CellParams) -> list[str]:
    """What of ``params`` a URDF (a fixed chain) cannot hold, in words: joint compliance
    (a deflection that depends on the pose) and level 3's terms, where non-zero."""
    return [what for what, on in (("the joint compliance", params.compliance.any()),
                                  ("the gear harmonics", params.gear.any()),
                                  ("the backlash", params.backlash.any()),
                                  ("the laser's linearity", params.laser.any())) if on]


def _num(v: float) -> str:
    """Shortest text that reads back as the same double (exact round trip)."""
    v = float(v)
    return "0" if v == 0 else repr(v)


def _vec(v) -> str:
    return " ".join(_num(x) for x in v)


def link_constant(kin: Kinematics, i: int) -> tuple[list[float], list[float]]:
    """(xyz, rpy) of the constant part of joint i+1 (0-based i) of the chain ``kin``:
    Rz(c) A (module docstring); for a standard DH row Rz(c) Tz(d) Tx(a) Rx(alpha)."""
    return _xyz_rpy(_constant(kin, i + 1), *_std_form(kin, i + 1, False))


def _constant(kin: Kinematics, j: int) -> np.ndarray:
    _, A = joint_between_links(kin, j)
    Rz = np.eye(4)
    Rz[:3, :3] = rot(2, float(kin.theta[j - 1]))
    return Rz @ A


def joint_origin(kin: Kinematics, j: int) -> np.ndarray:
    """The origin (4x4) of URDF joint j (1-based; j = n + 1: the fixed flange joint) in its
    parent link (module docstring)."""
    n = kin.n_joints
    T = kin.base @ link_site(kin, 0) if j == 1 else _constant(kin, j - 1)
    return T if j > n else T @ joint_between_links(kin, j)[0]


def _std_form(kin: Kinematics, j: int, with_next: bool):
    """(a, d, alpha, c) where joint j's constant part (with the next joint's P when
    ``with_next``) has the standard DH form Rz(c) Tz(d) Tx(a) Rx(alpha), else ()."""
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
    return (float(a), float(kin.d[j - 1]), float(alpha), float(kin.theta[j - 1]))


def _xyz_rpy(T: np.ndarray, *std) -> tuple[list[float], list[float]]:
    """URDF xyz and rpy of T: exactly (a cos c, a sin c, d), (alpha, 0, c) for the standard
    DH form ``std`` = (a, d, alpha, c), else from the matrix."""
    if std:
        a, d, alpha, c = std
        return [a * np.cos(c), a * np.sin(c), d], [alpha, 0.0, c]
    return [float(v) for v in T[:3, 3]], rpy_angles(T[:3, :3])


def origin_xyz_rpy(kin: Kinematics, j: int) -> tuple[list[float], list[float]]:
    """(xyz, rpy) of URDF joint j's origin (``joint_origin``)."""
    std = ()
    if j == 1:
        if np.array_equal(joint_origin(kin, 1), np.eye(4)):
            return [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    else:
        std = _std_form(kin, j - 1, True)
    return _xyz_rpy(joint_origin(kin, j), *std)


def joint_names(robot: Robot) -> list[str]:
    """The URDF's joint names: robot.json's ``joint_names`` where it has them (an imported
    robot keeps its URDF's), else joint1..joint6."""
    return list(robot.joint_names) if robot.joint_names else [f"joint{i}" for i in range(1, 7)]


def robot_name(robot: Robot) -> str:
    return re.sub(r"[^a-z0-9]+", "_", robot.name.lower()).strip("_") or "robot"


def joint_velocities(robot: Robot) -> np.ndarray:
    """Per joint the fastest the controller link lets it move [rad/s]: robot.json's trip
    step a tick over the joint's encoder gain (module docstring)."""
    return robot.trip_step_counts / (np.abs(robot.gains) * robot.tick_s)


def _link_of(kin: Kinematics, frame: int) -> tuple[str, np.ndarray]:
    """The URDF link carrying link frame ``frame`` (1..6) and the frame's pose in it."""
    if frame == kin.n_joints:
        return "flange", np.eye(4)
    return f"link{frame}", _constant(kin, frame)


def _inertials(robot: Robot, kin: Kinematics, links: dict) -> None:
    """Each URDF link's ``<inertial>``: the masses of the link frames it carries, lumped
    (``gravity.lumped``) in the link's axes."""
    by_link: dict[str, list] = {}
    for frame, com, m, six in robot.masses:
        link, X = _link_of(kin, frame)
        J = inertia_matrix(six)
        by_link.setdefault(link, []).append((X[:3, :3] @ np.asarray(com, float) + X[:3, 3], m,
                                             None if J is None else X[:3, :3] @ J @ X[:3, :3].T))
    for link, masses in by_link.items():
        M, c, I = lumped(masses)
        if not M:
            continue
        el = ET.SubElement(links[link], "inertial")
        ET.SubElement(el, "origin", xyz=_vec(c), rpy="0 0 0")
        ET.SubElement(el, "mass", value=_num(M))
        ET.SubElement(el, "inertia", ixx=_num(I[0, 0]), ixy=_num(I[0, 1]), ixz=_num(I[0, 2]),
                      iyy=_num(I[1, 1]), iyz=_num(I[1, 2]), izz=_num(I[2, 2]))


def _shapes(robot: Robot, kin: Kinematics, links: dict, root, meshes) -> None:
    """The meshes as ``<visual>``/``<collision>`` elements of their links (module
    docstring), one grey material for every visual."""
    by_link: dict[str, list[tuple[MeshRef, tuple | None]]] = {}
    for m in meshes:
        if m.kind not in ("visual", "collision"):
            raise ValueError(f"mesh kind {m.kind!r}: visual or collision")
        if m.body == 0:
            T0 = kin.base @ link_site(kin, 0)
            by_link.setdefault("base", []).append(
                (m, None if np.array_equal(T0, np.eye(4)) else _xyz_rpy(T0)))
        elif 1 <= m.body <= 5:
            by_link.setdefault(f"link{m.body}", []).append((m, link_constant(kin, m.body - 1)))
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
    if any(m.kind == "visual" for m in meshes):
        # one grey for every visual (a URDF colour is declared once, by name)
        mat = ET.Element("material", name="planecal_grey")
        ET.SubElement(mat, "color", rgba="0.75 0.75 0.78 1")
        root.insert(1, mat)
        for v in root.iter("visual"):
            ET.SubElement(v, "material", name="planecal_grey")


def urdf_tree(robot: Robot, params: CellParams, name: str | None = None,
              meshes: list[MeshRef] | None = None, source: str = "") -> ET.ElementTree:
    """The URDF document (module docstring) of the model ``robot`` with ``params`` (its
    joint offsets, geometry and base frame; ``not_in_urdf`` says what is left out), its
    sensor pose and robot.json's masses."""
    if robot.n_joints != 6:
        raise ValueError(f"{robot.name}: URDF export is written for six joints")
    kin = kinematics_of(robot, params)
    root = ET.Element("robot", name=name or robot_name(robot))
    from planecal import __version__
    left = not_in_urdf(params)
    root.append(ET.Comment(
        f" written by planecal {__version__}: {robot.name}"
        + (f"; {source}" if source else "")
        + ". Joint values are planecal's joint angles q [rad]; the joint offsets are in the "
          "joint origins' yaw, the joint geometry and base frame in the origins"
        + (f"; not in a URDF: {', '.join(left)}" if left else "") + ". "))
    links = {n: ET.SubElement(root, "link", name=n) for n in LINKS}
    _inertials(robot, kin, links)
    _shapes(robot, kin, links, root, meshes or [])
    root.append(ET.Comment(" velocity: the fastest the controller link moves a joint (robot.json's "
                           "trip step a tick); robot.json holds no torques: effort is 0 "
                           "(unknown), give a planner its own limits "))
    parent = "base"
    names = joint_names(robot)
    for i, v in enumerate(joint_velocities(robot)):
        j = ET.SubElement(root, "joint", name=names[i], type="revolute")
        ET.SubElement(j, "parent", link=parent)
        ET.SubElement(j, "child", link=f"link{i + 1}")
        xyz, rpy = origin_xyz_rpy(kin, i + 1)
        ET.SubElement(j, "origin", xyz=_vec(xyz), rpy=_vec(rpy))
        ET.SubElement(j, "axis", xyz="0 0 1")
        lo, hi = robot.limits[i]
        ET.SubElement(j, "limit", lower=_num(lo), upper=_num(hi), effort="0", velocity=_num(v))
        parent = f"link{i + 1}"
    j = ET.SubElement(root, "joint", name="flange_joint", type="fixed")
    ET.SubElement(j, "parent", link="link6")
    ET.SubElement(j, "child", link="flange")
    xyz, rpy = origin_xyz_rpy(kin, 7)
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
