"""The command-line contracts: output formats, exit codes, one-line errors."""
import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import INITIAL, perturbed, synthetic_counts
from planecal.cli import main
from planecal.io.params import save_params
from repo import repo_path
from planecal.io.samples import write_samples

SEED = str(repo_path("examples", "seed_samples.tsv"))
TABLE10 = str(repo_path("examples", "table10_params.json"))


def test_predict_prints_index_measured_predicted_error(capsys):
    assert main(["predict", SEED, "--params", TABLE10]) == 0
    head, *rows = [line.split("\t") for line in capsys.readouterr().out.splitlines()]
    assert head == ["index", "measured_mm", "predicted_mm", "error_mm"]  # issue 33
    assert len(rows) == 5 and all(len(r) == 4 for r in rows)
    pred = [float(r[2]) for r in rows]
    np.testing.assert_allclose(pred, [89.776, 85.318, 68.221, 68.017, 71.580], atol=0.01)
    assert rows[0][0] == "0" and float(rows[0][1]) == 92.52
    assert abs(float(rows[0][3]) - (pred[0] - 92.52)) < 1e-3  # predicted - measured


@pytest.fixture(scope="module")
def run_file(robot, tmp_path_factory):
    rng = np.random.default_rng(21)
    truth = perturbed(INITIAL, rng)
    qe, d = synthetic_counts(robot, truth, 150, rng)
    d = d + rng.normal(0, 2e-6, len(d))
    path = tmp_path_factory.mktemp("cli") / "run.tsv"
    write_samples(path, qe, d * 1e3)
    return path, truth


def test_calibrate_writes_result_json(run_file, tmp_path, capsys):
    path, truth = run_file
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "--out", str(out), "--outlier-sigma", "4"]) == 0
    text = capsys.readouterr().out
    assert "model error (predicted - measured) RMS" in text and "delta2" in text
    assert "fixed" in text
    r = json.loads(out.read_text())
    for key in ("joint_offsets_rad", "planes", "sensor", "std", "residual_rms_mm",
                "iterations", "outliers", "identifiability"):
        assert key in r
    assert r["std"]["joint_offsets_rad"][0] is None  # delta1 fixed: no number
    assert 0.001 < r["residual_rms_mm"] < 0.003
    err = np.array(r["joint_offsets_rad"]) - truth.joint_offsets
    std = np.array(r["std"]["joint_offsets_rad"][1:5], float)
    assert np.all(np.abs(err[1:5]) < 4 * std)


def test_calibrate_result_holds_the_covariance_by_name(run_file, tmp_path, capsys):
    # the free parameters' covariance, named; its diagonal is the std the file reports;
    # rows and columns of what is not identifiable are null
    path, _ = run_file
    out = tmp_path / "r.json"
    # every parameter a candidate: delta1 and delta6 are combinations of the planes and
    # the sensor (the base set leaves them out, and says so); the 12 others are fitted
    assert main(["calibrate", str(path), "--out", str(out), "--free", "all"]) == 0
    text = capsys.readouterr().out
    assert "EXCLUDED delta1: a combination of others" in text
    assert "EXCLUDED delta6: a combination of others" in text
    r = json.loads(out.read_text())
    assert len(r["candidates"]) == 14
    assert {e["parameter"] for e in r["excluded"]} == {"delta1", "delta6"}
    status = {p["name"]: p["status"] for p in r["parameters"]}
    assert status["delta1"] == status["delta6"] == "excluded: combination"
    cov = r["covariance"]
    assert cov["names"] == r["free"] == r["identifiability"]["free"] == r["base_set"]
    assert len(cov["names"]) == 12 and all(len(row) == 12 for row in cov["matrix"])
    bad = set(r["identifiability"]["not_identifiable"])
    for i, a in enumerate(cov["names"]):
        for j, b in enumerate(cov["names"]):
            v = cov["matrix"][i][j]
            assert (v is None) == (a in bad or b in bad)
            if v is not None:
                assert v == cov["matrix"][j][i]
    C = np.array([[np.nan if v is None else v for v in row] for row in cov["matrix"]])
    k = cov["names"].index("delta3")
    assert np.sqrt(C[k, k]) == pytest.approx(r["std"]["joint_offsets_rad"][2], rel=1e-12)
    k = cov["names"].index("n1_z")
    assert np.sqrt(C[k, k]) == pytest.approx(r["std"]["planes"][0]["n_tilde"][2], rel=1e-12)


def test_calibrate_weighted_reports_its_variance_factor(run_file, tmp_path, capsys):
    # white 2 um noise, as the run file has, against the repeatability model (~10 um,
    # pose dependent): the weighted fit lands within 4 std of the truth and says the
    # model's noise level is ~50x the residuals' in variance
    path, truth = run_file
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "--weighted", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "weighted by the repeatability noise model: variance factor" in text
    r = json.loads(out.read_text())
    ident = r["identifiability"]
    assert ident["weighted"] is True and 0.005 < ident["variance_factor"] < 0.2
    err = np.array(r["joint_offsets_rad"]) - truth.joint_offsets
    std = np.array(r["std"]["joint_offsets_rad"][1:5], float)
    assert np.all(np.abs(err[1:5]) < 4 * std)


def test_calibrate_with_initial_file_and_free_list(run_file, tmp_path, capsys):
    path, _ = run_file
    p = tmp_path / "init.json"
    save_params(p, INITIAL)
    # 5 iterations from afar: not converged (exit 1); the report still names delta1 and
    # delta6 as what one plate cannot tell from the planes and the sensor
    assert main(["calibrate", str(path), "--initial", str(p), "--free",
                 "all", "--max-iter", "5"]) == 1
    cap = capsys.readouterr()
    assert "EXCLUDED delta1: a combination" in cap.out and "excluded" in cap.out
    assert cap.err.count("\n") == 1 and "did not converge in 5 iterations" in cap.err


@pytest.mark.parametrize("argv, message", [
    (["calibrate", "nope.tsv"], "nope.tsv: file not found"),
    (["calibrate", SEED], "5 samples cannot determine 12 free parameters"),
    (["predict", SEED, "--params", "missing.json"], "missing.json: file not found"),
    (["calibrate", SEED, "--free", "delta9"], "unknown parameter 'delta9'"),
    (["calibrate", SEED, "--repeatability-mm", "0.05"], "--repeatability-mm needs --weighted"),
    (["calibrate", SEED, "--distance-sigma-um", "2"], "--distance-sigma-um needs --weighted"),
    (["calibrate", SEED, "--weighted", "--repeatability-mm", "0"], "--repeatability-mm must be > 0"),
    (["calibrate", SEED, "--weighted", "--distance-sigma-um", "nan"], "--distance-sigma-um must be > 0"),
])
def test_errors_are_one_line_exit_2(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err


def test_bad_parameter_file(tmp_path, capsys):
    p = tmp_path / "p.json"
    p.write_text('{"joint_offsets_rad": [0, 0, 0], "planes": [], "sensor": {}}')
    assert main(["predict", SEED, "--params", str(p)]) == 2
    assert "p.json: joint_offsets_rad: must hold 6 offsets, one per joint, got 3" in capsys.readouterr().err
    p.write_text('{"joint_offsets_rad": [0, 0,')
    assert main(["predict", SEED, "--params", str(p)]) == 2
    assert "p.json:1: invalid JSON" in capsys.readouterr().err


def test_console_script_runs_without_traceback(tmp_path):
    bad = tmp_path / "bad.tsv"
    bad.write_text("1\t2\t3\n")
    proc = subprocess.run([sys.executable, "-m", "planecal.cli", "calibrate", str(bad)],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().endswith("bad.tsv:1: expected 7 tab-separated columns (q1..q6, Dm), found 3")


def test_demo_end_to_end(tmp_path, capsys):
    """The README's main job, shortened: rehearse on the twin, calibrate, compare."""
    assert main(["demo", "--samples", "40", "--seed", "3", "--dir", str(tmp_path),
                 "--errors", "ideal"]) == 0
    out = capsys.readouterr().out
    assert "3 reported standard deviations of the truth" in out
    r = json.loads((tmp_path / "result.json").read_text())
    t = json.loads((tmp_path / "truth.json").read_text())
    err = np.abs(np.array(r["joint_offsets_rad"]) - t["joint_offsets_rad"])[1:5]
    std = np.array(r["std"]["joint_offsets_rad"][1:5], float)
    assert np.all(err < 4 * std) and np.all(std < 5e-4)  # 40 samples: delta2 ~0.13 mrad
    assert r["residual_rms_mm"] < 0.03 < r["residual_rms_initial_mm"]


def test_outputs_are_checked_before_the_fit(run_file, tmp_path, capsys):
    path, _ = run_file
    before = path.read_bytes()
    # the output is an input: refused, the samples untouched
    assert main(["calibrate", str(path), "--out", str(path)]) == 2
    assert "that is an input of this command" in capsys.readouterr().err
    assert path.read_bytes() == before
    # a directory, a missing directory
    assert main(["calibrate", str(path), "--out", str(tmp_path)]) == 2
    assert "is a directory" in capsys.readouterr().err
    assert main(["calibrate", str(path), "--out", str(tmp_path / "no" / "r.json")]) == 2
    assert "does not exist" in capsys.readouterr().err
    # an existing file planecal did not write: only with --force
    notes = tmp_path / "notes.json"
    notes.write_text('{"mine": true}')
    assert main(["calibrate", str(path), "--out", str(notes)]) == 2
    assert "use --force" in capsys.readouterr().err and "mine" in notes.read_text()
    assert main(["calibrate", str(path), "--out", str(notes), "--force"]) == 0
    # an earlier result is replaced by a new one
    assert main(["calibrate", str(path), "--out", str(notes)]) == 0
    capsys.readouterr()


@pytest.mark.parametrize("flag,value", [("--outlier-sigma", "0"), ("--outlier-sigma", "-2"),
                                        ("--improvement-limit", "nan"), ("--max-iter", "0")])
def test_bad_fit_options_are_refused(run_file, flag, value, capsys):
    path, _ = run_file
    assert main(["calibrate", str(path), flag, value]) == 2
    err = capsys.readouterr().err
    assert flag in err and err.count("\n") == 1
