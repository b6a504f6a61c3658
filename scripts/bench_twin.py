#!/usr/bin/env python
"""Twin throughput: ticks per wall second, as a multiple of real time (the FD11 runs 100
ticks/s). Trajectories are made before the clock starts, so only the twin is timed (the
tick: FD11 semantics, servo, rest, joint rows; the MuJoCo beams; the laser model).

Workloads on the final cell with the default options (lag servo, laser noise,
repeatability):
* moving:   the delta changes every tick, a reading every tick (every tick casts a beam);
* holding:  the robot at rest, one reading per tick (one beam in all);
* sampling: the sampling loop (seed 7.1.3) as ``planecal rehearse`` drives it: a ramp to
            a new pose at <= 50 counts/tick without reading (one ``run(read=False)``),
            then a hold of 105 ticks reading the laser (one ``run``).
Side by side: ``run`` (the compiled tick, what the sampling loop calls), ``per-tick``
(``exchange`` + ``read`` per tick: what the FD11 emulator calls) and ``reference`` (the
same tick run by the interpreter, ``Twin(..., reference_ticks=True)``, on a tenth of the
workload), in wall and in this process's CPU seconds. ``--repeat N`` keeps the best of N
(alternating); ``--quick`` (CI) runs a fifth of each workload. The last line, ``twin_realtime_factor: X``, is the sampling workload
through ``run``, wall clock.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402

from planecal.twin import Twin  # noqa: E402

TICK_HZ = 100.0


def moving_traj(base, n):
    step = np.array([1, -1, 1, 1, -1, 1], np.int64)
    signs = np.where((np.arange(n) // 200) % 2 == 0, 1, -1)[:, None]
    return base + np.cumsum(signs * step, axis=0)


def sampling_traj(base, n_samples, rng):
    """Segments as a sampler would send them: a ramp to a new pose, then a hold."""
    segments, delta = [], base.copy()
    for _ in range(n_samples):
        target = base + rng.integers(-2500, 2500, 6)
        ramp = []
        while not np.array_equal(delta, target):
            delta = delta + np.clip(target - delta, -50, 50)
            ramp.append(delta)
        segments += [np.array(ramp), np.repeat(delta[None], 105, axis=0)]
    return segments


def per_tick(twin, D):
    segments = D if isinstance(D, list) else [D]
    exchange, read = twin.exchange, twin.read
    n = sum(len(seg) for seg, _ in segments) if isinstance(D, list) else len(D)
    t0, c0 = time.perf_counter(), time.process_time()
    for seg in segments:
        rows, reading = seg if isinstance(D, list) else (seg, True)
        for d in rows:
            exchange(d)
            if reading:
                read()
    return n / (time.perf_counter() - t0), n / (time.process_time() - c0)


def batch(twin, D, chunk=1000):
    """One Twin.run per (segment, read) of a list, or per ``chunk`` ticks of one array."""
    segments = D if isinstance(D, list) else [(D[i:i + chunk], True)
                                               for i in range(0, len(D), chunk)]
    n = sum(len(seg) for seg, _ in segments)
    t0, c0 = time.perf_counter(), time.process_time()
    for seg, reading in segments:
        twin.run(seg, read=reading)
    return n / (time.perf_counter() - t0), n / (time.process_time() - c0)


def fresh(reference=False):
    twin = Twin("thesis_final", seed=1, reference_ticks=reference)
    return twin, twin.current_counts - twin.reference_counts


APIS = (("run", batch, False, 1), ("per-tick", per_tick, False, 1),
        ("reference", batch, True, 10))


def shrink(work, k):
    if k == 1:
        return work
    if isinstance(work, list):
        return work[:max(2, len(work) // k)]
    return work[:len(work) // k]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=1, help="best of N (alternating)")
    ap.add_argument("--quick", action="store_true", help="a fifth of each workload (CI)")
    args = ap.parse_args(argv)
    q = 5 if args.quick else 1
    for _, fn, ref, _ in APIS:  # warm up (numba's compile or cache load)
        twin, base = fresh(ref)
        fn(twin, moving_traj(base, 200))
    workloads = {
        "moving": lambda base: moving_traj(base, 40_000 // q),
        "holding": lambda base: np.repeat(base[None], 100_000 // q, axis=0),
        "sampling": lambda base: [(seg, i % 2 == 1) for i, seg in enumerate(
            sampling_traj(base, 250 // q, np.random.default_rng(1)))],
    }
    results = {}
    for _ in range(max(1, args.repeat)):
        for work, make in workloads.items():
            for api, fn, ref, k in APIS:
                twin, base = fresh(ref)
                wall, cpu = fn(twin, shrink(make(base), k))
                best = results.get((api, work), (0.0, 0.0))
                results[api, work] = (max(best[0], wall), max(best[1], cpu))
    print("api        workload   wall ticks/s (x real time)   cpu ticks/s (x real time)")
    for work in workloads:
        for api, *_ in APIS:
            wall, cpu = results[api, work]
            print(f"{api:10s} {work:8s} {wall:10.0f} ({wall / TICK_HZ:7.0f} x)      "
                  f"{cpu:10.0f} ({cpu / TICK_HZ:7.0f} x)")
    for work in workloads:
        for other in ("per-tick", "reference"):
            (w0, c0), (w1, c1) = results[other, work], results["run", work]
            print(f"run / {other:9s}, {work:8s}: wall {w1 / w0:6.1f}x, cpu {c1 / c0:6.1f}x")
    print(f"load average: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores "
          "(cpu = this process's CPU time; wall includes waiting for a core)")
    print(f"twin_realtime_factor: {results['run', 'sampling'][0] / TICK_HZ:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
