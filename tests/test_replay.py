"""planecal replay --errors: the seed's real samples replayed in a world of an error
profile; the twin's ray cast against an independent analytic model of that world."""
import json

import numpy as np
import pytest
from conftest import SEED_DM, SEED_QE, TABLE10

from planecal.model.measurement import beam_direction, plane_distance
from planecal.cli import main
from planecal.model.encoder import counts_to_joints
from planecal.model.kinematics import fk
from planecal.model.scene import load_scene
from planecal.twin.world import without
from planecal.studies.replay import replay, replay_world
from planecal.twin.world import WorldRef


@pytest.fixture(scope="module")
def scene():
    return load_scene("thesis_final")


def _twin(res):
    return np.array([r["twin_mm"] for r in res["rows"]])


def test_ideal_profile_world_is_the_exact_twin(scene):
    base = replay(scene, TABLE10, SEED_QE, SEED_DM)
    w, o = replay_world(scene, TABLE10, WorldRef("ideal", 0))
    res = replay(scene, TABLE10, SEED_QE, SEED_DM, world=w, options=o)
    np.testing.assert_allclose(_twin(res), _twin(base), atol=1e-9)
    np.testing.assert_allclose(_twin(res), [89.776, 85.318, 68.221, 68.017, 71.580], atol=6e-4)


def test_realistic_geometry_against_the_analytic_true_kinematics(scene):
    """The world's geometry alone (compliance, gear, backlash off): MuJoCo's ray cast equals
    the ray-plane distance of the true kinematics (an independent model), to 1e-6 mm."""
    w, o = replay_world(scene, TABLE10, WorldRef("realistic", 2))
    wg, og = without(w, o, ("compliance", "gear", "backlash", "thermal"))
    res = replay(scene, TABLE10, SEED_QE, SEED_DM, world=wg, options=og)
    q = counts_to_joints(scene.robot, SEED_QE)
    T = fk(wg.kinematics.with_offsets(TABLE10.joint_offsets), q)
    R, p = T[:, :3, :3], T[:, :3, 3]
    o_b = R @ TABLE10.sensor_origin + p
    z_b = R @ beam_direction(TABLE10.phi_y, TABLE10.phi_z)
    d = plane_distance(TABLE10.planes[0], o_b, z_b) * 1e3
    np.testing.assert_allclose(_twin(res), d, atol=1e-6)
    analytic = np.array([r["analytic_mm"] for r in res["rows"]])
    assert np.max(np.abs(_twin(res) - analytic)) > 0.05  # a drawn robot, not the nominal
    # all the profile's errors at rest: compliance and gear move the distances further,
    # deterministically (no noise in a replay)
    full = replay(scene, TABLE10, SEED_QE, SEED_DM, world=w, options=o)
    again = replay(scene, TABLE10, SEED_QE, SEED_DM, world=w, options=o)
    np.testing.assert_array_equal(_twin(full), _twin(again))
    assert np.max(np.abs(_twin(full) - _twin(res))) > 1e-3


def test_replay_command_errors(tmp_path, capsys):
    from repo import repo_path
    ex = repo_path("examples")
    args = [str(ex / "seed_samples.tsv"), "--params", str(ex / "table10_params.json")]
    out = tmp_path / "R.json"
    assert main(["replay"] + args + ["--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "realistic world of truth seed 0" in text and "5 of 5 rays hit" in text
    r = json.loads(out.read_text())
    assert r["errors"] == "realistic" and r["truth_seed"] == 0
    assert r["summary"]["max_abs_twin_minus_analytic_mm"] > 0.05
    assert main(["replay"] + args + ["--errors", "ideal", "--out", str(out), ]) == 0
    r = json.loads(out.read_text())
    assert r["errors"] == "ideal" and r["summary"]["max_abs_twin_minus_analytic_mm"] < 1e-6
    # twin - measured (predicted - measured): the seed's samples read 1.21 mm long
    assert r["summary"]["mean_diff_mm"] == pytest.approx(-1.2114, abs=1e-3)
    assert main(["replay"] + args + ["--errors", "nonesuch"]) == 2


def test_replay_takes_the_world_from_the_run_and_its_truth_file(tmp_path, capsys):
    """The issue's case: a rehearsal in the realistic world of truth seed 3 replayed with
    its truth file agrees to the noise (tens of um), not to the 2 mm of another world; the
    sidecar alone says the same; a flag that contradicts the record is refused."""
    run, truth = tmp_path / "r.tsv", tmp_path / "t.json"
    assert main(["rehearse", "--out", str(run), "--seed", "3", "--samples", "20",
                 "--truth-out", str(truth), "-q"]) == 0
    capsys.readouterr()
    out = tmp_path / "R.json"
    assert main(["replay", str(run), "--params", str(truth), "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["world"]["truth_file"] == str(truth) and "world of" in capsys.readouterr().out
    assert r["summary"]["rms_diff_mm"] < 0.1  # the noise of the run, not a world apart
    # without the truth's world: the sidecar names the world (realistic, truth seed 3)
    from planecal.io.params import load_params, save_params
    cell = tmp_path / "cell.json"
    save_params(cell, load_params(truth))
    assert main(["replay", str(run), "--params", str(cell), "--out", str(out)]) == 0
    r2 = json.loads(out.read_text())
    assert r2["world"]["truth_seed"] == 3 and r2["world"]["errors"] == "realistic"
    assert r2["summary"]["rms_diff_mm"] == pytest.approx(r["summary"]["rms_diff_mm"], rel=1e-9)
    # a flag that contradicts the record
    assert main(["replay", str(run), "--params", str(cell), "--truth-seed", "4"]) == 2
    err = capsys.readouterr().err
    assert "--truth-seed 4" in err and "records truth seed 3" in err and err.count("\n") == 1


def test_a_calibration_result_is_replayed_as_its_own_model(tmp_path, capsys):
    """issue 33: replay r1.tsv --params cal.json (the README's old form) put the world's
    errors on the calibrated cell and reported twin - measured -3.73 mm where the run's
    truth file gives +0.005 mm, and nothing said which to give. A calibration result is
    its model exactly: twin - measured is its own model error (the fit's residuals, ray
    cast), the output says so and names the truth file for the run's world; a flag that
    would put a world on it is refused."""
    run, truth, cal = tmp_path / "r.tsv", tmp_path / "t.json", tmp_path / "cal.json"
    assert main(["rehearse", "--out", str(run), "--samples", "40", "--truth-out", str(truth),
                 "-q"]) == 0
    assert main(["calibrate", str(run), "--out", str(cal), "-q"]) == 0
    capsys.readouterr()
    out = tmp_path / "R.json"
    assert main(["replay", str(run), "--params", str(cal), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"twin: the model of {cal} exactly, a calibration result" in text
    assert "give its truth file (rehearse --truth-out)" in text
    r = json.loads(out.read_text())
    doc = json.loads(cal.read_text())
    assert r["summary"]["rms_diff_mm"] == pytest.approx(doc["residual_rms_mm"], rel=1e-6)
    assert abs(r["summary"]["mean_diff_mm"]) < 0.05  # not the -3.7 mm of a world counted twice
    assert r["summary"]["max_abs_twin_minus_analytic_mm"] < 1e-6
    assert r["errors"] == "ideal" and r["truth_seed"] is None
    # the truth file: the world the run was made in, to the noise
    assert main(["replay", str(run), "--params", str(truth), "--out", str(out)]) == 0
    assert json.loads(out.read_text())["summary"]["rms_diff_mm"] < 0.1
    for flag in (["--errors", "realistic"], ["--truth-seed", "0"]):
        assert main(["replay", str(run), "--params", str(cal)] + flag) == 2
        err = capsys.readouterr().err
        assert "is a calibration result" in err and err.count("\n") == 1
