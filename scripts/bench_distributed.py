#!/usr/bin/env python
"""Benchmark: the same Monte Carlo runs in this process (``Engine(jobs=1)``) and on the
default in-process LocalCluster (``Engine()``: one worker process per core), side by side.

    python scripts/bench_distributed.py [--runs 40] [--samples 150] [--mode twin]
                                        [--scene thesis_final] [--jobs N]

Each run is ``studies.montecarlo.run_one`` (twin mode: the sampling run's planner with
collision checks, the twin at rest per sample, a calibration, the bounds at the truth).
Both engines warm up first (``warm_twin``: imports, the numba tick loaded from its cache),
timed apart; the throughput is runs over the map's wall time. The results must be
identical (every field, arrays bitwise), or the script fails. The machine's load average
is printed before and after: on a shared machine the ratio means little without it.
Last line, exactly: ``distributed_speedup: X`` (map throughput, cluster over jobs=1;
issue 15's target: >= 1.7 on 2 cores).
"""
from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import time

os.environ.setdefault("MUJOCO_GL", "disable")


def same(a: list, b: list) -> bool:
    import numpy as np
    for ra, rb in zip(a, b):
        for k in ra:
            va, vb = ra[k], rb[k]
            if isinstance(va, np.ndarray):
                if va.dtype != vb.dtype or va.shape != vb.shape or va.tobytes() != vb.tobytes():
                    return False
            elif json.dumps(va) != json.dumps(vb):
                return False
    return len(a) == len(b)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--samples", type=int, default=150)
    ap.add_argument("--mode", default="twin", choices=("twin", "synthetic", "rehearse"))
    ap.add_argument("--scene", default="thesis_final")
    ap.add_argument("--jobs", type=int, default=None, help="cluster workers (default: cores)")
    args = ap.parse_args()
    from planecal.studies.distributed import Engine, warm_twin
    from planecal.studies.montecarlo import MCSettings, run_one

    st = MCSettings(scene=args.scene, samples=args.samples, runs=args.runs, mode=args.mode,
                    seed=4242)
    items = [(st, k) for k in range(st.runs)]
    warm = functools.partial(warm_twin, args.scene)
    print(f"cpus {os.cpu_count()}, load average {os.getloadavg()[0]:.2f} (1 min) before; "
          f"{args.runs} {args.mode} runs of {args.samples} samples on {args.scene}")
    out = {}
    for label, kw in (("jobs=1", {"jobs": 1}), ("LocalCluster", {"jobs": args.jobs})):
        t0 = time.perf_counter()
        with Engine(warmup=warm, **kw) as eng:
            t1 = time.perf_counter()
            res = eng.map(run_one, items)
            t2 = time.perf_counter()
            desc = eng.describe()
        t3 = time.perf_counter()
        out[label] = (res, t2 - t1, t3 - t0)
        print(f"{label:>12}: {desc}; start + warm-up {t1 - t0:.2f} s, map {t2 - t1:.2f} s "
              f"({args.runs / (t2 - t1):.3f} runs/s), close {t3 - t2:.2f} s; "
              f"load average {os.getloadavg()[0]:.2f}")
    (r1, m1, w1), (r2, m2, w2) = out["jobs=1"], out["LocalCluster"]
    if not same(r1, r2):
        print("the two engines gave different results", file=sys.stderr)
        return 1
    print("results identical (every field, arrays bitwise)")
    print(f"whole map incl. start, warm-up and close: x{w1 / w2:.2f}")
    print(f"distributed_speedup: {m1 / m2:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
