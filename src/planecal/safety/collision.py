"""Collision checking for the sampling loop: configurations and straight joint-space paths.

The planner only knows nominal values, so every moving part is posed with
``robot.fk_frames(robot, q)`` (no joint offsets) and the scene's nominal sensor mounting.

Parts (``planecal.safety.collision_parts``)
-------------------------------------------
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

Pairs checked (``collision_parts.checked_pairs``)
-------------------------------------------------
* Self: moving parts on different bodies, except adjacent bodies (|body_i - body_j| = 1:
  base-link1, link1-link2, ..., link5-link6) and the tool against bodies 5 and 6.
* Environment: every moving part against every static part, except the floor against the
  base (body 0) and link 1, which are bolted to it.
``allowed_pairs`` adds further (name, name) pairs to skip, as do the robot's shapes.json
(its ``allowed_pairs``: pieces its structure keeps apart, a UR's nested wrist joints) and
the scene (its ``allowed_pairs``: the tool's pieces against the arm's that ``scene new``
found touching in every configuration).
* One-joint pairs (``planecal.safety.collision_joint``): self pairs two bodies apart whose
  distance one joint decides once a part is replaced by its hull of revolution; their safe
  intervals of that joint are swept once per world (``safe_sets``), and a configuration or
  path whose angle of that joint stays inside one is clear for that pair without a query.
  On thesis_final this halves the exact distance queries of a run's path checks (25,916 ->
  12,146 for 150 plans) and changes no verdict.

A configuration is ok when it is within the joint limits and every checked pair is
farther apart than ``clearance_m``.

Path certification (``check_path``; ``planecal.safety.collision_path``): conservative advancement
-------------------------------------------------------------------------------------------------
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

Procedure (``planecal.safety.collision_path``): every pair at both ends, then on a coarse
grid, then the intervals still open are refined by the steps of their ends; cheap lower
bounds first, exact distances where a bound is within the clearance. Rejection is always
safe; acceptance means every checked pair stays farther than the clearance everywhere on
the segment, in the nominal model with the geometry as given: no false "clear".

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
from planecal.safety.collision_parts import (Part, checked_pairs, contained, make_part,
                                             moving_parts, static_boxes, static_parts,
                                             support_gap)
from planecal.safety.collision_path import PathCheck
from planecal.base.errors import InputError
from planecal.model.mesh import prism
from planecal.model.robot import Robot, within_limits
from planecal.model.kinematics import joint_between_links, link_frames

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

        self.parts: list[Part] = moving_parts(links, tools)
        self.n_moving = len(self.parts)
        self.parts += static_parts(static)
        names = [p.name for p in self.parts]
        if len(set(names)) != len(names):
            raise InputError(f"collision: part names must be unique, got {names}")

        self._rates = self._axis_radii()  # (n_moving, 6) r_k for each moving part
        self._axes_z = self._tilted_axes()
        pairs, kinds, skipped = checked_pairs(self.parts, self.n_moving, allowed_pairs)
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
        self._box_inv, self._box_half = static_boxes(self.parts)  # oriented, else axis-aligned
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
        if self.scene is not None:  # the scene's: tool pieces its sampling found always touching
            allowed_pairs += self.scene.allowed_pairs
        tools = geometry.tool_meshes(self.scene, "collision") if tools is None else tools
        static = geometry.scene_meshes(self.scene) if static is None else static
        return links, tools, static, allowed_pairs

    def _tilted_axes(self):
        """Joint k's axis in link frame k-1 (P_k's z, rows k = 1..6), or None where every
        one is that frame's z (no Hayati beta tilts it)."""
        axes = np.array([joint_between_links(self.robot.kinematics, k)[0][:3, 2]
                         for k in range(1, 7)])
        return None if np.array_equal(axes, np.tile([0.0, 0.0, 1.0], (6, 1))) else axes

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

    def _hull_part(self, name: str, body: int, X: np.ndarray, T_body_mesh: np.ndarray) -> Part:
        """The circumscribed prism of the hull of revolution about z of points X (the
        hull's own frame), on ``body`` with ``T_body_mesh`` from that frame to the body's."""
        r, z_lo, z_hi = hull_of_revolution(X)
        T = np.eye(4)
        T[2, 3] = (z_lo + z_hi) / 2
        mesh = prism(r / np.cos(np.pi / HULL_SECTIONS), max(z_hi - z_lo, 1e-6), HULL_SECTIONS, T)
        return make_part(f"{name} (hull)", body, "hull", mesh, T_body_mesh)

    def _sweep_pair(self, n: int, fixed: Part, moving: Part, m: int, hull: str) -> SafeSet:
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

    def _distance(self, a: Part, b: Part, F: np.ndarray) -> float:
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
                gap = support_gap(a, Ta, b, Tb, u)
                if gap >= d - 1e-9:
                    return float(min(gap, d))
            self.counters["gjk_fallbacks"] += 1
        for p, T in ((a, Ta), (b, Tb)):
            if T is not None:
                p.bvh.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
        d = fcl.distance(a.bvh, b.bvh, self._req, fcl.DistanceResult())
        if d <= 0 or contained(a, b, F):
            return 0.0
        return float(d)

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
        if len(self._pairs) == 0:
            return CheckResult(True, float("inf"), None)
        path = PathCheck(self, q0, q1)
        bad = path.run()
        if bad is not None:
            return self._reject(bad.reason, bad.d, bad.n, bad.s)
        self.counters["paths_clear"] += 1
        best, best_n = path.best
        return CheckResult(True, best, None if best_n is None else self._names[best_n])

    def summary(self) -> dict:
        """Counters and checking time, for a run's sidecar."""
        out = {k: int(v) for k, v in sorted(self.counters.items())}
        out["check_time_s"] = round(self.check_time_s, 6)
        return out
