"""Level 2's identifiable base set (identifiability.select_base) and the one calibrate() entry."""
import json

import numpy as np
import pytest

from planecal.estimation.calibrate import CalibrationSettings, calibrate
from planecal.model.levels import layout_for
from planecal.model.cell_params import CellParams
from planecal.model.measurement import predict, predict_with_jacobian
from planecal.estimation.fit import Problem, solve
from planecal.estimation.identifiability import select_base
from planecal.model.layout import level1_layout
from planecal.model.scene import load_scene, nominal_params
from planecal.twin.synthetic import synthetic_samples


def _design(name, per_plate=60, seed=2):
    scene = load_scene(name)
    nominal = nominal_params(scene)
    qe, _, plate = synthetic_samples(scene, nominal, per_plate * nominal.n_planes,
                                     np.random.default_rng(seed))
    return scene, nominal, qe, plate


def _fd_jacobian(robot, qe, plate, params, layout):
    """Central differences of the distance model (cell.predict), column by column."""
    x = params.to_vector(layout)
    J = np.empty((len(qe), len(layout)))
    for k, name in enumerate(layout.names):
        h = 1e-9 if layout.param(name).unit == "rad/(N m)" else 1e-6
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        J[:, k] = (predict(robot, qe, CellParams.from_vector(xp, layout), plate)
                   - predict(robot, qe, CellParams.from_vector(xm, layout), plate)) / (2 * h)
    return J


def _scaled(A):
    n = np.linalg.norm(A, axis=0)
    return A / np.where(n > 0, n, 1.0)


@pytest.mark.parametrize("scene_name,compliance", [("thesis_final", False),
                                                   ("three_plates", False),
                                                   ("three_plates", True)])
def test_base_set_agrees_with_an_svd_of_a_finite_difference_jacobian(scene_name, compliance):
    """The independent cross-check (issue 13): the pivoted QR of the analytic Jacobian picks
    as many parameters as the finite-difference Jacobian's SVD has singular values above
    the gap, the picked columns are independent in the FD Jacobian, and every excluded
    parameter's FD column is the combination select_base names."""
    scene, nominal, qe, plate = _design(scene_name)
    robot = scene.robot
    L = layout_for(robot, nominal.n_planes, "full", compliance)
    free = L.default_free
    _, J = predict_with_jacobian(robot, qe, nominal, plate, L)
    bs = select_base(J, L, free)
    Jfd = _fd_jacobian(robot, qe, plate, nominal, L)
    s = np.linalg.svd(_scaled(Jfd[:, free]), compute_uv=False)
    ratios = s / s[0]
    # a clear gap: above 1e-5 (real directions) and below 1e-8 (FD noise, 1e-10)
    rank_fd = int(np.sum(ratios > 1e-7))
    assert ratios[rank_fd - 1] > 1e-5 and (rank_fd == len(s) or ratios[rank_fd] < 1e-8)
    assert bs.rank == len(bs.base) == rank_fd
    assert len(bs.base) + len(bs.excluded) == int(free.sum())
    sb = np.linalg.svd(_scaled(Jfd[:, L.indices(bs.base)]), compute_uv=False)
    assert sb[-1] / sb[0] > 1e-5  # the base set is independent in the FD Jacobian too
    for e in bs.excluded:
        col = Jfd[:, L.index(e.parameter)]
        if e.reason == "no_effect":
            assert np.abs(col).max() < 1e-9 * np.abs(Jfd).max(), e.parameter
            continue
        pred = sum(c * Jfd[:, L.index(k)] for k, c in e.combination.items())
        assert np.abs(pred - col).max() <= 1e-3 * np.abs(col).max(), e.parameter
    # what every robot-plane calibration must leave out: base z moves like d1 (one
    # direction along the first axis), d3 like d2 (the parallel J2-J3 axes)
    names = {e.parameter: e for e in bs.excluded}
    for a, b in (("d1", "base_z"), ("d2", "d3")):  # identical columns: at most one of each
        assert not (a in bs.base and b in bs.base)
        if a in bs.base or b in bs.base:  # (on one plate the plane takes d1 and base_z)
            gone, kept = (a, b) if a in names else (b, a)
            assert names[gone].combination == pytest.approx({kept: 1.0}, rel=1e-6)
    assert "beta3" in bs.base and "a2" in bs.base and "alpha2" in bs.base
    if compliance:
        assert {"c2", "c3"} <= set(bs.base)


def test_identifiable_counts_of_one_and_three_plates():
    # measured (docs/STUDIES.md, "Level 2"): of 37 candidates 26 on one plate, on
    # three_plates (its three plates and the stepped block's top: four planes) of 46, 35
    # (delta1 and delta6 fixed as in level 1; the arm's scale among the candidates here)
    for name, n_free, n_base in (("thesis_final", 37, 26), ("three_plates", 46, 35)):
        scene, nominal, qe, plate = _design(name)
        L = layout_for(scene.robot, nominal.n_planes, "full")
        _, J = predict_with_jacobian(scene.robot, qe, nominal, plate, L)
        bs = select_base(J, L, L.default_free)
        assert (len(bs.free), len(bs.base)) == (n_free, n_base), name


def test_select_base_names_zero_and_combined_columns():
    from planecal.model.layout import Group, Param, ParamLayout
    g = Group("g", "g", 0, tuple(Param(n, "m", "g", 1.0, "m", 1.0) for n in "abcde"))
    L = ParamLayout([g])
    rng = np.random.default_rng(0)
    J = np.zeros((50, 5))
    J[:, 0] = rng.normal(size=50)
    J[:, 1] = 1e3 * rng.normal(size=50)  # another scale: column scaling must not mind
    J[:, 2] = 2.0 * J[:, 0] - 0.5e-3 * J[:, 1]  # c = 2 a - 0.5 b (in b's units: -0.5e-3)
    J[:, 4] = rng.normal(size=50)
    bs = select_base(J, L, np.ones(5, bool))
    assert bs.rank == 3 and len(bs.base) == 3 and "d" not in bs.base
    ex = {e.parameter: e for e in bs.excluded}
    assert ex["d"].reason == "no_effect"
    dep = [p for p in "abc" if p not in bs.base]
    assert len(dep) == 1
    e = ex[dep[0]]
    assert e.reason == "combination"
    recon = sum(c * J[:, "abcde".index(k)] for k, c in e.combination.items())
    np.testing.assert_allclose(recon, J[:, "abcde".index(dep[0])], rtol=0, atol=1e-9 * np.abs(J).max())


def test_calibrate_offsets_is_todays_fit():
    scene, nominal, qe, plate = _design("three_plates", 40)
    d = predict(scene.robot, qe, nominal, plate) + 1e-4 * np.sin(np.arange(len(qe)))
    cal = calibrate(scene.robot, qe, d, nominal, plate)
    res = solve(Problem.from_arrays(scene.robot, qe, d, nominal, plate))
    # the whole default free set is the base set: the fit is solve's on it
    assert cal.level == "offsets" and cal.excluded == []
    L1 = level1_layout(nominal.n_planes)
    assert cal.base_set.base == L1.names_of(L1.default_free)
    # the same fit: calibrate's first evaluation is the base set's Jacobian (the same values
    # in another array, whose products may round apart in the last bit), so the same
    # solution to the rounding of its last correction (1e-13 rad at the default limit)
    np.testing.assert_allclose(cal.params.to_vector(), res.params.to_vector(), rtol=0,
                               atol=1e-12)
    np.testing.assert_allclose(cal.result.residuals_m, res.residuals_m, rtol=0, atol=1e-12)
    assert cal.result.layout is L1


def test_calibrate_full_recovers_a_whole_kinematic_truth_on_three_plates():
    """Noise-free samples of a robot whose every parameter is off (tolerances of the
    realistic profile, x3): the full fit reproduces the samples to < 1e-9 m and predicts
    new poses' distances as the truth does; the offsets fit cannot (tens of um)."""
    scene, nominal, qe, plate = _design("three_plates", 60)
    robot = scene.robot
    rng = np.random.default_rng(4)
    truth = nominal.copy()
    truth.joint_offsets = nominal.joint_offsets + rng.normal(0.0, 2e-3, 6)
    truth.geometry = rng.normal(0.0, 4.5e-4, (6, 4))
    truth.geometry[:, 2] = 0.0
    truth.geometry[2, 2] = 4.5e-4  # beta3 only: J2 || J3
    truth.base = rng.normal(0.0, 1e-3, 6)
    d = predict(robot, qe, truth, plate)
    cal = calibrate(robot, qe, d, nominal, plate, CalibrationSettings(level="full", free_scale=True))
    assert cal.result.converged
    assert np.abs(cal.result.residuals_m).max() < 1e-9
    assert cal.result.identifiability.not_identifiable == []
    # held-out poses: the identified base set predicts as the truth does
    qe2, _, plate2 = synthetic_samples(scene, nominal, 90, np.random.default_rng(99))
    err_full = predict(robot, qe2, cal.params, plate2) - predict(robot, qe2, truth, plate2)
    off = calibrate(robot, qe, d, nominal, plate, CalibrationSettings(level="offsets"))
    err_off = predict(robot, qe2, off.params, plate2) - predict(robot, qe2, truth, plate2)
    assert np.abs(err_full).max() < 1e-8
    assert np.abs(err_off).max() > 1e-5
    # the identifiable combinations are the truth's: beta3 has no partner (the one
    # parameter of the parallel pair), so it is recovered itself
    assert cal.params.geometry[2, 2] == pytest.approx(truth.geometry[2, 2], abs=1e-9)


def test_calibrate_full_with_compliance_recovers_the_stiffness_of_j2_and_j3():
    scene, nominal, qe, plate = _design("three_plates", 60)
    robot = scene.robot
    truth = nominal.copy()
    truth.compliance = np.array([0.0, 1 / 5e6, 1 / 3e6, 0.0, 0.0, 0.0])  # the realistic profile's
    d = predict(robot, qe, truth, plate)
    cal = calibrate(robot, qe, d, nominal, plate, CalibrationSettings(level="full", compliance=True))
    assert np.abs(cal.result.residuals_m).max() < 1e-9
    np.testing.assert_allclose(cal.params.compliance[1:3], truth.compliance[1:3], rtol=1e-6)


def test_calibrate_free_overrides_the_candidates():
    scene, nominal, qe, plate = _design("thesis_final", 80)
    d = predict(scene.robot, qe, nominal, plate)
    cal = calibrate(scene.robot, qe, d, nominal, plate, CalibrationSettings(level="full", free="delta2,delta3,a2,d2,d3,o_x,o_y,o_z"))
    assert cal.base_set.free == ["delta2", "delta3", "o_x", "o_y", "o_z", "a2", "d2", "d3"]
    assert [e.parameter for e in cal.excluded if e.reason == "combination"] in (["d2"], ["d3"])
    with pytest.raises(Exception, match="unknown parameter 'zz'"):
        calibrate(scene.robot, qe, d, nominal, plate, CalibrationSettings(level="full", free="zz"))
    with pytest.raises(Exception, match="unknown level"):
        calibrate(scene.robot, qe, d, nominal, plate, CalibrationSettings(level="everything"))


def test_cli_calibrate_level_full_result_is_read_by_predict_and_export(tmp_path, capsys):
    from planecal.cli import main
    from planecal.io.samples import write_samples
    scene, nominal, qe, plate = _design("thesis_final", 80)
    truth = nominal.copy()
    truth.geometry[1, 1] = 3e-4  # a2 0.3 mm long
    truth.joint_offsets[2] = 1e-3
    d = predict(scene.robot, qe, truth, plate)
    f = tmp_path / "r.tsv"
    write_samples(f, qe, d * 1e3)
    out = tmp_path / "full.json"
    assert main(["calibrate", str(f), "--level", "full", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "level full: 24 of 35 candidate parameters identifiable" in text
    assert "EXCLUDED base_z: a combination of others (acts as " in text
    assert "EXCLUDED a3: sets the arm's scale" in text and "EXCLUDED d4: sets the arm's scale" in text
    doc = json.loads(out.read_text())
    assert doc["level"] == "full" and len(doc["base_set"]) == 24
    assert {e["parameter"]: e["reason"] for e in doc["excluded"]}["d4"] == "scale"
    assert {e["parameter"]: e["reason"] for e in doc["excluded"]}["base_x"] in (
        "no_effect", "combination")
    assert doc["std"]["kinematics"]["base"][2] is None  # base_z excluded: no std
    assert doc["kinematics"]["a_m"][1] != 0.0
    assert main(["predict", str(f), "--params", str(out)]) == 0
    rows = [line.split("\t") for line in capsys.readouterr().out.strip().splitlines()]
    resid = np.array([float(r[-1]) for r in rows[1:] if len(r) == 4])
    assert len(resid) == len(qe) and np.abs(resid).max() < 1e-4  # mm
    assert main(["export", str(out)]) == 0
    assert "planecal compensate" in capsys.readouterr().err  # the geometry is not in counts
    assert main(["report", str(out), "--out", str(tmp_path / "report")]) == 0
    assert (tmp_path / "report" / "index.html").exists()
    # level offsets: the same file keys as before plus level "offsets"
    out1 = tmp_path / "off.json"
    assert main(["calibrate", str(f), "--out", str(out1)]) == 0
    doc1 = json.loads(out1.read_text())
    assert doc1["level"] == "offsets" and doc1["excluded"] == [] and "kinematics" not in doc1
    assert len(doc1["base_set"]) == 12
    assert doc1["geometry_prior_m_rad"] is None
    out2 = tmp_path / "prior.json"
    assert main(["calibrate", str(f), "--level", "full", "--geometry-prior", "0.5,0.5",
                 "--out", str(out2)]) == 0
    assert json.loads(out2.read_text())["geometry_prior_m_rad"] == [5e-4, 5e-4]
    assert main(["calibrate", str(f), "--geometry-prior", "0.5,0.5"]) == 2
    assert "--geometry-prior needs --level full" in capsys.readouterr().err


def test_planes_carry_the_base_frame_and_level2_enters_only_for_what_level1_cannot():
    scene, nominal, qe, plate = _design("three_plates")
    k = nominal.n_planes
    L = layout_for(scene.robot, k, "full")
    _, J = predict_with_jacobian(scene.robot, qe, nominal, plate, L)
    bs = select_base(J, L, L.default_free)
    ex = {e.parameter: e for e in bs.excluded}
    assert {f"base_{c}" for c in ("x", "y", "z", "rx", "ry", "rz")} <= set(ex)
    assert {"d1", "alpha1", "a1"} <= set(ex)  # first joint: moves every plane alike
    lv1 = set(level1_layout(k).names)
    for name in ("base_z", "d1", "alpha1"):  # explained by level-1 parameters alone
        assert set(ex[name].combination) <= lv1, name
    # the turn about the base z axis is the planes': delta1 fixed, base_rz is a combination
    # of the planes alone
    assert set(ex["base_rz"].combination) <= {f"n{i}_{c}" for i in range(1, k + 1)
                                               for c in "xyz"}


def test_geometry_prior_pulls_weak_geometry_towards_nominal_and_vanishes_when_wide():
    scene, nominal, qe, plate = _design("three_plates", 50)
    robot = scene.robot
    rng = np.random.default_rng(8)
    truth = nominal.copy()
    truth.geometry = rng.normal(0.0, 3e-4, (6, 4))
    truth.geometry[:, 2] = 0.0
    d = predict(robot, qe, truth, plate) + rng.normal(0.0, 2e-5, len(qe))
    free = calibrate(robot, qe, d, nominal, plate, CalibrationSettings(level="full"))
    wide = calibrate(robot, qe, d, nominal, plate, CalibrationSettings(level="full", geometry_prior=(1e3, 1e3)))
    tight = calibrate(robot, qe, d, nominal, plate, CalibrationSettings(level="full", geometry_prior=(1e-8, 1e-8)))
    np.testing.assert_allclose(wide.params.geometry, free.params.geometry, atol=1e-9)
    assert np.abs(tight.params.geometry).max() < 0.1 * np.abs(free.params.geometry).max()
    assert tight.result.rms_mm() > free.result.rms_mm()
    with pytest.raises(Exception, match="--geometry-prior needs --level full"):
        calibrate(robot, qe, d, nominal, plate, CalibrationSettings(geometry_prior=(1e-3, 1e-3)))


def test_the_arms_scale_stays_nominal_unless_freed_a_laser_gain_error_shows_why():
    """A laser that reads 0.1 % long (the ZS-LD80's linearity class) on noise-free data of
    an otherwise nominal cell: the distances are those of a world 0.1 % larger, so a fit
    with the arm's scale free makes the arm longer and misplaces the flange by ~1 mm at
    2 m; with the scale kept at robot.json's (the default) the error stays in the sensor
    and plane parameters and the flange is within 0.1 mm."""
    from planecal.model.levels import scale_lengths
    from planecal.model.encoder import counts_to_joints
    from planecal.model.measurement import flange_pose
    scene, nominal, qe, plate = _design("three_plates", 60)
    robot = scene.robot
    assert scale_lengths(robot) == ["d4", "a3"]  # 0.99 m and 0.9 m
    d = predict(robot, qe, nominal, plate) * 1.001
    q = counts_to_joints(robot, qe)
    true = flange_pose(robot, q, nominal)[:, :3, 3]
    err = {}
    for free_scale in (False, True):
        cal = calibrate(robot, qe, d, nominal, plate, CalibrationSettings(level="full", free_scale=free_scale))
        got = flange_pose(robot, q, cal.params)[:, :3, 3]
        err[free_scale] = float(np.sqrt(np.mean(np.sum((got - true) ** 2, axis=1))))
        assert ("d4" in cal.base_set.base) is free_scale
    assert err[True] > 0.5e-3
    assert err[False] < 0.1e-3
