#!/usr/bin/env python
"""The speed benchmarks' quick modes, one after the other, for CI (``.ci/run`` after the
tests, when numba's and the shape caches are warm): each one's ``name: X`` lines, prefixed
by the benchmark, so a regression shows in CI's output. About 40 s on an idle 2-core
machine; the figures are one run's (the full benchmarks take medians, see each script).

    python scripts/bench_quick.py [--only rehearse,calibrate,...] [--timeout-s 120]

Run here: ``bench_rehearse`` (``rehearsal_speedup``, ``rehearse_command_s``),
``bench_calibrate``, ``bench_twin``, ``bench_studies`` (each with ``--quick``). Not run
(minutes to hours; studies of accuracy, not speed): bench_collision, bench_distributed,
bench_drift_check, bench_robot_time, bench_table9.

Exit 1 when a benchmark fails (an exception, a wrong exit); a benchmark that runs out of
its time (a loaded machine) is reported and does not fail: figures never gate CI.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
QUICK = ("rehearse", "calibrate", "twin", "studies")
KEY = re.compile(r"^[a-z][a-z0-9_]*: \S")


def run(name: str, timeout_s: float) -> bool:
    """One benchmark's quick mode; prints its key lines. False when it failed."""
    argv = [sys.executable, str(HERE / f"bench_{name}.py"), "--quick"]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(argv, capture_output=True, text=True, timeout=timeout_s,
                           env=dict(os.environ, MUJOCO_GL="disable"))
    except subprocess.TimeoutExpired:
        print(f"bench_{name}: not finished in {timeout_s:.0f} s (a loaded machine?)", flush=True)
        return True
    wall = time.perf_counter() - t0
    keys = [line for line in p.stdout.splitlines() if KEY.match(line)]
    for line in keys:
        print(f"bench_{name} {line}")
    if p.returncode != 0:
        print(f"bench_{name}: FAILED (exit {p.returncode})")
        print("\n".join((p.stderr or p.stdout).splitlines()[-15:]))
        return False
    print(f"bench_{name}: {len(keys)} figures in {wall:.1f} s", flush=True)
    return True


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(QUICK), help="benchmarks to run, by name")
    ap.add_argument("--timeout-s", type=float, default=120.0, help="per benchmark")
    args = ap.parse_args()
    names = [n for n in args.only.split(",") if n]
    unknown = sorted(set(names) - set(QUICK))
    if unknown:
        ap.error(f"no quick mode: {', '.join(unknown)} (quick: {', '.join(QUICK)})")
    print(f"benchmarks (quick): cpus {os.cpu_count()}, load average "
          f"{os.getloadavg()[0]:.1f}", flush=True)
    ok = [run(n, args.timeout_s) for n in names]
    print(f"benchmarks (quick): load average after {os.getloadavg()[0]:.1f}")
    return 0 if all(ok) else 1


if __name__ == "__main__":
    sys.exit(main())
