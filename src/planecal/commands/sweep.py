"""planecal sweep SPEC.toml --out DIR [--resume] [--jobs J | --scheduler tls://HOST:8786]

A grid of scene x error profile x pose design (random, planned, planned+ordered) x sample
count x calibration level, R runs per cell; each run rehearses in the twin, calibrates and
measures the offsets' error against the truth and the robot time (planecal.studies.sweep;
the spec: docs/SWEEP.md). The runs go through the distributed engine
(planecal.studies.distributed): --jobs 1 in this process, by default a local Dask cluster,
--scheduler a cluster you run. Each result is appended to DIR/results.jsonl as it
completes; after a kill, the same command with --resume runs only what is missing and
ends with the same table. Writes DIR/sweep.json (the table's figures, format
planecal-sweep/1), DIR/sweep.txt (the table) and DIR/accuracy_vs_robot_time.png.
"""
from __future__ import annotations

from pathlib import Path

from planecal.base.errors import InputError

RESULTS = "results.jsonl"


def add_arguments(p):
    p.add_argument("spec", metavar="SPEC.toml", help="the sweep (docs/SWEEP.md)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder for results.jsonl, sweep.json, sweep.txt and the plots")
    p.add_argument("--resume", action="store_true",
                   help="continue the sweep in DIR (its results file): only missing runs")
    from planecal.commands.engine_options import add_engine_arguments
    add_engine_arguments(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the spec,
    its scenes and error-profile files; the folder and every file the sweep writes in it
    (the folder is planecal's when it holds a sweep's results file, or nothing)."""
    from planecal.commands.io_options import (RESULTS_FORMAT, Files, profile_inputs,
                                              scene_inputs)
    from planecal.io.outputs import PNG_MARK
    from planecal.studies.sweep import FORMAT, load_spec

    spec = load_spec(args.spec)
    f = Files().read(args.spec)
    for s in spec.scene:
        f.read(*scene_inputs(s), *[p for e in spec.errors for p in profile_inputs(e, s)])
    from planecal.commands.io_options import results_output
    members = ((RESULTS, (RESULTS_FORMAT,)), (RESULTS + ".lock", ()), ("sweep.json", (FORMAT,)),
               ("sweep.txt", ()), ("*.png", (PNG_MARK,)))
    if args.resume:  # the results file continued is a results file (one line, before all)
        results_output(Files(), Path(args.out) / RESULTS, True)
    return f.write(args.out, "--out", folder=True, members=members, anchor=RESULTS,
                   keep=args.resume, hint="give another folder")


def run(args) -> int:
    from planecal.base.errors import RunFailed
    from planecal.io.outputs import make_folder
    from planecal.io.params import save_json
    from planecal.base.progress import Progress
    from planecal.present.report.sweep import fig_accuracy_vs_time
    from planecal.commands.engine_options import engine_from_args
    from planecal.present.sweep import format_sweep
    from planecal.studies.distributed import warm_twin
    from planecal.studies.sweep import load_spec, plans_needed, run_sweep

    from planecal.studies.results import check_header
    spec = load_spec(args.spec)
    out = Path(args.out)  # checked before the run (``files``)
    results = out / RESULTS
    if results.exists() and results.stat().st_size > 0 and not args.resume:
        raise InputError(f"--out {out}: holds a sweep's {RESULTS}; continue it with --resume "
                         "or give another folder")
    if args.resume:  # before the engine starts and the plans are made: nothing said first
        check_header(results, spec.header())
    engine = engine_from_args(args, warmup=lambda: warm_twin(spec.scene[0]))  # checked here
    n_runs = len(spec.cells()) * spec.runs
    with engine as eng:  # the scheduler reached before anything is made
        make_folder(out, "--out")
        bar = Progress("planning", len(plans_needed(spec)), unit=" plans")
        res = run_sweep(spec, results, eng, resume=args.resume,
                        progress=Progress(f"sweep: {n_runs} runs, {eng.describe()}", n_runs),
                        plan_progress=bar)
    text = format_sweep(res)
    print(text)
    save_json(out / "sweep.json", res)
    (out / "sweep.txt").write_text(text + "\n")
    plot = fig_accuracy_vs_time(out, res)
    print(f"results: {results}; table: {out / 'sweep.txt'}, {out / 'sweep.json'}; "
          f"plot: {out / plot.file}")
    if not any(c["runs"] for c in res["cells"]):
        raise RunFailed(f"every run of the sweep failed (the table says why: {out / 'sweep.txt'})")
    return 0
