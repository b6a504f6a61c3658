"""Collision checker (planecal.safety.collision): exact distances, pair filtering, configurations
and certified paths. MuJoCo cross-checks are in test_collision_mujoco.py."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from planecal.safety.collision import CollisionWorld
from planecal.safety.collision_parts import FLOOR_DEPTH_M
from planecal.base.errors import InputError
from planecal.model.geometry import LinkMesh, StaticMesh, box_mesh
from planecal.model.kinematics import fk, link_frames
from planecal.model.scene import load_scene

C = 0.01  # clearance used throughout [m]


@pytest.fixture(scope="module")
def scene():
    return load_scene("thesis_final")


@pytest.fixture(scope="module")
def world(scene):
    return CollisionWorld(scene, clearance_m=C)


def _T(R=None, t=(0, 0, 0)):
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = t
    return T


def _world(scene, links, static, **kw):
    return CollisionWorld(scene, clearance_m=kw.pop("clearance_m", C), links=links, tools=[],
                          static=static, **kw)


# ----- exact distances -----

def test_box_primitive_distance_is_analytic(scene):
    # a part on body 0 (the base frame, still) and an obstacle box: 0.3 m face to face
    link = LinkMesh("cube", 0, box_mesh([1, 1, 1], _T(t=(0, 0, 5))),
                    box_extents=np.array([1.0, 1, 1]), box_pose=_T(t=(0, 0, 5)))
    ob = StaticMesh("ob", box_mesh([1, 1, 1], _T(t=(1.3, 0.2, 5))), "obstacle",
                    np.array([1.0, 1, 1]), _T(t=(1.3, 0.2, 5)))
    w = _world(scene, [link], [ob])
    assert w.pairs == [("cube", "ob", "environment")]
    assert w.distances(np.zeros(6))[0] == pytest.approx(0.3, abs=1e-12)
    r = w.check_config(np.zeros(6))
    assert r.ok and r.min_distance_m == pytest.approx(0.3, abs=1e-12) and r.pair == ("cube", "ob")


def test_rotated_convex_mesh_distance_is_analytic(scene):
    # unit cube and a cube turned 45 deg about z, centres 2 m apart along x, given as
    # plain meshes (fcl.Convex): distance 2 - 0.5 - sqrt(0.5)
    Rz = trimesh.transformations.rotation_matrix(np.pi / 4, [0, 0, 1])[:3, :3]
    link = LinkMesh("cube", 0, box_mesh([1, 1, 1], _T(t=(0, 0, 5))))
    ob = StaticMesh("ob", box_mesh([1, 1, 1], _T(Rz, (2, 0, 5))), "obstacle")
    w = _world(scene, [link], [ob])
    assert w.distances(np.zeros(6))[0] == pytest.approx(2 - 0.5 - np.sqrt(0.5), abs=1e-9)


def test_wrong_gjk_distances_are_caught(scene):
    """FCL's GJK returns 0.937 m for the 45-degree cube pair above (fcl issue #508:
    parallel features); the support-gap certificate catches it and the triangle-exact
    BVH distance is used. Structured random box/cylinder pairs: never above the BVH value."""
    import fcl
    Rz = trimesh.transformations.rotation_matrix(np.pi / 4, [0, 0, 1])[:3, :3]
    o1 = fcl.CollisionObject(fcl.Box(1, 1, 1), fcl.Transform())
    o2 = fcl.CollisionObject(fcl.Box(1, 1, 1), fcl.Transform(Rz, np.array([2.0, 0, 0])))
    raw = fcl.distance(o1, o2, fcl.DistanceRequest(), fcl.DistanceResult())
    exact = 2 - 0.5 - np.sqrt(0.5)
    if raw - exact < 1e-3:
        pytest.skip("this FCL build gets the 45-degree box pair right")
    box = np.array([1.0, 1, 1])
    link = LinkMesh("cube", 0, box_mesh(box, _T(t=(0, 0, 5))), box_extents=box,
                    box_pose=_T(t=(0, 0, 5)))
    ob = StaticMesh("ob", box_mesh(box, _T(Rz, (2, 0, 5))), "obstacle", box, _T(Rz, (2, 0, 5)))
    w = _world(scene, [link], [ob])
    assert w.distances(np.zeros(6))[0] == pytest.approx(exact, abs=1e-9)
    assert w.counters["gjk_fallbacks"] == 1
    rng = np.random.default_rng(0)
    cyl = trimesh.creation.cylinder(radius=0.2, height=0.8, sections=12)
    for k in range(150):
        R = trimesh.transformations.rotation_matrix(rng.choice([np.pi / 4, np.pi / 6,
                                                                rng.uniform(0, np.pi)]), [0, 0, 1])
        R[:3, 3] = [rng.uniform(1.0, 2.0), rng.choice([0.0, rng.uniform(-0.3, 0.3)]),
                    5 + rng.choice([0.0, 0.1])]
        other = box_mesh(box * rng.choice([1.0, 0.5]), R) if k % 2 else cyl.copy().apply_transform(R)
        w = _world(scene, [link], [StaticMesh("ob", other, "obstacle")])
        ref = fcl.distance(w.parts[0].bvh, w.parts[1].bvh, fcl.DistanceRequest(), fcl.DistanceResult())
        assert w.distances(np.zeros(6))[0] == pytest.approx(max(ref, 0.0), abs=1e-9)


def test_moving_part_is_posed_by_nominal_fk(scene):
    # a 40 mm cube centred on the flange; a plate-like box 200 mm out along the flange z
    q = np.deg2rad([20, -10, -30, 40, 60, -70])
    T = fk(scene.robot.kinematics, q)
    cube = LinkMesh("cube", 6, box_mesh([0.04] * 3))
    ob_pose = T @ _T(t=(0, 0, 0.2 + 0.005))  # 10 mm thick, its near face 0.2 m out
    ob = StaticMesh("ob", box_mesh([0.3, 0.3, 0.01], ob_pose), "obstacle")
    w = _world(scene, [cube], [ob])
    assert w.distances(q)[0] == pytest.approx(0.2 - 0.02, abs=1e-9)


def test_non_convex_part_uses_bvh_and_detects_containment(scene):
    # a non-convex static part: two disjoint 1 m boxes in one mesh. A 0.1 m cube 0.25 m
    # beside the first box is 0.2 m away; the same cube wholly inside it touches no
    # triangle, yet is a collision.
    two = trimesh.util.concatenate([box_mesh([1, 1, 1], _T(t=(0, 0, 5))).to_trimesh(),
                                    box_mesh([1, 1, 1], _T(t=(3, 0, 5))).to_trimesh()])
    assert not two.is_convex and two.is_watertight
    for centre, expected in (((0.8, 0, 5), 0.25), ((0.1, 0.1, 5.1), 0.0)):
        cube = LinkMesh("cube", 0, box_mesh([0.1] * 3, _T(t=centre)))
        w = _world(scene, [cube], [StaticMesh("two", two, "obstacle")])
        assert w.distances(np.zeros(6))[0] == pytest.approx(expected, abs=1e-9)
        assert w.check_config(np.zeros(6)).ok is (expected > C)


def test_clearance_band(scene):
    ob = StaticMesh("ob", box_mesh([1, 1, 1], _T(t=(0, 0, 5))), "obstacle")
    for gap, ok in ((0.005, False), (0.0101, True), (0.0, False), (-0.05, False)):
        cube = LinkMesh("cube", 0, box_mesh([0.2] * 3, _T(t=(0.6 + gap, 0, 5))))
        r = _world(scene, [cube], [ob]).check_config(np.zeros(6))
        assert r.ok is ok, gap
        assert r.min_distance_m == pytest.approx(max(gap, 0.0), abs=1e-9)
        if not ok:
            assert r.reason == "environment" and r.pair == ("cube", "ob")


def test_floor_is_solid_ground_and_its_distance_is_the_lowest_vertex(world, scene):
    rng = np.random.default_rng(3)
    floor_pairs = [n for n, (a, b, k) in enumerate(world.pairs) if b == "floor"]
    lo, hi = scene.robot.limits.T
    seen_above = seen_below = 0
    for _ in range(40):
        q = rng.uniform(lo, hi)
        F = link_frames(scene.robot.kinematics, q)
        d = world.distances(q)
        for n in floor_pairs:
            part = next(p for p in world.parts if p.name == world.pairs[n][0])
            zmin = (part.V @ F[part.body, :3, :3].T + F[part.body, :3, 3])[:, 2].min()
            if zmin > 1e-6:
                assert d[n] == pytest.approx(zmin - scene.floor_z, abs=1e-7)
                seen_above += 1
            else:  # below the floor's top face, even below the 5 cm slab: contact
                assert d[n] == 0.0
                seen_below += 1
    assert seen_above > 50 and seen_below > 10
    assert FLOOR_DEPTH_M >= 5.0


# ----- which pairs are checked -----

ADJACENT = {("base", "turret"), ("turret", "upper_arm"), ("upper_arm", "elbow"),
            ("elbow", "forearm"), ("elbow", "wrist_fork_p"), ("elbow", "wrist_fork_n"),
            ("forearm", "wrist"), ("wrist_fork_p", "wrist"), ("wrist_fork_n", "wrist"),
            ("wrist", "flange"), ("wrist", "flange_adapter"), ("wrist", "laser_head")}


def test_adjacent_links_are_never_checked_nor_reported(world, scene):
    bodies = {p.name: p.body for p in world.parts}
    tools = {p.name for p in world.parts if p.kind == "tool"}
    for a, b, kind in world.pairs:
        if kind == "self":
            if {a, b} & tools:  # the tool is adjacent to the wrist (5) and flange (6)
                other = b if a in tools else a
                assert other not in tools and bodies[other] not in (5, 6), (a, b)
            else:  # links: consecutive bodies are adjacent
                assert abs(bodies[a] - bodies[b]) > 1, (a, b)
            assert (a, b) not in ADJACENT and (b, a) not in ADJACENT
    skipped = {(a, b) for a, b, why in world.skipped_pairs if why == "adjacent"}
    assert ADJACENT <= skipped | {(b, a) for a, b in skipped}
    assert {("base", "floor"), ("turret", "floor")} <= {(a, b) for a, b, why in world.skipped_pairs
                                                       if why == "bolted"}
    # the filter matters: adjacent pieces overlap at the joints (raw FCL contact) ...
    import fcl
    F = link_frames(scene.robot.kinematics, scene.calibration_q)
    parts = {p.name: p for p in world.parts}
    for name in ("turret", "upper_arm"):
        p = parts[name]
        p.obj.setTransform(fcl.Transform(F[p.body, :3, :3], F[p.body, :3, 3]))
    assert fcl.collide(parts["turret"].obj, parts["upper_arm"].obj, fcl.CollisionRequest(),
                       fcl.CollisionResult()) > 0
    # ... but random configurations never report an adjacent pair
    rng = np.random.default_rng(5)
    lo, hi = scene.robot.limits.T
    reported = set()
    for _ in range(150):
        r = world.check_config(rng.uniform(lo, hi))
        if not r.ok:
            reported.add(r.pair)
    assert reported and not reported & (ADJACENT | {(b, a) for a, b in ADJACENT})


def test_folded_configuration_is_self_collision(world):
    # elbow turned 250 deg: the forearm folds back beside the (offset) upper arm, clear of
    # it, and its wrist runs into the turret
    q = np.deg2rad([0, 0, 250, 0, 0, 0])
    r = world.check_config(q)
    assert not r.ok and r.reason == "self" and r.pair in {("turret", "wrist_fork_p"),
                                                          ("turret", "wrist_fork_n")}
    assert r.min_distance_m == 0.0
    d = dict(zip([(a, b) for a, b, _ in world.pairs], world.distances(q)))
    assert d[("upper_arm", "forearm")] > C
    # the wrist bent to 120 deg keeps the flange clear of the forearm's end; at the
    # datasheet's 125 deg the envelopes come closer than the clearance, without contact
    r = world.check_config(np.deg2rad([0, 0, 0, 0, 120, 0]))
    assert r.ok and r.min_distance_m > C
    for q5 in (125, -125):
        r = world.check_config(np.deg2rad([0, 0, 0, 0, q5, 0]))
        assert not r.ok and r.reason == "self" and r.pair == ("forearm", "flange")
        assert 0.0 < r.min_distance_m < C
    # straight out it is clear
    assert world.check_config(np.zeros(6)).ok


def test_calibration_position_of_thesis_final_is_clear(world, scene):
    r = world.check_config(scene.calibration_q)
    assert r.ok and r.reason is None
    assert r.min_distance_m > C
    assert world.check_path(scene.calibration_q, scene.calibration_q).ok


def test_limits_are_rejected(world, scene):
    q = scene.calibration_q.copy()
    q[4] = np.deg2rad(126)
    assert world.check_config(q).reason == "limits"
    assert world.check_path(scene.calibration_q, q).reason == "limits"


# ----- path certification -----

def test_rate_bound_holds_along_random_paths(world, scene):
    """|d(s') - d(s)| <= L |s' - s| (the global bound) for every pair, and the local
    step: the upper part's vertices move, relative to the other part's frame, by no more
    than the gap over the step that _step_sizes certifies."""
    rng = np.random.default_rng(11)
    lo, hi = scene.robot.limits.T
    q0 = scene.calibration_q
    S = np.linspace(0, 1, 101)
    for _ in range(3):
        q1 = np.clip(q0 + rng.uniform(-0.6, 0.6, 6), lo, hi)
        L = world.pair_rates(q0, q1)
        D = np.array([world.distances(q0 + s * (q1 - q0)) for s in S])
        slope = np.abs(np.diff(D, axis=0)) / np.diff(S)[:, None]
        assert np.all(slope <= L + 1e-9)
        # local steps from s = 0.3 for a gap of 5 cm, checked on the vertices
        dq = q1 - q0
        s0 = 0.3
        F0 = link_frames(scene.robot.kinematics, q0 + s0 * dq)
        idx = np.arange(len(world.pairs))
        _, cu = world._lower_bounds(np.broadcast_to(F0, (len(idx),) + F0.shape), idx)
        gap = np.full(len(idx), 0.05)
        steps = world._step_sizes(np.broadcast_to(F0, (len(idx),) + F0.shape), cu, idx, gap,
                                  np.abs(dq), L)
        for n in idx:
            i, j = world._pairs[n]
            up = world._upper[n]
            other = j if up == i else i
            p, o = world.parts[up], world.parts[other]
            ss = np.linspace(s0, min(s0 + steps[n], 1.0), 60)
            Fs = link_frames(scene.robot.kinematics, q0 + ss[:, None] * dq)
            ref = Fs[:, max(o.body, 0)]  # the other part's frame (base for static parts)
            rel = np.linalg.inv(ref) @ Fs[:, p.body]
            X = np.einsum("sab,vb->sva", rel[:, :3, :3], p.V) + rel[:, None, :3, 3]
            assert np.linalg.norm(X - X[0], axis=-1).max() <= 0.05 + 1e-9


def test_accepted_paths_are_clear_at_dense_samples(world, scene):
    """No false clear: every accepted random path keeps every pair farther than the
    clearance at 200 samples (exact smallest distance, check_config)."""
    rng = np.random.default_rng(7)
    lo, hi = scene.robot.limits.T
    q0 = scene.calibration_q
    accepted = rejected = 0
    for _ in range(30):
        q1 = np.clip(q0 + rng.uniform(-0.5, 0.5, 6), lo, hi)
        r = world.check_path(q0, q1)
        if r.ok:
            accepted += 1
            S = np.linspace(0, 1, 200)
            dmin = min(world.check_config(q0 + s * (q1 - q0)).min_distance_m for s in S)
            assert dmin > C
            assert r.min_distance_m > C
        else:
            rejected += 1
            assert r.reason in ("self", "environment", "undecided")
            if r.reason != "undecided":
                q = q0 + r.s * (q1 - q0)
                assert world.distances(q).min() <= C + world.resolution_m
    assert accepted >= 5 and rejected >= 5


def test_grazing_path_is_rejected_not_looped(scene):
    # a cube on the base frame passes nothing, but a flange cube swept past an obstacle
    # whose face is tangent-ish to the motion: the checker must terminate either way
    q0 = np.deg2rad([0, 0, 0, 0, 0, 0])
    q1 = np.deg2rad([30, 0, 0, 0, 0, 0])
    T = fk(scene.robot.kinematics, q0 + 0.5 * (q1 - q0))
    cube = LinkMesh("cube", 6, box_mesh([0.04] * 3))
    # obstacle whose near face is exactly clearance + 0.05 mm from the cube at s = 0.5
    ob = StaticMesh("ob", box_mesh([0.2, 0.2, 0.2], T @ _T(t=(0, 0, 0.02 + C + 5e-5 + 0.1))),
                    "obstacle")
    w = _world(scene, [cube], [ob])
    r = w.check_path(q0, q1)
    assert not r.ok and r.reason in ("environment", "undecided")
    # it ends within the refinement budget: both ends, the coarse grid and at most
    # max_steps rounds of 3 measurements per open interval
    assert w.counters["distance_queries"] <= 2 + 2 * w.coarse_samples + 3 * w.max_steps


def test_bad_input_is_one_line_input_error(world, scene):
    for bad in (np.zeros(5), [0, 0, 0, 0, 0, np.nan], "abc"):
        with pytest.raises(InputError) as e:
            world.check_config(bad)
        assert "\n" not in str(e.value)
    with pytest.raises(InputError):
        world.check_path(np.zeros(6), np.zeros(7))
    with pytest.raises(InputError):
        CollisionWorld(scene, clearance_m=-0.01)


def test_rehearsal_counters(scene):
    """150 samples as the sampling loop draws them (random sensor poses on the plate, IK
    nearest to the current configuration), each target's path checked from the current
    configuration: the counters add up (the time is printed; speed is
    scripts/bench_collision.py's and bench_rehearse.py's to measure, not a test's)."""
    from planecal.sampling.poses import PoseGenerator
    w = CollisionWorld(scene, clearance_m=C)
    gen = PoseGenerator(scene)
    rng = np.random.default_rng(2)
    q = scene.calibration_q.copy()
    accepted = 0
    for i in range(150):
        qt = gen.joint_target(gen.draw(rng), q)
        if qt is None:
            continue
        if w.check_path(q, qt).ok:
            q, accepted = qt, accepted + 1
    c = w.counters
    rejected = sum(c[f"rejected_{k}"] for k in ("limits", "self", "environment", "undecided"))
    assert c["paths"] == c["paths_clear"] + rejected
    assert c["paths_clear"] == accepted > 30
    summary = w.summary()
    print(f"\nrehearsal: {c['paths']} path checks, {accepted} accepted, "
          f"{c['distance_queries']} FCL distance queries, {summary['check_time_s']:.3f} s checking "
          f"({1e3 * summary['check_time_s'] / c['paths']:.2f} ms/path); {dict(c)}")


# ----- the appendix-D cell (issue 11) -----

def test_appendix_d_calibration_position_is_clear():
    """The appendix-D calibration position holds the J6 housing 17 mm above the plate's
    edge (exact shapes); the first envelope (10 mm margin, 12-sided polygons) put it at
    1.9 mm, inside the clearance, so every rehearsal gave up at its start."""
    scene = load_scene("appendix_d")
    w = CollisionWorld(scene, clearance_m=C)
    r = w.check_config(scene.calibration_q)
    assert r.ok and r.min_distance_m > C and r.pair == ("wrist", "plate")
    assert w.check_path(scene.calibration_q, scene.calibration_q).ok


@pytest.mark.parametrize("start", ["calibration", "home"])
def test_appendix_d_rehearsal_completes(tmp_path, capsys, start):
    import json

    from planecal.cli import main
    out = tmp_path / "D.tsv"
    code = main(["rehearse", "--scene", "appendix_d", "--samples", "3", "--seed", "0",
                 "--start", start, "--out", str(out)])
    summary = json.loads(capsys.readouterr().out)
    assert code == 0 and summary["status"] == "complete" and summary["samples"] == 3
    assert len(out.read_text().strip().splitlines()) >= 3


def test_one_joint_safe_sets_are_clear_and_cover_the_mc70_pairs(world, scene):
    """planecal.safety.collision_joint: where a safe set covers its joint's angle, the real parts
    (not the hull) are farther than the clearance whatever the other joints do; the
    sets exist for the pairs that cost the most queries, and cover their ranges."""
    rng = np.random.default_rng(3)
    lim = scene.robot.limits
    by_name = {}
    for st in world.safe_sets:
        by_name.setdefault(world.pairs[st.pair][:2], []).append(st)
        assert np.all(st.lo < st.hi) and np.all(st.hi[:-1] < st.lo[1:])  # sorted, disjoint
        for _ in range(40):
            k = rng.integers(len(st.lo))
            q = rng.uniform(lim[:, 0], lim[:, 1])
            q[st.joint] = rng.uniform(st.lo[k], st.hi[k])
            assert st.covers(q[st.joint], q[st.joint])
            assert world.distances(q)[st.pair] > C
    # J5 alone decides fork/adapter against the flange (round about J6), J2 the base
    # against the upper arm (round about J1); measured safe: 250 / 250 / 200 of 215 deg
    for pair, joint, safe_deg in [(("wrist_fork_p", "flange"), 4, 249),
                                  (("wrist_fork_n", "flange_adapter"), 4, 249),
                                  (("base", "upper_arm"), 1, 195)]:
        assert max(np.rad2deg(s.safe_rad) for s in by_name[pair] if s.joint == joint) > safe_deg
    assert world.sweep_queries < 5000


def test_safe_sets_change_no_verdict_but_undecided(scene):
    """The same paths checked with and without the safe sets: a safe set only skips
    pairs it has certified, so every verdict stays, except 'undecided' may become clear."""
    world = CollisionWorld(scene, clearance_m=C)
    plain = CollisionWorld(scene, clearance_m=C)
    plain.safe_sets = []
    rng = np.random.default_rng(11)
    lim = scene.robot.limits
    q0 = scene.calibration_q
    seen = {"ok": 0, "rejected": 0}
    for _ in range(60):
        q1 = np.clip(q0 + rng.normal(0, 0.6, 6), lim[:, 0], lim[:, 1])
        a, b = world.check_path(q0, q1), plain.check_path(q0, q1)
        if a.ok != b.ok:
            assert a.ok and b.reason == "undecided"
        else:
            assert a.reason == b.reason
        seen["ok" if a.ok else "rejected"] += 1
        if a.ok:
            q0 = q1
    assert seen["ok"] > 10 and seen["rejected"] > 5
    assert world.counters["distance_queries"] < plain.counters["distance_queries"]
