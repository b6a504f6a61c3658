#!/usr/bin/env python
"""Benchmark: Monte Carlo throughput of ``planecal montecarlo`` (runs = rehearsal +
calibration + bounds, per second, on all cores).

    python scripts/bench_studies.py [--runs 8] [--samples 150] [--mode twin] [--jobs N]

Each run samples (default: twin mode, the sampling run's planner with collision checks
and the twin at rest per sample), calibrates from the nominal values and evaluates the
Cramer-Rao bound at the truth. Also prints the calibration-only rate (the fits alone on
the samples of one run) for scale. ``--quick`` (CI): 4 runs in the command's own process
(``--jobs 1``: no cluster to start), 5 fits. Last line, exactly:
``montecarlo_runs_per_s: X``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("MUJOCO_GL", "disable")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--samples", type=int, default=150)
    ap.add_argument("--mode", default="twin", choices=("twin", "synthetic", "rehearse"))
    ap.add_argument("--jobs", type=int, default=None)
    ap.add_argument("--quick", action="store_true", help="4 runs, --jobs 1, 5 fits (CI)")
    args = ap.parse_args()
    if args.quick:
        args.runs, args.jobs = 4, 1
    from planecal.estimation.calibrate import calibrate
    from planecal.model.scene import nominal_params
    from planecal.studies.common import cached_scene
    from planecal.studies.montecarlo import MCSettings, run_many, truth_for
    from planecal.studies.rehearsal import twin_samples

    jobs = args.jobs or (os.cpu_count() or 1)  # run_many: an Engine of this many jobs
    print(f"cpus {os.cpu_count()}, jobs {jobs}, load average {os.getloadavg()[0]:.1f}")
    st = MCSettings(samples=args.samples, runs=args.runs, mode=args.mode, seed=4242)
    t0 = time.perf_counter()
    runs = run_many(st, jobs, quiet=True)
    wall = time.perf_counter() - t0
    rate = len(runs) / wall
    print(f"{len(runs)} {args.mode} runs of {args.samples} samples in {wall:.2f} s "
          f"({wall / len(runs) * jobs:.2f} s per run per process)")
    scene = cached_scene(st.scene)
    qe, d, plate, *_ = twin_samples(scene, truth_for(st, 0), MCSettings(samples=args.samples), 7)
    n = 5 if args.quick else 20
    t0 = time.perf_counter()
    for _ in range(n):
        calibrate(scene.robot, qe, d, nominal_params(scene), plate)
    fit_s = (time.perf_counter() - t0) / n
    print(f"calibration alone: {fit_s * 1e3:.1f} ms for {args.samples} samples "
          f"({1 / fit_s:.0f} per second per process)")
    print(f"montecarlo_runs_per_s: {rate:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
