"""ISO 9283 where the tool is (issue 22): AP and RP by their definition, the tool point read
from MuJoCo against the analytic model, the twin's own true model as the floor (the
oracle), the cube inside the calibrated region, named TCPs, the approach-direction seam and
the retired flange-AP files."""
import json

import numpy as np
import pytest

from planecal.base.errors import InputError
from planecal.model.scene import load_scene


def test_ap_and_rp_by_their_iso_definition():
    """ISO 9283 7.2.1/7.2.2 on a hand-made case: AP of a pose is |barycentre - commanded|;
    the figure of a set is its worst pose's, not the mean; RP = l_bar + 3 S_l."""
    from planecal.studies.validation import ap_rp
    commanded = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    # pose 1: three visits around (0.3, 0.4, 0) -> AP 0.5; pose 2: exactly on target
    att = np.array([[[0.3, 0.4, 0.1], [1.0, 0.0, 0.0]],
                    [[0.3, 0.4, -0.1], [1.0, 0.0, 0.0]],
                    [[0.3, 0.4, 0.0], [1.0, 0.0, 0.0]]])
    ap, vec, rp = ap_rp(att, commanded)
    np.testing.assert_allclose(ap, [0.5, 0.0], atol=1e-15)
    np.testing.assert_allclose(vec[0], [0.3, 0.4, 0.0], atol=1e-15)
    l = np.array([0.1, 0.1, 0.0])  # distances from the barycentre (0.3, 0.4, 0)
    assert rp[0] == pytest.approx(l.mean() + 3 * l.std(ddof=1), abs=1e-15)
    assert rp[1] == 0.0
    assert ap.max() == 0.5 and ap.mean() == 0.25  # the set's AP is 0.5, not the mean


def test_a_change_says_larger_when_ap_grew():
    from planecal.present.validation import change
    assert change(2.0228, 2.8392) == "x1.4 larger"  # the "(x0.7 smaller)"
    assert change(4.0, 1.0) == "x4.0 smaller"


def test_a_scene_names_its_tools_checked_on_load(tmp_path):
    raw = json.loads(load_scene("three_plates").path.read_text())
    p = tmp_path / "s.json"
    for tools, msg in (([{"name": "tool", "tcp_m": [0, 0, 0]}], "tools[0].name: 'tool'"),
                       ([{"name": "a", "tcp_m": [0, 0, 0]}, {"name": "a", "tcp_m": [0, 0, 1]}],
                        "tools[1].name: 'a' is named twice"),
                       ([{"name": "a", "tcp_m": [0, 0, 3]}], "tools[0].tcp_m"),
                       ([{"name": "a", "tcp_mm": [0, 0, 3]}], "tools[0]")):
        p.write_text(json.dumps({**raw, "tools": tools}))
        with pytest.raises(InputError, match=msg.replace("[", r"\[").replace("]", r"\]")):
            load_scene(p)
    p.write_text(json.dumps({**raw, "tools": [{"name": "pin", "tcp_m": [0, 0.05, 0.3]}]}))
    s = load_scene(p)
    assert s.tools[0].name == "pin" and s.tools[0].tcp.tolist() == [0, 0.05, 0.3]
    assert s.standoff_m == pytest.approx(0.080)  # the ZS-LD80's 65-95 mm window's middle
    assert load_scene("three_plates").tools == []


@pytest.fixture(scope="module")
def realistic_twin():
    from planecal.twin import Twin
    from planecal.twin.world import WorldRef
    scene = load_scene("three_plates")
    world, opts = WorldRef("realistic", 2).build(scene)
    return scene, world, Twin(scene, truth=world, seed=0, options=opts)


def test_the_true_tool_point_mujoco_against_the_analytic_chain(realistic_twin):
    """The twin's true tool point (MuJoCo's laser site on the true flange, the beam point
    at the measuring centre) equals the analytic chain of the world's kinematics at the
    twin's joint row with the truth's sensor parameters, and the oracle's constant."""
    from planecal.model.kinematics import fk
    from planecal.model.measurement import beam_point
    from planecal.twin.oracle import TrueModel
    scene, world, twin = realistic_twin
    t = world.params
    t_true = beam_point(t.sensor_origin, t.phi_y, t.phi_z, scene.standoff_m)
    assert np.linalg.norm(world.kinematics.flange[:3, 3]) > 1e-5  # a flange frame error
    for dc in ([0] * 6, [4000, -9000, 7000, 20000, -15000, 30000]):
        twin.set_counts(twin.current_counts + np.array(dc))
        S = twin.sensor_pose()
        F = fk(world.kinematics, twin.qpos)
        np.testing.assert_allclose(S[:3, 3] + scene.standoff_m * S[:3, 2],
                                   F[:3, :3] @ t_true + F[:3, 3], rtol=0, atol=1e-12)
        np.testing.assert_allclose(twin.flange_pose(), F, rtol=0, atol=1e-12)
    np.testing.assert_allclose(TrueModel(twin, scene.standoff_m).tool_in_flange, t_true,
                               rtol=0, atol=1e-12)


@pytest.fixture(scope="module")
def floor_run(tmp_path_factory):
    """Truth 0 of three_plates with a named TCP, in the realistic world without backlash
    and noise (link geometry, frames, compliance, gear error and the laser's linearity
    stay): a level-1 calibration of 40 samples and the ISO poses, 2 cycles."""
    from planecal.estimation.calibrate import CalibrationSettings
    from planecal.studies.validation import TruthJob, ValidationSettings, truth_run
    raw = json.loads(load_scene("three_plates").path.read_text())
    p = tmp_path_factory.mktemp("tools") / "three_plates_pin.json"
    p.write_text(json.dumps({**raw, "tools": [{"name": "pin", "tcp_m": [0, 0.05, 0.3]}]}))
    job = TruthJob(scene=str(p), errors="realistic", truth_seed=0, samples=40, seed=0,
                   settings=ValidationSettings(cycles=2, gauge=False),
                   off=("backlash", "noise"), calibration=CalibrationSettings())
    v, _, (qe, _, _) = truth_run(job)
    return load_scene(p), v, qe


def test_the_oracle_leaves_only_whole_counts_without_backlash_and_noise(floor_run):
    """The twin's own true model, in a world with no backlash and no noise, leaves only its
    rounding to whole counts: its AP at the tool point is that rounding's share exactly,
    bounded by half a count of every joint (measured 13 um on three_plates truth 0: one
    MC70 count is 18-41 urad, 10-60 um at a 1.5-2 m lever), and its RP is 0."""
    from planecal.twin import Twin
    from planecal.twin.oracle import TrueModel
    from planecal.twin.world import WorldRef, without
    scene, v, _ = floor_run
    rounding = np.asarray(v["oracle"]["rounding_mm"])
    assert v["ap_oracle_tool_mm"] == pytest.approx(rounding.max(), abs=1e-9)
    assert v["rp_oracle_tool_mm"] < 1e-9
    # the bound: half a count on every joint, through the map's own central differences
    world, opts = without(*WorldRef("realistic", 0).build(scene), ("backlash", "noise"))
    tm = TrueModel(Twin(scene, truth=world, seed=0, options=opts), scene.standoff_m)
    for c, r in zip(np.asarray(v["iso"]["models"]["oracle"]["counts"]), rounding):
        J = np.array([(tm.tool_point(c + e) - tm.tool_point(c - e)) / 2 for e in np.eye(6)])
        assert r <= 0.5 * np.linalg.norm(J, axis=1).sum() * 1e3 + 1e-9
    assert 1e-4 < v["ap_oracle_tool_mm"] < 0.03
    # the calibration leaves the geometry and compliance it cannot fit: 10x the floor
    assert v["ap_after_tool_mm"] > 10 * v["ap_oracle_tool_mm"]
    # the oracle knows the true flange: a named TCP lands as well as the tool point
    pin = v["tcps"][0]
    assert pin["name"] == "pin" and pin["tcp_m"].tolist() == [0, 0.05, 0.3]
    assert pin["ap_oracle_tcp_mm"] < 0.05 < pin["ap_after_tcp_mm"]


def test_the_cube_lies_inside_the_calibrated_region(floor_run):
    """Every model's ISO poses are inside the region (the samples' flange hull + 50 mm,
    their joint ranges + 2 deg) and collision-free; P1 is a sample's tool point; the
    distances to the nearest sample are the brute-force ones."""
    from planecal.estimation.compensate import Region
    from planecal.model.encoder import counts_to_joints
    from planecal.safety.collision import CollisionWorld
    from planecal.studies.validation import SamplePoses
    scene, v, qe = floor_run
    region = Region.from_counts(scene.robot, qe, "samples")
    world = CollisionWorld(scene, clearance_m=0.01)
    for name, m in v["iso"]["models"].items():
        q = counts_to_joints(scene.robot, np.asarray(m["counts"]))
        assert np.all(region.distance_m(q, scene.robot) == 0), name
        assert np.all(region.outside(q) == 0), name
        assert all(world.check_config(qi).ok for qi in q), name
    cube = v["cube"]
    assert cube["inside_region"] and not np.any(cube["outside_region_mm"])
    tool = SamplePoses.of(scene, qe).tool
    P = np.asarray(v["iso"]["points_m"])
    d = np.array([np.min(np.linalg.norm(tool - p, axis=1)) for p in P]) * 1e3
    np.testing.assert_allclose(cube["nearest_sample_mm"], d, rtol=1e-12, atol=1e-12)
    assert d[0] == 0 and np.all(d[1:] <= 0.8 * np.sqrt(3) / 2 * cube["edge_m"] * 1e3 + 1e-9)
    np.testing.assert_allclose(P[0], tool[cube["sample_index"]], atol=1e-15)


def test_the_approach_direction_reaches_the_model_and_moves_its_backlash():
    """The seam for level 3's backlash (issue 22): the Mover's path gives each joint's
    approach direction (joint side, wrist coupling applied); the calibrated model puts each
    joint on the flank that direction leaves it on, and commanding a target from the other
    side moves the joint by its whole backlash."""
    from planecal.estimation.compensate import CalibratedModel, solve_poses
    from planecal.model.scene import nominal_params
    from planecal.studies.validation import Mover
    scene = load_scene("thesis_final")
    robot = scene.robot
    mover = Mover.__new__(Mover)  # only its robot: no twin needed for a direction
    mover.robot = robot
    c0 = np.full(6, 8_000_000)
    d = mover.approach(c0, c0 + np.array([100, -100, 0, 0, 0, 0]))
    assert d.dtype == np.int64 and d[:3].tolist() == [np.sign(robot.gains[0]),
                                                       -np.sign(robot.gains[1]), 0]
    M = robot.coupling / robot.gains[None, :]
    dq = M @ np.array([0, 0, 0, 0, 100.0, 0])  # one wrist motor: the coupling moves others
    np.testing.assert_array_equal(mover.approach(c0, c0 + [0, 0, 0, 0, 100, 0]), np.sign(dq))
    # no backlash in the model: the direction changes nothing
    model = CalibratedModel(robot, nominal_params(scene))
    q = np.deg2rad([[10, -20, -30, 40, 50, 60]])
    up, down = np.ones((1, 6), int), -np.ones((1, 6), int)
    np.testing.assert_array_equal(model.flange(q, model.sides(q, up)), model.flange(q))
    # J4's backlash of 200 urad: from above the joint rests b/2 below its motor, from
    # below b/2 above it, so the same target is commanded b apart (J1 is not gravity-held)
    p = nominal_params(scene)
    p.backlash = np.array([0, 0, 0, 2e-4, 0, 0])
    model = CalibratedModel(robot, p, "nonkinematic")
    T = model.flange(q + 0.01, model.sides(q + 0.01, up))
    a = solve_poses(model, T, q, direction=up)[0]
    b = solve_poses(model, T, q, direction=down)[0]
    np.testing.assert_allclose(a - (q + 0.01), 0, atol=1e-10)
    np.testing.assert_allclose(b - a, [[0, 0, 0, -2e-4, 0, 0]], atol=1e-10)


def test_a_report_refuses_a_flange_ap_result(tmp_path):
    """A validate file from before the tool point (format /1, or no format) holds the
    flange's AP under ap_after_mm: planecal report refuses it in one line."""
    from planecal.cli import main
    from planecal.present.report import detect_kind
    for doc in ({"format": "planecal-validate/1", "iso": {}, "gauge": None},
                {"iso": {}, "gauge": None, "ap_after_mm": 1.0}):
        with pytest.raises(InputError, match="tool point.*run planecal validate again"):
            detect_kind(doc, "v.json")
    f = tmp_path / "old.json"
    f.write_text(json.dumps({"format": "planecal-validate/1", "ap_after_mm": 1.0}))
    assert main(["report", str(f), "--out", str(tmp_path / "rep")]) == 2
