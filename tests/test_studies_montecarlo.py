"""Monte Carlo study: the twin mode reproduces a rehearsal sample for sample; on small
instances the spread agrees with the Cramer-Rao bound and the chi-square check holds."""
import numpy as np
import pytest

from planecal.cli import main
from planecal.estimation.identifiability import covariances
from planecal.studies.common import cached_scene
from planecal.studies.montecarlo import MCSettings, analyze, run_many, truth_for
from planecal.present.montecarlo import format_montecarlo
from planecal.studies.rehearsal import rehearse_samples, twin_samples


def test_covariance_forms_agree_for_white_noise_and_order_otherwise():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(200, 5)) * [1, 10, 0.1, 3, 1]
    c = covariances(J, np.full(200, 4e-10))
    np.testing.assert_allclose(c["white"], c["sandwich"], rtol=1e-9, atol=1e-30)
    np.testing.assert_allclose(c["white"], c["crb"], rtol=1e-9, atol=1e-30)
    v = rng.uniform(0.2, 3.0, 200) * 1e-10
    c = covariances(J, v)
    # the Cramer-Rao bound is below the sandwich (unweighted fit) in the PSD order
    assert np.linalg.eigvalsh(c["sandwich"] - c["crb"]).min() > -1e-12 * np.abs(c["sandwich"]).max()


def test_twin_mode_reproduces_the_rehearsal_sample_for_sample():
    st = MCSettings(samples=4)
    scene = cached_scene(st.scene)
    truth = truth_for(st, 0)
    qe_r, d_r, p_r, dir_r, _ = rehearse_samples(scene, truth, st, 11)
    qe_t, d_t, p_t, dir_t, _ = twin_samples(scene, truth, st, 11)
    np.testing.assert_array_equal(qe_r, qe_t)
    np.testing.assert_array_equal(p_r, p_t)
    # the ideal world's twin mode sets the twin at rest (no path-dependent error): it
    # drives no path, so every approach direction is unknown; the rehearsal drove there
    assert dir_t.shape == (4, 6) and not dir_t.any()
    assert dir_r.shape == (4, 6) and np.all(dir_r[1:] != 0)
    # the sample file keeps 6 decimals of a mm
    np.testing.assert_allclose(d_r, d_t, atol=1e-9, rtol=0)


def test_synthetic_monte_carlo_meets_the_bound():
    st = MCSettings(mode="synthetic", samples=60, runs=24, seed=5)
    res = analyze(run_many(st, 2, quiet=True), st)
    for n in ("delta3", "delta4", "delta5"):
        p = res["params"][n]
        # 24 runs: a std is known to +-15 %; allow 3 standard errors
        assert 0.55 < p["ratio_emp_to_crb"] < 1.5, (n, p)
        assert p["bias_over_crb"] < 0.7, (n, p)
        # mild heteroscedasticity: the white-noise bound is within 10 % of the CR bound
        assert abs(p["crb_white_std"] / p["crb_std"] - 1) < 0.1
    c = res["chi2_offsets_reported"]
    assert c["dof"] == 4 and abs(c["mean"] - 4) < 3 * c["standard_error"] + 0.5
    assert res["not_identifiable_all_free"][:2] == ["delta1", "delta6"]


def test_twin_monte_carlo_small(capsys, tmp_path):
    out = tmp_path / "M.json"
    assert main(["montecarlo", "--errors", "ideal", "--runs", "3", "--samples", "40", "--jobs", "2",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "emp/CRB" in text and "chi-square" in text
    import json
    res = json.loads(out.read_text())
    assert res["runs"] == 3 and res["samples_per_run"] == 40
    for n in ("delta2", "delta3", "delta4", "delta5"):
        p = res["params"][n]
        # the error of every run is within reach of the bound (4 sigma over 3 runs)
        assert abs(p["bias"]) < 4 * p["crb_std"]
        assert 0.7 < p["reported_std"] / p["crb_std"] < 1.4
    assert main(["montecarlo", "--runs", "1"]) == 2
    assert main(["montecarlo", "--mode", "twin", "--quantization"]) == 2
    assert main(["montecarlo", "--mode", "synthetic", "--quantization", "--weighted"]) == 2
    assert main(["montecarlo", "--mode", "synthetic", "--repeatability-mm", "0",
                 "--laser-noise-mm", "0"]) == 2
    err = capsys.readouterr().err
    assert "no quantisation term" in err and "no noise to study" in err


def test_weighted_monte_carlo_reports_the_weighted_fit():
    # same runs, fit unweighted and weighted: the header says which. The weighted fit
    # reports the Cramer-Rao bound of the noise model times one variance factor per run
    # (~1 +- 11 % in std at 60 samples), so the same ratio for every offset; the
    # unweighted fit reports the white-noise form, off by different ratios
    base = dict(scene="three_plates", mode="synthetic", samples=60, runs=2, seed=3)
    runs = {w: run_many(MCSettings(weighted=w, **base), 1, quiet=True) for w in (False, True)}
    res = {w: analyze(runs[w], MCSettings(weighted=w, **base)) for w in (False, True)}
    offsets = ("delta2", "delta3", "delta4", "delta5")
    idx = [res[True]["free"].index(n) for n in offsets]
    for w in (False, True):  # per run: reported std over the run's own bound, per offset
        for r in runs[w]:
            ratio = np.asarray(r["reported_std"])[idx] / np.sqrt(np.asarray(r["crb_var"])[idx])
            if w:  # one variance factor per run (~1 +- 11 % in std at 60 samples)
                assert np.ptp(ratio) < 0.03 and abs(ratio.mean() - 1) < 0.35, ratio
            else:  # the white-noise form: off by different ratios
                assert np.ptp(ratio) > 0.1, ratio
    for n in offsets:
        assert res[True]["params"][n]["crb_std"] == res[False]["params"][n]["crb_std"]
    assert "fit weighted by the noise model" in format_montecarlo(res[True])
    assert res[True]["chi2_offsets_sandwich"] is None  # the unweighted estimator's: no check
    assert "fit unweighted" in format_montecarlo(res[False])


def test_three_planes_do_not_free_delta1_delta6():
    st = MCSettings(scene="three_plates", mode="synthetic", samples=60, runs=2, seed=3)
    runs = run_many(st, 1, quiet=True)
    res = analyze(runs, st)
    bad = res["not_identifiable_all_free"]
    assert "delta1" in bad and "delta6" in bad
    # everything fitted by default is identifiable, one n~ per plate (three plates and the
    # stepped block's top)
    assert len(res["free"]) == 4 + 5 + 12 and not any(r["not_identifiable"] for r in runs)


def test_plots_go_to_a_rerun_recording(tmp_path, capsys):
    from planecal.present.rerun import is_recording
    rrd = tmp_path / "m.rrd"
    assert main(["montecarlo", "--mode", "synthetic", "--runs", "3", "--samples", "30",
                 "--jobs", "1", "--slope", "30,40", "--slope-runs", "2", "--rrd", str(rrd)]) == 0
    assert is_recording(rrd)


def test_pose_draw_settings_reach_the_runs():
    """--ik-choice / --roll-deg set the sampling run's pose draw: nearest IK keeps the
    wrist in its branch (q5 sign never changes), wrist changes it; roll 0 keeps the sensor's
    x axis on the plate's x edge, so the last joint moves far less than at any roll."""
    from planecal.model.encoder import counts_to_joints
    from planecal.base.errors import InputError
    scene = cached_scene("thesis_final")

    def q(**kw):
        st = MCSettings(samples=40, **kw)
        qe, _, _, _, _ = twin_samples(scene, truth_for(st, 0), st, 5)
        return counts_to_joints(scene.robot, qe)

    flips = {c: int(np.sum(np.diff(np.sign(q(ik_choice=c)[:, 4])) != 0))
             for c in ("nearest", "wrist")}
    assert flips["nearest"] == 0 and flips["wrist"] >= 1
    spread6 = {r: np.ptp(q(roll_deg=r, ik_choice="nearest")[:, 5]) for r in (0.0, 180.0)}
    assert spread6[0.0] < 0.7 * spread6[180.0]  # measured 1.03 vs 1.97 rad
    for bad in (dict(roll_deg=200.0), dict(mode="synthetic", ik_choice="nearest")):
        with pytest.raises(InputError):
            MCSettings(**bad).check()


def test_a_parameter_no_run_reports_is_counted_not_averaged():
    """In the realistic world the fit's residual sigma carries the model mismatch and
    phi_z exceeds its practical std limit in every run: its reported std is NaN in all of
    them. ``analyze`` must say so without numpy's 'Mean of empty slice' warning."""
    import warnings
    st = MCSettings(mode="synthetic", samples=40, runs=4, seed=7)
    runs = run_many(st, 1, quiet=True)
    names = analyze(runs, st)["free"]
    k = names.index("phi_z")
    for r in runs[:2]:
        r["reported_std"] = np.asarray(r["reported_std"], float).copy()
        r["reported_std"][names.index("phi_y")] = np.nan
    for r in runs:
        r["reported_std"] = np.asarray(r["reported_std"], float).copy()
        r["reported_std"][k] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        res = analyze(runs, st)
    p = res["params"]
    assert p["phi_z"]["reported_in_runs"] == 0 and np.isnan(p["phi_z"]["reported_std"])
    assert p["phi_y"]["reported_in_runs"] == 2
    # the RMS over the two runs that report it
    rep = [np.asarray(r["reported_std"])[names.index("phi_y")] for r in runs[2:]]
    assert p["phi_y"]["reported_std"] == pytest.approx(np.sqrt(np.mean(np.square(rep))))
    assert p["delta3"]["reported_in_runs"] == 4
    assert "no std reported in any run" in format_montecarlo(res)
    assert "phi_z" in format_montecarlo(res).split("no std reported in any run")[1]


def test_realistic_twin_runs_analyze_without_warnings():
    import warnings
    st = MCSettings(runs=2, samples=30, errors="realistic", seed=3)
    runs = run_many(st, 1, quiet=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        res = analyze(runs, st)
        format_montecarlo(res)
    assert res["world"]["model_mismatch"]  # the realistic world: errors the model lacks
    # Table 9's class of model error, not the noise's 0.03 mm
    assert res["world"]["max_residual_mm"]["median"] > 0.08


def test_progress_names_the_scene_not_its_path(capsys):
    # issue 33: the progress line printed the whole site-packages path of the scene
    assert main(["montecarlo", "--mode", "synthetic", "--runs", "2", "--samples", "30",
                 "--jobs", "1"]) == 0
    err = capsys.readouterr().err
    assert "montecarlo thesis_final N=30 2/2" in err and ".json" not in err, err
