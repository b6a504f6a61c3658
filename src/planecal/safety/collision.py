"""Collision checking for the sampling loop: configurations and straight joint-space paths.

The planner only knows nominal values, so every moving part is posed with
``robot.fk_frames(robot, q)`` (no joint offsets) and the scene's nominal sensor mounting.

Parts
-----
* Moving: the robot link pieces (``geometry.robot_link_meshes``, bodies 0..6) and the tool
  (``geometry.tool_meshes``: flange adapter and laser head, body 6).
* Static: plates, stands, floor and obstacles (``geometry.scene_meshes``), in the base frame.

Distances
---------
Each mesh becomes an FCL geometry: an exact ``fcl.Box`` where the geometry module says the
shape is that box, ``fcl.Convex`` where the mesh is convex, else an ``fcl.BVHModel``; every
part also keeps a BVH of its triangles. Convex pairs use FCL's GJK distance d *certified*
by the gap of the two vertex sets along the line through GJK's nearest points
(min u.V_b - max u.V_a, a lower bound for convex sets): if the gap equals d (to 1e-9 m)
it is the distance, otherwise GJK was wrong and the triangle-exact BVH distance is used
(FCL 0.7's GJK overestimates some box and polytope distances with parallel features, by
up to 0.4 m here; fcl issue #508; counted as ``gjk_fallbacks``). A BVH is a surface, so a
part wholly inside another reports "separated": BVH distances are followed by a
point-in-mesh (winding number) test. Contact reports distance 0 (FCL returns -1 on
penetration; no depth is used). The floor is solid ground: its box keeps its top face
and x-y extent and reaches ``FLOOR_DEPTH_M`` down, so a part below the slab is inside it.

Pairs checked
-------------
* Self: moving parts on different bodies, except adjacent bodies (|body_i - body_j| = 1:
  base-link1, link1-link2, ..., link5-link6) and the tool against bodies 5 and 6.
* Environment: every moving part against every static part, except the floor against the
  base (body 0) and link 1, which are bolted to it.
``allowed_pairs`` adds further (name, name) pairs to skip, as does the robot's shapes.json
(its ``allowed_pairs``: pieces its structure keeps apart, a UR's nested wrist joints).
* One-joint pairs (``planecal.safety.collision_joint``): self pairs two bodies apart whose
  distance one joint decides once a part is replaced by its hull of revolution; their safe
  intervals of that joint are swept once per world (``safe_sets``), and a configuration or
  path whose angle of that joint stays inside one is clear for that pair without a query.
  On thesis_final this halves the exact distance queries of a run's path checks (25,916 ->
  12,146 for 150 plans) and changes no verdict.

A configuration is ok when it is within the joint limits and every checked pair is
farther apart than ``clearance_m``.

Path certification (``check_path``): conservative advancement
-------------------------------------------------------------
The step generator moves all joints synchronously and linearly in encoder counts; the
joint angles q = C x are linear in the counts, so the motion is q(s) = q0 + s dq,
s in [0, 1], dq = q1 - q0. A point x on body j moves with

    dx/ds = sum_{k<=j} dq_k z_{k-1} x (x - o_{k-1}),  so  |dx/ds| <= sum_k |dq_k| dist(x, axis k).

Global bound: dist(x, axis k) <= r_kj over *all* configurations: for k = j the exact
largest distance of the part's vertices from axis j (that axis is fixed in frame j); for
k < j, r_kj = |a_k| + sum_{m=k+1..j} hypot(a_m, d_m) + max|v| (o_k is |a_k| from axis k,
consecutive frame origins are hypot(a_m, d_m) apart, v the part's vertices in frame j;
for any chain, ``kinematics.joint_between_links``: |a_k| is the xy part of A_k's
translation and hypot(a_m, d_m) its length).
Convex combinations of vertices move no faster than the fastest vertex, so this bounds
every point. For a self pair (bodies i < j) the distance is measured in frame i, where
body i is still and body j moves with joints i+1..j only; an environment pair counts
all joints up to j. So |d(s') - d(s)| <= L |s' - s|, L = sum_k |dq_k| w_k (``pair_rates``).

Local bound, from a configuration s: D_k = dist(bounding-sphere centre, axis k) + radius
>= dist(x, axis k) now; joint k does not change a point's distance from axis k and the
joints beyond it move the point relative to frame k-1 at most G_k = sum_{m>k} |dq_m| r_mj
per unit s, so dist(x, axis k) <= min(r_kj, D_k + G_k |t - s|) and the displacement over
|t - s| <= h is <= A h + B h^2 / 2 (A = sum |dq_k| D_k, B = sum |dq_k| G_k). The step
certified by a measured gap g = d - c is the larger of g / L and the root of that
quadratic (``_step_sizes``): on it the pair stays farther than c.

Procedure: (1a) every pair at both ends, the target first: cheap lower bounds (bounding
sphere against the static part's box, or sphere against sphere), exact distances only
where a bound is within the clearance; a measured distance <= c + ``resolution_m``
rejects the path; pairs whose end bounds already certify [0, 1] are done. (1b) the other
pairs on ``coarse_samples`` interior grid points, likewise (most rejected paths end in 1a
or 1b); a grid interval [a, b] of a pair is certified when the steps from its ends cover
it, measuring exact distances at the ends of intervals the bounds leave open.
(2) each open interval shrinks by the steps of its ends to [a', b'] and is split at its
midpoint; a', the midpoint and b' are measured exactly, and so on until every interval
is certified, a measurement rejects the path, or a pair exceeds ``max_steps``
refinement rounds ('undecided').
Rejection is always safe; acceptance means every checked pair stays farther than c
everywhere on the segment, in the nominal model with the geometry as given: no false
"clear". ``resolution_m`` ends the slow convergence of steps toward a point where the
distance touches c (a path grazing within 0.1 mm of the clearance is rejected).

Why not ``fcl.continuousCollide``: it certifies a linear or screw *rigid* motion of each
object between two poses; a link under joint interpolation follows neither, so it would
certify a different motion, and it has no clearance.

Counters (``counters``, ``summary()``): configurations and paths checked, clear paths, FCL
distance queries, GJK fallbacks, checking time (``check_time_s``), and rejections by
reason ('limits', 'self', 'environment', 'undecided').

Independent checks live with the tests (tests/mujoco_oracle.py): MuJoCo's own contacts,
and exact distances of the visual (real) link shapes along a path.
"""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass

import fcl
import numpy as np

from planecal.safety.collision_joint import (HULL_SECTIONS, SafeSet, axis_coordinates,
                                      axis_distance_max, hull_of_revolution, sweep)
from planecal.base.errors import InputError
from planecal.model.mesh import Mesh, box, prism
from planecal.model.robot import Robot, within_limits
from planecal.model.kinematics import joint_between_links, link_frames

FLOOR_DEPTH_M = 10.0  # the floor box reaches this far below the floor's top face
REASONS = ("limits", "self", "environment", "undecided")


@dataclass(frozen=True)
class CheckResult:
    """Verdict of a configuration or path check.

    ok: safe (within limits and every checked pair farther than the clearance).
    min_distance_m: smallest distance measured [m] (0 for contact; NaN for a limits
        rejection). For a path, the smallest of the distances measured at the sampled
        configurations, an upper estimate of the minimum along the path; for an accepted
        path every pair stays farther than the clearance everywhere on it.
    pair: (name, name) of the closest (or offending) pair, None if nothing was measured.
    reason: None when ok, else 'limits', 'self', 'environment' or 'undecided'.
    s: path parameter in [0, 1] where the violation was found (paths only).
    """
    ok: bool
    min_distance_m: float
    pair: tuple[str, str] | None
    reason: str | None = None
    s: float | None = None


@dataclass
class _Part:
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


def _make_part(name, body, kind, mesh, T_body_mesh, box_extents=None, box_pose=None) -> _Part:
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
    return _Part(name, body, kind, geom, fcl.CollisionObject(geom, _transform(Tg)), Tg, V, c, r,
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


def _as_q(q, what: str) -> np.ndarray:
    try:
        a = np.asarray(q, float)
    except (TypeError, ValueError):
        raise InputError(f"collision: {what} must be 6 joint angles [rad]") from None
    if a.shape != (6,) or not np.all(np.isfinite(a)):
        raise InputError(f"collision: {what} must be 6 finite joint angles [rad], got shape {a.shape}")
    return a


class CollisionWorld:
    """FCL model of the cell for the planner (nominal kinematics); see the module docstring.

    ``links``, ``tools`` (lists of ``geometry.LinkMesh``) and ``static`` (list of
    ``geometry.StaticMesh``) default to the geometry module's collision shapes of
    ``robot`` (default ``scene.robot``) and ``scene``. ``allowed_pairs``: further
    (name, name) pairs not to check. ``max_steps``: refinement rounds per pair before a
    path is rejected as 'undecided'. ``resolution_m``: a distance measured on a path must
    exceed clearance + resolution. ``coarse_samples``: interior grid points of step (1).
    Not thread-safe (FCL objects are re-posed in place).
    """

    def __init__(self, scene, clearance_m: float = 0.01, robot: Robot | None = None, *,
                 links=None, tools=None, static=None, allowed_pairs=(), max_steps: int = 200,
                 resolution_m: float = 1e-4, coarse_samples: int = 8):
        if not (np.isfinite(clearance_m) and clearance_m >= 0):
            raise InputError(f"collision: clearance must be a finite distance >= 0 m, got {clearance_m}")
        if max_steps < 1:
            raise InputError(f"collision: max_steps must be >= 1, got {max_steps}")
        if not (np.isfinite(resolution_m) and resolution_m >= 0) or coarse_samples < 0:
            raise InputError("collision: resolution must be >= 0 m and coarse samples >= 0")
        self.scene = scene
        self.robot = robot if robot is not None else scene.robot
        if self.robot.n_joints != 6:
            raise InputError(f"collision: {self.robot.name} has {self.robot.n_joints} joints, 6 expected")
        self.clearance_m = float(clearance_m)
        self.max_steps = int(max_steps)
        self.resolution_m = float(resolution_m)
        self.coarse_samples = int(coarse_samples)
        links, tools, static, allowed_pairs = self._parts(links, tools, static, allowed_pairs)

        self.parts: list[_Part] = []
        for kind, group in (("link", links), ("tool", tools)):
            for lm in group:
                if not 0 <= int(lm.body) <= 6:
                    raise InputError(f"collision: part {lm.name!r} has body {lm.body}, expected 0..6")
                T = np.eye(4) if lm.T_body_mesh is None else np.asarray(lm.T_body_mesh, float)
                self.parts.append(_make_part(lm.name, int(lm.body), kind, lm.mesh, T,
                                             lm.box_extents, lm.box_pose))
        self.n_moving = len(self.parts)
        for sm in static:
            ext, pose = sm.box_extents, sm.box_pose
            mesh = sm.mesh
            if sm.kind == "floor":  # solid ground: same top face and extent, deep
                lo, hi = mesh.bounds
                ext = np.array([hi[0] - lo[0], hi[1] - lo[1], FLOOR_DEPTH_M])
                pose = np.eye(4)
                pose[:3, 3] = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2] - FLOOR_DEPTH_M / 2]
                mesh = box(ext, pose)
            self.parts.append(_make_part(sm.name, -1, sm.kind, mesh, np.eye(4), ext, pose))
        names = [p.name for p in self.parts]
        if len(set(names)) != len(names):
            raise InputError(f"collision: part names must be unique, got {names}")

        self._rates = self._axis_radii()  # (n_moving, 6) r_k for each moving part
        self._axes_z = self._tilted_axes()
        allowed = {frozenset(p) for p in allowed_pairs}
        pairs, kinds, skipped = [], [], []
        for i in range(self.n_moving):
            a = self.parts[i]
            for j in range(i + 1, len(self.parts)):
                b = self.parts[j]
                if frozenset((a.name, b.name)) in allowed:
                    skipped.append((a.name, b.name, "allowed"))
                    continue
                if b.body >= 0:  # self pair
                    if a.body == b.body:
                        continue  # rigidly attached to each other
                    if self._adjacent(a, b):
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
        self._pairs = np.array(pairs, int).reshape(-1, 2)
        self._kinds = kinds
        self._names = [(self.parts[i].name, self.parts[j].name) for i, j in self._pairs]
        self.skipped_pairs = skipped
        # the part whose motion changes a pair's distance (relative to the other part)
        self._upper = np.array([i if self.parts[j].body < 0 or self.parts[i].body > self.parts[j].body
                                else j for i, j in self._pairs], int)
        self._W = self._pair_rate_matrix()
        # data for the vectorized lower bounds
        self._body_of = np.array([max(p.body, 0) for p in self.parts])
        self._centers = np.array([p.center for p in self.parts])
        self._radii = np.array([p.radius for p in self.parts])
        self._static_b = np.array([self.parts[j].body < 0 for _, j in self._pairs], bool)
        self._box_inv = np.zeros((len(self.parts), 4, 4))
        self._box_half = np.zeros((len(self.parts), 3))
        for k, p in enumerate(self.parts):
            if p.body >= 0:
                continue
            if isinstance(p.geom, fcl.Box):  # oriented box: the exact shape
                self._box_inv[k] = np.linalg.inv(p.T_body_geom)
                self._box_half[k] = np.ptp(p.V @ p.T_body_geom[:3, :3], axis=0) / 2
            else:  # axis-aligned bounding box of the vertices
                lo, hi = p.V.min(0), p.V.max(0)
                self._box_inv[k] = np.eye(4)
                self._box_inv[k, :3, 3] = -(lo + hi) / 2
                self._box_half[k] = (hi - lo) / 2
        self._req = fcl.DistanceRequest()
        self._req_np = fcl.DistanceRequest(enable_nearest_points=True)
        self.counters: Counter = Counter()
        self.check_time_s = 0.0
        # one-joint pairs (planecal.safety.collision_joint): their safe intervals, swept once
        self.safe_sets: list[SafeSet] = self._one_joint_safe_sets()
        self.sweep_queries = int(self.counters["distance_queries"])
        self.counters.clear()

    # ----- structure -----

    def _parts(self, links, tools, static, allowed_pairs):
        """The geometry module's collision shapes where not given: the robot's pieces (and
        the pairs its shapes.json says never meet), the tool's, the cell's."""
        from planecal.model import geometry
        allowed_pairs = tuple(allowed_pairs)
        if links is None:
            links = geometry.robot_link_meshes(self.robot, "collision")
            allowed_pairs += geometry.robot_shapes(self.robot).allowed_pairs
        tools = geometry.tool_meshes(self.scene, "collision") if tools is None else tools
        static = geometry.scene_meshes(self.scene) if static is None else static
        return links, tools, static, allowed_pairs

    def _tilted_axes(self):
        """Joint k's axis in link frame k-1 (P_k's z, rows k = 1..6), or None where every
        one is that frame's z (no Hayati beta tilts it)."""
        axes = np.array([joint_between_links(self.robot.kinematics, k)[0][:3, 2]
                         for k in range(1, 7)])
        return None if np.array_equal(axes, np.tile([0.0, 0.0, 1.0], (6, 1))) else axes

    @staticmethod
    def _adjacent(a: _Part, b: _Part) -> bool:
        if a.kind == "tool" or b.kind == "tool":
            other = b if a.kind == "tool" else a
            return other.kind != "tool" and other.body in (5, 6)
        return abs(a.body - b.body) == 1

    def _axis_radii(self) -> np.ndarray:
        """r[p, k-1]: bound on the distance of moving part p's points from joint axis k,
        over all configurations (module docstring); 0 for k > body."""
        kin = self.robot.kinematics
        A = [None] + [joint_between_links(kin, k)[1] for k in range(1, 7)]
        ell = np.array([0.0] + [np.linalg.norm(A[k][:3, 3]) for k in range(1, 7)])
        off = np.array([0.0] + [np.hypot(A[k][0, 3], A[k][1, 3]) for k in range(1, 7)])
        out = np.zeros((self.n_moving, 6))
        for pi in range(self.n_moving):
            p = self.parts[pi]
            j = p.body
            if j == 0:
                continue
            rho = float(np.sqrt((p.V ** 2).sum(1).max()))
            out[pi, j - 1] = axis_distance_max(p.V, A[j])
            for k in range(1, j):
                out[pi, k - 1] = off[k] + ell[k + 1:j + 1].sum() + rho
        return out

    def _pair_rate_matrix(self) -> np.ndarray:
        W = np.zeros((len(self._pairs), 6))
        for n, (i, j) in enumerate(self._pairs):
            a, b = self.parts[i], self.parts[j]
            if b.body < 0:  # environment: all joints up to the part's body
                W[n] = self._rates[i]
            else:  # self: in the lower body's frame, joints above it move the upper body
                lo, hi = (i, j) if a.body < b.body else (j, i)
                k0 = self.parts[lo].body
                W[n, k0:] = self._rates[hi, k0:]
        return W

    def _one_joint_safe_sets(self) -> list[SafeSet]:
        """Safe intervals of the self pairs two bodies apart (planecal.safety.collision_joint),
        one set per hull of revolution: the upper part's about joint i+2, the lower
        part's about joint i+1."""
        kin = self.robot.kinematics
        out = []
        for n, (i, j) in enumerate(self._pairs):
            if self._kinds[n] != "self":
                continue
            low, up = sorted((self.parts[i], self.parts[j]), key=lambda p: p.body)
            bl, bu = low.body, up.body
            if bu - bl != 2:
                continue
            # the upper part's hull about joint bu's axis, fixed in frame bu-1 (by P):
            # joint bu-1 alone moves it
            P, A = joint_between_links(kin, bu)
            X = axis_coordinates(up.V, A)
            hull = self._hull_part(up.name, bu - 1, X, P)
            out.append(self._sweep_pair(n, low, hull, bu - 1, up.name))
            # the lower part's hull about joint bl+1's axis (P's z in frame bl), carried
            # into frame bl+1 (it is round about that axis): joint bu alone moves against it
            P, A = joint_between_links(kin, bl + 1)
            X = axis_coordinates(low.V, np.linalg.inv(P))
            hull = self._hull_part(low.name, bl + 1, X, np.linalg.inv(A))
            out.append(self._sweep_pair(n, hull, up, bu, low.name))
        return [s for s in out if len(s.lo)]

    def _hull_part(self, name: str, body: int, X: np.ndarray, T_body_mesh: np.ndarray) -> _Part:
        """The circumscribed prism of the hull of revolution about z of points X (the
        hull's own frame), on ``body`` with ``T_body_mesh`` from that frame to the body's."""
        r, z_lo, z_hi = hull_of_revolution(X)
        T = np.eye(4)
        T[2, 3] = (z_lo + z_hi) / 2
        mesh = prism(r / np.cos(np.pi / HULL_SECTIONS), max(z_hi - z_lo, 1e-6), HULL_SECTIONS, T)
        return _make_part(f"{name} (hull)", body, "hull", mesh, T_body_mesh)

    def _sweep_pair(self, n: int, fixed: _Part, moving: _Part, m: int, hull: str) -> SafeSet:
        """Sweep joint m (1-based), which alone moves ``moving`` (body m) against
        ``fixed`` (body m-1), over its limits."""
        rb = self.robot
        P, A = joint_between_links(rb.kinematics, m)
        rho = axis_distance_max(moving.V, A)
        q = np.zeros(6)
        F = self._frames(q)  # only frame m changes with joint m: F[m] = F[m-1] P Rz(t) B
        B = np.linalg.inv(P) @ np.linalg.inv(F[m - 1]) @ F[m]
        FP = F[m - 1] @ P
        Rz = np.eye(4)

        def distance(t: float) -> float:
            c, s_ = np.cos(t), np.sin(t)
            Rz[:2, :2] = [[c, -s_], [s_, c]]
            F[m] = FP @ Rz @ B
            return self._distance(fixed, moving, F)

        lo, hi = rb.limits[m - 1]
        starts, ends, _ = sweep(distance, float(lo), float(hi), rho, self.clearance_m,
                                self.clearance_m + self.resolution_m)
        return SafeSet(n, m - 1, starts, ends, hull)

    def _covered(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        """Pairs a safe set clears on the straight path q0 -> q1 (q0 = q1: a configuration)."""
        cov = np.zeros(len(self._pairs), bool)
        for st in self.safe_sets:
            if not cov[st.pair] and st.covers(q0[st.joint], q1[st.joint]):
                cov[st.pair] = True
        return cov

    @property
    def pairs(self) -> list[tuple[str, str, str]]:
        """Checked pairs: (name, name, 'self' | 'environment')."""
        return [(self.parts[i].name, self.parts[j].name, k)
                for (i, j), k in zip(self._pairs, self._kinds)]

    def pair_rates(self, q0, q1) -> np.ndarray:
        """L per checked pair [m per unit s]: |d(s') - d(s)| <= L |s' - s| on q0 -> q1."""
        dq = np.abs(_as_q(q1, "q1") - _as_q(q0, "q0"))
        return self._W @ dq

    # ----- distances -----

    def _frames(self, Q: np.ndarray) -> np.ndarray:
        return link_frames(self.robot.kinematics, Q)

    def _lower_bounds(self, F: np.ndarray, idx: np.ndarray, rows: np.ndarray | None = None):
        """Cheap lower bounds of the distances of pairs idx, pair idx[e] with the frames
        F[rows[e]] (F: (K, 7, 4, 4); rows default: one frame set per pair): bounding sphere
        of the moving part against the static part's box (its exact box, else its
        axis-aligned bounding box), or sphere against sphere for self pairs. Also returns
        the world centres of the pairs' upper parts. Only the two frames of each pair are
        gathered (not F[rows]: the path check's 544 x 7 frames were a 0.5 MB copy a call)."""
        i, j = self._pairs[idx, 0], self._pairs[idx, 1]
        r = np.arange(len(idx)) if rows is None else rows
        Fi, Fj = F[r, self._body_of[i]], F[r, self._body_of[j]]
        ci = np.einsum("nab,nb->na", Fi[:, :3, :3], self._centers[i]) + Fi[:, :3, 3]
        cj = np.einsum("nab,nb->na", Fj[:, :3, :3], self._centers[j]) + Fj[:, :3, 3]
        lb = np.linalg.norm(ci - cj, axis=1) - self._radii[i] - self._radii[j]
        st = self._static_b[idx]
        if st.any():
            B = self._box_inv[j[st]]
            x = np.einsum("nab,nb->na", B[:, :3, :3], ci[st]) + B[:, :3, 3]
            out = np.maximum(np.abs(x) - self._box_half[j[st]], 0.0)
            lb[st] = np.linalg.norm(out, axis=1) - self._radii[i[st]]
        up = self._upper[idx]
        cu = np.where((up == i)[:, None], ci, cj)
        return lb, cu

    def _exact(self, n: int, F: np.ndarray) -> float:
        """Distance of pair n with frames F (7,4,4); 0 for contact.

        Convex pairs: FCL's GJK distance d with its nearest points p_a, p_b, certified by
        the gap of the two vertex sets along u = (p_b - p_a)/|p_b - p_a|,
        min(u . V_b) - max(u . V_a), a lower bound of the distance of convex sets. If the
        gap is d (to 1e-9 m) the gap is returned; otherwise GJK was wrong (FCL's libccd
        GJK overestimates some distances between boxes and polytopes with parallel
        features, fcl issue #508; seen here by up to 0.4 m) and the triangle-exact BVH
        distance is used. Pairs with a non-convex part always use the BVHs, with a
        containment test (a BVH is a surface)."""
        i, j = self._pairs[n]
        return self._distance(self.parts[i], self.parts[j], F)

    def _distance(self, a: _Part, b: _Part, F: np.ndarray) -> float:
        """Distance of parts a and b with frames F (``_exact``)."""
        Ta = F[a.body] if a.body >= 0 else None
        Tb = F[b.body] if b.body >= 0 else None
        self.counters["distance_queries"] += 1
        if a.convex and b.convex:
            for p, T in ((a, Ta), (b, Tb)):
                if T is not None:
                    G = T if p.is_identity else T @ p.T_body_geom
                    p.obj.setTransform(fcl.Transform(G[:3, :3], G[:3, 3]))
            res = fcl.DistanceResult()
            d = fcl.distance(a.obj, b.obj, self._req_np, res)
            if d <= 0:
                return 0.0  # GJK intersection (a wrong "contact" only costs a rejection)
            pa, pb = res.nearest_points
            u = pb - pa
            nu = np.sqrt(u @ u)
            if nu > 0:
                u = u / nu
                gap = self._support_gap(a, Ta, b, Tb, u)
                if gap >= d - 1e-9:
                    return float(min(gap, d))
            self.counters["gjk_fallbacks"] += 1
        for p, T in ((a, Ta), (b, Tb)):
            if T is not None:
                p.bvh.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
        d = fcl.distance(a.bvh, b.bvh, self._req, fcl.DistanceResult())
        if d <= 0 or self._contained(a, b, F):
            return 0.0
        return float(d)

    @staticmethod
    def _support_gap(a: _Part, Ta, b: _Part, Tb, u: np.ndarray) -> float:
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

    def _contained(self, a: _Part, b: _Part, F: np.ndarray) -> bool:
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

    def distances(self, q) -> np.ndarray:
        """Exact distance [m] of every checked pair (``pairs`` order) at q; 0 for contact."""
        F = self._frames(_as_q(q, "q"))
        return np.array([self._exact(n, F) for n in range(len(self._pairs))])

    # ----- checks -----

    def _reject(self, reason: str, d: float, n: int | None, s: float | None = None) -> CheckResult:
        self.counters[f"rejected_{reason}"] += 1
        return CheckResult(False, d, None if n is None else self._names[n], reason, s)

    def check_config(self, q) -> CheckResult:
        """Is configuration q (6 joint angles, rad) within limits and clear by the
        clearance? min_distance_m is the exact smallest pair distance."""
        q = _as_q(q, "q")
        t0 = time.perf_counter()
        try:
            self.counters["configs"] += 1
            if not within_limits(self.robot, q):
                return self._reject("limits", float("nan"), None)
            F = self._frames(q)
            P = len(self._pairs)
            if P == 0:
                return CheckResult(True, float("inf"), None)
            lb, _ = self._lower_bounds(F[None], np.arange(P), np.zeros(P, np.intp))
            lb[self._covered(q, q)] = np.inf  # certified clear by a safe set
            best, best_n = float("inf"), None
            for n in np.argsort(lb):
                if lb[n] >= best or not np.isfinite(lb[n]):
                    break
                d = self._exact(int(n), F)
                if d < best:
                    best, best_n = d, int(n)
            if best <= self.clearance_m:
                return self._reject(self._kinds[best_n], best, best_n)
            return CheckResult(True, best, self._names[best_n])
        finally:
            self.check_time_s += time.perf_counter() - t0

    def check_path(self, q0, q1) -> CheckResult:
        """Certify the straight joint-space motion q0 -> q1 (module docstring): ok only
        if every checked pair stays farther than the clearance along the whole segment."""
        q0, q1 = _as_q(q0, "q0"), _as_q(q1, "q1")
        t0 = time.perf_counter()
        try:
            return self._check_path(q0, q1)
        finally:
            self.check_time_s += time.perf_counter() - t0

    def _step_sizes(self, F, cu, idx, gap, adq, L, rows=None):
        """Safe path-parameter steps for pair-ends idx (pair idx[e] at frames F[rows[e]],
        as ``_lower_bounds``) with clearance gaps ``gap`` (m): the largest Delta with
        displacement bound <= gap (module docstring)."""
        W = self._W[idx]  # (E, 6) global axis radii of the upper part, masked to its joints
        up = self._upper[idx]
        r = np.arange(len(idx)) if rows is None else rows
        o = F[r, :6, :3, 3]  # axis k passes through o_{k-1} along z_{k-1} (P_k z with beta)
        z = F[r, :6, :3, 2] if self._axes_z is None else np.einsum(
            "nkab,kb->nka", F[r, :6, :3, :3], self._axes_z)
        v = cu[:, None, :] - o
        dist = np.linalg.norm(v - np.sum(v * z, -1, keepdims=True) * z, axis=-1)
        D = np.minimum(dist + self._radii[up][:, None], W)  # current distance from axis k
        aW = adq * W
        G = np.cumsum(aW[:, ::-1], axis=1)[:, ::-1] - aW  # sum over m > k
        A = np.sum(adq * D, axis=1)
        Bq = np.sum(adq * (W > 0) * G, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            step_global = np.where(L > 0, gap / L, np.inf)
            step_local = np.where(A + Bq > 0, 2 * gap / (A + np.sqrt(A * A + 2 * Bq * gap)), np.inf)
        return np.maximum(step_global, step_local)

    def _check_path(self, q0: np.ndarray, q1: np.ndarray) -> CheckResult:
        self.counters["paths"] += 1
        if not (within_limits(self.robot, q0) and within_limits(self.robot, q1)):
            return self._reject("limits", float("nan"), None)  # the box of limits is convex
        P = len(self._pairs)
        if P == 0:
            return CheckResult(True, float("inf"), None)
        c = self.clearance_m
        c_meas = c + self.resolution_m  # a measured distance must exceed this
        dq = q1 - q0
        adq = np.abs(dq)
        L = self._W @ adq
        self._best = (float("inf"), None)

        grid = np.linspace(0.0, 1.0, self.coarse_samples + 2)
        K = len(grid)
        Fg = self._frames(q0 + grid[:, None] * dq)
        D = np.zeros((K, P))  # distance or lower bound at grid point k of pair n
        G = np.zeros((K, P))  # the step it certifies
        X = np.zeros((K, P), bool)  # D is exact
        CU = np.zeros((K, P, 3))  # centre of the pair's moving part

        def bound(rows, cols):
            D[rows, cols], CU[rows, cols] = self._lower_bounds(Fg, cols, rows)

        def exact(rows, cols):
            for k, n in zip(rows, cols):
                if not X[k, n]:
                    d = self._measure(int(n), Fg[k], c_meas, float(grid[k]))
                    if isinstance(d, CheckResult):
                        return d
                    D[k, n], X[k, n] = d, True
            return None

        def steps(rows, cols):
            G[rows, cols] = self._step_sizes(Fg, CU[rows, cols], cols, D[rows, cols] - c,
                                             adq, L[cols], rows)

        def certify(rows, cols, bounds=True):
            """Grid points (rows, cols): lower bounds (``bounds``) and exact distances where
            a bound is within the clearance (all of them without bounds), then the steps
            they certify; the rejection if a distance is within the clearance."""
            if bounds:
                bound(rows, cols)
                sel = D[rows, cols] <= c_meas
                bad = exact(rows[sel], cols[sel])
            else:
                bad = exact(rows, cols)
            if bad is None:
                steps(rows, cols)
            return bad

        # 1a. both ends of every pair (the target first: colliding targets are common);
        #     exact distances where the bound is within the clearance; pairs whose end
        #     bounds certify the whole path are done
        cols = np.flatnonzero(~self._covered(q0, q1))  # the rest: certified by safe sets
        bad = certify(np.repeat([K - 1, 0], len(cols)), np.tile(cols, 2))
        if bad is not None:
            return bad
        R = cols[~(G[0, cols] + G[K - 1, cols] > 1.0)]
        # 1b. the pairs still open on the interior grid points: bounds, exact distances
        #     where a bound is within the clearance (most rejected paths end here)
        unc = np.zeros((K - 1, P), bool)
        if len(R) and K > 2:
            bad = certify(np.repeat(np.arange(1, K - 1), len(R)), np.tile(R, K - 2))
            if bad is not None:
                return bad
            h = np.diff(grid)[:, None]
            unc[:, R] = ~(G[:-1, R] + G[1:, R] > h)
            # exact distances at the ends of the grid intervals still open, test again
            ends = np.zeros((K, P), bool)
            ends[:-1] |= unc
            ends[1:] |= unc
            rows, cols = np.nonzero(ends & ~X)
            if len(rows):
                bad = certify(rows, cols, bounds=False)
                if bad is not None:
                    return bad
            unc[:, R] = ~(G[:-1, R] + G[1:, R] > h)
        elif len(R):
            unc[0, R] = True
        # 2. refine the intervals still open: shrink each by the steps its ends certify
        #    and split the rest at its midpoint, measuring the three new points exactly
        kk, nn = np.nonzero(unc)
        n_iv = nn
        a_iv, b_iv = grid[kk], grid[kk + 1]
        ga, gb = G[kk, nn], G[kk + 1, nn]
        evals = np.zeros(P, int)
        while len(n_iv):
            a2, b2 = a_iv + ga, b_iv - gb
            m = (a2 + b2) / 2
            S = np.concatenate([a2, m, b2])
            nidx = np.concatenate([n_iv, n_iv, n_iv])
            np.add.at(evals, n_iv, 3)
            if np.any(evals > 3 * self.max_steps):
                k = int(np.argmax(evals[n_iv]))
                return self._reject("undecided", self._best[0], int(n_iv[k]), float(a2[k]))
            F = self._frames(q0 + S[:, None] * dq)
            _, cuN = self._lower_bounds(F, nidx)
            dN = np.empty(len(S))
            for e in range(len(S)):
                bad = self._measure(int(nidx[e]), F[e], c_meas, float(S[e]))
                if isinstance(bad, CheckResult):
                    return bad
                dN[e] = bad
            gN = self._step_sizes(F, cuN, nidx, dN - c, adq, L[nidx])
            r = len(n_iv)
            ga_new = np.concatenate([gN[:r], gN[r:2 * r]])
            gb_new = np.concatenate([gN[r:2 * r], gN[2 * r:]])
            a_new = np.concatenate([a2, m])
            b_new = np.concatenate([m, b2])
            n_new = np.concatenate([n_iv, n_iv])
            open_ = ~(ga_new + gb_new > b_new - a_new)
            n_iv, a_iv, b_iv = n_new[open_], a_new[open_], b_new[open_]
            ga, gb = ga_new[open_], gb_new[open_]
        self.counters["paths_clear"] += 1
        best, best_n = self._best
        return CheckResult(True, best, None if best_n is None else self._names[best_n])

    def _measure(self, n: int, F: np.ndarray, c_meas: float, s: float):
        """Exact distance of pair n at frames F, or the rejection if it is <= c_meas."""
        d = self._exact(n, F)
        if d < self._best[0]:
            self._best = (d, n)
        if d <= c_meas:
            return self._reject(self._kinds[n], d, n, s)
        return d

    def summary(self) -> dict:
        """Counters and checking time, for a run's sidecar."""
        out = {k: int(v) for k, v in sorted(self.counters.items())}
        out["check_time_s"] = round(self.check_time_s, 6)
        return out
