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
    from planecal.twin.generic_profile import REFERENCE_REACH_M, generic_document
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
    k2 = prof.doc.joints.stiffness_nm_per_rad[1]
    assert k2 == pytest.approx(mc.joints.stiffness_nm_per_rad[1] * s * 7.0 / 70.0)
    assert prof.doc.geometry.alpha_rad == mc.geometry.alpha_rad  # angles as they are
    ideal, how = generic_document("ideal", robot)
    assert "used as it is" in how


def test_scenes_lists_each_scenes_robot(capsys):
    assert main(["scenes", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows["ur5_table"]["robot"] == "ur5" and rows["thesis_final"]["robot"] == "mc70"
