"""planecal compensate (issue 13 item 4): the solve against the closed-form IK and the
encoder offsets, the Jacobian against the analytic one, the file formats, the region
check and the command's refusals."""
import json

import numpy as np
import pytest

from planecal.cli import main
from planecal.estimation.compensate import (COMPENSATED_FORMAT, OffsetsModel, Region, Targets,
                                 compensate, flange_jacobian, load_calibrated, pose_from,
                                 read_targets, solve_poses)
from planecal.model.encoder import joints_to_counts, offsets_to_qe0
from planecal.base.errors import InputError
from planecal.model.robot import fk, ik_nearest, jacobian, load_robot

ROBOT = load_robot()
DELTA = np.array([0.0, 2e-3, -1.5e-3, 1e-3, -2e-3, 0.0])
Q_CAL = np.radians([28.7, -15.2, -44.5, -66.1, 73.3, -92.5])


def _poses(n=40, seed=0, spread=0.3):
    q = Q_CAL + np.random.default_rng(seed).uniform(-spread, spread, (n, 6))
    return q, fk(ROBOT, q)


def _region(q, margin=0.01):
    return Region(q.min(0) - margin, q.max(0) + margin, len(q), "test")


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


def test_model_jacobian_matches_the_analytic_one():
    q, _ = _poses(10, seed=3)
    J = flange_jacobian(OffsetsModel(ROBOT, DELTA), q)
    assert np.abs(J - jacobian(ROBOT, q, DELTA)).max() < 1e-8


def test_newton_converges_near_the_elbow_singularity():
    # a target of the three-plate study whose Jacobian has condition ~6e3: the nominal
    # Jacobian stalled above 1 nm here; the model's own converges
    q0 = np.radians([[129.2558242, -15.59006963, 81.31942904, 61.89651627, 85.84678861,
                      -326.45103647]])
    delta = np.array([0.0, -0.0013652, -0.00246441, -0.00308399, 0.00137508, 0.0])
    assert np.linalg.cond(jacobian(ROBOT, q0)[0]) > 3e3
    m = OffsetsModel(ROBOT, delta)
    q, its, ok, rp, rw = solve_poses(m, fk(ROBOT, q0), q0)
    assert ok.all() and its[0] <= 8 and rp[0] < 1e-9 and rw[0] < 1e-9
    # the joints to the closed form within what 1 nm means at condition 6e3
    assert np.abs(q - ik_nearest(ROBOT, fk(ROBOT, q0)[0], q0[0], delta=delta)).max() < 1e-8


def test_zero_offsets_change_nothing():
    q, T = _poses(5)
    t = Targets(list("abcde"), np.full_like(T, np.nan), q, ["x"] * 5, "x")
    c = compensate(OffsetsModel(ROBOT, np.zeros(6)), t, _region(q))
    assert (c.correction_counts == 0).all() and c.iterations.max() == 0


def test_region_distance_outside():
    r = Region(np.zeros(6), np.ones(6), 2, "x")
    d = r.outside(np.array([[0.5] * 6, [-0.2, 0.5, 1.3, 0.5, 0.5, 0.5]]))
    assert (d[0] == 0).all() and d[1, 0] == pytest.approx(0.2) and d[1, 2] == pytest.approx(0.3)


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
    T = fk(ROBOT, q)
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
    region = _region(q[None], 0.1)
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
    assert "joint box of 40 samples" in text and "converged in <= 2 iterations" in text
    lines = out.read_text().splitlines()
    assert lines[0] == "name\tq1\tq2\tq3\tq4\tq5\tq6" and lines[1].startswith("a\t")
    model, _ = load_calibrated(ROBOT, d / "res.json")
    q = np.radians([[30, -15, -44, -66, 73, -92], [35, -12, -40, -60, 70, -90]])
    want = joints_to_counts(ROBOT, [ik_nearest(ROBOT, fk(ROBOT, qi), qi, delta=model.delta)
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
    assert "1 of 2 targets lie outside the calibrated region" in err and "out, by" in err
    assert "on J2" in err and "--allow-outside" in err and not out.exists()
    assert main(["compensate", str(t), "--params", str(d / "res.json"), "--out", str(out),
                 "--allow-outside"]) == 0
    assert "WARNING" in capsys.readouterr().out and out.exists()


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
