"""The FCL checker against MuJoCo's own contacts (mj_kinematics + mj_collision) on the
twin's scene model (planecal.twin.mjcf.scene_spec: the same geometry meshes, robot links
as convex mesh geoms, the laser head and the cell as box geoms).

Comparison model: the twin's scene with two changes that make MuJoCo report the pairs the
checker checks, and only differences of computation remain:
* ``mjDSBL_FILTERPARENT``: MuJoCo's parent-child filter uses weld bodies, so with the
  base welded to the world it would also drop link 1 against every cell geom; the
  checker's own pair list filters the contacts instead.
* the floor geom keeps its top face and reaches ``FLOOR_DEPTH_M`` down, as the checker's
  solid ground does (the twin's slab is 5 cm thick).
All collision geoms get margin = clearance, so MuJoCo reports pairs closer than it;
contacts are then kept if dist < clearance.

Agreement, precisely, for a configuration q within the limits, with c the clearance and
tol = 2 mm:
1. verdict: checker ok  <=>  no MuJoCo contact on a checked pair with dist < c, whenever
   the checker's smallest distance is outside [c - tol, c + tol];
2. contact: every checked pair FCL finds in contact (distance 0) MuJoCo reports with
   dist <= 1e-6, and every pair MuJoCo reports penetrating (dist < -1e-6) FCL finds in
   contact;
3. distance: a pair MuJoCo reports separated (0 <= dist < c) has FCL distance within tol.
tol covers MuJoCo's mesh-box distances inside the margin, which are approximate: one was
seen 1.6 mm above the exact value (the lowest vertex height; test_collision checks FCL's
floor distances against it to 1e-7). All shapes are convex, so MuJoCo's convex hulls are
the shapes themselves.
"""
from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from mujoco_oracle import mujoco_contacts, mujoco_contacts_along_path  # noqa: E402
from planecal.safety.collision import CollisionWorld  # noqa: E402
from planecal.safety.collision_parts import FLOOR_DEPTH_M  # noqa: E402
from planecal.model.kinematics import fk  # noqa: E402
from planecal.model.scene import load_scene  # noqa: E402

C = 0.01
TOL = 0.002


def comparison_model(scene, clearance=C):
    from planecal.twin.mjcf import scene_spec
    spec = scene_spec(scene)
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_FILTERPARENT
    floor = spec.geom("floor")
    floor.size = [floor.size[0], floor.size[1], FLOOR_DEPTH_M / 2]
    floor.pos = [floor.pos[0], floor.pos[1], scene.floor_z - FLOOR_DEPTH_M / 2]
    m = spec.compile()
    m.geom_margin[m.geom_contype > 0] = clearance
    return m, mujoco.MjData(m)


def _part(geom_name: str) -> str:
    return geom_name[2:] if geom_name.startswith("c_") else geom_name


def mj_pair_distances(world, contacts, clearance=C) -> dict[int, float]:
    """Smallest MuJoCo contact dist per checked pair (index into world.pairs), dist < c."""
    index = {frozenset((a, b)): n for n, (a, b, _) in enumerate(world.pairs)}
    out: dict[int, float] = {}
    for ct in contacts:
        n = index.get(frozenset((_part(ct.geom1), _part(ct.geom2))))
        if n is not None and ct.dist < clearance:
            out[n] = min(out.get(n, np.inf), ct.dist)
    return out


@pytest.fixture(scope="module")
def thesis():
    scene = load_scene("thesis_final")
    m, d = comparison_model(scene)
    return scene, CollisionWorld(scene, clearance_m=C), m, d


def test_model_geoms_are_the_checker_parts(thesis):
    scene, world, m, _ = thesis
    names = {_part(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g))
             for g in np.flatnonzero(m.geom_contype > 0)}
    assert {p.name for p in world.parts} == names


def test_checker_agrees_with_mujoco_contacts_on_random_configurations(thesis):
    scene, world, m, d = thesis
    rng = np.random.default_rng(0)
    lo, hi = scene.robot.limits.T
    n_ok = n_bad = n_band = 0
    for _ in range(200):
        q = rng.uniform(lo, hi)
        dist = world.distances(q)
        mj = mj_pair_distances(world, mujoco_contacts(m, d, q))
        dmin = dist.min()
        ok = world.check_config(q).ok
        assert ok == (dmin > C)
        if abs(dmin - C) <= TOL:
            n_band += 1
        else:  # 1. verdict
            assert ok == (len(mj) == 0), (q, dmin, mj)
        for n in np.flatnonzero(dist == 0.0):  # 2. contact
            assert n in mj and mj[n] <= 1e-6, (world.pairs[n], q)
        for n, dm in mj.items():
            if dm < -1e-6:
                assert dist[n] == 0.0, (world.pairs[n], q, dm)
            elif dm >= 0:  # 3. distance
                assert abs(dist[n] - dm) <= TOL, (world.pairs[n], q, dist[n], dm)
        n_ok += ok
        n_bad += not ok
    assert n_ok >= 20 and n_bad >= 20  # both verdicts exercised
    assert n_band <= 10


# ----- the obstacle scene -----

@pytest.fixture(scope="module")
def obstacle():
    scene = load_scene("obstacle_test")
    m, d = comparison_model(scene)
    return scene, CollisionWorld(scene, clearance_m=C), m, d


def _head_centre_track(scene, q0, q1, n=200):
    """Centre of the laser head box (30 mm behind the sensor origin along the beam) along
    the path: a point inside the robot's solid, whatever the link shapes."""
    from planecal.model.geometry import HEAD_EXTENTS, sensor_pose
    T_fs = sensor_pose(scene.sensor_origin, scene.phi_y, scene.phi_z)
    S = np.linspace(0, 1, n)
    T = fk(scene.robot.kinematics, q0 + S[:, None] * (q1 - q0)) @ T_fs
    return T[:, :3, :3] @ np.array([0, 0, -HEAD_EXTENTS[2] / 2]) + T[:, :3, 3]


def _inside_box(box, p):
    from planecal.model.geometry import _rpy_matrix
    x = (p - box.center) @ _rpy_matrix(box.rpy)
    return np.all(np.abs(x) < box.size / 2, axis=-1)


def test_obstacle_scene_blocks_paths_and_accepted_paths_touch_nothing(obstacle):
    """From the calibration position to random sensor poses on the plate (as the
    sampling loop draws them): every path whose head passes through the fin is rejected
    although both ends are clear, and every accepted path is contact-free at 100 samples
    in MuJoCo (no checked pair penetrating, none closer than the clearance - tol)."""
    from planecal.sampling.poses import PoseGenerator
    scene, world, m, d = obstacle
    fin = scene.obstacles[0]
    q0 = scene.calibration_q
    assert world.check_config(q0).ok
    from planecal.sampling.poses import PoseSettings
    gen = PoseGenerator(scene, PoseSettings(cone_deg=scene.cone_deg, roll_deg=180.0,
                                            distance_mm=tuple(scene.distance_mm)))
    rng = np.random.default_rng(0)
    through = accepted = 0
    for _ in range(120):
        q1 = gen.joint_target(gen.draw(rng), q0)
        if q1 is None:
            continue
        r = world.check_path(q0, q1)
        if _inside_box(fin, _head_centre_track(scene, q0, q1)).any() \
                and world.check_config(q1).ok:
            through += 1
            assert not r.ok and r.reason == "environment", r
        if r.ok:
            accepted += 1
            mj = mj_pair_distances(world, mujoco_contacts_along_path(m, d, q0, q1, 100))
            assert not mj or min(mj.values()) > C - TOL, (q1, {world.pairs[n]: v for n, v in mj.items()})
    assert through >= 3 and accepted >= 10
    assert world.counters["rejected_environment"] >= through


def test_mujoco_sees_the_fin_on_a_blocked_path(obstacle):
    """The helper itself: on a path the checker rejects because of the fin, MuJoCo's
    contacts along the path include the fin penetrating a tool or wrist part."""
    from planecal.sampling.poses import PoseGenerator
    scene, world, m, d = obstacle
    gen = PoseGenerator(scene)
    rng = np.random.default_rng(0)
    q0 = scene.calibration_q
    for _ in range(200):
        q1 = gen.joint_target(gen.draw(rng), q0)
        if q1 is None or not world.check_config(q1).ok:
            continue
        r = world.check_path(q0, q1)
        if not r.ok and "fin" in r.pair:
            contacts = mujoco_contacts_along_path(m, d, q0, q1, 200)
            hits = [ct for ct in contacts if "fin" in (ct.geom1, ct.geom2) and ct.dist < 0]
            assert hits
            return
    pytest.fail("no path blocked by the fin")
