"""planecal report: the HTML page and its PNG figures for each kind of result file, made
from real results of the commands (small runs, made once per session)."""
import json
import re
import shutil

import numpy as np
import pytest
from PIL import Image

from planecal.cli import main
from planecal.base.errors import InputError
from repo import repo_path
from planecal.present.report import detect_kind, write_report
from planecal.present.report.figures import display_scale, num
from planecal.present.report.inputs import sha256

TABLE10 = str(repo_path("examples", "table10_params.json"))


@pytest.fixture(scope="session")
def results(tmp_path_factory):
    """Result files of demo, montecarlo, bootstrap, validate and plan (small runs)."""
    d = tmp_path_factory.mktemp("results")
    run = [
        ["demo", "--samples", "40", "--dir", str(d / "demo")],
        ["montecarlo", "--runs", "5", "--samples", "30", "--jobs", "1", "--out", str(d / "M.json")],
        ["bootstrap", str(d / "demo" / "demo.tsv"), "--sizes", "15,20,30", "--repeats", "3",
         "--out", str(d / "B.json")],
        ["validate", "--samples", "30", "--cycles", "3", "--gauge-repeats", "2",
         "--out", str(d / "V.json")],
        ["plan", "--samples", "20", "--candidates", "60", "--out", str(d / "P.json")],
    ]
    for argv in run:
        assert main(argv) == 0, argv
    return {"dir": d, "demo": d / "demo" / "result.json", "tsv": d / "demo" / "demo.tsv",
            "montecarlo": d / "M.json", "bootstrap": d / "B.json", "validation": d / "V.json",
            "plan": d / "P.json"}


def figures(index) -> list[str]:
    return re.findall(r'<img src="([^"]+)"', index.read_text(encoding="utf-8"))


def check_png(path) -> None:
    """A real figure: a PNG of a readable size with something drawn on it."""
    assert path.stat().st_size > 10_000, path
    with Image.open(path) as im:
        assert im.format == "PNG"
        w, h = im.size
        a = np.asarray(im.convert("L"), float)
    assert w >= 450 and h >= 300, (path.name, w, h)
    assert a.std() > 15, (path.name, a.std())  # not blank
    assert np.mean(a < 128) > 0.01, path.name  # lines, text and bars, not a white page


def check_page(index, at_least: int) -> list[str]:
    html = index.read_text(encoding="utf-8")
    assert "<script" not in html
    imgs = figures(index)
    assert len(imgs) >= at_least, imgs
    assert len(set(imgs)) == len(imgs)
    for name in imgs:
        assert "/" not in name and ":" not in name  # relative, beside index.html
        check_png(index.parent / name)
    assert "Provenance" in html and "report by" in html
    return imgs


# ----- calibration --------------------------------------------------------------------------------

def test_demo_report_has_the_seed_graphs_and_the_model_error(results, tmp_path, capsys):
    out = tmp_path / "rep"
    assert main(["report", str(results["demo"]), "--out", str(out),
                 "--samples", str(results["tsv"])]) == 0
    assert "report written to" in capsys.readouterr().out
    imgs = check_page(out / "index.html", 6)
    for name in ("distances.png", "error_before.png", "error_after.png",
                 "error_per_sample.png", "offsets.png", "singular_values.png"):
        assert name in imgs
    doc = json.loads(results["demo"].read_text())
    assert ("convergence.png" in imgs) == ("history" in doc)
    assert ("correlation.png" in imgs) == ("covariance" in doc)
    html = (out / "index.html").read_text(encoding="utf-8")
    # the recomputed model error reproduced the file's RMS, so no mismatch was noted
    assert "not the samples" not in html and "started elsewhere" not in html
    assert "delta2" in html and "fixed" in html and str(results["tsv"]) in html


def _covariance_and_history(doc, tsv):
    """What the result file will hold (another engineer's change): the covariance of the
    free parameters by name, and the fit's iteration history. Made here from the fit's
    own formula at the solution (sigma^2 (J^T J)^-1), one parameter marked unidentifiable."""
    from planecal.model.measurement import predict_with_jacobian
    from planecal.io.params import params_from_dict
    from planecal.present.calibration import parameter_rows
    from planecal.io.samples import read_samples
    from planecal.model.scene import load_scene
    s = read_samples(tsv)
    robot = load_scene("thesis_final").robot
    _, J = predict_with_jacobian(robot, s.qe, params_from_dict(doc), s.plate)
    names = [r.name for r in parameter_rows(doc)]
    idx = [names.index(n) for n in doc["free"]]
    C = (doc["identifiability"]["sigma_mm"] * 1e-3) ** 2 * np.linalg.inv(J[:, idx].T @ J[:, idx])
    M = [[float(v) for v in row] for row in C]
    k = doc["free"].index("phi_z")
    for i in range(len(M)):
        M[i][k] = M[k][i] = None
    hist = [{"iteration": 0, "rms_m": doc["residual_rms_initial_mm"] * 1e-3,
             "max_m": 9e-3, "samples": 40}]
    hist += [{"iteration": i, "rms_m": doc["residual_rms_mm"] * 1e-3 * (1 + 10 ** (3 - 2 * i)),
              "max_m": doc["residual_max_mm"] * 1e-3 * (1 + 10 ** (3 - 2 * i)), "samples": 40}
             for i in range(1, 5)]
    return {"names": list(doc["free"]), "matrix": M}, hist, C


def test_covariance_and_history_give_heatmap_and_convergence(results, tmp_path):
    doc = json.loads(results["demo"].read_text())
    cov, hist, C = _covariance_and_history(doc, results["tsv"])
    doc = {**doc, "covariance": cov, "history": hist, "format": "planecal-result/1"}
    index = write_report(doc, tmp_path / "rep", samples=[results["tsv"]])
    imgs = check_page(index, 8)
    assert "correlation.png" in imgs and "convergence.png" in imgs
    from planecal.present.report.calibration import correlation
    names, R = correlation(cov)
    k = names.index("phi_z")
    assert np.all(np.isnan(R[k])) and np.all(np.isnan(R[:, k]))
    i, j = names.index("delta2"), names.index("n1_x")
    assert R[i, j] == pytest.approx(C[i, j] / np.sqrt(C[i, i] * C[j, j]), rel=1e-12)
    assert R[i, i] == pytest.approx(1.0, abs=1e-12)
    assert "format planecal-result/1" in index.read_text(encoding="utf-8")


def test_wrong_samples_are_said_not_drawn(results, tmp_path):
    from planecal.io.samples import read_samples, write_samples
    s = read_samples(results["tsv"])
    other = tmp_path / "other.tsv"
    write_samples(other, s.qe, s.d_mm + 0.05)  # 50 um off: not this result's data
    index = write_report(results["demo"], tmp_path / "rep", samples=[other])
    html = index.read_text(encoding="utf-8")
    assert "they are not the samples of this result" in html
    imgs = figures(index)
    assert "error_after.png" not in imgs and "error_per_sample.png" not in imgs
    assert "distances.png" in imgs  # the distances are what the file holds, whatever it is


def test_level3_report_draws_the_model_error_of_its_own_samples(tmp_path, capsys):
    """issue 33: a level-3 report said its very samples were "not the samples of this
    result" (their model error recomputed without the approach directions, so level 3's
    backlash took the gravity flank: 0.034 mm rms where the fit left 0.010). The report's
    recomputed RMS is the result file's."""
    from planecal.io.samples import read_samples
    from planecal.model.measurement import predict
    from planecal.model.scene import load_scene
    from planecal.io.params import params_from_dict
    run, cal, out = tmp_path / "r.tsv", tmp_path / "cal3.json", tmp_path / "rep"
    assert main(["rehearse", "--out", str(run), "--samples", "150", "-q"]) == 0
    assert main(["calibrate", str(run), "--level", "nonkinematic", "--out", str(cal),
                 "--report", str(out)]) == 0
    capsys.readouterr()
    html = (out / "index.html").read_text(encoding="utf-8")
    assert "not the samples" not in html
    assert {"error_after.png", "error_per_sample.png"} <= set(figures(out / "index.html"))
    doc = json.loads(cal.read_text())
    s = read_samples(run)
    robot = load_scene("thesis_final").robot
    r = predict(robot, s.qe, params_from_dict(doc), s.plate, s.direction) - s.d_mm * 1e-3
    assert np.sqrt(np.mean(r ** 2)) * 1e3 == pytest.approx(doc["residual_rms_mm"], rel=1e-6)
    flank = predict(robot, s.qe, params_from_dict(doc), s.plate) - s.d_mm * 1e-3
    assert np.sqrt(np.mean(flank ** 2)) * 1e3 > 1.5 * doc["residual_rms_mm"]  # it matters


def test_samples_recorded_in_the_provenance_are_used_and_checked(results, tmp_path):
    doc = json.loads(results["demo"].read_text())
    entry = {"role": "samples", "path": str(results["tsv"]), "sha256": sha256(results["tsv"]),
             "bytes": results["tsv"].stat().st_size}
    doc["provenance"] = {"planecal_version": "0.1.0", "created_utc": "2026-01-01T00:00:00+00:00",
                         "scene": "thesis_final", "inputs": [entry]}
    index = write_report(doc, tmp_path / "ok")
    assert "error_after.png" in figures(index)
    doc["provenance"]["inputs"] = [{**entry, "sha256": "0" * 64}]
    index = write_report(doc, tmp_path / "bad")
    assert "error_after.png" not in figures(index)
    assert "is not the samples file the result was made from" in index.read_text(encoding="utf-8")


def test_without_samples_the_page_says_what_is_missing(results, tmp_path):
    doc = json.loads(results["demo"].read_text())
    doc.pop("provenance")  # the demo records its samples, as calibrate does
    index = write_report(doc, tmp_path / "rep")
    html = index.read_text(encoding="utf-8")
    assert "no sample file given" in html
    assert "error_after.png" not in figures(index)
    check_page(index, 2)  # the offsets and the singular values need no samples


# ----- studies ------------------------------------------------------------------------------------

def test_montecarlo_report(results, tmp_path, capsys):
    out = tmp_path / "rep"
    assert main(["report", str(results["montecarlo"]), "--out", str(out)]) == 0
    imgs = check_page(out / "index.html", 4)
    for name in ("errors_joint_offsets.png", "errors_sensor_pose.png", "errors_normalized.png",
                 "chi2.png", "ratios.png"):
        assert name in imgs
    html = (out / "index.html").read_text(encoding="utf-8")
    assert "delta2" in html and "Chi-square" in html


@pytest.mark.parametrize("kind, n, names", [
    ("bootstrap", 3, ["spread_joint_offsets.png", "spread_sensor_pose.png"]),
    ("validation", 4, ["ap_vectors.png", "ap_rp.png", "gauge.png", "offset_error.png"]),
    ("plan", 3, ["predicted_std.png", "design_joints.png", "design_spots.png"]),
])
def test_study_reports(results, tmp_path, kind, n, names):
    index = write_report(results[kind], tmp_path / kind)
    imgs = check_page(index, n)
    for name in names:
        assert name in imgs


# ----- kinds, errors ----------------------------------------------------------------------------

def test_kind_from_the_format_field_first_then_the_content(results):
    docs = {k: json.loads(results[k].read_text()) for k in
            ("demo", "montecarlo", "bootstrap", "validation", "plan")}
    assert [detect_kind(docs[k]) for k in docs] == [
        "calibration", "montecarlo", "bootstrap", "validation", "plan"]
    mc = dict(docs["montecarlo"])
    mc["format"] = "planecal-montecarlo/1"
    assert detect_kind(mc) == "montecarlo"
    mc["format"] = "planecal-bootstrap/1"  # the field wins over the content
    assert detect_kind(mc) == "bootstrap"
    mc["format"] = "planecal-montecarlo/2"
    with pytest.raises(InputError, match="version"):
        detect_kind(mc)
    with pytest.raises(InputError, match="format planecal-run/1"):
        detect_kind({"format": "planecal-run/1", "status": "complete"})
    with pytest.raises(InputError, match="not a result"):
        detect_kind(json.loads(open(TABLE10).read()))  # parameters, not a result


@pytest.mark.parametrize("make, what", [
    (lambda d: d / "missing.json", "file not found"),
    (lambda d: shutil.copy(TABLE10, d / "p.json"), "not a result"),
])
def test_bad_input_is_one_line(tmp_path, capsys, make, what):
    path = make(tmp_path)
    assert main(["report", str(path), "--out", str(tmp_path / "rep")]) == 2
    err = capsys.readouterr().err.strip()
    assert what in err and len(err.splitlines()) == 1


def test_out_must_be_a_directory(results, tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    assert main(["report", str(results["plan"]), "--out", str(f)]) == 2
    assert "not a directory" in capsys.readouterr().err
    assert f.read_text() == "x"


def test_incomplete_result_is_an_input_error(results, tmp_path):
    doc = json.loads(results["montecarlo"].read_text())
    del doc["params"]
    with pytest.raises(InputError, match="not a complete montecarlo result"):
        write_report(doc, tmp_path / "rep")


# ----- figure helpers ----------------------------------------------------------------------------

def test_display_units_give_ticks_of_one_to_three_digits():
    assert display_scale("rad", [2.3e-5, -1e-6]) == (1e6, "µrad")
    assert display_scale("rad", [0.0021]) == (1e3, "mrad")
    assert display_scale("m", [0.009, 0.0001]) == (1e3, "mm")
    assert display_scale("m", [1.3e-5]) == (1e6, "µm")
    assert display_scale("m", [2.0]) == (1.0, "m")
    assert display_scale("m", [np.nan, 0.0]) == (1.0, "m")
    assert display_scale("1/m", [0.004]) == (1e3, "10⁻³/m")


def test_numbers_for_tables():
    assert num(18467.2) == "18470"
    assert num(0.0123456) == "0.01235"
    assert num(1.5e-7) == "1.500e-07"
    assert num(None) == "–" and num(float("nan")) == "–"
    assert num(0.0) == "0"
