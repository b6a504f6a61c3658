#!/usr/bin/env python
"""Benchmark: progress within 2 s (issue 33). Two parts:

1. The CPU cost of one call of each work primitive ``tests/progress_trace.py`` counts
   (``COSTS``), measured while planecal's long commands run in this process (the calling
   thread's CPU clock: time spent working, not waiting for a core):
   ``cost_<primitive>_ms: X`` (the mean). The tests' costs are these, rounded up.
2. Each long command at its defaults in its own process, every line it prints stamped on
   the wall clock: ``silence_<command>_s: X``, its longest stretch without a line (from
   the start, to the end), and ``wall_<command>_s: X``. On an idle machine these are the
   issue's figures (montecarlo and sweep smaller than their defaults: ``COMMANDS``).

    python scripts/bench_progress.py [--part costs|silences|both] [--only NAME ...]
"""
from __future__ import annotations

import argparse
import os
import selectors
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

SWEEP = ('[grid]\nerrors = ["realistic"]\ndesign = ["random", "planned+ordered"]\n'
         'samples = [150]\n[sweep]\nruns = 4\n')
# (name, argv after "planecal"; {d}: a scratch folder)
COMMANDS = [
    ("demo", ["demo", "--dir", "{d}/demo"]),
    ("rehearse", ["rehearse", "--out", "{d}/r.tsv", "--truth-out", "{d}/t.json"]),
    ("calibrate_level3_report", ["calibrate", "{d}/r.tsv", "--level", "nonkinematic",
                                 "--out", "{d}/c3.json", "--report", "{d}/rep3"]),
    ("report", ["report", "{d}/c3.json", "--out", "{d}/rep"]),
    ("plan", ["plan", "--out", "{d}/p.json"]),
    ("validate", ["validate"]),
    ("validate_calibrated", ["validate", "--calibrated", "{d}/c3.json", "--truth",
                             "{d}/t.json", "--run", "{d}/r.tsv"]),
    ("montecarlo", ["montecarlo", "--runs", "10"]),
    ("bootstrap", ["bootstrap", "{d}/r.tsv"]),
    ("sweep", ["sweep", "{d}/spec.toml", "--out", "{d}/sweep"]),
    ("scene_new", ["scene", "new", "--robot", "mc70", "--out", "{d}/cell.json"]),
]


def costs() -> None:
    """Part 1 (module docstring)."""
    import contextlib
    import importlib
    import io

    from planecal.cli import main
    from progress_trace import COSTS

    stats = {k: [0, 0.0] for k in COSTS}
    for key, (mod, owner, name, _) in COSTS.items():
        target = importlib.import_module(mod)
        target = getattr(target, owner) if owner else target
        fn = getattr(target, name)

        def timed(*a, _fn=fn, _key=key, **kw):
            t = time.thread_time()
            try:
                return _fn(*a, **kw)
            finally:
                stats[_key][0] += 1
                stats[_key][1] += time.thread_time() - t
        setattr(target, name, timed)
    with tempfile.TemporaryDirectory() as d:
        for argv in (["rehearse", "--out", f"{d}/r.tsv", "-q"],
                     ["plan", "--out", f"{d}/p.json", "-q"],
                     ["calibrate", f"{d}/r.tsv", "--level", "nonkinematic", "--out",
                      f"{d}/c.json", "-q", "--no-history"],
                     ["report", f"{d}/c.json", "--out", f"{d}/rep", "-q"],
                     ["validate", "--truth-seeds", "0", "--breakdown", "none", "--jobs", "1",
                      "-q"]):
            with contextlib.redirect_stdout(io.StringIO()):
                main(argv)
    for key, (n, t) in stats.items():
        print(f"cost_{key}_ms: {t / n * 1e3:.3f}" if n else f"cost_{key}_ms: none called")


def silence(argv: list[str]) -> tuple[float, float]:
    """(longest stretch without a line, wall time) of ``planecal ARGV`` in its own process."""
    t0 = time.monotonic()
    p = subprocess.Popen([sys.executable, "-m", "planecal.cli", *argv], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, env=dict(os.environ, MUJOCO_GL="disable"))
    sel = selectors.DefaultSelector()
    for f in (p.stdout, p.stderr):
        sel.register(f, selectors.EVENT_READ)
    last, worst, open_ = t0, 0.0, 2
    while open_:
        for key, _ in sel.select():
            data = os.read(key.fileobj.fileno(), 65536)
            if not data:
                sel.unregister(key.fileobj)
                open_ -= 1
                continue
            now = time.monotonic()
            if b"\n" in data:
                worst, last = max(worst, now - last), now
    p.wait()
    end = time.monotonic()
    return max(worst, end - last), end - t0


def silences(only) -> None:
    """Part 2 (module docstring)."""
    with tempfile.TemporaryDirectory() as d:
        Path(d, "spec.toml").write_text(SWEEP)
        os.environ.setdefault("PLANECAL_HISTORY", str(Path(d, "planecal.db")))
        for name, argv in COMMANDS:
            if only and name not in only:
                continue
            s, wall = silence([a.format(d=d) for a in argv])
            print(f"silence_{name}_s: {s:.2f}")
            print(f"wall_{name}_s: {wall:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", choices=("costs", "silences", "both"), default="both")
    ap.add_argument("--only", nargs="*", default=None,
                    help="the commands of part 2 to run (their names in COMMANDS); rehearse "
                         "and calibrate_level3_report make the files the others read")
    a = ap.parse_args()
    if a.part in ("costs", "both"):
        costs()
    if a.part in ("silences", "both"):
        silences(a.only)


if __name__ == "__main__":
    main()
