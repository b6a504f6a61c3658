"""The notebook API (planecal.api, re-exported by planecal): cheap import, SI units at the
edges (a sample file's mm become m), the wrappers give what the code they wrap gives, and
the answers are right against independent peers (a noise-free fit recovers the drawn truth;
the twin's distances match the analytic model at the truth)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import planecal
from planecal.base.errors import InputError

pytest.importorskip("planecal.twin")


def test_import_is_cheap_and_names_resolve_lazily():
    code = ("import sys, planecal; heavy = [m for m in ('numpy', 'scipy', 'mujoco', 'rerun') "
            "if m in sys.modules]; print(heavy); print(callable(planecal.calibrate))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split("\n")
    assert out[0] == "[]" and out[1] == "True"
    assert {"load_samples", "rehearse", "calibrate", "validate"} <= set(dir(planecal))
    with pytest.raises(AttributeError):
        planecal.no_such_thing  # noqa: B018


@pytest.fixture(scope="module")
def scene():
    from planecal.model.scene import load_scene
    return load_scene("thesis_final")


@pytest.fixture(scope="module")
def synthetic(scene):
    """40 noise-free samples of the analytic model at a drawn truth."""
    from planecal.twin.synthetic import synthetic_samples
    from planecal.twin.truth import draw_truth
    truth = draw_truth(scene, 7)
    qe, d, plate = synthetic_samples(scene, truth, 40, np.random.default_rng(2))
    return truth, planecal.SampleSet(qe, d, plate, "synthetic")


def test_load_samples_reads_mm_as_metres(tmp_path, synthetic):
    from planecal.io.samples import write_samples
    _, s = synthetic
    path = tmp_path / "run.tsv"
    d_mm = np.round(s.distance_m * 1e3, 6)  # the file's resolution
    write_samples(path, s.counts, d_mm, s.plate)
    got = planecal.load_samples(path)
    np.testing.assert_array_equal(got.counts, s.counts)
    np.testing.assert_array_equal(got.plate, s.plate)
    np.testing.assert_allclose(got.distance_m, d_mm * 1e-3, rtol=0, atol=1e-15)
    text = repr(got)
    assert text.startswith(f"SampleSet: {len(s)} samples from {path}")
    assert f"{d_mm.min():.2f} to {d_mm.max():.2f} mm" in text and "plate 1: 40" in text
    with pytest.raises(InputError):
        planecal.load_samples(tmp_path / "missing.tsv")
    assert got.direction is None  # a file without the direction group
    signs = np.random.default_rng(0).integers(-1, 2, (len(s), 6))
    write_samples(path, s.counts, d_mm, s.plate, direction=signs)
    np.testing.assert_array_equal(planecal.load_samples(path).direction, signs)


def test_calibrate_recovers_the_truth_and_wraps_fit_solve(scene, synthetic, tmp_path):
    from planecal.estimation.fit import Problem, solve
    from planecal.model.scene import nominal_params
    truth, s = synthetic
    cal = planecal.calibrate(s, scene)
    # independent peer: the truth the samples were drawn at (delta1, delta6 fixed at 0)
    err = cal.params.joint_offsets[1:5] - truth.joint_offsets[1:5]
    assert np.abs(err).max() < 1e-9, err
    assert cal.rms_after_m < 1e-12 and cal.rms_before_m > 1e-4 and cal.converged
    # the same numbers as the fit it wraps
    res = solve(Problem.from_arrays(scene.robot, s.counts, s.distance_m, nominal_params(scene),
                                    s.plate))
    # (calibrate's first evaluation is the base set's Jacobian: the same values, whose
    # products may round apart in the last bit)
    np.testing.assert_allclose(cal.params.to_vector(res.layout),
                               res.params.to_vector(res.layout), rtol=0, atol=1e-12)
    assert cal.values["delta3"] == cal.params.joint_offsets[2]
    assert np.isnan(cal.std["delta1"]) and cal.units["o_x"] == "m"
    text = repr(cal)
    assert "Calibration on scene thesis_final, level offsets: converged" in text
    # the terminal report of planecal calibrate (present.calibration.text)
    assert (f"model error (predicted - measured) RMS  before {cal.rms_before_m * 1e3:.4f} mm"
            in text)
    for name in res.names:
        assert f"\n{name} " in text
    assert "fixed" in text
    # a file path works too; bad input is one InputError
    from planecal.io.samples import write_samples
    write_samples(tmp_path / "s.tsv", s.counts, s.distance_m * 1e3, s.plate)
    assert planecal.calibrate(tmp_path / "s.tsv", scene).result.iterations >= 1
    with pytest.raises(InputError, match="SampleSet"):
        planecal.calibrate([1, 2, 3], scene)
    with pytest.raises(InputError, match="max_iter"):
        planecal.calibrate(s, scene, max_iter=0)


@pytest.fixture(scope="module")
def rehearsal():
    return planecal.rehearse(samples=30, seed=0, errors="ideal")


def test_rehearse_gives_si_samples_that_match_the_model_at_the_truth(scene, rehearsal):
    from planecal.model.measurement import predict
    from planecal.model.scene import nominal_params
    s = rehearsal.samples
    assert len(s) == 30 and s.counts.shape == (30, 6) and s.counts.dtype == np.int64
    lo, hi = scene.laser_range_mm
    assert lo * 1e-3 <= s.distance_m.min() and s.distance_m.max() <= hi * 1e-3  # metres
    # the twin (MuJoCo) against the analytic model: at the truth within the noise
    # (repeatability 0.07 mm 3-sigma at the flange), at the nominal values mm off
    at_truth = predict(scene.robot, s.counts, rehearsal.truth, s.plate) - s.distance_m
    at_nominal = predict(scene.robot, s.counts, nominal_params(scene), s.plate) - s.distance_m
    print(f"twin vs model: at the truth max {np.abs(at_truth).max() * 1e3:.4f} mm, "
          f"nominal RMS {np.sqrt(np.mean(at_nominal ** 2)) * 1e3:.3f} mm")
    assert np.abs(at_truth).max() < 1e-4
    assert np.sqrt(np.mean(at_nominal ** 2)) > 1e-3
    text = repr(rehearsal)
    assert text.startswith("Rehearsal on scene thesis_final (ideal world, seed 0")
    assert "SampleSet: 30 samples" in text
    with pytest.raises(InputError, match=">= 20"):
        planecal.rehearse(samples=5)


def test_validate_compares_nominal_and_calibrated(rehearsal):
    cal = planecal.calibrate(rehearsal, free="delta2,delta3,delta4,delta5,o_x,o_y,o_z,"
                                            "n1_x,n1_y,n1_z")
    val = planecal.validate(cal, rehearsal, cycles=2, gauge_repeats=1)
    d = val.details
    assert val.ap_tool_nominal_m == d["ap_before_tool_mm"] * 1e-3
    assert val.ap_tool_calibrated_m == d["ap_after_tool_mm"] * 1e-3
    assert val.ap_tool_calibrated_m < 0.5 * val.ap_tool_nominal_m  # the calibration helps
    text = repr(val)
    assert f"before {val.ap_tool_nominal_m * 1e3:.4f} mm" in text and "2 cycles" in text
    with pytest.raises(InputError):
        planecal.validate(cal, rehearsal.samples)
