"""The checker (FCL on the collision envelope) against exact distances of the visual link
shapes (MuJoCo's mj_geomDistance, tests/mujoco_oracle.py), and the oracle against FCL on
the same visual shapes and against brute-force sampling."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from mujoco_oracle import ExactOracle  # noqa: E402
from planecal.safety.collision import CollisionWorld  # noqa: E402
from planecal.model.geometry import COLLISION_MARGIN, scene_meshes  # noqa: E402
from planecal.model.ik import ik_nearest  # noqa: E402
from planecal.sampling.poses import PoseGenerator  # noqa: E402
from planecal.model.scene import load_scene  # noqa: E402

C = 0.01
M = COLLISION_MARGIN
SLACK = 0.0035  # polygon corners and cylinder rims beyond the margin, per piece


@pytest.fixture(scope="module")
def thesis():
    scene = load_scene("thesis_final")
    return scene, CollisionWorld(scene, clearance_m=C), ExactOracle(scene, clearance_m=C)


def test_oracle_agrees_with_fcl_on_the_visual_shapes(thesis):
    """Two engines, the same shapes: MuJoCo's GJK on the model's meshes (vertices rounded
    to 1e-6 m, float32) and the checker's certified FCL distances on the visual pieces."""
    scene, _, oracle = thesis
    rng = np.random.default_rng(0)
    lo, hi = scene.robot.limits.T
    seen = {"apart": 0, "contact": 0}
    for _ in range(60):
        q = rng.uniform(lo, hi)
        dm, df = oracle.distances(q), oracle.world.distances(q)
        apart = (dm > 1e-5) & (df > 1e-5)
        assert np.all(np.abs(dm[apart] - df[apart]) <= 1e-5)
        assert np.all(dm[df == 0.0] <= 1e-5)  # FCL contact: MuJoCo touching or penetrating
        assert np.all(df[dm < -1e-5] == 0.0)  # MuJoCo penetration: FCL contact
        seen["apart"] += apart.sum()
        seen["contact"] += (df == 0.0).sum()
    assert seen["apart"] > 1000 and seen["contact"] > 20


def test_checker_distances_against_exact_distances(thesis):
    """On random configurations every checked pair's checker distance is the exact
    distance less the margin of each moving piece (one for the cell, two for a self
    pair), and at most SLACK per piece less than that: conservative and tight."""
    scene, world, oracle = thesis
    assert [(a, b) for a, b, _ in world.pairs] == oracle.pairs
    rng = np.random.default_rng(1)
    lo, hi = scene.robot.limits.T
    n_self = n_env = 0
    for _ in range(40):
        q = rng.uniform(lo, hi)
        dc, de = world.distances(q), oracle.distances(q)
        for n, (_, _, kind) in enumerate(world.pairs):
            k = 2 if kind == "self" else 1
            if de[n] <= k * M:  # the envelopes touch
                assert dc[n] == 0.0
                continue
            if dc[n] == 0.0:  # contact of the envelopes within the slack
                assert de[n] <= k * (M + SLACK)
                continue
            gap = de[n] - k * M - dc[n]
            assert -1e-5 <= gap <= k * SLACK, (world.pairs[n], q, de[n], dc[n])
            n_self += kind == "self"
            n_env += kind == "environment"
    assert n_self > 500 and n_env > 100


def test_oracle_path_sampling_against_brute_force(thesis):
    """path_min's smallest distance is within 0.5 mm (half its 1 mm step) of a brute-force
    minimum on a 0.2 mm grid (+ 0.1 mm) where that minimum is below the threshold; above
    it, path_min never reports below the threshold by more than that. The brute force
    covers the pairs that a coarse grid and the pair rates cannot rule out."""
    scene, world, oracle = thesis
    rng = np.random.default_rng(2)
    lo, hi = scene.robot.limits.T
    q0 = scene.calibration_q
    thr, below = 0.08, 0
    for _ in range(8):
        q1 = np.clip(q0 + rng.uniform(-0.3, 0.3, 6), lo, hi)
        pm = oracle.path_min(q0, q1, threshold=thr)
        L = oracle.world.pair_rates(q0, q1)
        S = np.linspace(0, 1, 101)
        D = np.array([oracle.distances(q0 + s * (q1 - q0)) for s in S])
        lower = D.min(0) - L * (S[1] - S[0]) / 2  # no pair gets closer than this
        brute = np.inf
        for n in np.flatnonzero(lower < thr):
            k = int(np.ceil(L[n] / 2e-4)) + 1
            brute = min(brute, min(oracle.distances(q0 + s * (q1 - q0), pairs=[n])[0]
                                   for s in np.linspace(0, 1, k)))
        if brute < thr:
            below += 1
            assert abs(pm.distance - brute) <= 6e-4, (pm, brute)
        else:
            assert pm.distance >= thr - 5e-4
    assert below >= 3


def _near_stand(scene, rng, q_near, gap):
    """A configuration whose tool points at the plate's stand from the robot's side, the
    sensor origin ``gap`` = (lo, hi) m (drawn) from the column's face, below the plate
    (or None)."""
    stand = [m for m in scene_meshes(scene) if m.kind == "stand"][0]
    c, half = stand.box_pose[:3, 3], stand.box_extents[0] / 2
    towards_robot = np.arctan2(c[1], c[0]) + np.pi
    for _ in range(50):
        a = towards_robot + rng.uniform(-0.8, 0.8)
        u = np.array([np.cos(a), np.sin(a), 0.0])
        z = -u + rng.normal(0, 0.2, 3)
        z /= np.linalg.norm(z)
        tip = c + u * (half + rng.uniform(*gap))
        tip[2] = rng.uniform(0.15, stand.box_extents[2] - 0.05)
        x = np.cross([0.0, 0.0, 1.0], z)
        x /= np.linalg.norm(x)
        T = np.eye(4)
        T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        T[:3, 3] = tip - 0.18 * z  # the sensor origin is ~0.18 m out from the flange
        q = ik_nearest(scene.robot, T, q_near)
        if q is not None:
            return q
    return None


@pytest.mark.parametrize("near", ["plate", "stand"])
def test_checker_never_accepts_a_path_the_oracle_finds_in_contact(thesis, near):
    """Random straight joint paths near the plate (from sampling poses, up to 0.25 rad a
    joint) or its stand (from the tool 5-25 cm off the column to the tool between 3 cm
    inside and 10 cm off it): the exact shapes touch the plate or the stand on some of
    them, the checker rejects every path they touch on, and every path it accepts keeps
    the exact shapes the clearance plus the margin apart (to the oracle's 0.5 mm)."""
    scene, world, oracle = thesis
    rng = np.random.default_rng(3 if near == "plate" else 4)
    lo, hi = scene.robot.limits.T
    gen = PoseGenerator(scene)
    part = "plate" if near == "plate" else "plate_stand"
    counts = {"paths": 0, "accepted": 0, "contact": 0, "contact_near": 0, "close_accepted": 0}
    while counts["paths"] < 60:
        if near == "plate":
            q0 = gen.joint_target(gen.draw(rng), scene.calibration_q)
            q1 = None if q0 is None else np.clip(q0 + rng.uniform(-0.25, 0.25, 6), lo, hi)
        else:
            q0 = _near_stand(scene, rng, scene.calibration_q, (0.05, 0.25))
            q1 = None if q0 is None else _near_stand(scene, rng, q0, (-0.03, 0.10))
        if q1 is None or not world.check_config(q0).ok:
            continue
        counts["paths"] += 1
        ok = world.check_path(q0, q1).ok
        pm = oracle.path_min(q0, q1, threshold=C + M)
        if pm.distance <= 0.0:
            assert not ok, (q0, q1, pm)
            counts["contact"] += 1
            counts["contact_near"] += oracle.path_min(q0, q1, threshold=C + M,
                                                      pairs=oracle.pair_indices(part)).distance <= 0
        if ok:
            counts["accepted"] += 1
            assert pm.distance >= C + M - 5e-4, (q0, q1, pm)
            counts["close_accepted"] += oracle.path_min(
                q0, q1, threshold=C + M, pairs=oracle.pair_indices(part)).distance < C + M + 0.02
    assert counts["contact_near"] >= 3 and counts["accepted"] >= 20, counts
    assert counts["close_accepted"] >= 1, counts  # accepted paths that pass close by


def test_visual_shapes_clear_where_the_checker_accepts_the_sampling_draws():
    """A short run of the sampling planner on three_plates: its accepted targets and
    paths keep the exact shapes the clearance apart (the bench's accepted_colliding_paths
    criterion, on a test-sized run)."""
    from planecal.model.encoder import counts_to_joints, joints_to_counts
    from planecal.sampling.planner import Planner
    from planecal.sampling.run import RunSettings
    scene = load_scene("three_plates")
    checker = CollisionWorld(scene, clearance_m=C)
    oracle = ExactOracle(scene, clearance_m=C)
    settings = RunSettings.for_scene(scene, samples=20, seed=5)
    planner = Planner(scene, settings.pose, checker)
    state = np.random.default_rng(5).bit_generator.state
    q0 = counts_to_joints(scene.robot, joints_to_counts(scene.robot, scene.calibration_q))
    for i in range(20):
        plan = planner.plan(q0, i, state, settings.max_attempts)
        assert plan.q is not None
        qs = [q0] + [q for q, _ in plan.via] + [plan.q]  # straight, or a detour's legs
        for a, b in zip(qs[:-1], qs[1:]):
            pm = oracle.path_min(a, b, threshold=C, stop_below=C - 5e-4)
            assert pm.distance >= C - 5e-4 and not pm.stopped
        state, q0 = plan.rng_after, plan.q
