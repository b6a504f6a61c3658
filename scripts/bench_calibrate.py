"""Benchmark: planecal's calibration (``estimation.calibrate.calibrate``, the path every
command and study takes: the base-set selection and the Gauss-Newton fit with the analytic
Jacobian) against scipy.optimize.least_squares with its numeric Jacobian on the same
synthetic problems (150, 1,000 and 10,000 samples on the thesis cell, 2 um noise), measured
side by side; scipy evaluates the same model function (``model.measurement.predict``).

Prints per size: both wall times, the largest difference in the identified parameters,
and the speed ratio: ``speedup_vs_scipy_1000: X``.

Level 2 (issue 13), on the three-plate cell with a truth whose every geometric parameter
is off (the realistic profile's tolerances, drawn here): ``calibrate(...,
CalibrationSettings(level="full"))`` (the base-set selection included) against scipy's
least_squares on the same base set (handed to it), once with its numeric Jacobian
("2-point") and once given planecal's analytic Jacobian, side by side on 1,000 samples;
then planecal alone on 10,000. Lines: ``level2_speedup_vs_scipy_numeric: X`` (target
>= 10), ``level2_vs_scipy_analytic: X`` (>= 1), ``level2_10k_s: X`` (< 0.5).

Level 3 (issue 22): a fit of 10,000 samples on three_plates with every level-3 term and
the scene's known length: ``level3_10k_s: X`` (< 0.5); the families chosen by held-out
prediction are in it (issue 31: closed-form refits, ``estimation.selection``).

What a user waits for after ``planecal calibrate`` of 150 samples at the default level
(issue 31): the fit, its verdict (the reference model, the simpler levels, the band) and
its accuracy figures and result document: ``calibrate_150_default_s: X`` (< 1).

One pose's flange and geometric Jacobian (``model.kinematics.fk_jacobian``, what IK,
planning and compensation's Newton steps pay per pose): ``fk_jacobian_one_pose_us: X``
(target < 20). Times are CPU times (``best_of``); report them with ``uptime``.
``--quick`` (CI): 150 and 1,000 samples, best of 2, the level 2 lines, and level 3 on
2,000 samples (``level3_2k_s``: drawing 10,000 level-3 samples takes 10 s).
"""
from __future__ import annotations

import os
import sys
import time

# both solvers run under the same BLAS setting (planecal's default: one thread)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from scipy.optimize import least_squares

from planecal.estimation.calibrate import CalibrationSettings, calibrate
from planecal.estimation.fit import FitOptions
from planecal.model.cell_params import CellParams
from planecal.model.measurement import predict
from planecal.model.scene import load_scene, nominal_params
from planecal.twin.synthetic import synthetic_samples
from planecal.twin.truth import draw_truth


def best_of(fn, repeat):
    """The least CPU time of ``repeat`` calls (and the last result). Both solvers run on
    one thread (one BLAS thread, numba's kernels serial), so on an idle machine this is
    their wall time; on a shared one it leaves out the time other processes took."""
    times, out = [], None
    for _ in range(repeat):
        t = time.process_time()
        out = fn()
        times.append(time.process_time() - t)
    return min(times), out


QUICK = "--quick" in sys.argv[1:]


def reps(n: int) -> int:
    """Best of n, or of 2 with --quick."""
    return min(n, 2) if QUICK else n


def main():
    quick = QUICK
    scene = load_scene("thesis_final")
    robot = scene.robot
    nominal = nominal_params(scene)
    rng = np.random.default_rng(2014)
    truth = draw_truth(scene, rng)
    opts = FitOptions(improvement_limit=1e-13)
    ratios = {}
    print(f"{'samples':>8} {'planecal_s':>11} {'scipy_s':>9} {'iters':>6} {'max|dx|_rad':>12} {'ratio':>7}")
    for n in (150, 1000) if quick else (150, 1000, 10000):
        qe, d, _ = synthetic_samples(scene, truth, n, rng, noise_m=2e-6)

        settings = CalibrationSettings(options=opts)

        def ours():  # the calibration every command takes
            return calibrate(robot, qe, d, nominal, None, settings).result

        first = ours()
        layout, free = first.layout, first.free
        x0 = nominal.to_vector(layout)

        def residual(xf):
            x = x0.copy()
            x[free] = xf
            return predict(robot, qe, CellParams.from_vector(x, layout)) - d

        def theirs():
            return least_squares(residual, x0[free], jac="2-point", method="trf",
                                 xtol=1e-15, ftol=1e-15, gtol=1e-15, x_scale="jac")

        repeat = reps(5 if n <= 1000 else 2)
        t_ours, res = best_of(ours, repeat)
        t_sp, sp = best_of(theirs, repeat)
        diff = dict(zip(layout.names_of(free), np.abs(res.params.to_vector(layout)[free] - sp.x)))
        offsets_diff = max(diff[n] for n in ("delta2", "delta3", "delta4", "delta5"))
        ratios[n] = t_sp / t_ours
        print(f"{n:>8} {t_ours:>11.4f} {t_sp:>9.4f} {res.iterations:>6} {offsets_diff:>12.2e} {ratios[n]:>7.1f}")
        assert offsets_diff < 1e-9, f"solutions differ by {offsets_diff:.3e} rad at n={n}"
    print(f"speedup_vs_scipy_1000: {ratios[1000]:.1f}")
    level2()
    level3()
    default_150()
    one_pose(robot)


def default_150():
    """One calibration of 150 samples at the default level as ``planecal calibrate`` makes
    it (thesis_final, a realistic truth's cell with 2 um noise): the fit, the verdict, the
    accuracy figures and the result document."""
    from planecal.estimation.accuracy import accuracy
    from planecal.estimation.reference import BUILT as reference_cache
    from planecal.present.calibration import document

    scene = load_scene("thesis_final")
    robot = scene.robot
    rng = np.random.default_rng(31)
    qe, d, plate = synthetic_samples(scene, draw_truth(scene, rng), 150, rng, noise_m=2e-6)

    def user_sees():
        reference_cache.clear()  # a command calibrates once: no reference of an earlier fit
        cal = calibrate(robot, qe, d, nominal_params(scene), plate, CalibrationSettings())
        return document(cal, robot, accuracy(robot, cal, qe, d, plate))
    user_sees()  # the compiled kernels and the hull cache warm, as in any later command
    t, doc = best_of(user_sees, 3)
    print(f"default level, thesis_final, 150 samples: verdict {doc['verdict']['grade']}, "
          f"tool {doc['verdict']['tool_mm']:.3f} mm")
    print(f"calibrate_150_default_s: {t:.3f}")


def one_pose(robot):
    """Level 3 (issue 22): a fit of 10,000 samples on three_plates with every level-3 term and
the scene's known length: ``level3_10k_s: X`` (< 0.5); the families chosen by held-out
prediction are in it (issue 31: closed-form refits, ``estimation.selection``).

What a user waits for after ``planecal calibrate`` of 150 samples at the default level
(issue 31): the fit, its verdict (the reference model, the simpler levels, the band) and
its accuracy figures and result document: ``calibrate_150_default_s: X`` (< 1).

One pose's flange and geometric Jacobian, called one pose at a time."""
    from planecal.model.kinematics import fk_jacobian
    q = np.radians([28.7, -15.2, -44.5, -66.1, 73.3, -92.5])
    kin = robot.kinematics
    fk_jacobian(kin, q)
    n = 20000
    t, _ = best_of(lambda: [fk_jacobian(kin, q) for _ in range(n)], reps(3))
    print(f"fk_jacobian_one_pose_us: {t / n * 1e6:.2f}")


def level2():
    from planecal.estimation.calibrate import calibrate
    from planecal.model.measurement import predict_with_jacobian

    scene = load_scene("three_plates")
    robot = scene.robot
    nominal = nominal_params(scene)
    rng = np.random.default_rng(13)
    truth = draw_truth(scene, rng)
    truth.geometry = rng.normal(0.0, 1.5e-4, (6, 4))
    truth.geometry[:, 2] = 0.0
    truth.geometry[2, 2] = rng.normal(0.0, 1.5e-4)  # beta3: J2 || J3
    truth.base = np.concatenate([rng.normal(0.0, 1e-3, 3), rng.normal(0.0, 1e-3, 3)])
    opts = FitOptions(improvement_limit=1e-13)
    qe, d, plate = synthetic_samples(scene, truth, 1000, rng, noise_m=2e-6)

    full = CalibrationSettings(level="full", options=opts)

    def ours():
        return calibrate(robot, qe, d, nominal, plate, full)

    cal = ours()
    layout, free = cal.result.layout, cal.base_set.mask(cal.result.layout)
    x0 = nominal.to_vector(layout)

    def params(xf):
        x = x0.copy()
        x[free] = xf
        return CellParams.from_vector(x, layout)

    def residual(xf):
        return predict(robot, qe, params(xf), plate) - d

    def jac(xf):
        return predict_with_jacobian(robot, qe, params(xf), plate, layout)[1][:, free]

    def scipy_run(j):
        return least_squares(residual, x0[free], jac=j, method="trf", xtol=1e-15,
                             ftol=1e-15, gtol=1e-15, x_scale="jac")

    t_ours, cal = best_of(ours, reps(5))
    t_num, sp_num = best_of(lambda: scipy_run("2-point"), reps(3))
    t_an, sp_an = best_of(lambda: scipy_run(jac), reps(5))
    d_ours = predict(robot, qe, cal.params, plate)
    print(f"level 2, three_plates, 1000 samples, {int(free.sum())} base parameters of "
          f"{len(cal.base_set.free)} candidates ({cal.result.iterations} iterations)")
    print(f"{'solver':>22} {'time_s':>8} {'rms_um':>8} {'max|d-d_ours|_um':>17}")
    for name, t, sp in (("planecal (with QR)", t_ours, None), ("scipy numeric jac", t_num, sp_num),
                        ("scipy analytic jac", t_an, sp_an)):
        dd = d_ours if sp is None else predict(robot, qe, params(sp.x), plate)
        print(f"{name:>22} {t:>8.4f} {np.sqrt(np.mean((dd - d) ** 2)) * 1e6:>8.3f} "
              f"{np.abs(dd - d_ours).max() * 1e6:>17.2e}")
        # the same minimum: predictions within 1 nm (the noise is 2 um)
        assert np.abs(dd - d_ours).max() < 1e-9, name
    qe10, d10, plate10 = synthetic_samples(scene, truth, 10000, rng, noise_m=2e-6)
    t10, cal10 = best_of(lambda: calibrate(robot, qe10, d10, nominal, plate10, full), reps(3))
    print(f"level 2, 10000 samples: {t10:.4f} s, {cal10.result.iterations} iterations, "
          f"rms {cal10.result.rms_mm() * 1e3:.3f} um")
    print(f"level2_speedup_vs_scipy_numeric: {t_num / t_ours:.1f}")
    print(f"level2_vs_scipy_analytic: {t_an / t_ours:.2f}")
    print(f"level2_10k_s: {t10:.3f}")


def level3():
    """Level 3 (issue 22) on three_plates with its stepped block, 10,000 samples: a truth
    with every level-3 term drawn (the realistic profile's magnitudes), each sample's
    approach direction drawn, 2 um noise; the one calibrate with the scene's known length
    (the prior rows re-weighed until they agree with the residuals: several solves)."""
    from planecal.estimation.calibrate import calibrate
    from planecal.model.levels import layout_for

    scene = load_scene("three_plates")
    robot = scene.robot
    nominal = nominal_params(scene)
    rng = np.random.default_rng(17)
    layout = layout_for(robot, len(scene.plates), "nonkinematic")
    x = draw_truth(scene, rng).to_vector(layout)
    for g in layout.groups:
        sd = {"joint_geometry": 7e-5, "gear": 5e-5, "backlash": 1e-4, "laser": 1e-5}.get(g.kind)
        if sd:
            x[layout.slice(g.name)] += rng.normal(0.0, sd, len(g))
    x[layout.slice("compliance")] = [0, 2e-7, 3.3e-7, 0, 0, 0]
    truth = nominal.with_vector(x, layout)
    n = 2000 if QUICK else 10000
    qe, _, plate = synthetic_samples(scene, truth, n, rng)
    direction = rng.choice([-1, 1], size=qe.shape).astype(np.int8)
    d = predict(robot, qe, truth, plate, direction) + rng.normal(0.0, 2e-6, len(qe))
    st = CalibrationSettings(level="nonkinematic")
    t, cal = best_of(lambda: calibrate(robot, qe, d, nominal, plate, st, direction,
                                       scene.references), 2)
    print(f"level 3, three_plates, {n} samples: {t:.3f} s, {len(cal.base_set.base)} base "
          f"parameters, {cal.result.iterations} iterations, rms "
          f"{cal.result.rms_mm() * 1e3:.3f} um")
    print(f"level3_{n // 1000}k_s: {t:.3f}")


if __name__ == "__main__":
    main()
