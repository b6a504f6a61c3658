#!/usr/bin/env python
"""Benchmark of the product command: ``planecal montecarlo`` run as a user runs it (a
subprocess), three ways, on the same settings:

* ``jobs1``: ``--jobs 1`` (in the command's process);
* ``cluster``: no engine option (the default: a LocalCluster, one worker process per core);
* ``scheduler``: ``--scheduler tcp://127.0.0.1:PORT`` after this script starts
  ``dask scheduler`` and ``--workers`` ``dask worker ... --nthreads 1`` processes by hand,
  after ``export $(planecal worker-env)`` as the README says (stopped at the end,
  whatever happens).

    python scripts/bench_distributed.py [--runs 200] [--samples 150] [--mode twin]
                                        [--errors realistic] [--workers 2]

By default ``--jobs 1`` runs first and last and its mean is the reference (the host's
speed drifts over the ~10 minutes; ``jobs1_drift`` is last over first). Each command
writes its summary JSON; the script fails unless every ``run_errors`` (in run order) is
identical. Throughput: runs per second of the command's map (its ``runs: R in T s`` line
on stderr: from the first run submitted to the last result, after the engine started and
warmed up), and of the whole command (wall time, start-up included). The machine's load
average is printed before and after each way: on a shared machine the ratios mean little
without it. Lines ``name: X``; the last one is ``distributed_speedup: X``, the smaller of
the two distributed map throughputs over the ``--jobs 1`` one (issue 15's target: >= 1.7
on 2 cores).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BIN = Path(sys.executable).parent
RUNS_LINE = re.compile(r"^runs: (\d+) in ([0-9.]+) s \(([0-9.]+) runs/s\).*$", re.M)


def load() -> str:
    return "/".join(f"{x:.2f}" for x in os.getloadavg())


def run_command(argv: list[str], log) -> tuple[float, float, str]:
    """(map runs per second, wall seconds, stderr) of one planecal command."""
    t0 = time.perf_counter()
    p = subprocess.run([str(BIN / "planecal"), *argv], stdout=log, stderr=subprocess.PIPE,
                       text=True, timeout=4 * 3600)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        sys.exit(f"planecal {' '.join(argv)} failed ({p.returncode}):\n{p.stderr}")
    m = RUNS_LINE.search(p.stderr)
    if m is None:
        sys.exit(f"no 'runs: R in T s' line in the command's stderr:\n{p.stderr}")
    return float(m.group(3)), wall, p.stderr


def stop(procs) -> None:
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)  # the session this script started
            p.wait(timeout=10)


def start_by_hand(d: Path, workers: int, log) -> tuple[str, list]:
    """``dask scheduler`` + ``workers`` ``dask worker`` processes on 127.0.0.1, as the
    README starts them; returns (address, processes) once every worker has joined."""
    printed = subprocess.run([str(BIN / "planecal"), "worker-env"], capture_output=True,
                             text=True, check=True).stdout.split()
    env = {**os.environ, **dict(line.split("=", 1) for line in printed)}  # export $(...)
    sfile = d / "dask-scheduler.json"
    procs = [subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--no-dashboard", "--scheduler-file", str(sfile)],
                              stdout=log, stderr=log, env=env, start_new_session=True)]
    try:
        deadline = time.monotonic() + 60
        while not sfile.exists() or not sfile.read_text().strip():
            if time.monotonic() > deadline or procs[0].poll() is not None:
                raise RuntimeError("the dask scheduler did not start (see its log)")
            time.sleep(0.2)
        addr = json.loads(sfile.read_text())["address"]
        for _ in range(workers):
            procs.append(subprocess.Popen(
                [str(BIN / "dask"), "worker", addr, "--nthreads", "1", "--no-dashboard"],
                stdout=log, stderr=log, env=env, start_new_session=True))
        from distributed import Client
        with Client(addr, timeout=60) as c:
            c.wait_for_workers(workers, timeout=120)
        return addr, procs
    except BaseException:
        stop(procs)
        raise


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--samples", type=int, default=150)
    ap.add_argument("--mode", default="twin", choices=("twin", "synthetic", "rehearse"))
    ap.add_argument("--errors", default=None, help="error profile (default: the command's)")
    ap.add_argument("--scene", default="thesis_final")
    ap.add_argument("--workers", type=int, default=2, help="dask workers started by hand")
    ap.add_argument("--only", default="jobs1,cluster,scheduler,jobs1",
                    help="comma-separated ways to run, in order; a way given twice is run "
                         "twice and its mean taken (default: all three, --jobs 1 first and "
                         "last, so the reference brackets the host's drift)")
    args = ap.parse_args()
    order = args.only.split(",")
    ways = list(dict.fromkeys(order))
    base = ["montecarlo", "--scene", args.scene, "--runs", str(args.runs), "--samples",
            str(args.samples), "--mode", args.mode]
    if args.errors:
        base += ["--errors", args.errors]
    print(f"cpus {os.cpu_count()}; planecal {' '.join(base)}")
    docs, rates, walls = {}, {w: [] for w in ways}, {w: [] for w in ways}
    with tempfile.TemporaryDirectory(prefix="bench_distributed_") as tmp:
        d = Path(tmp)
        log = open(d / "log.txt", "w")
        for n, way in enumerate(order):
            procs = []
            extra = {"jobs1": ["--jobs", "1"], "cluster": []}.get(way)
            try:
                if way == "scheduler":
                    addr, procs = start_by_hand(d, args.workers, log)
                    extra = ["--scheduler", addr]
                elif extra is None:
                    sys.exit(f"--only: unknown way {way!r}")
                before = load()
                out = d / f"{n}-{way}.json"
                r_map, t_wall, err = run_command(base + extra + ["--out", str(out)], log)
            finally:
                stop(procs[1:])
                stop(procs[:1])
            docs.setdefault(way, []).append(json.loads(out.read_text()))
            rates[way].append(r_map)
            walls[way].append(t_wall)
            line = RUNS_LINE.search(err).group(0).split("; each written")[0]
            print(f"{way}: {line}; whole command {t_wall:.1f} s; load average {before} "
                  f"before, {load()} after", flush=True)
        log.close()
    rate = {w: sum(v) / len(v) for w, v in rates.items()}
    wall = {w: sum(v) / len(v) for w, v in walls.items()}
    for way in ways:
        print(f"{way}_runs_per_s: {rate[way]:.4f}")
        print(f"{way}_command_wall_s: {wall[way]:.1f}")
        if len(rates[way]) > 1:  # the same command later: how far the host drifted
            print(f"{way}_drift: {rates[way][-1] / rates[way][0]:.3f}")
    first = docs[ways[0]][0]["run_errors"]
    same = all(doc["run_errors"] == first for w in ways for doc in docs[w])
    print(f"run_errors_identical: {int(same)}")
    if not same:
        print("the ways gave different run_errors", file=sys.stderr)
        return 1
    if "jobs1" not in ways:
        return 0
    dist = [w for w in ways if w != "jobs1"]
    for w in dist:
        print(f"{w}_speedup: {rate[w] / rate['jobs1']:.2f}")
        print(f"{w}_command_speedup: {wall['jobs1'] / wall[w]:.2f}")
    if dist:
        print(f"distributed_speedup: {min(rate[w] for w in dist) / rate['jobs1']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
