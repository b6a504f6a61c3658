"""The seed's UR5 end to end (issue 23): its shipped cell runs the demo with the
command's defaults (150 samples: seconds on the twin), its calibration exports as the
UR ROS driver's kinematics file (rebuilt here as a URDF chain would be and checked against
the calibrated model), joint offsets export for any robot with their sign, a robot
without its own error profile gets the generic one and says so, and planecal scenes
names each scene's robot."""
import contextlib
import io
import json
import re

import numpy as np
import pytest

from checkers import NoWayTo
from planecal.cli import main
from planecal.model.cell_params import CellParams
from planecal.model.kinematics import fk, frame_error, rot
from planecal.model.robot import load_robot
from planecal.model.scene import load_scene


def _run(argv):
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(argv)
    return code, buf.getvalue()


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    d = tmp_path_factory.mktemp("ur5demo")
    code, out = _run(["demo", "--scene", "ur5_table", "--seed", "1",
                      "--dir", str(d), "-q"])
    return code, out, d


def test_ur5_demo_runs_end_to_end(demo):
    code, out, d = demo
    assert code == 0, out
    m = re.search(r"before calibration ([0-9.]+) mm, after ([0-9.]+) mm", out)
    assert m, out
    before, after = float(m.group(1)), float(m.group(2))
    assert before > 0.5 and after > 0  # the realistic UR5 is mm off before
    assert "ur5_table" in out and (d / "result.json").exists()
    doc = json.loads((d / "result.json").read_text())
    assert doc["robot"]["name"] == load_robot("ur5").name


def test_ur5_description_is_complete():
    ur5 = load_robot("ur5")
    assert ur5.controller_kind == "ur" and len(ur5.masses) == 6 and ur5.payload_kg == 5.0
    from planecal.model.geometry import robot_link_meshes, robot_shapes
    assert len(robot_link_meshes(ur5, "collision")) == 7
    assert len(robot_shapes(ur5).allowed_pairs) == 3
    from planecal.twin.mjcf import robot_xml, robot_xml_path
    assert robot_xml_path(ur5).read_text() == robot_xml(ur5), "run scripts/build_mjcf.py ur5"
    s = load_scene("ur5_table")
    assert s.robot.name == ur5.name and len(s.plates) == 1


def _segments_chain(kinematics: dict, q):
    """The URDF the UR driver builds from its kinematics file: per joint the origin
    (x y z, rpy = Rz(yaw) Ry(pitch) Rx(roll)), then the joint's turn about z; tool0 on
    wrist_3_link."""
    T = np.eye(4)
    for name, qi in zip(("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2",
                         "wrist_3"), q):
        s = kinematics[name]
        O = np.eye(4)
        O[:3, :3] = rot(2, s["yaw"]) @ rot(1, s["pitch"]) @ rot(0, s["roll"])
        O[:3, 3] = s["x"], s["y"], s["z"]
        J = np.eye(4)
        J[:3, :3] = rot(2, qi)
        T = T @ O @ J
    return T


def _read_kinematics_yaml(text: str) -> dict:
    out, cur = {}, None
    for line in text.splitlines():
        if line.startswith("#") or not line.strip() or line.strip() == "kinematics:":
            continue
        key, _, val = line.strip().partition(":")
        if line.startswith("    "):
            out[cur][key] = float(val)
        elif val.strip():
            out[key] = val.strip()
        else:
            cur = key
            out[cur] = {}
    return out


def test_ur_kinematics_file_rebuilds_the_calibrated_model(tmp_path, capsys):
    from planecal.io.params import save_params
    from planecal.model.measurement import kinematics_of
    ur5 = load_robot("ur5")
    scene = load_scene("ur5_table")
    rng = np.random.default_rng(0)
    p = CellParams(rng.normal(0, 2e-3, 6), scene.sensor_origin, scene.phi_y, scene.phi_z,
                   np.array([pl.n_tilde for pl in scene.plates]))
    p.geometry = rng.normal(0, 3e-4, (6, 4))  # a whole-model result: geometry, base frame
    p.base = rng.normal(0, 1e-3, 6)
    path = tmp_path / "full.json"
    save_params(path, p)
    out = tmp_path / "calibration.yaml"
    assert main(["export", str(path), "--scene", "ur5_table", "--out", str(out)]) == 0
    k = _read_kinematics_yaml(out.read_text())
    assert k["hash"].startswith("calib_planecal_")
    model = kinematics_of(ur5, p)
    worst = 0.0
    for q in rng.uniform(-np.pi, np.pi, (100, 6)):
        worst = max(worst, np.abs(_segments_chain(k, q) - fk(model, q)).max())
    assert worst < 1e-12
    # nominal: the segments are ur_description's default UR5 kinematics
    save_params(path, CellParams(np.zeros(6), scene.sensor_origin, scene.phi_y, scene.phi_z,
                                 np.array([pl.n_tilde for pl in scene.plates])))
    capsys.readouterr()
    assert main(["export", str(path), "--scene", "ur5_table", "--format", "ur"]) == 0
    k = _read_kinematics_yaml(capsys.readouterr().out)
    assert k["shoulder"]["z"] == 0.089159 and k["forearm"]["x"] == -0.425
    assert k["wrist_1"]["x"] == -0.39225 and k["wrist_1"]["z"] == 0.10915
    assert k["wrist_2"]["y"] == pytest.approx(-0.09465, abs=1e-15)
    assert k["wrist_3"]["y"] == pytest.approx(0.0823, abs=1e-15)
    assert frame_error(np.zeros(6)).shape == (4, 4)


def test_joint_offsets_export_for_any_robot_and_ur_only_for_a_ur(tmp_path, capsys):
    from planecal.io.params import save_params
    scene = load_scene("thesis_final")
    p = CellParams([0.0, 1e-3, -2e-3, 5e-4, 3e-4, 0.0], scene.sensor_origin, scene.phi_y,
                   scene.phi_z, np.array([pl.n_tilde for pl in scene.plates]))
    path = tmp_path / "p.json"
    save_params(path, p)
    out = tmp_path / "offsets.json"
    assert main(["export", str(path), "--format", "offsets", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["format"] == "planecal-joint-offsets/1"
    assert doc["joint_offsets_rad"] == p.joint_offsets.tolist()
    assert "theta_j = theta0_j + q_j + delta_j" in doc["sign"]
    assert doc["joint_names"] == [f"joint{i}" for i in range(1, 7)]
    capsys.readouterr()
    assert main(["export", str(path), "--format", "ur"]) == 2  # the MC70 is no UR
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a UR" in err


def test_generic_profile_for_a_robot_without_one(tmp_path, caplog):
    from planecal.model.robot import REFERENCE_REACH_M
    from planecal.twin.generic_profile import generic_document
    from planecal.twin.profile import load_profile
    kr = tmp_path / "arm"
    kr.mkdir()
    doc = json.loads(load_robot("ur5").source.read_text())
    doc["name"] = "UR5 copy without profiles"
    doc["payload_kg"] = 7.0
    (kr / "robot.json").write_text(json.dumps(doc))
    robot = load_robot(kr)
    with caplog.at_level("WARNING"):
        prof = load_profile("realistic", robot)
    assert "no 'realistic' error profile of its own" in caplog.text
    assert prof.doc.description.startswith("GENERIC for UR5 copy")
    mc = load_profile("realistic", load_robot("mc70")).doc
    from planecal.model.kinematics import reach_m
    s = reach_m(robot.kinematics) / REFERENCE_REACH_M
    np.testing.assert_allclose(prof.doc.geometry.a_m, np.array(mc.geometry.a_m) * s)
    # stiffness by the torque class (reach times payload), or by each joint's gravity
    # torque over the MC70's where that is larger: a UR5's arm is far lighter than its
    # size class, so the class decides
    from planecal.twin.generic_profile import gravity_class
    pl = (mc.payload.mass_kg, np.array(mc.payload.com_m))
    own, ref = gravity_class(robot, pl), gravity_class(load_robot("mc70"), pl)
    for j in (1, 2):
        k, k_mc = prof.doc.joints.stiffness_nm_per_rad[j], mc.joints.stiffness_nm_per_rad[j]
        assert own[j] / ref[j] < s * 7.0 / 70.0
        assert k == pytest.approx(k_mc * s * 7.0 / 70.0)
    assert prof.doc.geometry.alpha_rad == mc.geometry.alpha_rad  # angles as they are
    ideal, how = generic_document("ideal", robot)
    assert "used as it is" in how


def test_a_robot_without_a_repeatability_gets_one_default_everywhere(tmp_path, capsys):
    """robot.json without repeatability_mm (robot import without --repeatability-mm): the
    MC70's 0.07 mm scaled by reach, the same figure for the twin's noise, the generic
    profile, plan and layouts, and robot show says it is a default (before: 0 in plan and
    layouts, the generic profile silently by reach)."""
    from planecal.estimation.noise import repeatability_sigma
    from planecal.model.kinematics import reach_m
    from planecal.model.robot import REFERENCE_REACH_M
    from planecal.studies.layouts import layout_study
    from planecal.twin.profile import load_profile
    arm = tmp_path / "arm"
    arm.mkdir()
    doc = json.loads(load_robot("ur5").source.read_text())
    doc.pop("repeatability_mm")
    doc["name"] = "UR5 copy without a repeatability"
    (arm / "robot.json").write_text(json.dumps(doc))
    robot = load_robot(arm)
    want = 0.07 * reach_m(robot.kinematics) / REFERENCE_REACH_M
    assert not robot.repeatability_given
    assert robot.repeatability_m * 1e3 == pytest.approx(want) and 0.015 < want < 0.03
    assert main(["robot", "show", str(arm)]) == 0
    out = capsys.readouterr().out
    assert f"repeatability: +-{want:.3g} mm, a default" in out
    # the generic profile: the robot's share of the MC70's (0.081 of 0.07 mm)
    mc = load_profile("realistic", load_robot("mc70")).doc.joints.repeatability_mm
    assert load_profile("realistic", robot).doc.joints.repeatability_mm == \
        pytest.approx(mc * want / 0.07)
    # the predictions' noise model: the same repeatability, not zero
    cell = json.loads((load_scene("ur5_table").path).read_text())
    cell["robot"] = "arm"
    (tmp_path / "cell.json").write_text(json.dumps(cell))
    res = layout_study(load_scene(tmp_path / "cell.json"), samples=20, seed=0)
    assert res["noise"]["joint_sigma_rad"] == pytest.approx(
        repeatability_sigma(robot, want * 1e-3)) and res["noise"]["joint_sigma_rad"] > 0


def test_scenes_lists_each_scenes_robot(capsys):
    assert main(["scenes", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows["ur5_table"]["robot"] == "ur5" and rows["thesis_final"]["robot"] == "mc70"


@pytest.fixture(scope="module")
def ur5_cell():
    from planecal.safety.collision import CollisionWorld
    scene = load_scene("ur5_table")
    return scene, CollisionWorld(scene, clearance_m=0.01)


def test_plans_robot_time_is_the_rehearsals_at_the_ur5s_step(ur5_cell, tmp_path):
    """plan's robot time of its list (the UR5's 129 counts a tick and 8 ms) is the time a
    rehearsal of that list takes, but for the laser reads: the plan counts the twin's
    median of 102 ticks a read, the exact twin (no noise) takes its buffer's 100. So within
    2 ticks a sample, and the travel exactly (at the MC70's 50 counts the plan said 2.6x)."""
    from planecal.studies.planning import plan
    from planecal.studies.rehearsal import rehearse_planned
    from planecal.twin import Twin, TwinOptions
    scene, world = ur5_cell
    res = plan(scene, 16, 120, 2, None, world)
    n, tick_s = res["samples"], scene.robot.tick_s
    stats = rehearse_planned(scene, np.array(res["counts"]), np.array(res["plates"]),
                             tmp_path / "run.tsv",
                             Twin(scene, truth="nominal", seed=0, options=TwinOptions.exact()),
                             world)
    assert stats.status == "complete" and stats.samples == n
    assert stats.read_ticks == 100 * n
    assert stats.travel_ticks == res["tour"]["travel_ticks"]  # the tour's own count
    predicted = res["robot_time_s"]["planned"] / tick_s
    assert predicted == pytest.approx(stats.ticks - 1 + 2 * n, abs=1e-6)  # 1: first exchange
    assert res["robot_time_per_sample_s"]["planned"] == pytest.approx(
        stats.robot_time_s / n, rel=0.02)


def test_a_plan_lists_only_poses_its_run_can_visit(ur5_cell, tmp_path):
    """A planned pose no path reaches (straight or by a detour) is dropped from the list,
    and the plan says so; the rehearsal of the list then completes (before: the pose stayed
    in the list, the run gave up on it at the end)."""
    from planecal.model.encoder import counts_to_joints
    from planecal.studies.planning import candidates, plan
    from planecal.studies.rehearsal import rehearse_planned
    from planecal.twin import Twin
    scene, world = ur5_cell
    n, m, seed = 16, 120, 2
    clear = plan(scene, n, m, seed, None, world)
    assert clear["dropped"] is None and clear["samples"] == n
    # a chosen pose of the candidates' first half (theirs is the checker-free draw)
    first = {tuple(c) for c in candidates(scene, m - m // 2, seed, world)[0].tolist()}
    bad = next(c for c in clear["counts"] if tuple(c) in first)
    checker = NoWayTo(world, counts_to_joints(scene.robot, np.array(bad)))
    res = plan(scene, n, m, seed, None, checker)
    assert res["dropped"].startswith(f"1 of the {n} planned poses dropped (")
    assert res["samples"] == len(res["counts"]) == n - 1 and bad not in res["counts"]
    assert sorted(map(tuple, res["counts"] + [bad])) == sorted(map(tuple, clear["counts"]))
    # the prediction is of the poses listed: one row fewer, det(J^T J) smaller
    # (det(G - a a^T) = det(G) (1 - a^T G^-1 a))
    assert res["logdet_planned"] < clear["logdet_planned"]
    stats = rehearse_planned(scene, np.array(res["counts"]), np.array(res["plates"]),
                             tmp_path / "run.tsv", Twin(scene, seed=1), checker)
    assert stats.status == "complete", stats.reason


def test_validate_names_the_profiles_compliant_joints():
    """validate's breakdown names the joints the world's profile makes compliant: the
    UR5's J2, J3 and J4 (before: 'J2, J3' for every robot), the MC70's J2 and J3."""
    from planecal.studies.validation.truths import cannot_remove
    from planecal.twin.profile import load_profile
    from planecal.twin.world import source_labels, study_world
    for scene, joints in (("ur5_table", "J2, J3, J4"), ("thesis_final", "J2, J3")):
        sc = load_scene(scene)
        _, opts = study_world(sc, load_profile("realistic", sc.robot), 0)
        assert source_labels(opts)["compliance"] == f"gravity compliance ({joints})"
    bd = {"mode": "alone", "sources": ["compliance"],
          "what": {"compliance": "gravity compliance (J2, J3, J4)"},
          "variants": [{"variant": "compliance alone", "ap_after_tool_mm": 0.9},
                       {"variant": "none (cell only)", "ap_after_tool_mm": 0.1}]}
    assert cannot_remove(bd)[0]["what"] == "gravity compliance (J2, J3, J4)"


def test_the_ur5_demo_works_at_any_seed(tmp_path):
    """The realistic UR5's link geometry leaves an offsets-only fit 3-15x the noise; its
    sensor angles are determined at the noise (0.1-0.4 of their 0.01 rad limit) but their
    reported std is then above the limit. Judged at the noise model's level they are a
    warning, not a refusal (before: seeds 0, 2, 3, 4 exited 1, 'the samples cannot
    identify phi_y, phi_z'); the joint offsets still must meet their limits. 40 samples,
    seeds 0-4."""
    for seed in range(5):
        d = tmp_path / f"s{seed}"
        code, out = _run(["demo", "--scene", "ur5_table", "--samples", "40", "--seed",
                          str(seed), "--dir", str(d), "-q"])
        assert code == 0, (seed, out[-400:])
        doc = json.loads((d / "result.json").read_text())
        ident = doc["identifiability"]
        assert not ident["not_identifiable"] and ident["residual_over_noise"] > 2
        for pd in ident["mismatch_inflated"]:  # the sensor's frame only, within at the noise
            assert pd["parameter"] in ("o_x", "o_y", "o_z", "phi_y", "phi_z")
            assert pd["noise_std"] < pd["limit"] < pd["std"]


def test_validates_cube_moves_to_the_next_centre_where_none_fits_the_first(tmp_path):
    """ur5_table truth 4 (its run since the sampling's route back): at the samples' medoid
    ISO pose P5 is in collision at every edge down to 7.5 % of the first; validate stopped
    with 'give a smaller --cube-mm', which no edge cured. The default cube now takes the
    next centre nearer the middle and says which (its medoid rank)."""
    out = tmp_path / "v.json"
    assert main(["validate", "--scene", "ur5_table", "--truth-seeds", "4", "--level", "offsets",
                 "--breakdown", "none", "--cycles", "3", "--gauge-repeats", "1",
                 "--no-history", "--out", str(out), "-q"]) == 0
    cube = json.loads(out.read_text())["cube"]
    assert cube["medoid_rank"] > 0 and cube["inside_region"]
