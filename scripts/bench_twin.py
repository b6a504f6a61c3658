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
CPU seconds (on a shared machine the two differ). The last line,
``twin_realtime_factor: X``, is the sampling workload through ``Twin.run``, wall clock.
"""
from __future__ import annotations

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


def fresh():
    twin = Twin("thesis_final", seed=1)
    return twin, twin.current_counts - twin.reference_counts


def main() -> int:
    rng = np.random.default_rng(0)
    results = {}
    for api, fn in (("per-tick", per_tick), ("batch", batch)):
        twin, base = fresh()
        fn(twin, moving_traj(base, 2000))  # warm up
        twin, base = fresh()
        results[api, "moving"] = fn(twin, moving_traj(base, 40_000))
        twin, base = fresh()
        results[api, "holding"] = fn(twin, np.repeat(base[None], 100_000, axis=0))
        twin, base = fresh()
        D = sampling_traj(base, 250, np.random.default_rng(1))
        results[api, "sampling"] = fn(twin, D)
    print("api      workload   wall ticks/s (x real time)   cpu ticks/s (x real time)")
    for (api, work), (wall, cpu) in results.items():
        print(f"{api:8s} {work:8s} {wall:10.0f} ({wall / TICK_HZ:7.0f} x)      "
              f"{cpu:10.0f} ({cpu / TICK_HZ:7.0f} x)")
    print(f"load average: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores "
          "(cpu = this process's CPU time; wall includes waiting for a core)")
    print(f"twin_realtime_factor: {results['batch', 'sampling'][0] / TICK_HZ:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
