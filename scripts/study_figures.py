#!/usr/bin/env python
"""Reproduce the figures of docs/STUDIES.md: every study at full size, each command's
terminal report saved as OUT/<name>.txt and its JSON as OUT/<name>.json.

    python scripts/study_figures.py [--out study_out] [--jobs N] [--only NAME[,NAME]]

Names: montecarlo, montecarlo_seed1000, montecarlo_seed5000, three_plates, slope, synthetic, synthetic_white,
synthetic_quant, plan, validate, validate_offsets_all, bootstrap, replay. The validation
over seeds 0-8 in docs/STUDIES.md is ``planecal validate --seed K`` (and ``--poses
OUT/plan.json``) per seed. Takes 20-60 min on 2 cores (the twin Monte Carlo runs dominate:
~20 ms of collision-checked planning per sample).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import time

os.environ.setdefault("MUJOCO_GL", "disable")


def studies(out: str, jobs: str) -> dict:
    j = ["--jobs", jobs]
    o = lambda n: ["--out", os.path.join(out, n + ".json")]  # noqa: E731
    pool = os.path.join(out, "pool.tsv")
    return {
        "montecarlo": ["montecarlo", "--runs", "600", "--samples", "150", "--seed", "10000", *j,
                       "--rrd", os.path.join(out, "montecarlo.rrd"), *o("montecarlo")],
        "montecarlo_seed1000": ["montecarlo", "--runs", "200", "--samples", "150", *j,
                                *o("montecarlo_seed1000")],
        "montecarlo_seed5000": ["montecarlo", "--runs", "100", "--samples", "150", "--seed",
                                "5000", *j, *o("montecarlo_seed5000")],
        "three_plates": ["montecarlo", "--scene", "three_plates", "--runs", "80",
                         "--samples", "150", *j, *o("three_plates")],
        "slope": ["montecarlo", "--runs", "30", "--samples", "50", "--slope", "50,100,200",
                  "--slope-runs", "30", *j, *o("slope")],
        "synthetic": ["montecarlo", "--mode", "synthetic", "--runs", "200", "--samples", "150",
                      *j, *o("synthetic")],
        "synthetic_white": ["montecarlo", "--mode", "synthetic", "--runs", "200", "--samples",
                            "150", "--repeatability-mm", "0", "--laser-noise-mm", "0.132", *j,
                            *o("synthetic_white")],
        "synthetic_quant": ["montecarlo", "--mode", "synthetic", "--quantization", "--runs", "100",
                            "--samples", "150", *j, *o("synthetic_quant")],
        "plan": ["plan", "--samples", "150", "--candidates", "1500", "--measure", "40", *j,
                 *o("plan")],
        "validate": ["validate", *o("validate")],
        "validate_offsets_all": ["validate", "--offsets-all", "--tcp-mm", "0,100,150",
                                 *o("validate_offsets_all")],
        "bootstrap": ["bootstrap", pool, "--sizes", "30,50,100,150,300", "--repeats", "10",
                      *j, *o("bootstrap")],
        "replay": ["replay", "examples/seed_samples.tsv", "--params",
                   "examples/table10_params.json", *o("replay")],
    }


def make_pool(path: str, n: int = 1000) -> None:
    """The bootstrap pool: one long twin rehearsal (twin mode, truth seed 0, seed 77)."""
    from planecal.io.samples import write_samples
    from planecal.studies.common import cached_scene
    from planecal.studies.montecarlo import MCSettings, truth_for
    from planecal.studies.rehearsal import twin_samples
    st = MCSettings(samples=n)
    qe, d, plate, _ = twin_samples(cached_scene(st.scene), truth_for(st, 0), st, 77)
    write_samples(path, qe, d * 1e3)


def main() -> int:
    from planecal.cli import main as cli
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="study_out")
    ap.add_argument("--jobs", default=str(os.cpu_count() or 1))
    ap.add_argument("--only", default=None)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    todo = studies(args.out, args.jobs)
    names = list(todo) if not args.only else args.only.split(",")
    for name in names:
        argv = todo[name]
        if name == "bootstrap" and not os.path.exists(os.path.join(args.out, "pool.tsv")):
            print("making the bootstrap pool (1000 twin samples)...", file=sys.stderr, flush=True)
            make_pool(os.path.join(args.out, "pool.tsv"))
        print(f"== {name}: planecal {' '.join(argv)}", file=sys.stderr, flush=True)
        buf = io.StringIO()
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(buf):
            code = cli(argv)
        text = buf.getvalue()
        with open(os.path.join(args.out, name + ".txt"), "w") as f:
            f.write(text)
        print(text)
        print(f"== {name}: exit {code}, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
