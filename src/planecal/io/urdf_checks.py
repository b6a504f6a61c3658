"""What ``planecal robot import`` checks of a URDF before and beside the chain
(``io.urdf_import``), each finding one line naming the link or joint.

* ``check_tree``: bad input, refused (InputError, exit 2, nothing written): a link that
  is the child of two joints or is not connected to the root (the joints form a loop: a
  URDF is a tree), a link name a file cannot carry (``/``, ``\\``: the import writes each
  link's meshes as ``meshes/<link>_<use>.stl``), a number that is not finite (NaN or inf
  in an origin, axis, limit, inertial or shape).
* ``snap_right_angles``: an ``rpy`` of a joint origin within ``SNAP_RAD`` of a multiple
  of 90 deg is taken as that multiple (the URDF's rounding: 1.57076 for pi/2 is 3.7e-5
  rad short, and breaks a spherical wrist by microns, so that no closed-form inverse
  kinematics applies); each snap is reported with how far it moves the flange.
* ``inertia_problem``: an inertia a rigid body cannot have (a negative eigenvalue, or one
  above the sum of the other two: MuJoCo refuses both); the import leaves it out with a
  warning (the link is a point mass at its centre of mass: the gravity torque, all the
  twin takes from it, is unchanged).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError

SNAP_RAD = 1e-4  # an rpy this close to a multiple of 90 deg is that multiple
BAD_NAME_CHARS = ("/", "\\", "\0")


def check_tree(path: Path, robot, root: str) -> None:
    """Refuse what is not one finite tree of links from ``root`` (module docstring)."""
    for link in robot.links:
        bad = [c for c in BAD_NAME_CHARS if c in link.name]
        if bad or link.name in (".", ".."):
            raise InputError(f"{path}: link {link.name!r}: a link name with {bad[0] if bad else '.'!r} "
                             "cannot name its mesh files (meshes/<link>.stl): rename the link")
    parent: dict = {}
    for j in robot.joints:
        if j.child in parent:
            raise InputError(f"{path}: link {j.child!r} is the child of two joints "
                             f"({parent[j.child].name!r} and {j.name!r}): the joints form a "
                             "loop, and a URDF is a tree")
        parent[j.child] = j
    kids: dict = {}
    for j in robot.joints:
        kids.setdefault(j.parent, []).append(j.child)
    seen, stack = {root}, [root]
    while stack:
        for c in kids.get(stack.pop(), []):
            if c not in seen:
                seen.add(c)
                stack.append(c)
    lost = [j.name for j in robot.joints if j.child not in seen]
    if lost:
        raise InputError(f"{path}: joints {', '.join(lost)} are not connected to the base link "
                         f"{root!r}: they form a loop, and a URDF is a tree")
    for j in robot.joints:
        _finite(path, f"joint {j.name!r}", origin=j.origin, axis=j.axis,
                limit=None if j.limit is None else
                [v for v in (j.limit.lower, j.limit.upper, j.limit.velocity) if v is not None])
    for link in robot.links:
        inert = link.inertial
        if inert is not None:
            _finite(path, f"link {link.name!r} <inertial>", origin=inert.origin,
                    mass=inert.mass, inertia=inert.inertia)
        for el in [*link.visuals, *link.collisions]:
            g = el.geometry
            _finite(path, f"link {link.name!r} <visual>/<collision>", origin=el.origin,
                    box=None if g.box is None else g.box.size,
                    cylinder=None if g.cylinder is None else [g.cylinder.radius, g.cylinder.length],
                    sphere=None if g.sphere is None else g.sphere.radius,
                    scale=None if g.mesh is None else g.mesh.scale)


def _finite(path: Path, where: str, **values) -> None:
    for name, v in values.items():
        if v is None:
            continue
        a = np.asarray(v, float)
        if not np.all(np.isfinite(a)):
            raise InputError(f"{path}: {where}: {name} holds {a.ravel()[~np.isfinite(a.ravel())][0]} "
                             "(every number must be finite)")


def _rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    """URDF's rpy: R = Rz(y) Ry(p) Rx(r)."""
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def snap_right_angles(path: Path, robot, joints: set, tol: float = SNAP_RAD) -> list[tuple]:
    """Snap, in ``robot`` (yourdfpy's model, changed in place), each rpy angle of the
    named joints' origins that lies within ``tol`` (rad) but not exactly at a multiple of
    pi/2 to that multiple, as the file writes it: [(joint, axis 'roll'|'pitch'|'yaw',
    written value, snapped value)]."""
    if tol <= 0:
        return []
    written = {}
    for el in ET.parse(path).getroot().iter("joint"):
        o = el.find("origin")
        if o is not None and el.get("name") in joints:
            written[el.get("name")] = [float(v) for v in o.get("rpy", "0 0 0").split()]
    out = []
    for j in robot.joints:
        rpy = written.get(j.name)
        if rpy is None or len(rpy) != 3:
            continue
        snapped = [round(v / (math.pi / 2)) * (math.pi / 2) for v in rpy]
        moved = [k for k in range(3) if 0 < abs(rpy[k] - snapped[k]) <= tol]
        if not moved:
            continue
        new = [snapped[k] if k in moved else rpy[k] for k in range(3)]
        T = np.asarray(j.origin, float).copy()
        T[:3, :3] = _rpy_matrix(*new)
        j.origin = T
        out += [(j.name, ("roll", "pitch", "yaw")[k], rpy[k], snapped[k]) for k in moved]
    return out


def inertia_problem(J: np.ndarray) -> str | None:
    """Why a symmetric 3x3 inertia is not a rigid body's (module docstring), or None."""
    ev = np.linalg.eigvalsh(0.5 * (J + J.T))
    scale = max(float(np.abs(ev).max()), 1e-300)
    if ev.min() < -1e-12 * scale:  # 0: a point mass or a thin rod, which the twin takes
        return f"eigenvalue {ev.min():.4g} kg m^2, an inertia's are not negative"
    if ev[2] > ev[0] + ev[1] + 1e-9 * scale:
        return (f"eigenvalues {ev[0]:.4g}, {ev[1]:.4g}, {ev[2]:.4g} kg m^2 break the "
                "triangle inequality, the largest at most the sum of the others")
    return None
