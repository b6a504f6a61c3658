"""Benchmark: planecal's Gauss-Newton (analytic Jacobian) against
scipy.optimize.least_squares with its numeric Jacobian on the same synthetic problems
(150, 1,000 and 10,000 samples on the thesis cell, 2 um noise), measured side by side.

Prints per size: both wall times, the largest difference in the identified parameters,
and the speed ratio. Last line: ``speedup_vs_scipy_1000: X``.
"""
from __future__ import annotations

import os
import time

# both solvers run under the same BLAS setting (planecal's default: one thread)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from scipy.optimize import least_squares

from planecal.cell import CellParams, predict
from planecal.fit import FitOptions, Problem, solve
from planecal.scene import load_scene, nominal_params
from planecal.synthetic import synthetic_samples
from planecal.twin.truth import draw_truth


def best_of(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def main():
    scene = load_scene("thesis_final")
    robot = scene.robot
    nominal = nominal_params(scene)
    rng = np.random.default_rng(2014)
    truth = draw_truth(scene, rng)
    opts = FitOptions(improvement_limit=1e-13)
    ratios = {}
    print(f"{'samples':>8} {'planecal_s':>11} {'scipy_s':>9} {'iters':>6} {'max|dx|_rad':>12} {'ratio':>7}")
    for n in (150, 1000, 10000):
        qe, d, _ = synthetic_samples(scene, truth, n, rng, noise_m=2e-6)

        problem = Problem.from_arrays(robot, qe, d, nominal, options=opts)
        layout, free = problem.layout, problem.free
        x0 = nominal.to_vector(layout)

        def ours():  # the problem built from the arrays, as every caller does, and solved
            return solve(Problem.from_arrays(robot, qe, d, nominal, options=opts))

        def residual(xf):
            x = x0.copy()
            x[free] = xf
            return predict(robot, qe, CellParams.from_vector(x, layout)) - d

        def theirs():
            return least_squares(residual, x0[free], jac="2-point", method="trf",
                                 xtol=1e-15, ftol=1e-15, gtol=1e-15, x_scale="jac")

        repeat = 5 if n <= 1000 else 2
        t_ours, res = best_of(ours, repeat)
        t_sp, sp = best_of(theirs, repeat)
        diff = dict(zip(layout.names_of(free), np.abs(res.params.to_vector(layout)[free] - sp.x)))
        offsets_diff = max(diff[n] for n in ("delta2", "delta3", "delta4", "delta5"))
        ratios[n] = t_sp / t_ours
        print(f"{n:>8} {t_ours:>11.4f} {t_sp:>9.4f} {res.iterations:>6} {offsets_diff:>12.2e} {ratios[n]:>7.1f}")
        assert offsets_diff < 1e-9, f"solutions differ by {offsets_diff:.3e} rad at n={n}"
    print(f"speedup_vs_scipy_1000: {ratios[1000]:.1f}")


if __name__ == "__main__":
    main()
