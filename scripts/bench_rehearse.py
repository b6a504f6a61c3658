#!/usr/bin/env python
"""Benchmark: ``planecal rehearse`` of 150 samples on the twin (thesis_final), collision
checking on, run as a user runs it: the command in its own process. Prints robot time
over wall time per run.

    python scripts/bench_rehearse.py [--samples 150] [--seed 0] [--repeat 3] [--foreground]
                                     [-- extra rehearse flags]

``rehearsal_speedup`` is the session's (from the first tick to the last sample, sample file
and sidecar written: robot time / wall time, from the command's JSON summary);
``rehearse_command_s`` is the whole command's wall time, start-up (imports, twin, collision
model, numba's cached compile) included. One warm-up run first (not counted) fills
numba's and the shape cache, as any user's first run does. With ``--repeat`` > 1 the runs use seeds
seed, seed+1, ... and the figures are medians. The same runs are repeated with ``--rrd`` and
reported on their own line. ``--quick`` (CI, after the tests: the caches are warm): the
warm-up of 20 samples and one run each way.

Last lines, exactly: ``rehearse_command_s: X`` then ``rehearsal_speedup: X``.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time


def one(samples: int, seed: int, tmp: str, rrd: bool, foreground: bool, extra) -> dict:
    out = os.path.join(tmp, f"bench_{seed}_{int(rrd)}.tsv")
    argv = [sys.executable, "-m", "planecal.cli", "rehearse", "--samples", str(samples),
            "--seed", str(seed), "--out", out, "--force", *extra]
    if rrd:
        argv += ["--rrd", os.path.join(tmp, f"bench_{seed}.rrd")]
    if foreground:
        argv.append("--foreground")
    env = dict(os.environ, MUJOCO_GL="disable")
    t0 = time.perf_counter()
    p = subprocess.run(argv, capture_output=True, text=True, env=env)
    total = time.perf_counter() - t0
    if p.returncode != 0:
        sys.stderr.write(p.stderr)
        raise SystemExit(f"rehearse failed (exit {p.returncode})")
    s = json.loads(p.stdout)
    s["process_wall_time_s"] = total
    return s


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=150)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--foreground", action="store_true", help="no background pose planning")
    ap.add_argument("--quick", action="store_true",
                    help="a warm-up of 20 samples and one run each way (CI)")
    ap.add_argument("extra", nargs="*", help="more rehearse flags (after --)")
    args = ap.parse_args()
    if args.quick:
        args.repeat = 1
    print(f"cpus {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}, "
          f"background planning {'off' if args.foreground else 'on'}")
    results = {False: [], True: []}
    command_s = []
    with tempfile.TemporaryDirectory() as tmp:
        one(20 if args.quick else args.samples, args.seed, tmp, False, args.foreground,
            args.extra)  # warm-up
        for rrd in (False, True):
            for k in range(args.repeat):
                s = one(args.samples, args.seed + k, tmp, rrd, args.foreground, args.extra)
                speed = s["session_robot_time_s"] / s["session_wall_time_s"]
                results[rrd].append(speed)
                if not rrd:
                    command_s.append(s["process_wall_time_s"])
                print(f"{'rrd ' if rrd else ''}seed {args.seed + k}: {s['samples']} samples, "
                      f"rejected {s['rejected_collision']} collision / {s['rejected_laser']} laser / "
                      f"{s['rejected_unreachable']} unreachable, max step {s['max_step_counts']}, "
                      f"robot time {s['session_robot_time_s']:.1f} s, wall time "
                      f"{s['session_wall_time_s']:.2f} s (set-up and all "
                      f"{s['process_wall_time_s']:.2f} s), planning {s['planning_time_s']:.2f} s "
                      f"-> robot/wall {speed:.0f}", flush=True)
    print(f"rehearsal_speedup_with_rrd: {statistics.median(results[True]):.1f}")
    print(f"load average after: {os.getloadavg()[0]:.1f}")
    print(f"rehearse_command_s: {statistics.median(command_s):.2f}")
    print(f"rehearsal_speedup: {statistics.median(results[False]):.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
