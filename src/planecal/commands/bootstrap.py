"""planecal bootstrap SAMPLES... [--sizes 30,50,100] [--repeats 10] [--seed K]
[--initial P.json] [--scene S] [--level offsets|full|nonkinematic] [--compliance] [--free NAMES] [--out B.json]
[--jobs J | --scheduler tcp://HOST:PORT] [--results FILE.jsonl] [--resume]

Seed 9.3's result analysis: random subsets of each size drawn from the pool of samples,
each calibrated from the same initial parameters; per size the spread (std, min, max) of
every free parameter, next to the std the fits report. Subsets that are a large share of
the pool (> 30 %) are flagged with their expected overlap, and every size also shows the
spread corrected to independent sets (see planecal.studies.bootstrap).

The fits go through planecal.studies.distributed (--jobs 1: in this process; default: a
local Dask cluster, one worker process per core; --scheduler: a cluster you run), the
same numbers every way: subset r of size s comes from the seed, s and r alone. Each fit
is written as it completes to --results FILE.jsonl (default with --out B.json:
B.runs.jsonl next to it); --resume fits only the subsets not in it yet.
"""
from __future__ import annotations

from planecal.commands.value_options import MAX_RUNS, MAX_SAMPLES, count, seed
from planecal.jobs.bootstrap import FORMAT


def add_arguments(p):
    from planecal.commands.cell_options import add_scene_argument
    p.add_argument("samples", nargs="+", help="sample file(s): the pool")
    p.add_argument("--sizes", default=None,
                   help="comma-separated subset sizes, each below the pool (default: those of "
                        "30,50,100,150 below the pool)")
    p.add_argument("--repeats", type=count(MAX_RUNS), default=10, help="subsets per size (default 10)")
    p.add_argument("--seed", type=seed, default=0, help="random seed of the subsets")
    p.add_argument("--initial", help="initial parameter file (default: the scene's nominal values)")
    add_scene_argument(p, "the nominal values and robot", "the runs' sidecars")
    from planecal.commands.calibration_options import (add_calibration_arguments,
                                                       add_fit_arguments)
    add_calibration_arguments(p)
    add_fit_arguments(p)
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="also write the plots as a Rerun recording (planecal view FILE)")
    p.add_argument("--out", help="write the result (JSON) here")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier bootstrap result")
    from planecal.commands.engine_options import add_engine_arguments, add_results_arguments
    add_engine_arguments(p)
    add_results_arguments(p)
    from planecal.commands.report_options import add_report_argument
    add_report_argument(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.cell_options import run_scene_inputs
    from planecal.commands.engine_options import results_path
    from planecal.commands.io_options import (Files, report_output, results_output,
                                              rrd_output, with_sidecars)
    f = Files().read(*with_sidecars(args.samples), args.initial,
                     *run_scene_inputs(args.samples, args.scene))
    f.write(args.out, "--out", FORMAT)
    results_output(f, results_path(args), args.resume)
    report_output(f, args.report, "--report")
    rrd_output(f, args.rrd)
    return f


def run(args) -> int:
    from planecal.commands.calibration_options import calibration_settings, fit_options
    from planecal.commands.engine_options import (check_results_path, engine_from_args,
                                                  results_path)
    from planecal.jobs.bootstrap import BootstrapRequest, bootstrap
    from planecal.studies.common import parse_int_list

    def engine():
        made = engine_from_args(args)
        results = results_path(args)
        check_results_path(results, args)
        return made, results

    sizes = None if args.sizes is None else tuple(parse_int_list(args.sizes, "--sizes", 1, MAX_SAMPLES))
    bootstrap(BootstrapRequest(
        tuple(args.samples), lambda robot: calibration_settings(args, robot,
                                                                fit_options(args, robot)),
        engine, args.scene, args.initial, sizes, args.repeats, args.seed, args.out,
        args.report, args.rrd, args.resume))
    return 0
