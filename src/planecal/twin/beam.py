"""The laser beam for many joint states in one MuJoCo call.

``mj_ray`` casts from a point along a direction in the world frame, so a batch of ticks
would need the laser site's pose at each tick before it can cast;
``mujoco.batch.Batch.ray`` runs ``mj_kinematics`` + ``mj_ray`` for many simulations in
C, but with rays fixed in each simulation's world frame. The ``BeamCaster`` turns the
problem around: a second MuJoCo model whose world is the laser site frame and whose cell
hangs off the robot's chain inverted,

    T_site^-1 = P_site^-1 P_tool^-1 R_6(-q_6) P_link6^-1 ... R_1(-q_1) P_link1^-1 P_base^-1

(``P_b`` the twin model's body/site poses, ``R_j`` its hinges), so the beam is the fixed
ray ``(0, 0, 0) + x (0, 0, 1)`` in every simulation and one ``Batch.ray`` call gives the
beams of all K ticks (state ``qpos = -q``, joints in reverse): kinematics and ray cast by
MuJoCo, ~0.5 us per tick plus ~15 us per call. Only the geoms the twin's ray sees are in
it (the static cell: world-body geoms in the mask's groups; the robot's link geoms are in
no group the mask keeps, the tool's are excluded), with their geom ids mapped back.
Distances agree with ``mj_ray`` in the world frame to ~1e-15 m (the intersection is
computed in the site frame); tests/test_twin_batch.py holds them to it on all scenes.

The caster covers the twin's own models (hinges at body origins on the site's path,
primitive geoms on the world body); ``BeamCaster`` raises ValueError for anything else.
"""
from __future__ import annotations

import mujoco
import numpy as np
from mujoco.batch import Batch

_PRIMITIVES = {int(mujoco.mjtGeom.mjGEOM_PLANE), int(mujoco.mjtGeom.mjGEOM_SPHERE),
               int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_ELLIPSOID),
               int(mujoco.mjtGeom.mjGEOM_CYLINDER), int(mujoco.mjtGeom.mjGEOM_BOX)}


MAX_CHUNK = 4096  # simulations per Batch.ray call (buffers grow up to this)


def _inverse(pos, quat):
    p, q = np.zeros(3), np.zeros(4)
    mujoco.mju_negPose(p, q, np.asarray(pos, float), np.asarray(quat, float))
    return p, q


def _compose(a, b):
    p, q = np.zeros(3), np.zeros(4)
    mujoco.mju_mulPose(p, q, a[0], a[1], b[0], b[1])
    return p, q


class BeamCaster:
    """``cast(Q)``: true distance [m] (-1: no hit) and geom id (twin model's, -1: none)
    of the beam at each joint state ``Q`` (K, nq) = the twin's qpos rows."""

    def __init__(self, model: mujoco.MjModel, site_id: int, mask: np.ndarray,
                 exclude_body: int, capacity: int = 256):
        self.mask = np.ascontiguousarray(mask, np.uint8)
        # the site's body path up to the world: bodies (deepest first)
        path, b = [], int(model.site_bodyid[site_id])
        while b != 0:
            path.append(b)
            b = int(model.body_parentid[b])
        joints = []  # (twin joint id, axis) deepest first
        spec = mujoco.MjSpec()
        spec.modelname = "beam"
        parent = spec.worldbody
        pose = _inverse(model.site_pos[site_id], model.site_quat[site_id])  # pending fixed part
        for b in path:
            body_pose = (model.body_pos[b].copy(), model.body_quat[b].copy())
            nj = int(model.body_jntnum[b])
            if nj > 1:
                raise ValueError("beam: more than one joint on a body")
            if nj == 1:
                j = int(model.body_jntadr[b])
                if (model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE
                        or np.any(model.jnt_pos[j] != 0.0)):
                    raise ValueError("beam: only hinges at the body origin")
                # this body's frame = parent * P_b * R_j(q): inverse R_j(-q) * P_b^-1
                child = parent.add_body(pos=pose[0].tolist(), quat=pose[1].tolist(),
                                        mass=1.0, inertia=[1.0, 1.0, 1.0],
                                        explicitinertial=True)
                child.add_joint(type=mujoco.mjtJoint.mjJNT_HINGE,
                                axis=model.jnt_axis[j].tolist())
                joints.append(j)
                parent = child
                pose = _inverse(*body_pose)
            else:
                pose = _compose(pose, _inverse(*body_pose))
        if model.nq != len(joints) or model.njnt != len(joints):
            raise ValueError("beam: joints off the laser's path")
        seen = [g for g in range(model.ngeom)
                if self.mask[min(len(self.mask) - 1, max(0, int(model.geom_group[g])))]]
        self.geoms = []
        for g in seen:
            b = int(model.geom_bodyid[g])
            if b == exclude_body:
                continue  # the twin's ray excludes it
            if b != 0:
                raise ValueError("beam: a seen geom on a moving body")
            if int(model.geom_type[g]) not in _PRIMITIVES or model.geom_matid[g] >= 0:
                raise ValueError("beam: only primitive geoms without materials")
            # on the innermost joint's body: the remaining fixed part, then the geom's pose
            gpos, gquat = _compose(pose, (model.geom_pos[g], model.geom_quat[g]))
            parent.add_geom(type=mujoco.mjtGeom(int(model.geom_type[g])),
                            size=model.geom_size[g].tolist(), pos=gpos.tolist(),
                            quat=gquat.tolist(), group=int(model.geom_group[g]),
                            rgba=model.geom_rgba[g].tolist(), contype=0, conaffinity=0)
            self.geoms.append(g)
        self.model = spec.compile()
        # beam joint k (tree order: the deepest twin joint first) turns by -qpos[order[k]]
        order = [int(model.jnt_qposadr[j]) for j in joints]
        self._order = slice(None, None, -1) if order == list(range(model.nq))[::-1] \
            else np.array(order, np.intp)
        self._geom_map = np.array(self.geoms + [-1], np.int32)  # index -1 -> -1
        self._cap = 0
        self._grow(capacity)

    def _grow(self, k: int) -> None:
        cap = min(max(k, 2 * self._cap), MAX_CHUNK)
        self._batch = Batch(self.model, cap, 1)
        self._qpos = self._batch.bind("qpos")
        self._ids = np.arange(cap, dtype=np.int32)
        self._pnt = np.zeros(3)
        self._vec = np.array([0.0, 0.0, 1.0])
        self._cap = cap

    def cast(self, Q: np.ndarray):
        """(distance (K,) [m], -1: no hit; geom ids (K,) of the twin model, -1: none) for
        the twin's qpos rows ``Q`` (K, nq)."""
        k = len(Q)
        if k > MAX_CHUNK:  # bounded buffers: a long run in chunks
            parts = [self.cast(Q[i:i + MAX_CHUNK]) for i in range(0, k, MAX_CHUNK)]
            return (np.concatenate([p[0] for p in parts]),
                    np.concatenate([p[1] for p in parts]))
        if k > self._cap:
            self._grow(k)
        # reversed joints, negated angles (exact): R_j(-q_j)
        np.negative(Q[:, self._order], out=self._qpos[:k])
        dist, geomid = self._batch.ray(self._pnt, self._vec, self.mask, True, -1,
                                       ids=self._ids[:k])
        return dist[:, 0], self._geom_map[geomid[:, 0]]
