#!/usr/bin/env python
"""Benchmark: a 150-sample rehearsal on the twin (thesis_final), collision checking on,
exactly as ``planecal rehearse`` runs it. Prints robot time over wall time per run.

    python scripts/bench_rehearse.py [--samples 150] [--seed 0] [--repeat 3] [--foreground]

Wall time is the sampling session's (from the first tick to the last sample, sample
file and sidecar written); the one-off set-up (building the twin and the collision model,
imports) is printed separately. With ``--repeat`` > 1 the runs use seeds seed, seed+1, ...
and the last line is the median. If ``planecal.rerun_log`` exists, the same runs are
repeated with ``--rrd`` and reported on their own line (before the last).

Last line, exactly: ``rehearsal_speedup: X`` (robot time / wall time, median).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import statistics
import sys
import tempfile
import time

os.environ.setdefault("MUJOCO_GL", "disable")


def one(samples: int, seed: int, tmp: str, rrd: bool, foreground: bool) -> dict:
    from planecal.cli import main

    out = os.path.join(tmp, f"bench_{seed}_{int(rrd)}.tsv")
    argv = ["rehearse", "--samples", str(samples), "--seed", str(seed), "--out", out, "--force"]
    if rrd:
        argv += ["--rrd", os.path.join(tmp, f"bench_{seed}.rrd")]
    if foreground:
        argv.append("--foreground")
    buf, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(err):
        code = main(argv)
    total = time.perf_counter() - t0
    if code != 0:
        sys.stderr.write(err.getvalue())
        raise SystemExit(f"rehearse failed (exit {code})")
    s = json.loads(buf.getvalue())
    s["process_wall_time_s"] = total
    return s


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=150)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--foreground", action="store_true", help="no background pose planning")
    args = ap.parse_args()
    import importlib.util
    have_rrd = importlib.util.find_spec("planecal.rerun_log") is not None
    print(f"cpus {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}, "
          f"background planning {'off' if args.foreground else 'on'}")
    results = {False: [], True: []}
    with tempfile.TemporaryDirectory() as tmp:
        for rrd in ([False, True] if have_rrd else [False]):
            for k in range(args.repeat):
                s = one(args.samples, args.seed + k, tmp, rrd, args.foreground)
                speed = s["session_robot_time_s"] / s["session_wall_time_s"]
                results[rrd].append(speed)
                print(f"{'rrd ' if rrd else ''}seed {args.seed + k}: {s['samples']} samples, "
                      f"rejected {s['rejected_collision']} collision / {s['rejected_laser']} laser / "
                      f"{s['rejected_unreachable']} unreachable, max step {s['max_step_counts']}, "
                      f"robot time {s['session_robot_time_s']:.1f} s, wall time "
                      f"{s['session_wall_time_s']:.2f} s (set-up and all "
                      f"{s['process_wall_time_s']:.2f} s), planning {s['planning_time_s']:.2f} s "
                      f"-> robot/wall {speed:.0f}", flush=True)
    if not have_rrd:
        print("--rrd not measured: planecal.rerun_log is not available")
    else:
        print(f"rehearsal_speedup_with_rrd: {statistics.median(results[True]):.1f}")
    print(f"rehearsal_speedup: {statistics.median(results[False]):.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
