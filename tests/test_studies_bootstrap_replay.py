"""Studies: subset resampling of a pool (seed 9.3) and replaying recorded samples in the twin."""
import json

import numpy as np
import pytest
from conftest import SEED_DM, SEED_QE, TABLE10

from planecal.cli import main
from planecal.estimation.calibrate import CalibrationSettings
from planecal.io.samples import write_samples
from planecal.model.scene import load_scene, nominal_params
from planecal.studies.bootstrap import BootstrapSettings, Pool, bootstrap, default_sizes, overlap
from planecal.twin.synthetic import synthetic_samples
from planecal.twin.truth import draw_truth


@pytest.fixture(scope="module")
def pool():
    scene = load_scene("thesis_final")
    truth = draw_truth(scene, 3)
    qe, d, plate = synthetic_samples(scene, truth, 240, np.random.default_rng(1), noise_m=20e-6)
    return scene, truth, qe, d, plate


def test_overlap_formula():
    ov = overlap(200, 500)
    assert ov["share"] == pytest.approx(0.4)
    assert ov["expected_common_samples"] == pytest.approx(80.0)
    assert ov["finite_population_factor"] == pytest.approx(np.sqrt(300 / 499))


def test_bootstrap_spread_shrinks_and_brackets_the_truth(pool):
    scene, truth, qe, d, plate = pool
    res = bootstrap(Pool(scene.robot, qe, d, plate, nominal_params(scene),
                         CalibrationSettings()),
                    BootstrapSettings((30, 120), 8, seed=2), quiet=True)
    small, big = res["sizes"]
    assert small["fits"] == big["fits"] == 8
    for k, name in enumerate(["delta2", "delta3", "delta4", "delta5"], start=1):
        s, b = small["params"][name], big["params"][name]
        assert b["std_independent"] < s["std_independent"]
        # the subset estimates scatter around the truth
        assert s["min"] - 3 * s["std"] < truth.joint_offsets[k] < s["max"] + 3 * s["std"]
        # 20 um noise: the spread agrees with the fits' reported std within a factor 2.5
        assert 0.4 < s["std_independent"] / s["reported_std"] < 2.5
    assert small["warning"] is None
    assert big["warning"] is not None and "50%" in big["warning"]  # 120 of 240


def test_subset_r_of_size_s_is_fixed_by_seed_size_and_r(pool):
    """Issue 15: a run's seed is fixed by its cell and its index: subset r of size s is the
    same whatever other sizes the study has (and whoever fits it: test_distributed)."""
    from planecal.studies.bootstrap import subset_indices
    scene, truth, qe, d, plate = pool
    problem = Pool(scene.robot, qe, d, plate, nominal_params(scene), CalibrationSettings())
    both = bootstrap(problem, BootstrapSettings((30, 60), 3, seed=4), quiet=True)
    alone = bootstrap(problem, BootstrapSettings((60,), 3, seed=4), quiet=True)
    assert both["sizes"][1] == alone["sizes"][0]
    other = bootstrap(problem, BootstrapSettings((60,), 3, seed=5), quiet=True)
    assert other["sizes"][0]["params"]["delta3"] != alone["sizes"][0]["params"]["delta3"]
    idx = subset_indices(240, 60, 2, 4)
    assert len(set(idx.tolist())) == 60 and np.all(np.diff(idx) > 0) and idx[-1] < 240
    np.testing.assert_array_equal(idx, np.sort(
        np.random.default_rng([4, 60, 2]).choice(240, 60, replace=False)))
    assert not np.array_equal(idx, subset_indices(240, 60, 1, 4))


def test_bootstrap_command(pool, tmp_path, capsys):
    scene, truth, qe, d, plate = pool
    f = tmp_path / "pool.tsv"
    write_samples(f, qe, d * 1e3)
    out = tmp_path / "B.json"
    assert main(["bootstrap", str(f), "--sizes", "40,100", "--repeats", "3", "--jobs", "1",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "subset size 40" in text and "WARNING" in text  # 100 of 240 > 30 %
    data = json.loads(out.read_text())
    assert [e["size"] for e in data["sizes"]] == [40, 100]
    assert main(["bootstrap", str(f), "--sizes", "300"]) == 2
    assert "is not below the pool of 240 samples" in capsys.readouterr().err
    # a subset as large as the pool: identical fits, no spread: refused too
    assert main(["bootstrap", str(f), "--sizes", "240"]) == 2
    assert "no spread" in capsys.readouterr().err
    assert main(["bootstrap", str(f), "--sizes", "5"]) == 2
    assert main(["bootstrap", str(f), "--sizes", "30", "--repeats", "1"]) == 2


def test_default_sizes_stay_below_the_pool():
    # the defaults 30, 50, 100, 150 where they fit strictly between the free parameters
    # and the pool; a small pool gets 30/50/70 % of itself
    assert default_sizes(240, 12) == (30, 50, 100, 150)
    assert default_sizes(150, 12) == (30, 50, 100)
    assert default_sizes(60, 12) == (30, 50)
    assert default_sizes(40, 12) == (20, 28)  # fewer than two defaults fit: 30-70 %
    assert default_sizes(14, 12) == (13,) or default_sizes(14, 12) == ()
    for n in (40, 150, 151, 1000):
        assert all(12 < s < n for s in default_sizes(n, 12))


def test_bootstrap_command_on_a_150_sample_pool_has_no_size_150(pool, tmp_path, capsys):
    scene, truth, qe, d, plate = pool
    f = tmp_path / "pool150.tsv"
    write_samples(f, qe[:150], d[:150] * 1e3)
    out = tmp_path / "B.json"
    assert main(["bootstrap", str(f), "--repeats", "2", "--jobs", "1", "--out", str(out)]) == 0
    assert [e["size"] for e in json.loads(out.read_text())["sizes"]] == [30, 50, 100]


def test_replay_seed_samples_in_the_twin():
    from planecal.studies.replay import replay
    res = replay(load_scene("thesis_final"), TABLE10, SEED_QE, SEED_DM)
    twin = np.array([r["twin_mm"] for r in res["rows"]])
    # the analytic model's figures (MODEL-NOTES); the twin's ray cast agrees to 1e-6 mm
    assert all(r["on_plate"] for r in res["rows"])
    np.testing.assert_allclose(twin, [89.776, 85.318, 68.221, 68.017, 71.580], atol=6e-4)
    analytic = np.array([r["analytic_mm"] for r in res["rows"]])
    assert np.max(np.abs(twin - analytic)) < 1e-6
    s = res["summary"]
    assert s["plate_hits"] == 5 and s["misses"] == 0
    assert s["mean_diff_mm"] == pytest.approx(-1.2114, abs=1e-3)  # twin - measured
    assert s["std_diff_mm"] == pytest.approx(1.4960, abs=1e-3)
    assert s["max_abs_diff_mm"] == pytest.approx(2.7436, abs=1e-3)
    assert s["min_edge_margin_mm"] > 15  # the plate is big enough for these rays


def test_replay_command(tmp_path, capsys):
    from repo import repo_path
    ex = repo_path("examples")
    out = tmp_path / "R.json"
    assert main(["replay", str(ex / "seed_samples.tsv"), "--params",
                 str(ex / "table10_params.json"), "--out", str(out)]) == 0
    assert "5 of 5 rays hit their plate" in capsys.readouterr().out
    assert json.loads(out.read_text())["summary"]["plate_hits"] == 5
    assert main(["replay", str(ex / "seed_samples.tsv"), "--params", str(tmp_path / "no.json")]) == 2
