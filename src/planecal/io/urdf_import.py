"""A URDF made into a planecal robot description: robot.json (the chain, limits, encoder
model, controller limits, masses) and shapes.json with its meshes (``planecal robot
import``; docs/ROBOTS.md).

What it takes: one serial chain of six revolute joints with limits, from the URDF's root
link (the robot's base frame, planecal's cell frame) to a tip link (the flange frame the
sensor mounts on): ``tip`` if given, else the end of the fixed joints after the sixth
joint (``tool0`` where they branch). Side branches of fixed joints (a ``base`` frame, a
``flange`` frame beside ``tool0``) are fine; their shapes and masses ride on the link they
hang from. What it refuses, with a one-line reason naming the joint (InputError, exit 2):
a joint that is prismatic, continuous (no limits), floating, planar or mimics another, a
revolute joint without lower and upper limits, movable joints on two branches, other
than six revolute joints, a zero axis.

The chain: the six joint axes at q = 0 in the root's frame, and the tip's pose there,
become the model's modified-DH-with-beta parameters, base and flange frames by
``kinematics.from_axes`` (exact: the import checks the flange against the URDF's own
forward kinematics, yourdfpy's, over random poses and refuses above ``MATCH_M``). The
URDF's joint angles are planecal's q (same zero, same sign).

Shapes: each <visual> and <collision> element becomes a piece of its link's body
(``use`` visual or collision), its box, cylinder, sphere or mesh placed in planecal's link
frame; meshes (any format trimesh reads) are written as binary STL under ``meshes/``,
already in that frame and scale. ``package://NAME/...`` is found from ``packages``
(NAME -> folder), else by the folders named NAME above the URDF, else in the URDF's
package (its folder's parent, the ROS layout ``NAME/urdf/robot.urdf``).

Masses: each link's <inertial> (mass, centre of mass, inertia) on its body; links fixed
to the base carry no gravity torque and are left out.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError, RunFailed
from planecal.io.urdf_checks import SNAP_RAD, check_tree, inertia_problem, snap_right_angles
from planecal.model.kinematics import Kinematics, fk, from_axes, link_frames, rpy_angles

MATCH_M = 1e-9  # the imported flange's largest difference from the URDF's (m and rotation)
SILENT_RAD = 1e-9  # snaps this small (pi/2 written to 11 digits) are not worth a warning
N = 6
REFUSED = {"prismatic": "a prismatic joint (planecal models revolute arms)",
           "continuous": "continuous (no limits): planecal needs lower and upper limits on "
                         "every joint (make it revolute with <limit lower= upper=>)",
           "floating": "a floating joint (planecal models one serial arm)",
           "planar": "a planar joint (planecal models revolute arms)"}


@dataclass
class Piece:
    name: str
    link: int
    use: str  # 'visual' | 'collision'
    primitive: dict  # one shapes.json primitive
    mesh: tuple | None = None  # (vertices (n, 3), faces (m, 3)) for a mesh primitive
    what: str | None = None


@dataclass
class Imported:
    """What the import found: the chain, its joints and links, shapes and masses."""
    name: str
    kin: Kinematics
    joints: list  # the six yourdfpy joints, base to tip
    limits: np.ndarray  # (6, 2) rad
    velocities: np.ndarray  # (6,) rad/s, 0 where the URDF gives none
    tip: str
    root: str
    body_of: dict  # link name -> body 0..6
    pieces: list[Piece] = field(default_factory=list)
    masses: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)  # repairs and what is not checked
    model: object = None  # yourdfpy's Robot, right angles snapped: what the chain is of
    snapped: list = field(default_factory=list)  # (joint, axis, written, snapped)
    snap_rad: float = SNAP_RAD
    unchecked: str | None = None  # why the arm has no collision pieces (shapes.json's)


def _yourdfpy(path: Path, **kw):
    """yourdfpy's ``URDF.load``, its own log lines silenced (what is wrong is said in one
    line by the caller)."""
    import logging

    import yourdfpy
    log = logging.getLogger("yourdfpy")
    level, log.level = log.level, logging.CRITICAL + 1
    try:
        return yourdfpy.URDF.load(str(path), load_meshes=False, load_collision_meshes=False,
                                  **kw)
    finally:
        log.setLevel(level)


def load_urdf(path: Path):
    """yourdfpy's model of the file, without meshes (one-line InputError if unreadable)."""
    if not path.is_file():
        raise InputError(f"{path}: file not found (URDF)")
    try:
        return _yourdfpy(path, build_scene_graph=False)
    except Exception as e:  # lxml, yourdfpy's own: any reason it cannot be read
        text = (str(e).splitlines() or [type(e).__name__])[0]
        raise InputError(f"{path}: not a URDF yourdfpy can read ({text})") from None


def _children(robot) -> dict:
    out: dict[str, list] = {}
    for j in robot.joints:
        out.setdefault(j.parent, []).append(j)
    return out


def serial_chain(path: Path, robot, root: str, tip: str | None):
    """(the six revolute joints base to tip, the tip link), or InputError (module
    docstring's refusals)."""
    for j in robot.joints:
        if j.type in REFUSED:
            raise InputError(f"{path}: joint {j.name!r} is {REFUSED[j.type]}")
        if j.type not in ("revolute", "fixed"):
            raise InputError(f"{path}: joint {j.name!r}: unknown type {j.type!r}")
        if j.mimic is not None:
            raise InputError(f"{path}: joint {j.name!r} mimics {j.mimic.joint!r}: planecal "
                             "takes independent joints only")
    kids = _children(robot)
    parent_joint = {j.child: j for j in robot.joints}
    revolute = [j for j in robot.joints if j.type == "revolute"]
    if len(revolute) != N:
        raise InputError(f"{path}: {len(revolute)} revolute joints "
                         f"({', '.join(j.name for j in revolute) or 'none'}): planecal takes "
                         f"six-axis arms")

    def ancestors(link):
        out = []
        while link in parent_joint:
            out.append(parent_joint[link])
            link = parent_joint[link].parent
        return out[::-1]

    chain = []
    for j in sorted(revolute, key=lambda j: len(ancestors(j.child))):
        above = [a for a in ancestors(j.child) if a.type == "revolute"]
        if chain and chain[-1] not in above:
            raise InputError(f"{path}: joints {chain[-1].name!r} and {j.name!r} are on "
                             "different branches of the tree: planecal takes one serial chain")
        chain.append(j)
    for j in chain:
        lim = j.limit
        if lim is None or lim.lower is None or lim.upper is None:
            raise InputError(f"{path}: joint {j.name!r}: revolute without <limit lower= upper=> "
                             "(planecal needs both)")
        if not lim.lower < lim.upper:
            raise InputError(f"{path}: joint {j.name!r}: limits [{lim.lower:g}, {lim.upper:g}] "
                             "rad: the lower must be below the upper")
        if j.axis is not None and not np.linalg.norm(j.axis) > 1e-9:
            raise InputError(f"{path}: joint {j.name!r}: axis (0, 0, 0) gives no direction")
    return chain, _tip(path, kids, chain[-1].child, tip, ancestors)


def _tip(path: Path, kids: dict, last: str, tip: str | None, ancestors) -> str:
    if tip is not None:
        if tip != last and last not in [a.parent for a in ancestors(tip)]:
            raise InputError(f"{path}: --tip {tip!r} is not a link fixed to {last!r} (the "
                             "sixth joint's link)")
        return tip
    leaves, stack = [], [last]
    while stack:
        link = stack.pop()
        below = kids.get(link, [])
        if not below:
            leaves.append(link)
        stack.extend(j.child for j in below)
    if len(leaves) == 1:
        return leaves[0]
    if "tool0" in leaves:
        return "tool0"
    raise InputError(f"{path}: the links after the sixth joint end in {', '.join(leaves)}: "
                     "say which is the flange with --tip LINK")


def _origin(j) -> np.ndarray:
    return np.eye(4) if j.origin is None else np.asarray(j.origin, float)


def _axis(j) -> np.ndarray:
    a = np.array([1.0, 0.0, 0.0]) if j.axis is None else np.asarray(j.axis, float)
    return a / np.linalg.norm(a)


def world_poses(robot, root: str) -> dict:
    """Every link's pose in the root's frame at q = 0."""
    kids = _children(robot)
    W, stack = {root: np.eye(4)}, [root]
    while stack:
        link = stack.pop()
        for j in kids.get(link, []):
            W[j.child] = W[link] @ _origin(j)
            stack.append(j.child)
    return W


def import_chain(path: Path, tip: str | None = None,
                 snap_rad: float = SNAP_RAD) -> tuple[Imported, object]:
    """The URDF's chain (``Imported`` without shapes and masses) and yourdfpy's model;
    the chain's origins' near-right angles snapped (``urdf_checks.snap_right_angles``)."""
    u = load_urdf(path)
    robot = u.robot
    children = {j.child for j in robot.joints}
    roots = [link.name for link in robot.links if link.name not in children]
    if len(roots) != 1:
        raise InputError(f"{path}: {len(roots)} root links ({', '.join(roots) or 'none'}): a "
                         "robot is one tree from its base link")
    root = roots[0]
    check_tree(path, robot, root)
    if tip is not None and tip not in {link.name for link in robot.links}:
        raise InputError(f"{path}: --tip {tip!r}: no link of that name (the flange link)")
    joints, tip = serial_chain(path, robot, root, tip)
    parent_joint = {j.child: j for j in robot.joints}
    on_chain, link = set(), tip
    while link in parent_joint:
        on_chain.add(parent_joint[link].name)
        link = parent_joint[link].parent
    snapped = snap_right_angles(path, robot, on_chain, snap_rad)
    W = world_poses(robot, root)
    points = np.array([(W[j.parent] @ _origin(j))[:3, 3] for j in joints])
    axes = np.array([(W[j.parent] @ _origin(j))[:3, :3] @ _axis(j) for j in joints])
    kin = from_axes(points, axes, W[tip])
    limits = np.array([[j.limit.lower, j.limit.upper] for j in joints], float)
    vel = np.array([float(j.limit.velocity or 0.0) for j in joints])
    body_of = _bodies(robot, root, joints)
    imp = Imported(robot.name, kin, joints, limits, vel, tip, root, body_of, model=robot,
                   snapped=snapped, snap_rad=snap_rad)
    return imp, u


def _bodies(robot, root: str, joints) -> dict:
    """Link -> the body (0..6) it moves with: the last of the six joints above it."""
    index = {j.name: i + 1 for i, j in enumerate(joints)}
    kids = _children(robot)
    body, stack = {root: 0}, [root]
    while stack:
        link = stack.pop()
        for j in kids.get(link, []):
            body[j.child] = index.get(j.name, body[link])
            stack.append(j.child)
    return body


def _flange_difference(u, imp: Imported, kin: Kinematics, n: int, seed: int) -> tuple:
    """(largest entry difference, largest translation [m], largest rotation [rad]) of
    ``kin``'s flange from yourdfpy's model ``u`` over n random poses within the limits."""
    names = [j.name for j in imp.joints]
    rng = np.random.default_rng(seed)
    worst = move = turn = 0.0
    for q in rng.uniform(imp.limits[:, 0], imp.limits[:, 1], (n, N)):
        u.update_cfg(dict(zip(names, q)))
        U, K = u.get_transform(imp.tip, imp.root), fk(kin, q)
        worst = max(worst, float(np.abs(U - K).max()))
        move = max(move, float(np.linalg.norm(U[:3, 3] - K[:3, 3])))
        c = (np.trace(U[:3, :3].T @ K[:3, :3]) - 1) / 2
        turn = max(turn, float(np.arccos(np.clip(c, -1.0, 1.0))))
    return worst, move, turn


def check_flange(path: Path, imp: Imported, kin: Kinematics | None = None, n: int = 200,
                 seed: int = 0) -> float:
    """Largest difference (m; rotation entries alike) of the flange of ``kin`` (default the
    import's chain) from the URDF's (yourdfpy's forward kinematics, of the URDF with its
    near-right angles snapped as the import did) over n random poses within the limits;
    RunFailed above MATCH_M. Each snap is noted with how far the flange moves from the
    URDF as written."""
    import yourdfpy
    kin = imp.kin if kin is None else kin
    u = (_yourdfpy(path, build_scene_graph=True) if imp.model is None else
         yourdfpy.URDF(robot=imp.model, build_scene_graph=True, load_meshes=False,
                       load_collision_meshes=False))
    worst = _flange_difference(u, imp, kin, n, seed)[0]
    if not worst <= MATCH_M:
        raise RunFailed(f"{path}: the imported chain's flange is {worst:.3g} m off the URDF's "
                        f"(at most {MATCH_M:g}): not imported")
    if imp.snapped and max(abs(w - n) for _, _, w, n in imp.snapped) > SILENT_RAD:
        _, move, turn = _flange_difference(_yourdfpy(path, build_scene_graph=True), imp, kin,
                                           n, seed)
        which = ", ".join(f"{joint} {axis} {was!r}" for joint, axis, was, _ in imp.snapped)
        off = max(abs(was - now) for _, _, was, now in imp.snapped)
        imp.warnings.append(
            f"joint origins {which}: taken as multiples of 90 deg (at most {off:.2g} rad off, "
            f"within {imp.snap_rad:g}: the URDF's rounding); the flange moves "
            f"{move * 1e6:.3g} um and turns {turn * 1e6:.3g} urad at most from the URDF as "
            "written (--snap-rad 0 keeps every angle)")
    return worst


def shapes_and_masses(path: Path, imp: Imported, u, packages: dict, visual_from: str) -> None:
    """Fill ``imp.pieces`` and ``imp.masses`` from the URDF's links (module docstring);
    ``visual_from`` 'visual' (the URDF's) or 'collision' (its collision elements drawn
    as the visuals too: for a URDF whose visual meshes are missing or unreadable)."""
    W = world_poses(u.robot, imp.root)
    G = link_frames(imp.kin, np.zeros(N))
    from_visual = []
    for link in u.robot.links:
        body = imp.body_of.get(link.name)
        if body is None:
            continue
        to_link = np.linalg.inv(G[body]) @ W[link.name]  # URDF link -> planecal link frame
        collisions, what = link.collisions, None
        if not collisions and link.visuals:  # the checker's envelope: the visual's hull
            collisions, what = link.visuals, "the visual element's hull (no <collision>)"
            from_visual.append(link.name)
        kinds = (("visual", collisions if visual_from == "collision" else link.visuals),
                 ("collision", collisions))
        for use, elements in kinds:
            for k, el in enumerate(elements):
                M = to_link @ (np.eye(4) if el.origin is None else np.asarray(el.origin, float))
                name = f"{link.name}_{use}{k}" if len(elements) > 1 else f"{link.name}_{use}"
                imp.pieces.append(_piece(path, name, body, use, el.geometry, M, packages))
                imp.pieces[-1].what = what if use == "collision" else None
        inert = link.inertial
        if body >= 1 and inert is not None and inert.mass and inert.mass > 0:
            O = to_link @ (np.eye(4) if inert.origin is None else np.asarray(inert.origin, float))
            R = O[:3, :3]
            J = R @ np.asarray(inert.inertia, float) @ R.T if inert.inertia is not None else None
            why = None if J is None else inertia_problem(J)
            if why:
                imp.warnings.append(f"link {link.name!r}: <inertia> is no rigid body's: {why}; "
                                    f"left out, the link is a point mass of {inert.mass:g} kg at "
                                    "its centre of mass (the gravity torque is the same)")
                J = None
            imp.masses.append({
                "frame": body, "com_m": [float(v) for v in O[:3, 3]], "mass_kg": float(inert.mass),
                **({} if J is None else {"inertia_kg_m2": [float(J[0, 0]), float(J[1, 1]),
                                                          float(J[2, 2]), float(J[0, 1]),
                                                          float(J[0, 2]), float(J[1, 2])]}),
                "what": f"link {link.name}"})
    if from_visual:
        imp.warnings.append(
            f"links {', '.join(from_visual)} have no <collision>: the collision checker takes "
            "their visual elements' convex hulls (grown by its margin) as their envelopes; "
            "check them against the real arm")
    shaped = {p.link for p in imp.pieces if p.use == "collision"}
    bare = [b for b in range(N + 1) if b not in shaped]
    if not shaped:
        imp.unchecked = (f"{path.name} has no <collision> or <visual> elements: the checker "
                         "sees only the tool and the cell, never the arm's links")
        imp.warnings.append(f"the robot is not checked for collisions: {imp.unchecked} "
                            "(shapes.json says so; give it pieces, docs/ROBOTS.md)")
    elif bare:
        links = {b: [n for n, v in imp.body_of.items() if v == b] for b in bare}
        imp.warnings.append(
            "no shape on " + "; ".join(f"body {b} (links {', '.join(links[b])})" for b in bare)
            + ": the collision checker cannot see those links")


def _piece(path: Path, name: str, body: int, use: str, geom, M: np.ndarray,
           packages: dict) -> Piece:
    where = f"{path}: link element {name}"
    if geom.box is not None:
        return Piece(name, body, use, {"box": {"center_m": _list(M[:3, 3]),
                                               "size_m": _list(geom.box.size),
                                               "rpy_rad": _list(rpy_angles(M[:3, :3]))}})
    if geom.cylinder is not None:
        h = M[:3, 2] * float(geom.cylinder.length) / 2
        return Piece(name, body, use, {"cylinder": {"from_m": _list(M[:3, 3] - h),
                                                    "to_m": _list(M[:3, 3] + h),
                                                    "radius_m": float(geom.cylinder.radius)}})
    if geom.sphere is not None:
        return Piece(name, body, use, {"sphere": {"center_m": _list(M[:3, 3]),
                                                  "radius_m": float(geom.sphere.radius)}})
    if geom.mesh is None:
        raise InputError(f"{where}: no geometry")
    f = resolve(path, geom.mesh.filename, packages)
    V, F = read_mesh(f, where)
    scale = np.ones(3) if geom.mesh.scale is None else np.broadcast_to(
        np.asarray(geom.mesh.scale, float), 3)
    A = M[:3, :3] * scale
    if np.linalg.det(A) < 0:
        F = F[:, ::-1]
    V = V @ A.T + M[:3, 3]
    return Piece(name, body, use, {"mesh": {"file": f"meshes/{name}.stl"}}, (V, F))


def resolve(path: Path, filename: str, packages: dict) -> Path:
    """The file a URDF mesh name means (module docstring); InputError if not found."""
    if filename.startswith("package://"):
        pkg, _, rel = filename[len("package://"):].partition("/")
        tried = []
        roots = [Path(packages[pkg])] if pkg in packages else []
        roots += [p for p in path.resolve().parents if p.name == pkg]
        roots.append(path.resolve().parent.parent)
        for r in roots:
            tried.append(str(r))
            if (r / rel).is_file():
                return r / rel
        raise InputError(f"{path}: mesh {filename}: not found (looked in {', '.join(tried)}; "
                         f"give --package {pkg}=FOLDER, or --visual collision where only the "
                         "visual meshes are missing)")
    f = Path(filename[len("file://"):] if filename.startswith("file://") else filename)
    f = f if f.is_absolute() else path.parent / f
    if not f.is_file():
        raise InputError(f"{path}: mesh {filename}: not found ({f})")
    return f


def read_mesh(f: Path, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a mesh file (trimesh reads STL, OBJ, PLY; DAE with pycollada)."""
    import trimesh
    try:
        m = trimesh.load(str(f), force="mesh")
        V, F = np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)
    except Exception as e:  # any reader's failure: one line
        text = (str(e).splitlines() or [type(e).__name__])[0]
        raise InputError(f"{where}: cannot read the mesh {f.name} ({text})") from None
    if len(V) < 4 or len(F) < 4:
        raise InputError(f"{where}: the mesh {f.name} holds no solid ({len(F)} triangles)")
    return V, F


def _list(v) -> list[float]:
    return [float(x) for x in np.asarray(v, float).ravel()]


def shapes_document(path: Path, imp: Imported) -> dict:
    """shapes.json's document (its meshes are written by ``write``)."""
    return {"format": "planecal-shapes/1",
            "source": f"the <visual> and <collision> elements of {path.name}, in planecal's "
                      "link frames (planecal robot import)",
            "pieces": [{"name": p.name, "link": p.link, "use": p.use,
                        "primitives": [p.primitive], **({"what": p.what} if p.what else {})}
                       for p in imp.pieces],
            **({"unchecked": imp.unchecked} if imp.unchecked else {})}


def write(out: Path, robot_doc: dict, shapes_doc: dict, imp: Imported) -> None:
    """robot.json, shapes.json and meshes/ into the new folder ``out``."""
    from planecal.formats.base import dumps
    from planecal.model.mesh import Mesh, write_stl
    (out / "meshes").mkdir(parents=True)
    for p in imp.pieces:
        if p.mesh is not None:
            with np.errstate(invalid="ignore", divide="ignore"):
                write_stl(out / p.primitive["mesh"]["file"], Mesh(p.mesh[0], p.mesh[1], False, False))
    for name, doc in (("robot.json", robot_doc), ("shapes.json", shapes_doc)):
        (out / name).write_text(dumps(doc), encoding="utf-8")
