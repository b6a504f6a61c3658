#!/usr/bin/env python
"""Twin throughput: ticks (exchange + laser read) per wall second, as a multiple of real
time (the FD11 runs 100 ticks/s). Trajectories are made before the clock starts, so only
the twin is timed (counts -> joints, MuJoCo kinematics, ray, laser model).

Workloads on the final cell with the default options (lag servo, laser noise,
repeatability):
* moving:   the delta changes every tick: every tick recomputes joints, kinematics, ray;
* holding:  the robot at rest, one reading per tick (kinematics and ray are cached);
* sampling: the thesis' sampling loop (7.1.3): ramp to a new pose at <= 50 counts/tick,
            then hold for 105 ticks while 100 readings fill the buffer (the batch API
            gets one ``run`` call per ramp and one per hold, as a sampler would).
Each through the per-tick API (``exchange`` + ``read``, what the sampling loop calls)
and through the batch API (``Twin.run``), timed in wall seconds and in this process's
CPU seconds (on a shared machine the two differ). ``Twin.run`` twice, side by side:
``batch-mj`` with ``Twin.batch_rays = False`` (``Twin._run_ref``: the tick logic in numpy,
one ``mj_kinematics`` + ``mj_ray`` per moving tick through the Python bindings; the
reference) and ``batch`` (the default: the tick loop compiled with numba, ``twin.ticks``,
and all moving ticks of a call cast in one MuJoCo call, ``twin.beam``). Twins are built
and the loop compiled before the clock starts, the batch caster included
(``Twin.prepare_run``, a few ms once per twin, printed). ``--repeat N`` runs every
measurement N times, alternating, and keeps the best (default 1). The last line,
``twin_realtime_factor: X``, is the sampling workload through ``Twin.run`` (``batch``),
wall clock.
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
    rows = [d for seg in (D if isinstance(D, list) else [D]) for d in seg]
    exchange, read = twin.exchange, twin.read
    t0, c0 = time.perf_counter(), time.process_time()
    for d in rows:
        exchange(d)
        read()
    return len(rows) / (time.perf_counter() - t0), len(rows) / (time.process_time() - c0)


def batch(twin, D, chunk=1000):
    """One Twin.run per segment (a list of arrays) or per ``chunk`` ticks of one array."""
    segments = D if isinstance(D, list) else [D[i:i + chunk] for i in range(0, len(D), chunk)]
    n = sum(len(seg) for seg in segments)
    t0, c0 = time.perf_counter(), time.process_time()
    for seg in segments:
        twin.run(seg)
    return n / (time.perf_counter() - t0), n / (time.process_time() - c0)


BUILD_MS = []


def fresh(batch_rays=True):
    twin = Twin("thesis_final", seed=1)
    twin.batch_rays = batch_rays
    if batch_rays:
        t0 = time.perf_counter()
        assert twin.prepare_run(), "the batch caster does not cover this model"
        BUILD_MS.append((time.perf_counter() - t0) * 1e3)
    return twin, twin.current_counts - twin.reference_counts


APIS = (("per-tick", per_tick, True), ("batch-mj", batch, False), ("batch", batch, True))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=1, help="best of N (alternating)")
    args = ap.parse_args(argv)
    for _, fn, mode in APIS:  # warm up
        twin, base = fresh(mode)
        fn(twin, moving_traj(base, 2000))
    workloads = {
        "moving": lambda base: moving_traj(base, 40_000),
        "holding": lambda base: np.repeat(base[None], 100_000, axis=0),
        "sampling": lambda base: sampling_traj(base, 250, np.random.default_rng(1)),
    }
    results = {}
    for _ in range(max(1, args.repeat)):
        for work, make in workloads.items():
            for api, fn, mode in APIS:
                twin, base = fresh(mode)
                wall, cpu = fn(twin, make(base))
                best = results.get((api, work), (0.0, 0.0))
                results[api, work] = (max(best[0], wall), max(best[1], cpu))
    print("api      workload   wall ticks/s (x real time)   cpu ticks/s (x real time)")
    for work in workloads:
        for api, _, _ in APIS:
            wall, cpu = results[api, work]
            print(f"{api:8s} {work:8s} {wall:10.0f} ({wall / TICK_HZ:7.0f} x)      "
                  f"{cpu:10.0f} ({cpu / TICK_HZ:7.0f} x)")
    for work in workloads:
        (w0, c0), (w1, c1) = results["batch-mj", work], results["batch", work]
        print(f"batch / batch-mj, {work:8s}: wall {w1 / w0:4.1f}x, cpu {c1 / c0:4.1f}x")
    print(f"batch caster build (outside the clock): {np.median(BUILD_MS):.1f} ms per twin")
    print(f"load average: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores "
          "(cpu = this process's CPU time; wall includes waiting for a core)")
    print(f"twin_realtime_factor: {results['batch', 'sampling'][0] / TICK_HZ:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
