#!/usr/bin/env python
"""The drift check's false-alarm rate over many calibrations (docs/HISTORY.md).

    .venv/bin/python scripts/bench_drift_check.py [--calibrations 12] [--runs 25]
        [--reference-runs 5] [--truth T.json] [--samples 150] [--short 30]

In one world of the realistic twin (a truth file, default: the realistic world of truth
seed 1), each of C calibrations (150 random samples, ``estimation.calibrate``, as
``planecal calibrate`` does) is followed by R short runs (30 random samples, set at
rest where the world allows, driven where its errors depend on the path: the studies'
rehearsal), all in control. For each calibration it prints the mean exceedance count of
its checks against (a) the calibration's residuals and (b) its first K runs (the history's
reference), against the exceedance test's expectation (14.9 for 150 / 30), and the
false-alarm rate each gives at alpha 0.01, and, for contrast, the alarms of Chow's
predictive F test (the run's errors against the calibration's residual sigma with each
pose's leverage; valid for Gaussian errors only). The spread of (a) between calibrations
is what (b) removes.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def chow_p(fr, run) -> float:
    """Chow's predictive F test of a run against a result (Gaussian errors assumed)."""
    from scipy.stats import f
    rows = fr.rows(*run)
    m = len(rows.r)
    S = fr.s2 * np.eye(m) + rows.Jf @ fr.C @ rows.Jf.T
    F = float(rows.rw @ np.linalg.solve(S, rows.rw)) / m
    return float(f.sf(F, m, fr.samples_used - len(fr.names)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calibrations", type=int, default=12)
    ap.add_argument("--runs", type=int, default=25)
    ap.add_argument("--reference-runs", type=int, default=5)
    ap.add_argument("--truth", default=None, help="a truth file (default: realistic seed 1)")
    ap.add_argument("--samples", type=int, default=150)
    ap.add_argument("--short", type=int, default=30)
    a = ap.parse_args(argv)
    from planecal.estimation.calibrate import calibrate
    from planecal.estimation.drift import FittedResult, check_run
    from planecal.model.scene import load_scene, nominal_params
    from planecal.present.calibration import document
    from planecal.studies.rehearsal import RehearsalSettings, twin_samples
    from planecal.twin.world import WorldRef

    scene = load_scene("thesis_final")
    robot = scene.robot
    ref = (WorldRef("realistic", None, a.truth) if a.truth else WorldRef("realistic", 1))
    world, opts = ref.build(scene)
    K = a.reference_runs
    totals = {"calibration": [0, 0], "runs": [0, 0], "F test": [0, 0]}
    print(f"{ref.describe()}: {a.calibrations} calibrations of {a.samples} samples, "
          f"{a.runs} runs of {a.short} each (the first {K}: the runs reference)")
    print("calib  mean X vs calibration  alarms   mean X vs runs  alarms   F test alarms  "
          "(expected X 14.9)")
    for c in range(a.calibrations):
        cal = twin_samples(scene, world, RehearsalSettings(samples=a.samples), 5000 + c,
                           opts)[:3]
        fit = calibrate(robot, *cal[:2], nominal_params(scene), cal[2])
        fr = FittedResult.of(document(fit, robot), robot, "result")
        runs = [twin_samples(scene, world, RehearsalSettings(samples=a.short),
                             6000 + 100 * c + k, opts)[:3] for k in range(a.runs)]
        out = {}
        for kind, refs in (("calibration", ()), ("runs", runs[:K])):
            checks = [check_run(fr, cal, r, 0.01, reference_runs=refs) for r in runs[K:]]
            x = np.mean([ch.test.exceed for ch in checks])
            alarms = sum(ch.drifted for ch in checks)
            totals[kind][0] += alarms
            totals[kind][1] += len(checks)
            out[kind] = (x, alarms, len(checks))
        f_alarms = sum(chow_p(fr, r) <= 0.01 for r in runs[K:])
        totals["F test"][0] += f_alarms
        totals["F test"][1] += len(runs) - K
        print(f"{c:5d}  {out['calibration'][0]:21.2f}  {out['calibration'][1]:3d}/"
              f"{out['calibration'][2]:<3d}  {out['runs'][0]:15.2f}  {out['runs'][1]:3d}/"
              f"{out['runs'][2]:<3d}  {f_alarms:6d}/{len(runs) - K}", flush=True)
    for kind, (n_alarm, n) in totals.items():
        print(f"reference {kind}: {n_alarm} false alarms in {n} checks "
              f"({n_alarm / n:.4f}; the test's stated rate at most 0.01)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
