"""planecal compensate (issue 13 item 4): the solve against the closed-form IK and the
encoder offsets, the Jacobian against the analytic one, the file formats, the region
check and the command's refusals."""
import json

import numpy as np
import pytest

from planecal.cli import main
from planecal.estimation.compensate import (COMPENSATED_FORMAT, CalibratedModel, Region,
                                            compensate, load_calibrated, solve_poses)
from planecal.io.targets import Targets, pose_from, read_targets
from planecal.model.cell_params import CellParams
from regions import joint_region
from planecal.model.encoder import counts_to_joints, joints_to_counts, offsets_to_qe0
from planecal.base.errors import InputError
from planecal.model.kinematics import fk, jacobian
from planecal.model.ik import ik_nearest
from planecal.model.robot import load_robot

ROBOT = load_robot()
DELTA = np.array([0.0, 2e-3, -1.5e-3, 1e-3, -2e-3, 0.0])
Q_CAL = np.radians([28.7, -15.2, -44.5, -66.1, 73.3, -92.5])


def _poses(n=40, seed=0, spread=0.3):
    q = Q_CAL + np.random.default_rng(seed).uniform(-spread, spread, (n, 6))
    return q, fk(ROBOT.kinematics, q)


def _region(q, margin=0.01):
    return joint_region(q, margin)


def OffsetsModel(robot, delta):
    """The calibrated model of a level-1 result: robot.json's chain with joint offsets."""
    return CalibratedModel(robot, CellParams(joint_offsets=delta))


def test_level1_solution_is_the_closed_form_ik_with_the_offsets():
    q, T = _poses()
    t = Targets([f"t{i}" for i in range(len(q))], T, np.full_like(q, np.nan),
                ["x"] * len(q), "x")
    c = compensate(OffsetsModel(ROBOT, DELTA), t, _region(q))
    assert c.converged.all() and c.iterations.max() <= 3
    closed = np.array([ik_nearest(ROBOT, T[i], c.q_nominal[i], delta=DELTA)
                       for i in range(len(q))])
    assert np.abs(c.q_corrected - closed).max() < 1e-10
    # on one IK branch the level-1 correction is -delta on every target ...
    assert np.abs(c.correction_rad + DELTA).max() < 1e-10
    # ... i.e. the encoder offsets planecal export would enter, to the count's rounding
    want = offsets_to_qe0(ROBOT, DELTA) - ROBOT.qe0
    assert np.abs(c.correction_counts - want).max() <= 1.0
    assert c.residual_m.max() < 1e-9 and c.residual_rad.max() < 1e-9
    # whole counts: under one count's worth of flange motion (~2.3e-5 rad x reach)
    assert 1e-6 < c.rounded_residual_m.max() < 5e-5
    s = c.summary()
    assert s["max_correction_counts"][0] == 0 and 70 <= s["max_correction_counts"][1] <= 120


def test_model_jacobian_against_central_differences_of_its_flange():
    # the model's Jacobian (Newton's) against central differences of its own flange, at
    # level 1 and with geometry, base frame and compliance (whose own derivative, ~1e-4 of
    # the Jacobian, the analytic one leaves out)
    q, _ = _poses(10, seed=3)
    full = CellParams(joint_offsets=DELTA, geometry=np.full((6, 4), 2e-4),
                      base=np.array([1e-3, -2e-3, 5e-4, 1e-3, -1e-3, 2e-3]),
                      compliance=np.array([0, 2e-7, 3e-7, 0, 0, 0]))
    for params, tol in ((CellParams(joint_offsets=DELTA), 1e-8), (full, 1e-3)):
        m = CalibratedModel(ROBOT, params)
        J, h = m.jacobian(q), 1e-6
        for j in range(6):
            dq = np.zeros(6)
            dq[j] = h
            Fp, Fm, F = m.flange(q + dq), m.flange(q - dq), m.flange(q)
            v = (Fp[:, :3, 3] - Fm[:, :3, 3]) / (2 * h)
            W = (Fp[:, :3, :3] - Fm[:, :3, :3]) / (2 * h) @ np.swapaxes(F[:, :3, :3], 1, 2)
            w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], -1)
            scale = np.abs(J[:, :, j]).max()
            assert np.abs(J[:, :3, j] - v).max() < tol * scale + 1e-9
            assert np.abs(J[:, 3:, j] - w).max() < tol * scale + 1e-9
    assert np.abs(CalibratedModel(ROBOT, CellParams(joint_offsets=DELTA)).jacobian(q)
                  - jacobian(ROBOT.kinematics.with_offsets(DELTA), q)).max() == 0


def test_newton_converges_near_the_elbow_singularity():
    # a target of the three-plate study whose Jacobian has condition ~6e3: the nominal
    # Jacobian stalled above 1 nm here; the model's own converges
    q0 = np.radians([[129.2558242, -15.59006963, 81.31942904, 61.89651627, 85.84678861,
                      -326.45103647]])
    delta = np.array([0.0, -0.0013652, -0.00246441, -0.00308399, 0.00137508, 0.0])
    assert np.linalg.cond(jacobian(ROBOT.kinematics, q0)[0]) > 3e3
    m = OffsetsModel(ROBOT, delta)
    q, its, ok, rp, rw = solve_poses(m, fk(ROBOT.kinematics, q0), q0)
    assert ok.all() and its[0] <= 8 and rp[0] < 1e-9 and rw[0] < 1e-9
    # the joints to the closed form within what 1 nm means at condition 6e3
    assert np.abs(q - ik_nearest(ROBOT, fk(ROBOT.kinematics, q0)[0], q0[0], delta=delta)).max() < 1e-8


def test_zero_offsets_change_nothing():
    q, T = _poses(5)
    t = Targets(list("abcde"), np.full_like(T, np.nan), q, ["x"] * 5, "x")
    c = compensate(OffsetsModel(ROBOT, np.zeros(6)), t, _region(q))
    assert (c.correction_counts == 0).all() and c.iterations.max() == 0


def test_region_distance_outside():
    r = joint_region(np.array([np.zeros(6), np.ones(6)]), 0.0)
    d = r.outside(np.array([[0.5] * 6, [-0.2, 0.5, 1.3, 0.5, 0.5, 0.5]]))
    assert (d[0] == 0).all() and d[1, 0] == pytest.approx(0.2) and d[1, 2] == pytest.approx(0.3)


def test_region_is_where_the_samples_are():
    # the issue's case: the samples' first pose turned 90 deg about J1 lies inside the
    # joint ranges the samples visited, but far from their flange positions: outside
    q, _ = _poses(60, seed=4, spread=0.25)
    r = Region.from_counts(ROBOT, joints_to_counts(ROBOT, q), "test")
    assert r.margin_m == pytest.approx(0.05) and np.degrees(r.margin_rad) == pytest.approx(2.0)
    inside = r.distance_m(q, ROBOT)
    assert (inside == 0).all() and (r.outside(q) == 0).all()
    turned = q[:1].copy()
    turned[0, 0] += np.pi / 2
    assert r.distance_m(turned, ROBOT)[0] > 0.5  # metres away from every sample
    # a pose just beyond the hull: its distance grows with the step, the margin first
    p = fk(ROBOT.kinematics, q)[:, :3, 3]
    far = np.argmax(np.linalg.norm(p - p.mean(0), axis=1))
    step = q[far] + 0.03 * (q[far] - q.mean(0))
    assert r.distance_m(step[None], ROBOT)[0] < r.distance_m((q[far] + 0.3 * (q[far] - q.mean(0)))[None], ROBOT)[0]


def test_pose_convention_is_fixed_axis_xyz():
    T = pose_from([100, 200, 300], [90, 0, 0])
    assert np.allclose(T[:3, :3], [[1, 0, 0], [0, 0, -1], [0, 1, 0]])
    T = pose_from([0, 0, 0], [10, 20, 30])
    c, s = np.cos, np.sin
    a, b, g = np.radians([10, 20, 30])
    Rx = np.array([[1, 0, 0], [0, c(a), -s(a)], [0, s(a), c(a)]])
    Ry = np.array([[c(b), 0, s(b)], [0, 1, 0], [-s(b), 0, c(b)]])
    Rz = np.array([[c(g), -s(g), 0], [s(g), c(g), 0], [0, 0, 1]])
    assert np.allclose(T[:3, :3], Rz @ Ry @ Rx)


def test_the_three_target_formats_agree(tmp_path):
    q = Q_CAL + 0.05
    T = fk(ROBOT.kinematics, q)
    from scipy.spatial.transform import Rotation
    ang = Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True)
    xyz = T[:3, 3] * 1e3
    (tmp_path / "cart.csv").write_text(
        "name,x_mm,y_mm,z_mm,rx_deg,ry_deg,rz_deg\n"
        "a," + ",".join(f"{v:.12f}" for v in [*xyz, *ang]) + "\n")
    (tmp_path / "deg.tsv").write_text(
        "# a comment\nq1_deg\tq2_deg\tq3_deg\tq4_deg\tq5_deg\tq6_deg\n"
        + "\t".join(f"{v:.12f}" for v in np.degrees(q)) + "\n")
    counts = joints_to_counts(ROBOT, q)
    (tmp_path / "counts.csv").write_text("q1;q2;q3;q4;q5;q6\n" + ";".join(map(str, counts)) + "\n")
    (tmp_path / "t.json").write_text(json.dumps({"format": "planecal-targets/1", "targets": [
        {"name": "p", "position_mm": xyz.tolist(), "rotation_deg": ang.tolist()},
        {"joints_deg": np.degrees(q).tolist()}, {"counts": counts.tolist()}]}))
    region = joint_region(q[None], 0.1)
    m = OffsetsModel(ROBOT, DELTA)
    res = {f: compensate(m, read_targets(tmp_path / f, ROBOT), region)
           for f in ("cart.csv", "deg.tsv", "counts.csv", "t.json")}
    ref = res["deg.tsv"].q_corrected[0]
    assert np.abs(res["cart.csv"].q_corrected[0] - ref).max() < 1e-9
    assert np.abs(res["t.json"].q_corrected[:2] - ref).max() < 1e-9
    assert np.abs(res["counts.csv"].q_corrected[0] - ref).max() < 3e-5  # one count
    assert res["t.json"].names == ["p", "T2", "T3"] and res["cart.csv"].names == ["a"]


@pytest.mark.parametrize("text,msg", [
    ("x_mm,y_mm\n1,2\n", "the header names the columns"),
    ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,extra\n1,2,3,4,5,6,7\n", "unknown column"),
    ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n1,2,3,4,5\n", ":2: 5 fields"),
    ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n1,2,x,4,5,6\n", ":2: q3_deg: not a number"),
    ("q1,q2,q3,q4,q5,q6\n1,2,3.5,4,5,6\n", ":2: q3: encoder counts are integers"),
    ("q1,q2,q3,q4,q5,q6\n1,2,3,4,5,99999999\n", "outside the 24-bit"),
    ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n", "no targets"),
    ("", "no targets"),
])
def test_bad_csv_is_one_line_naming_the_line(tmp_path, text, msg):
    p = tmp_path / "t.csv"
    p.write_text(text)
    with pytest.raises(InputError) as e:
        read_targets(p, ROBOT)
    assert msg in str(e.value) and str(p) in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("doc,msg", [
    ({"targets": []}, "format"),
    ({"format": "planecal-targets/1", "targets": []}, "non-empty"),
    ({"format": "planecal-targets/1", "targets": [{"position_mm": [1, 2, 3]}]},
     "targets[0]: give position_mm with rotation_deg"),
    ({"format": "planecal-targets/1", "targets": [{"joints_deg": [1, 2]}]},
     "targets[0].joints_deg: 6 numbers"),
    ({"format": "planecal-targets/1", "targets": [{"joints_deg": [0] * 6, "q": 1}]},
     "unknown key(s) q"),
])
def test_bad_json_targets(tmp_path, doc, msg):
    p = tmp_path / "t.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=None) as e:
        read_targets(p, ROBOT)
    assert msg in str(e.value)


def test_unreachable_and_out_of_limits_targets_are_named(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("name,x_mm,y_mm,z_mm,rx_deg,ry_deg,rz_deg\nfar,9000,0,0,0,0,0\n")
    q = Q_CAL[None]
    with pytest.raises(InputError, match=r"t.csv:2: target far is out of reach"):
        compensate(OffsetsModel(ROBOT, DELTA), read_targets(p, ROBOT), _region(q))
    p.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,100,0,0,0,0\n")
    with pytest.raises(InputError, match=r"t.csv:2: target T1 is outside the joint limits"):
        compensate(OffsetsModel(ROBOT, DELTA), read_targets(p, ROBOT), _region(q))


# ----- the command ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """A level-1 calibration of 40 twin samples (ideal world) with its result file."""
    d = tmp_path_factory.mktemp("cal")
    run = d / "run.tsv"
    assert main(["rehearse", "--samples", "40", "--errors", "ideal", "--out", str(run),
                 "-q"]) == 0
    assert main(["calibrate", str(run), "--out", str(d / "res.json"), "-q"]) == 0
    return d


def _targets(d, rows):
    p = d / "t.csv"
    p.write_text("name,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n"
                 + "".join(f"{n}," + ",".join(map(str, r)) + "\n" for n, r in rows))
    return p


def test_command_writes_counts_from_the_recorded_samples(calibrated, capsys):
    d = calibrated
    t = _targets(d, [("a", [30, -15, -44, -66, 73, -92]), ("b", [35, -12, -40, -60, 70, -90])])
    out = d / "c.tsv"
    assert main(["compensate", str(t), "--params", str(d / "res.json"), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "flange positions and joint ranges of 40 samples" in text
    assert "converged in <= 2 iterations" in text
    lines = out.read_text().splitlines()
    assert lines[0] == "name\tq1\tq2\tq3\tq4\tq5\tq6" and lines[1].startswith("a\t")
    model, _ = load_calibrated(ROBOT, d / "res.json")
    q = np.radians([[30, -15, -44, -66, 73, -92], [35, -12, -40, -60, 70, -90]])
    delta = model.params.joint_offsets
    want = joints_to_counts(ROBOT, [ik_nearest(ROBOT, fk(ROBOT.kinematics, qi), qi, delta=delta)
                                    for qi in q])
    got = np.array([[int(v) for v in ln.split("\t")[1:]] for ln in lines[1:]])
    assert (got == want).all()
    # JSON: the whole record
    js = d / "c.json"
    assert main(["compensate", str(t), "--params", str(d / "res.json"), "--out", str(js),
                 "-q"]) == 0
    doc = json.loads(js.read_text())
    assert doc["format"] == COMPENSATED_FORMAT and doc["level"] == "offsets"
    assert doc["targets"][1]["counts"] == got[1].tolist()
    assert doc["region"]["samples"] == 40 and doc["summary"]["outside"] == 0
    # an own earlier output is replaced; never an input
    assert main(["compensate", str(t), "--params", str(d / "res.json"), "--out", str(js),
                 "-q"]) == 0
    assert main(["compensate", str(t), "--params", str(d / "res.json"), "--out", str(t)]) == 2
    assert "that is an input" in capsys.readouterr().err
    assert main(["compensate", str(t), "--params", str(d / "res.json"), "--out",
                 str(d / "run.tsv"), "--force"]) == 2


def test_command_refuses_targets_outside_the_region(calibrated, capsys):
    d = calibrated
    t = _targets(d, [("in", [30, -15, -44, -66, 73, -92]), ("out", [30, 40, -44, -66, 73, -92])])
    out = d / "o.tsv"
    assert main(["compensate", str(t), "--params", str(d / "res.json"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "1 of 2 targets lie outside the calibrated region" in err
    assert "out 37.93 deg beyond J2's sampled range" in err
    assert "beyond the samples' flange positions" in err
    assert "--allow-outside" in err and not out.exists() and err.count("\n") == 1
    assert main(["compensate", str(t), "--params", str(d / "res.json"), "--out", str(out),
                 "--allow-outside"]) == 0
    assert "WARNING" in capsys.readouterr().out and out.exists()


def test_command_refuses_a_target_turned_away_from_every_sample(calibrated, capsys):
    # the case: the samples' first pose turned 90 deg about J1 stays inside J1's
    # sampled range but is far from every sample's flange: outside the region
    from planecal.io.samples import read_samples
    d = calibrated
    qe = read_samples(d / "run.tsv").qe
    q = counts_to_joints(ROBOT, qe)
    turned = q[0] + [np.pi / 2, 0, 0, 0, 0, 0]
    t = _targets(d, [("turned", np.degrees(turned).tolist())])
    out = d / "turned.tsv"
    assert main(["compensate", str(t), "--params", str(d / "res.json"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "turned" in err and "beyond the samples' flange positions" in err
    assert not out.exists()


def test_command_needs_the_region(calibrated, tmp_path, capsys):
    d = calibrated
    doc = json.loads((d / "res.json").read_text())
    doc.pop("provenance")
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(doc))
    t = _targets(tmp_path, [("a", [30, -15, -44, -66, 73, -92])])
    assert main(["compensate", str(t), "--params", str(bare), "--out",
                 str(tmp_path / "c.tsv")]) == 2
    assert "--samples" in capsys.readouterr().err
    assert main(["compensate", str(t), "--params", str(bare), "--out", str(tmp_path / "c.tsv"),
                 "--samples", str(d / "run.tsv")]) == 0
    # a recorded sample file that changed is not the calibration's
    run2 = tmp_path / "run.tsv"
    run2.write_text((d / "run.tsv").read_text() + "")
    doc2 = json.loads((d / "res.json").read_text())
    doc2["provenance"]["inputs"][0]["path"] = str(run2)
    doc2["provenance"]["inputs"][0]["sha256"] = "0" * 64
    changed = tmp_path / "changed.json"
    changed.write_text(json.dumps(doc2))
    assert main(["compensate", str(t), "--params", str(changed), "--out",
                 str(tmp_path / "c2.tsv")]) == 2
    assert "SHA-256 differs" in capsys.readouterr().err


def test_targets_are_registered_in_the_robots_own_frame():
    # a model whose delta1 is a turn of the plates no plane sees: in the robot's frame
    # (J1's zero) the compensation ignores it; in the cell frame it turns every target
    q, T = _poses(10, seed=4)
    t = Targets([f"t{i}" for i in range(10)], T, np.full_like(q, np.nan), ["x"] * 10, "x")
    d1 = DELTA + [0.02, 0, 0, 0, 0, 0]
    m = OffsetsModel(ROBOT, d1)
    F = m.robot_frame()
    c, s = np.cos(0.02), np.sin(0.02)
    assert np.allclose(F, [[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], atol=1e-12)
    assert np.allclose(OffsetsModel(ROBOT, DELTA).robot_frame(), np.eye(4), atol=1e-12)
    rob = compensate(m, t, _region(q, 0.1))
    ref = compensate(OffsetsModel(ROBOT, DELTA), t, _region(q, 0.1))
    assert np.abs(rob.q_corrected - ref.q_corrected).max() < 1e-9  # delta1 drops out
    cell = compensate(m, t, _region(q, 0.1), frame="cell")
    assert np.abs(cell.correction_rad[:, 0] + 0.02).max() < 1e-9  # J1 turns back by delta1
    with pytest.raises(InputError, match="--frame"):
        compensate(m, t, _region(q), frame="tool")
