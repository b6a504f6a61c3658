"""Test-only MuJoCo references for the collision checker (planecal.safety.collision).

* ``mujoco_contacts`` / ``mujoco_contacts_along_path``: MuJoCo's own contacts
  (mj_kinematics + mj_collision) for a model such as the twin's scene.
* ``ExactOracle``: exact signed distances between the *visual* link and tool shapes
  (``geometry.robot_link_meshes(robot, "visual")``, ``geometry.tool_meshes(scene,
  "visual")``: the model of the real robot) and the nominal cell, with
  ``mujoco.mj_geomDistance``, for the pairs the checker checks; and the smallest
  distance along a straight joint path, sampled so densely that no point of a pair's
  moving part moves more than ``step_m`` (1 mm) relative to the other part between two
  samples, except where a distance proves a skip safe.

Why exact: every visual piece is a convex polytope (a convex hull; test_geometry checks
it), and MuJoCo collides a mesh by its convex hull, so MuJoCo's GJK distance is the
distance of the pieces themselves. The model rounds mesh vertices to 1e-6 m
(``twin.mjcf``) and stores them as float32; the cell's and the laser head's boxes are
exact primitives. It agrees with FCL's certified distances on the same pieces to
1.3e-6 m (test_collision_exact).

Path sampling: the checker's ``pair_rates(q0, q1)`` (its tested global bound) gives L,
the fastest a point of the pair's moving part can move relative to the other part, per
unit of the path parameter s. From a sample at distance d the next sample is
``max(step_m, d - threshold) / L`` further on: either at most ``step_m`` of motion, or a
skip over which the distance provably stays >= threshold. So wherever the true distance
is below the threshold the samples are at most ``step_m`` apart in motion, and the
smallest sampled distance is within ``step_m / 2`` of the true minimum there.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from planecal.safety.collision import CollisionWorld
from planecal.safety.collision_parts import FLOOR_DEPTH_M
from planecal.base.errors import InputError


# ----- MuJoCo's own contacts --------------------------------------------------------------

@dataclass(frozen=True)
class MjContact:
    s: float  # path parameter of the sample
    geom1: str
    geom2: str
    body1: str
    body2: str
    dist: float  # MuJoCo's signed contact distance [m] (< 0: penetration)


def _as_q(q, what: str) -> np.ndarray:
    a = np.asarray(q, float)
    if a.shape != (6,) or not np.all(np.isfinite(a)):
        raise InputError(f"oracle: {what} must be 6 finite joint angles [rad]")
    return a


def robot_qpos_adr(model, qpos_adr=None) -> np.ndarray:
    """The qpos addresses of the robot's six joints: ``qpos_adr`` as given, else the
    first six hinge joints'."""
    if qpos_adr is None:
        hinges = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)[:6]
        if len(hinges) < 6:
            raise InputError(f"oracle: the MuJoCo model has {len(hinges)} hinge joints, 6 expected")
        qpos_adr = model.jnt_qposadr[hinges]
    return np.asarray(qpos_adr, int)


def mujoco_contacts(model, data, q, qpos_adr=None, s: float = 0.0) -> list[MjContact]:
    """MuJoCo's own contacts at configuration q: sets the six robot joints (``qpos_adr``,
    default the first six hinge joints' qpos addresses), runs ``mj_kinematics`` +
    ``mj_collision`` and reads ``d.contact`` as arrays.

    MuJoCo reports geom pairs closer than their margin (``geom_margin``; 0: touching or
    penetrating) and collides meshes by their convex hull; its own filters (parent-child,
    excludes, contype/conaffinity) apply, so filter the result by the pairs you care about.
    """
    q = _as_q(q, "q")
    data.qpos[robot_qpos_adr(model, qpos_adr)] = q
    mujoco.mj_kinematics(model, data)
    mujoco.mj_collision(model, data)
    k = data.ncon
    if k == 0:
        return []
    G = np.array(data.contact.geom[:k]).reshape(k, 2)
    D = np.array(data.contact.dist[:k]).reshape(k)
    out = []
    for (g1, g2), dist in zip(G, D):
        out.append(MjContact(float(s), _mj_name(model, mujoco.mjtObj.mjOBJ_GEOM, g1),
                             _mj_name(model, mujoco.mjtObj.mjOBJ_GEOM, g2),
                             _mj_name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[g1]),
                             _mj_name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[g2]),
                             float(dist)))
    return out


def _mj_name(model, kind, i) -> str:
    return mujoco.mj_id2name(model, kind, int(i)) or f"{kind.name}{int(i)}"


def mujoco_contacts_along_path(model, data, q0, q1, n: int, qpos_adr=None) -> list[MjContact]:
    """MuJoCo's contacts (``mujoco_contacts``) at n evenly spaced configurations of the
    straight joint motion q0 -> q1 (s = 0 .. 1): an independent check of a path."""
    q0, q1 = _as_q(q0, "q0"), _as_q(q1, "q1")
    if n < 2:
        raise InputError(f"oracle: need n >= 2 samples along a path, got {n}")
    adr = robot_qpos_adr(model, qpos_adr)
    out = []
    for s in np.linspace(0.0, 1.0, n):
        out += mujoco_contacts(model, data, q0 + s * (q1 - q0), adr, float(s))
    return out


# ----- exact distances of the visual shapes ------------------------------------------------

@dataclass(frozen=True)
class PathMin:
    """Smallest sampled distance along a path (see ExactOracle.path_min)."""
    distance: float  # [m], signed (< 0: penetration), over the pairs sampled
    pair: tuple[str, str] | None
    s: float | None
    evaluations: int  # mj_geomDistance calls
    stopped: bool  # True when a sample at or below ``stop_below`` ended the search


def oracle_model(scene, sensor=None):
    """The twin's scene model (``twin.mjcf.scene_spec``: visual and collision geoms of
    the robot and tool, the cell as boxes) with the floor made solid ground: its top face
    and x-y extent kept, ``FLOOR_DEPTH_M`` deep, as the checker models it."""
    from planecal.twin.mjcf import scene_spec
    spec = scene_spec(scene, sensor)
    floor = spec.geom("floor")
    floor.size = [floor.size[0], floor.size[1], FLOOR_DEPTH_M / 2]
    floor.pos = [floor.pos[0], floor.pos[1], scene.floor_z - FLOOR_DEPTH_M / 2]
    m = spec.compile()
    return m, mujoco.MjData(m)


class ExactOracle:
    """Exact distances of the visual link and tool shapes to each other and to the cell
    (module docstring), for the pairs a ``CollisionWorld`` checks.

    ``world``: a CollisionWorld built on the visual shapes (its pair list, pair rates and
    FCL distances of the same shapes, for cross-checks); ``model``/``data``: MuJoCo."""

    def __init__(self, scene, clearance_m: float = 0.01):
        from planecal.model import geometry
        self.scene = scene
        self.robot = scene.robot
        self.world = CollisionWorld(scene, clearance_m=clearance_m,
                                    links=geometry.robot_link_meshes(self.robot, "visual"),
                                    tools=geometry.tool_meshes(scene, "visual"),
                                    static=geometry.scene_meshes(scene))
        self.model, self.data = oracle_model(scene)
        self.adr = robot_qpos_adr(self.model)
        ids = {}
        for g in range(self.model.ngeom):
            name = mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_GEOM, g)
            if name is not None:
                ids[name] = g
        parts = {p.name: p for p in self.world.parts}

        def geom(name):
            key = name if parts[name].body < 0 else f"v_{name}"
            if key not in ids:
                raise KeyError(f"oracle: no MuJoCo geom {key!r} for part {name!r}")
            return ids[key]

        self.pairs = [(a, b) for a, b, _ in self.world.pairs]
        self.kinds = [k for _, _, k in self.world.pairs]
        self._geoms = np.array([(geom(a), geom(b)) for a, b in self.pairs], int)
        self.evaluations = 0

    def _set(self, q) -> None:
        self.data.qpos[self.adr] = q
        mujoco.mj_kinematics(self.model, self.data)

    def _dist(self, n: int, distmax: float) -> float:
        self.evaluations += 1
        g1, g2 = self._geoms[n]
        return mujoco.mj_geomDistance(self.model, self.data, int(g1), int(g2), distmax, None)

    def pair_indices(self, part: str) -> np.ndarray:
        """Indices (into ``pairs``) of the checked pairs that involve ``part``."""
        return np.array([n for n, p in enumerate(self.pairs) if part in p], int)

    def distances(self, q, distmax: float = 10.0, pairs=None) -> np.ndarray:
        """Signed distance [m] of every checked pair (``pairs`` order; or of the pair
        indices ``pairs``) at q, capped at distmax (< 0: penetration depth as MuJoCo
        estimates it)."""
        self._set(_as_q(q, "q"))
        idx = range(len(self.pairs)) if pairs is None else pairs
        return np.array([self._dist(int(n), distmax) for n in idx])

    def path_min(self, q0, q1, threshold: float, stop_below: float = -np.inf,
                 step_m: float = 1e-3, distmax: float = 1.0, pairs=None) -> PathMin:
        """Smallest distance along q0 -> q1 (s in [0, 1]) over every checked pair (or the
        pair indices ``pairs``), sampled as the module docstring says around
        ``threshold`` [m]: where a pair is closer than the threshold its samples are at
        most ``step_m`` of motion apart. Stops at the first sample at or below
        ``stop_below``."""
        q0, q1 = _as_q(q0, "q0"), _as_q(q1, "q1")
        dq = q1 - q0
        L = self.world.pair_rates(q0, q1)
        best = (np.inf, None, None)
        e0 = self.evaluations
        idx = np.arange(len(self.pairs)) if pairs is None else np.asarray(pairs, int)
        for n in idx[np.argsort(-L[idx])]:
            if L[n] == 0.0:  # the pair does not move relative to itself on this path
                self._set(q0)
                d = self._dist(n, distmax)
                if d < best[0]:
                    best = (d, n, 0.0)
                if d <= stop_below:
                    return self._path_result(best, e0, True)
                continue
            s = 0.0
            while True:
                self._set(q0 + s * dq)
                d = self._dist(n, distmax)
                if d < best[0]:
                    best = (d, n, s)
                if d <= stop_below:
                    return self._path_result(best, e0, True)
                if s >= 1.0:
                    break
                s = min(1.0, s + max(step_m, d - threshold) / L[n])
        return self._path_result(best, e0, False)

    def _path_result(self, best, e0, stopped) -> PathMin:
        d, n, s = best
        return PathMin(float(d), None if n is None else self.pairs[n], s,
                       self.evaluations - e0, stopped)
