import numpy as np
import pytest
from scipy.optimize import least_squares

from conftest import INITIAL, perturbed, synthetic_counts
from planecal.model.cell_params import CellParams
from planecal.model.measurement import predict
from planecal.estimation.fit import FitOptions, Problem, solve
from planecal.estimation.identifiability import analyze
from planecal.model.layout import level1_layout
from planecal.model.scene import load_scene, nominal_params


@pytest.fixture(scope="module")
def problem(robot):
    rng = np.random.default_rng(11)
    truth = perturbed(INITIAL, rng)
    qe, d = synthetic_counts(robot, truth, 150, rng)
    return truth, qe, d


def test_noise_free_recovery_from_thesis_initial_values(robot, problem):
    truth, qe, d = problem
    res = solve(Problem.from_arrays(robot, qe, d, INITIAL))
    err = res.params.to_vector() - truth.to_vector()
    assert np.abs(err[1:5]).max() < 1e-9  # delta2..delta5 [rad]
    assert np.abs(err[level1_layout(1).default_free]).max() < 1e-9
    assert res.converged and res.iterations < 10
    assert res.rms_mm() < 1e-9 and res.rms_mm(initial=True) > 0.5
    assert res.identifiability.not_identifiable == []


def test_levenberg_marquardt_and_unscaled_reach_the_same_solution(robot, problem):
    truth, qe, d = problem
    for opts in (FitOptions(method="lm"), FitOptions(scale=False)):
        res = solve(Problem.from_arrays(robot, qe, d, INITIAL, options=opts))
        assert np.abs(res.params.joint_offsets - truth.joint_offsets).max() < 1e-9


def test_same_solution_as_scipy_least_squares(robot, problem):
    truth, qe, d = problem
    rng = np.random.default_rng(3)
    dn = d + rng.normal(0, 2e-6, len(d))
    layout = level1_layout(1)
    free = layout.default_free
    x0 = INITIAL.to_vector()

    def f(xf):
        x = x0.copy()
        x[free] = xf
        return predict(robot, qe, CellParams.from_vector(x, layout)) - dn

    sp = least_squares(f, x0[free], method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    res = solve(Problem.from_arrays(robot, qe, dn, INITIAL))
    np.testing.assert_allclose(res.params.to_vector()[free], sp.x, atol=1e-9)


def test_offsets_within_three_sigma_over_seeds(robot):
    """With 2 um laser noise the reported std is honest: errors within 3 sigma, and the
    normalized errors have about unit variance over seeds."""
    z = []
    for seed in range(8):
        rng = np.random.default_rng(100 + seed)
        truth = perturbed(INITIAL, rng)
        qe, d = synthetic_counts(robot, truth, 150, rng)
        res = solve(Problem.from_arrays(robot, qe, d + rng.normal(0, 2e-6, len(d)), INITIAL))
        zs = (res.params.joint_offsets - truth.joint_offsets)[1:5] / res.std[1:5]
        assert np.all(np.abs(zs) < 3.5), zs
        assert 1.4e-6 < res.sigma_m < 2.6e-6
        z.extend(zs)
    assert 0.4 < np.std(z) < 1.6


def test_outliers_are_dropped_and_named(robot, problem):
    truth, qe, d = problem
    rng = np.random.default_rng(4)
    dn = d + rng.normal(0, 2e-6, len(d))
    dn[[7, 42]] += 0.5e-3  # two 0.5 mm blunders
    res = solve(Problem.from_arrays(robot, qe, dn, INITIAL, options=FitOptions(outlier_sigma=4)))
    assert res.outliers == [7, 42]
    assert res.used.sum() == len(d) - 2
    assert np.abs(res.params.joint_offsets - truth.joint_offsets).max() < 1e-4
    assert res.rms_mm() < 0.004


def test_freed_delta1_delta6_are_named_not_numbered(robot, problem):
    truth, qe, d = problem
    res = solve(Problem.from_arrays(robot, qe, d, INITIAL, free=np.ones(14, bool)))
    ni = res.identifiability.not_identifiable
    assert "delta1" in ni and "delta6" in ni
    assert np.isnan(res.std[0]) and np.isnan(res.std[5])
    dirs = res.identifiability.unidentifiable_directions
    mixes = [set(d) for d in dirs]
    assert any("delta6" in m and "phi_z" in m for m in mixes)  # roll of the sensor
    assert any("delta1" in m and ({"n1_x", "n1_y"} & m) for m in mixes)  # plane about base z
    # the identifiable offsets are still right
    assert np.abs(res.params.joint_offsets[1:5] - truth.joint_offsets[1:5]).max() < 1e-9


def test_several_planes_share_robot_and_sensor(robot):
    rng = np.random.default_rng(7)
    nominal = CellParams(np.zeros(6), INITIAL.sensor_origin, INITIAL.phi_y, INITIAL.phi_z,
                         [[0, -1.02511, 3.62708], [0.3, -0.9, 3.2]])
    truth = perturbed(nominal, rng)
    qe0, d0 = synthetic_counts(robot, truth, 80, rng, plane=0)
    qe1, d1 = synthetic_counts(robot, truth, 80, rng, plane=1)
    qe = np.vstack([qe0, qe1])
    d = np.concatenate([d0, d1])
    pidx = np.r_[np.zeros(len(d0), int), np.ones(len(d1), int)]
    res = solve(Problem.from_arrays(robot, qe, d, nominal, pidx))
    assert np.abs(res.params.to_vector() - truth.to_vector())[level1_layout(2).default_free].max() < 1e-9
    assert len(res.names) == 17


def test_max_iter_reports_not_converged(robot, problem):
    truth, qe, d = problem
    res = solve(Problem.from_arrays(robot, qe, d, INITIAL, options=FitOptions(max_iter=1)))
    assert res.iterations == 1 and not res.converged and res.notes


def test_too_few_samples(robot, problem):
    _, qe, d = problem
    with pytest.raises(ValueError, match="cannot determine 12 free parameters"):
        solve(Problem.from_arrays(robot, qe[:12], d[:12], INITIAL))


def test_scene_nominal_values_are_thesis_initial_values():
    p = nominal_params(load_scene())
    np.testing.assert_array_equal(p.to_vector(), INITIAL.to_vector())


def _scene_problem(name, n, seed, **pose):
    from planecal.sampling.poses import PoseSettings
    from planecal.twin.synthetic import synthetic_samples
    from planecal.twin.truth import draw_truth
    scene = load_scene(name)
    nominal = nominal_params(scene)
    settings = PoseSettings(**{"cone_deg": scene.cone_deg,
                               "distance_mm": tuple(scene.distance_mm), **pose})
    rng = np.random.default_rng(seed)
    truth = draw_truth(scene, seed)
    qe, d, plate = synthetic_samples(scene, truth, n, rng, noise_m=2e-6, settings=settings)
    return scene, nominal, truth, qe, d, plate


def test_fixed_perpendicular_orientation_cannot_see_the_beam_angles(robot):
    """Seed 8.2, 'random orientation OFF': with the beam always along the plate normal the
    beam angles do not change any distance (first order); the analysis must say so."""
    scene, nominal, truth, qe, d, plate = _scene_problem("thesis_final", 60, 4, cone_deg=0.0)
    # at the nominal values every beam is exactly perpendicular to the (nominal) plate
    ident, cov = analyze(robot, qe, nominal, plate)
    # not exactly zero columns: whole encoder counts tilt each beam by ~1e-5 rad
    poor = {p.parameter: p.std for p in ident.poorly_determined}
    assert poor["phi_y"] > 0.05 and poor["phi_z"] > 0.05
    assert {"phi_y", "phi_z"} <= set(ident.not_identifiable)
    assert np.isnan(cov.std("phi_y")) and np.isnan(cov.std("phi_z"))
    # with the default 30 deg cone they are identified
    scene, nominal, truth, qe, d, plate = _scene_problem("thesis_final", 60, 4)
    ident, cov = analyze(robot, qe, nominal, plate)
    assert ident.not_identifiable == [] and all(cov.std(n) < 1e-3 for n in ("phi_y", "phi_z"))


def test_parallel_plate_delta1_has_no_effect(robot):
    """Seed appendix D: with the plate parallel to the base a base rotation (delta1) moves
    no distance at all — a zero Jacobian column, named as such — while with the tilted
    final plate delta1 mixes with the plane's rotation about the base z axis."""
    scene, nominal, truth, qe, d, plate = _scene_problem("appendix_d", 80, 5)
    free = np.ones(14, bool)
    free[5] = False
    ident, _ = analyze(robot, qe, nominal, plate, free)  # at the exactly parallel nominal plate
    assert ident.no_effect == ["delta1"] and "delta1" in ident.not_identifiable
    assert {"delta1": 1.0} in ident.unidentifiable_directions or \
        {"delta1": -1.0} in ident.unidentifiable_directions
    scene, nominal, truth, qe, d, plate = _scene_problem("thesis_final", 80, 5)
    ident, _ = analyze(robot, qe, nominal, plate, free)
    assert "delta1" not in ident.no_effect and "delta1" in ident.not_identifiable
    assert any("delta1" in d and "n1_x" in d for d in ident.unidentifiable_directions)


# ----- weighted fit (heteroscedastic repeatability noise) ----------------------------------

@pytest.fixture(scope="module")
def three_plate_design():
    """150 fixed poses round robin on the three-plate cell, the truth, the repeatability's
    joint std and the noise-free joint angles. The design of docs/STUDIES.md's three-plate
    study: any roll about the beam, IK nearest (pinned: the run's defaults changed)."""
    from planecal.model.encoder import counts_to_joints
    from planecal.estimation.noise import repeatability_sigma
    from planecal.sampling.poses import PoseSettings
    from planecal.twin.synthetic import synthetic_samples
    from planecal.twin.truth import draw_truth
    from dataclasses import replace
    scene = load_scene("three_plates")  # its three plates, without the stepped block
    scene = replace(scene, plates=scene.plates[:3], references=())
    truth = draw_truth(scene, 3)
    pose = PoseSettings(cone_deg=scene.cone_deg, distance_mm=tuple(scene.distance_mm),
                        roll_deg=180.0, ik_choice="nearest")
    qe, _, plate = synthetic_samples(scene, truth, 150, np.random.default_rng(5), settings=pose)
    return scene, truth, qe, plate, repeatability_sigma(scene.robot), \
        counts_to_joints(scene.robot, qe)


def _measure(scene, truth, q0, plate, s, rng, laser_m=1e-7):
    """Distances with the robot's repeatability (joints ~ N(0, s^2) per sample) + laser."""
    from planecal.model.measurement import plane_distance, sensor_in_base
    o, z = sensor_in_base(scene.robot, q0 + rng.normal(0.0, s, q0.shape), truth)
    return plane_distance(truth.planes[plate], o, z) + rng.normal(0.0, laser_m, len(q0))


def test_weighted_fit_is_the_fixed_point_of_scipy_with_its_weights(three_plate_design):
    # iteratively reweighted: at the solution, x minimises sum (w_i r_i)^2 with the w_i
    # of the solution; scipy's least_squares with those weights held finds the same x
    from planecal.estimation.noise import row_weights
    from planecal.model.measurement import predict_with_jacobian
    scene, truth, qe, plate, s, q0 = three_plate_design
    d = _measure(scene, truth, q0, plate, s, np.random.default_rng(1))
    opts = FitOptions(joint_sigma_rad=s, distance_sigma_m=1e-7)
    init = nominal_params(scene)
    res = solve(Problem.from_arrays(scene.robot, qe, d, init, plate, options=opts))
    _, J = predict_with_jacobian(scene.robot, qe, res.params, plate)
    w = row_weights(J[:, res.layout.slice("joint_offsets")], opts.joint_sigma_rad,
                    opts.distance_sigma_m)
    free = res.free
    x0 = init.to_vector()

    def f(xf):
        x = x0.copy()
        x[free] = xf
        return (predict(scene.robot, qe, CellParams.from_vector(x, res.layout), plate) - d) * w
    sp = least_squares(f, x0[free], method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert np.abs(sp.x[:4] - res.params.to_vector()[1:5]).max() < 1e-10  # delta2..5 [rad]
    assert np.abs(sp.x - res.params.to_vector()[free]).max() < 1e-8
    unweighted = solve(Problem.from_arrays(scene.robot, qe, d, init, plate))
    assert np.abs(unweighted.params.to_vector()[1:5] - res.params.to_vector()[1:5]).max() > 1e-7
    assert res.identifiability.weighted and not unweighted.identifiability.weighted


def test_weighted_fit_reports_honest_std_where_the_unweighted_does_not(three_plate_design):
    # 200 noise draws on one design: the spread of the errors against the std the fit
    # reports (a std from 200 draws is known to +-5 %, 1 s.e.). With the repeatability
    # projected on the beam the noise is heteroscedastic: the unweighted fit's white-noise
    # covariance misjudges delta3 by ~20 %; the weighted one is honest, reaches the
    # Cramer-Rao bound and finds the noise level (variance factor ~1)
    from planecal.model.measurement import predict_with_jacobian
    from planecal.estimation.noise import noise_variance
    scene, truth, qe, plate, s, q0 = three_plate_design
    rng = np.random.default_rng(7)
    init = nominal_params(scene)
    free = level1_layout(truth.n_planes).default_free
    want = truth.to_vector()[free][:4]  # delta2..delta5
    err = {"u": [], "w": []}
    rep = {"u": [], "w": []}
    vf = []
    for _ in range(200):
        d = _measure(scene, truth, q0, plate, s, rng)
        for key, opts in (("u", FitOptions()),
                          ("w", FitOptions(joint_sigma_rad=s, distance_sigma_m=1e-7))):
            res = solve(Problem.from_arrays(scene.robot, qe, d, init, plate, options=opts))
            err[key].append(res.params.to_vector()[free][:4] - want)
            rep[key].append(res.std[free][:4])
            if key == "w":
                vf.append(res.identifiability.variance_factor)
    _, J = predict_with_jacobian(scene.robot, qe, truth, plate)
    Jf = J[:, free]
    crb = np.sqrt(np.diag(np.linalg.inv(Jf.T @ (Jf / noise_variance(J[:, :6], s, 1e-7)[:, None]))))[:4]
    emp = {k: np.std(err[k], axis=0) for k in err}
    ratio = {k: emp[k] / np.sqrt(np.mean(np.square(rep[k]), axis=0)) for k in err}
    assert np.all(np.abs(ratio["w"] - 1) < 0.15), ratio["w"]
    assert np.all(np.abs(emp["w"] / crb - 1) < 0.15), emp["w"] / crb
    assert abs(np.mean(vf) - 1) < 0.05
    assert ratio["u"][1] > 1.12  # delta3: the unweighted fit reports too small a std
    assert emp["w"][1] < emp["u"][1]  # and the weighted fit's delta3 is better


def test_sigma_counts_only_the_identifiable_directions(robot, problem):
    # everything free: two directions (delta1, delta6 with their partners) are not
    # identifiable, the fit moves rank = p - 2 directions, and sigma^2 = |r|^2/(m - rank);
    # analyze() with a known sigma predicts exactly sigma sqrt(diag((J^T J)^-1))
    from planecal.model.measurement import predict_with_jacobian
    truth, qe, d = problem
    dn = d + np.random.default_rng(4).normal(0, 2e-6, len(d))
    everything = np.ones(len(INITIAL.to_vector()), bool)
    res = solve(Problem.from_arrays(robot, qe, dn, INITIAL, free=everything))
    rank = res.identifiability.rank
    assert rank == everything.sum() - 2
    r = res.residuals_m
    assert res.sigma_m == pytest.approx(np.sqrt(r @ r / (len(r) - rank)), rel=1e-12)
    ident, cov = analyze(robot, qe, truth, sigma_m=2e-6)
    _, J = predict_with_jacobian(robot, qe, truth)
    Jf = J[:, level1_layout(1).default_free]
    want = 2e-6 * np.sqrt(np.diag(np.linalg.inv(Jf.T @ Jf)))
    np.testing.assert_allclose(cov.stds, want, rtol=1e-6)
    assert ident.sigma_mm == pytest.approx(2e-3)


# ----- the typed problem and result ---------------------------------------------------------

@pytest.fixture(scope="module")
def two_plane_problem(robot):
    rng = np.random.default_rng(17)
    nominal = CellParams(np.zeros(6), INITIAL.sensor_origin, INITIAL.phi_y, INITIAL.phi_z,
                         [[0, -1.02511, 3.62708], [0.3, -0.9, 3.2]])
    truth = perturbed(nominal, rng)
    qe0, d0 = synthetic_counts(robot, truth, 70, rng, plane=0)
    qe1, d1 = synthetic_counts(robot, truth, 70, rng, plane=1)
    qe = np.vstack([qe0, qe1])
    d = np.concatenate([d0, d1]) + rng.normal(0, 2e-6, len(d0) + len(d1))
    plate = np.r_[np.zeros(len(d0), int), np.ones(len(d1), int)]
    return Problem.from_arrays(robot, qe, d, nominal, plate,
                               options=FitOptions(improvement_limit=1e-14))


def test_solve_matches_scipy_least_squares_by_name(two_plane_problem):
    # the same problem given to scipy, with the model's analytic Jacobian and with scipy's
    # own finite differences: the same minimum, parameter by parameter (the solver loop,
    # scaling and masks checked); the same cost; and the covariance sigma^2 (J^T J)^-1 from
    # scipy's numeric Jacobian at its solution.
    # Tolerances from the problem's conditioning, not from one machine's last digits: two
    # minimisers of one cost differ along its flat directions by what the cost cannot
    # resolve, so each parameter is compared in units of its own standard error (the
    # distance noise through (J^T J)^-1). With the analytic Jacobian they agree to 2e-8 of
    # it (the predicted distances to 2e-9 of the noise: femtometres); bounds 1e-6 and 1e-7.
    # scipy's numeric Jacobian resolves the minimum to ~2e-6 of it (forward differences);
    # bound 1e-4.
    from planecal.model.measurement import predict_with_jacobian
    pb = two_plane_problem
    L, free = pb.layout, pb.free
    x0 = pb.initial.to_vector(L)

    def params(xf):
        x = x0.copy()
        x[free] = xf
        return CellParams.from_vector(x, L)

    def f(xf):
        return predict(pb.robot, pb.qe, params(xf), pb.plate) - pb.d_m

    def jac(xf):
        return predict_with_jacobian(pb.robot, pb.qe, params(xf), pb.plate, L)[1][:, free]

    tight = dict(method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    sp_a = least_squares(f, x0[free], jac=jac, **tight)
    sp = least_squares(f, x0[free], **tight)
    res = solve(pb)
    assert res.converged and res.outliers == [] and res.used.all()
    got = res.params.to_vector(L)
    std = res.covariance.stds
    assert np.all(np.isfinite(std)) and np.all(std > 0)
    for name, want_a, want, sd in zip(L.names_of(free), sp_a.x, sp.x, std):
        x = got[L.index(name)]
        assert abs(x - want_a) < 1e-6 * sd, (name, (x - want_a) / sd)
        assert abs(x - want) < 1e-4 * sd, (name, (x - want) / sd)
    dx = got[free] - sp_a.x  # the same predicted distances, to far below the noise
    assert np.sqrt(np.mean((jac(got[free]) @ dx) ** 2)) < 1e-7 * res.sigma_m
    xf = got[free]
    S = np.linalg.norm(jac(xf), axis=0)
    assert np.abs(jac(xf).T @ f(xf) / S).max() <= np.abs(jac(sp.x).T @ f(sp.x) / S).max()
    for name in L.names_of(~free):  # delta1, delta6 stay where they were
        assert got[L.index(name)] == x0[L.index(name)]
    assert res.initial_cost == pytest.approx(0.5 * np.sum(f(x0[free]) ** 2), rel=1e-12)
    assert res.final_cost == pytest.approx(sp_a.cost, rel=1e-10)
    assert res.final_cost < 1e-3 * res.initial_cost
    m, p = len(pb), int(free.sum())
    cov_sp = 2 * sp.cost / (m - p) * np.linalg.inv(sp.jac.T @ sp.jac)
    assert res.covariance.names == tuple(L.names_of(free))
    np.testing.assert_allclose(res.covariance.matrix, cov_sp, rtol=1e-4,
                               atol=1e-6 * np.abs(cov_sp).max())
    for j, name in enumerate(res.covariance.names):
        assert res.covariance.std(name) == pytest.approx(np.sqrt(cov_sp[j, j]), rel=1e-4)
        assert res.std[L.index(name)] == res.covariance.std(name)
    assert np.isnan(res.std[L.index("delta1")]) and np.isnan(res.std[L.index("delta6")])


def test_covariance_and_identifiability_are_typed_and_agree(two_plane_problem):
    from dataclasses import asdict
    res = solve(two_plane_problem)
    cov, ident = res.covariance, res.identifiability
    C = cov.correlation()
    np.testing.assert_allclose(np.diag(C), 1.0, rtol=1e-12)
    np.testing.assert_allclose(C, C.T, rtol=1e-12)
    pairs = cov.correlated_pairs(0.5)
    want = {(a, b) for i, a in enumerate(cov.names) for j, b in enumerate(cov.names)
            if i < j and abs(C[i, j]) > 0.5}
    assert {(pr.a, pr.b) for pr in pairs} == want and want
    for pr in pairs:
        assert pr.rho == round(C[cov.index(pr.a), cov.index(pr.b)], 5)
    assert ident.correlated_pairs == cov.correlated_pairs(FitOptions().correlation_limit)
    d = asdict(ident)  # the result file's object: today's keys, in today's order
    assert list(d) == ["free", "not_identifiable", "no_effect", "poorly_determined",
                       "unidentifiable_directions", "weak_directions", "correlated_pairs",
                       "singular_values", "scaled_singular_values", "condition_number_scaled",
                       "observability", "sigma_mm", "samples", "rank",
                       "identifiable_min_scaled_ratio", "weighted", "variance_factor",
                       "mismatch_inflated", "residual_over_noise"]
    assert list(d["observability"]) == ["O1", "O2", "O3", "O4"]
    assert d["free"] == list(cov.names) and d["samples"] == len(two_plane_problem)
    assert d["rank"] == len(cov.names) and d["sigma_mm"] == pytest.approx(res.sigma_m * 1e3)
    with pytest.raises(KeyError, match="not a free parameter"):
        cov.std("delta1")
    out = cov.to_dict()
    assert out["names"] == list(cov.names) and len(out["matrix"]) == len(cov.names)
    assert out["matrix"][0][0] == pytest.approx(cov.matrix[0, 0])


def test_problem_from_samples_and_its_checks(robot, problem, tmp_path):
    from planecal.base.errors import InputError
    from planecal.io.samples import read_samples, write_samples
    truth, qe, d = problem
    f = tmp_path / "s.tsv"
    write_samples(f, qe, d * 1e3)
    s = read_samples(f)
    pb = Problem.from_samples(robot, s, INITIAL, free="delta2,delta3,o_x")
    assert pb.free_names == ["delta2", "delta3", "o_x"] and pb.qe.dtype == np.int64
    np.testing.assert_allclose(pb.d_m, d, atol=1e-9)  # mm in the file (6 decimals), m here
    assert len(pb.subset(np.arange(10))) == 10
    with pytest.raises(InputError, match="--free: unknown parameter 'n2_x'"):
        Problem.from_samples(robot, s, INITIAL, free=["n2_x"])
    with pytest.raises(ValueError, match="refer to plate 2, parameters hold 1"):
        Problem.from_arrays(robot, qe, d, INITIAL, np.ones(len(d), int))
    with pytest.raises(ValueError, match="free mask"):
        Problem.from_arrays(robot, qe, d, INITIAL, free=np.ones(17, bool))
    with pytest.raises(ValueError, match="do not match"):
        Problem.from_arrays(robot, qe[:-1], d, INITIAL)
