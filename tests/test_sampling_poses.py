"""Random sensor poses (seed 7.1.2): spot on the plate within the margin, beam within the
cone (uniform over its solid angle), distance in range; flange pose and IK consistent with
the nominal sensor mounting."""
import json
from dataclasses import dataclass

import numpy as np
import pytest

from planecal.model.measurement import predict, sensor_in_base
from planecal.model.encoder import joints_to_counts
from planecal.base.errors import InputError
from planecal.model.kinematics import fk
from planecal.model.robot import within_limits
from planecal.sampling.poses import PoseGenerator, PoseSettings
from planecal.model.scene import load_scene, nominal_params


@pytest.fixture(scope="module")
def scene():
    return load_scene("thesis_final")


def two_plate_scene(tmp_path):
    raw = json.loads(load_scene("thesis_final").path.read_text())
    p2 = dict(raw["plates"][0], name="plate2", corner_m=[0.30, 0.805229, 0.479085],
              n_tilde=[0.0, -0.9, 3.6])  # the corner on its plane (the scene check: 5 mm)
    raw["plates"].append(p2)
    path = tmp_path / "two.json"
    path.write_text(json.dumps(raw))
    return load_scene(path)


def draws(gen, n, seed=0, plate=0):
    rng = np.random.default_rng(seed)
    return [gen.draw(rng, plate) for _ in range(n)]


def test_geometry_of_drawn_poses(scene):
    s = PoseSettings(cone_deg=30.0, distance_mm=(70.0, 90.0), margin_m=0.025)
    gen = PoseGenerator(scene, s)
    F = scene.plates[0].frame()
    size = scene.plates[0].size
    inward = -F[:3, 2]
    poses = draws(gen, 4000)
    uv = np.array([F[:3, :2].T @ (p.point - F[:3, 3]) for p in poses])
    off_plane = np.array([scene.plates[0].n_tilde @ p.point - 1 for p in poses])
    cos_t = np.array([p.beam @ inward for p in poses])
    d = np.array([p.distance_m for p in poses])
    # spot on the plate, inside the margin, spread over it
    assert np.max(np.abs(off_plane)) < 1e-12
    assert uv[:, 0].min() >= 0.025 and uv[:, 0].max() <= size[0] - 0.025
    assert uv[:, 1].min() >= 0.025 and uv[:, 1].max() <= size[1] - 0.025
    assert uv[:, 0].max() - uv[:, 0].min() > 0.29 and uv[:, 1].max() - uv[:, 1].min() > 0.19
    # beam within the cone, up to its rim
    angle = np.rad2deg(np.arccos(np.clip(cos_t, -1, 1)))
    assert angle.max() <= 30.0 + 1e-9 and angle.max() > 29.5
    # uniform over the solid angle: cos(theta) ~ U[cos 30, 1]
    c30 = np.cos(np.deg2rad(30))
    u = (cos_t - c30) / (1 - c30)
    assert abs(u.mean() - 0.5) < 0.015 and abs(np.mean(u < 0.25) - 0.25) < 0.025
    # azimuth uniform: the mean tilt direction is near zero
    tilt = np.array([p.beam - (p.beam @ inward) * inward for p in poses])
    assert np.linalg.norm(tilt.mean(axis=0)) < 0.01
    # distance in range and the sensor origin d before the spot along the beam
    assert d.min() >= 0.070 and d.max() <= 0.090 and d.max() - d.min() > 0.019
    for p in poses[:50]:
        assert np.allclose(p.T_sensor[:3, 3] + p.distance_m * p.beam, p.point, atol=1e-12)
        assert np.allclose(p.T_sensor[:3, :3].T @ p.T_sensor[:3, :3], np.eye(3), atol=1e-12)
        assert np.linalg.det(p.T_sensor[:3, :3]) == pytest.approx(1.0)


def test_fixed_distance_and_narrow_cone(scene):
    gen = PoseGenerator(scene, PoseSettings(cone_deg=0.0, fixed_distance_mm=80.0, roll_deg=0.0))
    inward = -scene.plates[0].frame()[:3, 2]
    for p in draws(gen, 50):
        assert p.distance_m == 0.080
        assert np.allclose(p.beam, inward, atol=1e-12)


def test_flange_pose_and_ik_meet_the_plate_at_the_drawn_distance(scene):
    """IK target of the nominal flange pose: the nominal model predicts the drawn distance
    (to the encoder's rounding) and the beam hits the drawn spot."""
    gen = PoseGenerator(scene)
    nom = nominal_params(scene)
    rng = np.random.default_rng(5)
    q = scene.calibration_q
    n_ok = 0
    for _ in range(60):
        p = gen.draw(rng, 0)
        qt = gen.joint_target(p, q)
        if qt is None:
            continue
        n_ok += 1
        assert within_limits(scene.robot, qt)
        assert np.allclose(fk(scene.robot.kinematics, qt), p.T_flange, atol=1e-9)
        o_b, z_b = sensor_in_base(scene.robot, qt, nom)
        assert np.allclose(o_b, p.T_sensor[:3, 3], atol=1e-9)
        assert np.allclose(z_b, p.beam, atol=1e-9)
        d = predict(scene.robot, joints_to_counts(scene.robot, qt)[None], nom)[0]
        assert abs(d - p.distance_m) < 2e-4  # counts rounding: < 0.2 mm
        q = qt
    assert n_ok >= 50


def test_ik_nearest_prefers_short_moves(scene):
    """Among IK solutions the target needs the fewest ticks from the current configuration."""
    from planecal.model.ik import ik_all
    gen = PoseGenerator(scene)
    rng = np.random.default_rng(2)
    q = scene.calibration_q
    for _ in range(20):
        p = gen.draw(rng, 0)
        qt = gen.joint_target(p, q)
        if qt is None:
            continue
        all_q = ik_all(scene.robot, p.T_flange)
        cost = np.max(np.abs(all_q - q) * np.abs(scene.robot.gains), axis=1)
        assert np.max(np.abs(qt - q) * np.abs(scene.robot.gains)) == pytest.approx(cost.min())


def test_plate_choice(tmp_path):
    sc = two_plate_scene(tmp_path)
    rng = np.random.default_rng(0)
    rr = PoseGenerator(sc, PoseSettings(plate_choice="round_robin"))
    assert [rr.plate_for(i, rng) for i in range(5)] == [0, 1, 0, 1, 0]
    rnd = PoseGenerator(sc, PoseSettings(plate_choice="random"))
    picks = [rnd.plate_for(i, rng) for i in range(400)]
    assert 150 < sum(picks) < 250
    for k in (0, 1):
        for p in draws(rr, 20, plate=k):
            assert p.plate == k
            assert abs(sc.plates[k].n_tilde @ p.point - 1) < 1e-12


@pytest.mark.parametrize("kw, msg", [
    (dict(cone_deg=95.0), "cone"),
    (dict(fixed_distance_mm=100.0), "laser range"),
    (dict(distance_mm=(60.0, 90.0)), "laser range"),
    (dict(plate_choice="nearest"), "plate choice"),
    (dict(margin_m=0.2), "margin"),
    (dict(roll_deg=200.0), "roll"),
])
def test_bad_settings_are_one_line_input_errors(scene, kw, msg):
    with pytest.raises(InputError, match=msg) as e:
        PoseGenerator(scene, PoseSettings(**kw))
    assert "\n" not in str(e.value)


class _Segments:
    """A collision checker that clears every configuration but only the listed straight
    paths (either way): a cell where one route is open."""

    def __init__(self, *open_paths):
        self.open = [(np.asarray(a, float), np.asarray(b, float)) for a, b in open_paths]

    def check_config(self, q):
        return _Verdict(True)

    def check_path(self, q0, q1):
        return _Verdict(any((np.allclose(q0, a) and np.allclose(q1, b))
                            or (np.allclose(q0, b) and np.allclose(q1, a))
                            for a, b in self.open))


@dataclass
class _Verdict:
    ok: bool
    pair: tuple | None = None


def test_a_detour_leaves_the_way_the_robot_came_in_where_nothing_else_is_clear(scene):
    """Issue 22's 450-sample rehearsal gave up at sample 159: from a pose on a plate with
    the wrist folded, every path out (to the next target, backed out along the beam, to
    both hubs) was blocked, while the route the robot came in by was clear. The detour now
    takes it back (each leg checked again) and goes on from there."""
    from planecal.sampling.detour import Detour
    from planecal.sampling.planner import Plan, route_back
    gen = PoseGenerator(scene, PoseSettings())
    rng = np.random.default_rng(3)
    q = [gen.joint_target(gen.draw(rng, 0), scene.calibration_q, rng) for _ in range(4)]
    prev, via, here, goal = q
    came = Plan(7, prev, [], {}, q=here, via=[(via, gen.counts_target(via))])
    back = route_back(came)
    assert [list(b) for b in back] == [list(via), list(prev)]  # nearest first
    # only the legs it came by and prev -> goal are open: no other detour is clear
    det = Detour(gen, _Segments((here, via), (via, prev), (prev, goal)))
    assert det.find(here, goal) is None
    legs = det.find(here, goal, back)
    assert [list(v) for v, _ in legs] == [list(via), list(prev)]
    assert all(np.array_equal(c, gen.counts_target(v)) for v, c in legs)
    # a leg back that is no longer clear is not taken
    assert Detour(gen, _Segments((here, via), (prev, goal))).find(here, goal, back) is None


class _Blocked:
    """Clears every configuration and no straight path."""

    def check_config(self, q):
        return _Verdict(True)

    def check_path(self, q0, q1):
        return _Verdict(False)


class _Detours:
    """A detour finder: the near detour clears the draw numbered ``near_at`` (0-based,
    counting the poses asked about), a far one clears every pose. Keeps what it was asked."""

    def __init__(self, near_at=None):
        self.near_at, self.asked = near_at, []

    def find(self, q0, q1, back=(), far=True):
        self.asked.append(np.array(q1))
        if len(self.asked) - 1 == self.near_at:
            return [(q1, None)]
        return self.far(q0, q1, back) if far else None

    def far(self, q0, q1, back=()):
        return [("hub", None)]


def test_a_pose_list_serves_a_pose_reachable_nearer_before_a_far_detour(scene):
    """Where no pose left has a clear straight path, the list's first pose a near detour
    reaches is served before an earlier one only a far detour reaches."""
    from planecal.sampling.planner import ListPlanner
    gen = PoseGenerator(scene, PoseSettings())
    rng = np.random.default_rng(5)
    q = [gen.joint_target(gen.draw(rng, 0), scene.calibration_q, rng) for _ in range(3)]
    counts = np.array([gen.counts_target(v) for v in q])
    lp = ListPlanner(scene, counts, np.zeros(3, int), _Blocked())
    lp.detour = det = _Detours(near_at=1)  # the list's second pose
    plan = lp.plan(scene.calibration_q, 0, {}, budget=10)
    assert lp.taken == [1] and plan.via[0][1] is None and not plan.rejections
    lp.detour = _Detours()  # none nearer: the first left, by a far detour
    plan = lp.plan(q[1], 1, {}, budget=10)
    assert lp.taken == [1, 0] and plan.via == [("hub", None)]
    assert len(det.asked) == 2


def test_a_list_pose_blocked_every_way_is_served_a_turn_away(scene):
    """Truth 419's list run stood where its last pose (J4 5 rad away) swept the wrist
    through a plate on every way. Where every pose left is blocked, the list serves one
    with a joint turned by whole turns: the same flange pose, other counts."""
    from planecal.model.ik import turns
    from planecal.model.kinematics import fk
    from planecal.sampling.planner import ListPlanner
    gen = PoseGenerator(scene, PoseSettings())
    rng = np.random.default_rng(5)
    q = gen.joint_target(gen.draw(rng, 0), scene.calibration_q, rng)
    Q = turns(scene.robot, q)
    assert len(Q) >= 1 and not any(np.allclose(v, q) for v in Q)
    lo, hi = scene.robot.limits.T
    assert np.all((Q >= lo - 1e-12) & (Q <= hi + 1e-12))
    kin = scene.robot.kinematics
    assert all(np.allclose(fk(kin, v), fk(kin, q), atol=1e-9) for v in Q)
    v = Q[0]  # only the straight path to this turn of the pose is open
    lp = ListPlanner(scene, gen.counts_target(q)[None], np.zeros(1, int),
                     _Segments((scene.calibration_q, v)))
    plan = lp.plan(scene.calibration_q, 0, {}, budget=10)
    assert plan.q is not None and np.allclose(plan.q, v) and lp.taken == [0]
    assert np.array_equal(plan.qe_goal, gen.counts_target(v)) and plan.via == []
    lp = ListPlanner(scene, gen.counts_target(q)[None], np.zeros(1, int), _Segments())
    plan = lp.plan(scene.calibration_q, 0, {}, budget=10)
    # blocked every way: the list ends there, the pose rejected and dropped
    assert plan.q is None and plan.exhausted and "a turn away" in plan.reason
    assert lp.left == [] and len(plan.rejections) == 1


def test_a_list_run_ends_complete_without_the_poses_it_cannot_reach(scene, tmp_path):
    """Truths 408 and 419 (issue 31's unseen truths, a 481-reading tool list): the run
    stood where the list's last pose could be reached no way, and validate failed the
    truth. The list now ends there: the pose rejected and dropped, the run complete with
    what it measured, and the reason says so; the tour a plan checks says it too."""
    from planecal.safety.collision import CollisionWorld
    from planecal.sampling import tour
    from planecal.studies.rehearsal import rehearse_planned
    from planecal.twin import Twin
    gen = PoseGenerator(scene, PoseSettings())
    world = CollisionWorld(scene)
    rng = np.random.default_rng(8)
    q = []
    while len(q) < 3:
        v = gen.joint_target(gen.draw(rng, 0), scene.calibration_q, rng)
        if v is not None and world.check_config(v).ok:
            q.append(v)
    counts = np.array([gen.counts_target(v) for v in q])
    from checkers import NoWayTo
    from planecal.model.encoder import counts_to_joints
    checker = NoWayTo(world, counts_to_joints(scene.robot, counts[2]))  # as the list has it
    _, taken, why = tour.visit_list(scene, counts, np.zeros(3, int), checker,
                                    scene.calibration_q)
    assert sorted(taken) == [0, 1] and "cannot be reached" in why and "(dropped)" in why
    stats = rehearse_planned(scene, counts, np.zeros(3, int), tmp_path / "r.tsv",
                             Twin(scene, seed=1), checker)
    assert stats.status == "complete" and stats.samples <= 2
    assert stats.rejected["collision"] >= 1 and "(dropped)" in stats.reason


def test_the_rehearsal_that_gave_up_at_sample_159_completes(tmp_path):
    from planecal.cli import main
    from planecal.io.samples import read_samples
    out = tmp_path / "r.tsv"
    assert main(["rehearse", "--scene", "three_plates", "--errors", "realistic", "--seed", "4",
                 "--samples", "450", "--out", str(out), "-q"]) == 0
    side = json.loads((tmp_path / "r.tsv.json").read_text())
    assert side["status"] == "complete" and len(read_samples(out).qe) == 450
    # the way back travels with the run (a resume takes it where the robot still is)
    rb = side["route_back"]
    assert len(rb["from_counts"]) == 6 and 1 <= len(rb["counts"]) <= 3
