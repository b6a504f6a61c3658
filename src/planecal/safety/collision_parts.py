"""The parts of the collision world (``planecal.safety.collision``) and which pairs of
them are checked.

A part is one mesh on one body (the robot's links and the tool on bodies 0..6, plates,
stands, floor and obstacles static in the base frame) made FCL geometry: an exact
``fcl.Box`` where the mesh is that box, ``fcl.Convex`` where it is convex, else an
``fcl.BVHModel``, with a BVH of its triangles, its vertices and bounding sphere in the body
frame (``make_part``). The floor is solid ground, ``FLOOR_DEPTH_M`` deep
(``static_parts``). ``support_gap`` and ``contained`` are the two checks of a distance
that the world's ``_distance`` makes (the GJK certificate, a part inside another);
``checked_pairs`` the pair rules (module docstring of ``collision``); ``static_boxes``
the boxes of the static parts for the cheap lower bounds.
"""
from __future__ import annotations

from dataclasses import dataclass

import fcl
import numpy as np

from planecal.base.errors import InputError
from planecal.model.mesh import Mesh, box

FLOOR_DEPTH_M = 10.0  # the floor box reaches this far below the floor's top face


@dataclass
class Part:
    """One part of the collision world: its FCL geometry, its triangles and bounds."""
    name: str
    body: int  # -1 for static parts
    kind: str  # 'link' | 'tool' | 'plate' | 'stand' | 'floor' | 'obstacle'
    geom: object  # fcl.Box | fcl.Convex (convex parts) | fcl.BVHModel (others)
    obj: fcl.CollisionObject
    T_body_geom: np.ndarray  # 4x4, FCL geometry frame in the body (or base) frame
    V: np.ndarray  # (n,3) vertices in the body frame (base frame if static)
    center: np.ndarray  # (3,) bounding-sphere centre, body frame
    radius: float
    tri: Mesh  # the part's triangles in the body frame (exact BVH, containment test)
    bvh: fcl.CollisionObject  # BVH of tri: triangle-exact distances, no GJK
    convex: bool = True
    is_identity: bool = False

    def __post_init__(self):
        self.is_identity = bool(np.array_equal(self.T_body_geom, np.eye(4)))


def _transform(T: np.ndarray) -> fcl.Transform:
    return fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


def _bvh(V: np.ndarray, faces: np.ndarray) -> fcl.BVHModel:
    bvh = fcl.BVHModel()
    bvh.beginModel(len(V), len(faces))
    bvh.addSubModel(np.ascontiguousarray(V, float), np.ascontiguousarray(faces, np.int32))
    bvh.endModel()
    return bvh


def make_part(name, body, kind, mesh, T_body_mesh, box_extents=None, box_pose=None) -> Part:
    """An exact fcl.Box where the mesh is that box, fcl.Convex where it is convex, a BVH
    otherwise; every part also gets a BVH of its triangles for exact distances."""
    V = np.asarray(mesh.vertices, float) @ T_body_mesh[:3, :3].T + T_body_mesh[:3, 3]
    faces = np.asarray(mesh.faces, np.int64)
    if np.linalg.det(T_body_mesh[:3, :3]) < 0:
        faces = faces[:, ::-1]
    tri = Mesh(V, faces, bool(mesh.is_convex), bool(mesh.is_watertight))
    geom, Tg, convex = None, np.eye(4), True
    if box_extents is not None and box_pose is not None:
        ext = np.asarray(box_extents, float)
        P = np.asarray(box_pose, float)
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                            for sz in (-1, 1)]) * ext / 2 @ P[:3, :3].T + P[:3, 3]
        # trust the box only if it is the mesh (box_pose given in the body frame)
        if len(V) == 8 and np.allclose(np.sort(corners, 0), np.sort(V, 0), atol=1e-9):
            geom, Tg = fcl.Box(*ext), P
    if geom is None and mesh.is_convex:
        flat = np.hstack([np.full((len(faces), 1), 3), faces]).astype(np.int32).ravel()
        geom = fcl.Convex(np.ascontiguousarray(V), len(faces), flat)
    bvh = _bvh(V, faces)
    if geom is None:
        geom, convex = bvh, False
    c, r = _sphere(V)
    return Part(name, body, kind, geom, fcl.CollisionObject(geom, _transform(Tg)), Tg, V, c, r,
                tri, fcl.CollisionObject(bvh, fcl.Transform()), convex)


def _inside(mesh, x: np.ndarray) -> bool:
    """Point x inside a closed, consistently oriented triangle mesh: its winding number
    (the solid angles of the triangles seen from x, Van Oosterom-Strackee, over 4 pi) is
    1 inside and 0 outside. (trimesh's ``contains`` needs the optional rtree package.)"""
    T = np.asarray(mesh.triangles, float) - x
    a, b, c = T[:, 0], T[:, 1], T[:, 2]
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la
           + np.einsum("ij,ij->i", c, a) * lb)
    return abs(np.arctan2(num, den).sum() / (2 * np.pi)) > 0.5


def _sphere(V: np.ndarray) -> tuple[np.ndarray, float]:
    c = (V.min(0) + V.max(0)) / 2
    return c, float(np.sqrt(((V - c) ** 2).sum(1).max()))


def moving_parts(links, tools) -> list[Part]:
    """The robot's link pieces and the tool's (lists of ``geometry.LinkMesh``), on bodies
    0..6, in that order."""
    parts = []
    for kind, group in (("link", links), ("tool", tools)):
        for lm in group:
            if not 0 <= int(lm.body) <= 6:
                raise InputError(f"collision: part {lm.name!r} has body {lm.body}, expected 0..6")
            T = np.eye(4) if lm.T_body_mesh is None else np.asarray(lm.T_body_mesh, float)
            parts.append(make_part(lm.name, int(lm.body), kind, lm.mesh, T,
                                   lm.box_extents, lm.box_pose))
    return parts


def static_parts(static) -> list[Part]:
    """Plates, stands, floor and obstacles (list of ``geometry.StaticMesh``) in the base
    frame (body -1); the floor as solid ground: same top face and extent, ``FLOOR_DEPTH_M``
    deep."""
    parts = []
    for sm in static:
        ext, pose = sm.box_extents, sm.box_pose
        mesh = sm.mesh
        if sm.kind == "floor":  # solid ground: same top face and extent, deep
            lo, hi = mesh.bounds
            ext = np.array([hi[0] - lo[0], hi[1] - lo[1], FLOOR_DEPTH_M])
            pose = np.eye(4)
            pose[:3, 3] = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2] - FLOOR_DEPTH_M / 2]
            mesh = box(ext, pose)
        parts.append(make_part(sm.name, -1, sm.kind, mesh, np.eye(4), ext, pose))
    return parts


def checked_pairs(parts: list[Part], n_moving: int, allowed_pairs=()):
    """The pairs of ``parts`` (the first ``n_moving`` moving) to check: (pairs [(i, j)],
    kinds ['self' | 'environment'], skipped [(name, name, why)]), why 'allowed' (in
    ``allowed_pairs``), 'adjacent' or 'bolted' (the floor and bodies 0, 1); parts on one
    body are rigidly attached and not listed."""
    allowed = {frozenset(p) for p in allowed_pairs}
    pairs, kinds, skipped = [], [], []
    for i in range(n_moving):
        a = parts[i]
        for j in range(i + 1, len(parts)):
            b = parts[j]
            if frozenset((a.name, b.name)) in allowed:
                skipped.append((a.name, b.name, "allowed"))
                continue
            if b.body >= 0:  # self pair
                if a.body == b.body:
                    continue  # rigidly attached to each other
                if _adjacent(a, b):
                    skipped.append((a.name, b.name, "adjacent"))
                    continue
                pairs.append((i, j))
                kinds.append("self")
            else:
                if b.kind == "floor" and a.body in (0, 1):
                    skipped.append((a.name, b.name, "bolted"))
                    continue
                pairs.append((i, j))
                kinds.append("environment")
    return pairs, kinds, skipped


def _adjacent(a: Part, b: Part) -> bool:
    """Parts on neighbouring bodies (a joint between them), or the tool and bodies 5, 6."""
    if a.kind == "tool" or b.kind == "tool":
        other = b if a.kind == "tool" else a
        return other.kind != "tool" and other.body in (5, 6)
    return abs(a.body - b.body) == 1


def static_boxes(parts: list[Part]) -> tuple[np.ndarray, np.ndarray]:
    """(inverse pose (n, 4, 4), half extents (n, 3)) of each static part's box: its exact
    box, else the axis-aligned bounding box of its vertices (zeros for moving parts)."""
    box_inv = np.zeros((len(parts), 4, 4))
    box_half = np.zeros((len(parts), 3))
    for k, p in enumerate(parts):
        if p.body >= 0:
            continue
        if isinstance(p.geom, fcl.Box):  # oriented box: the exact shape
            box_inv[k] = np.linalg.inv(p.T_body_geom)
            box_half[k] = np.ptp(p.V @ p.T_body_geom[:3, :3], axis=0) / 2
        else:  # axis-aligned bounding box of the vertices
            lo, hi = p.V.min(0), p.V.max(0)
            box_inv[k] = np.eye(4)
            box_inv[k, :3, 3] = -(lo + hi) / 2
            box_half[k] = (hi - lo) / 2
    return box_inv, box_half


def support_gap(a: Part, Ta, b: Part, Tb, u: np.ndarray) -> float:
    """min over b's vertices of u . x minus max over a's (world frame): with x = R v + t,
    u . x = v . (R^T u) + u . t, one product ``u @ T[:3]`` gives both."""
    if Ta is None:
        hi = (a.V @ u).max()
    else:
        w = u @ Ta[:3]
        hi = (a.V @ w[:3]).max() + w[3]
    if Tb is None:
        lo = (b.V @ u).min()
    else:
        w = u @ Tb[:3]
        lo = (b.V @ w[:3]).min() + w[3]
    return float(lo - hi)


def contained(a: Part, b: Part, F: np.ndarray) -> bool:
    """One part wholly inside the other: BVHs (surfaces) report them separated, so
    test one vertex of each against the other (closed meshes only)."""
    for inner, outer in ((a, b), (b, a)):
        if not outer.tri.is_watertight:
            continue
        Ti = F[inner.body] if inner.body >= 0 else np.eye(4)
        x = Ti[:3, :3] @ inner.V[0] + Ti[:3, 3]
        To = F[outer.body] if outer.body >= 0 else np.eye(4)
        x = To[:3, :3].T @ (x - To[:3, 3])
        lo, hi = outer.tri.bounds
        if np.all(x >= lo) and np.all(x <= hi) and _inside(outer.tri, x):
            return True
    return False
