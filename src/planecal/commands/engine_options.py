"""Where a study's runs go, the same options on every study command (montecarlo,
bootstrap, plan --measure, validate):

    --jobs N                    1: in this process; N: a local Dask cluster of N worker
                                processes (default: one per core)
    --scheduler tcp://HOST:PORT a Dask cluster the user already runs

and its results file (``add_results_arguments``):

    --results FILE.jsonl        each run written as it completes (default with --out
                                OUT.json: OUT.runs.jsonl next to it)
    --resume                    run only the runs not in the results file yet

A cluster on other machines (every machine with planecal installed, the same version)::

    export $(planecal worker-env)
    dask scheduler --port 8786
    dask worker tcp://SCHEDULER-HOST:8786 --nthreads 1  # once per core

then ``planecal montecarlo ... --scheduler tcp://SCHEDULER-HOST:8786``.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, Callable

from planecal.base.errors import InputError
from planecal.studies.distributed import Engine

RESULTS_SUFFIX = ".runs.jsonl"


def add_engine_arguments(p) -> None:
    """``--jobs N`` and ``--scheduler tcp://HOST:PORT`` on parser ``p``."""
    g = p.add_argument_group("where the runs go (planecal.studies.distributed)")
    g.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="1: run in this process; N: a local Dask cluster of N worker "
                        "processes (default: one per core)")
    g.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run on a Dask cluster you already run ('export $(planecal "
                        "worker-env)', then 'dask scheduler' and 'dask worker "
                        "tcp://HOST:PORT --nthreads 1' on each machine)")


def engine_from_args(args, warmup: Callable[[], Any] | None = None) -> Engine:
    """The ``Engine`` the options name (not started: use it as a context manager).
    ``warmup`` runs on every worker before the runs (``studies.distributed.warm_twin``)."""
    return Engine(jobs=args.jobs, scheduler=args.scheduler, warmup=warmup,
                  notify=lambda m: print(f"note: {m}", file=sys.stderr, flush=True))


def add_results_arguments(p) -> None:
    """``--results FILE.jsonl`` and ``--resume`` on parser ``p`` (which has ``--out``)."""
    g = p.add_argument_group("results of each run")
    g.add_argument("--results", default=None, metavar="FILE.jsonl",
                   help="write each run to this JSON-lines file as it completes (default "
                        f"with --out OUT.json: OUT{RESULTS_SUFFIX} next to it)")
    g.add_argument("--resume", action="store_true",
                   help="continue the results file: run only the runs not in it yet")


def results_path(args, tag: str = "") -> Path | None:
    """The results file of the study (``tag``: one of several maps, e.g. ``slope-50``):
    ``--results`` (with ``.TAG`` before its suffix), else next to ``--out``; None without
    either. InputError for ``--resume`` without a file."""
    base = args.results
    if base:
        p = Path(base)
        return p.with_name(f"{p.stem}.{tag}{p.suffix}") if tag else p
    out = args.out
    if out:
        o = Path(out)
        return o.with_name(o.stem + (f".{tag}" if tag else "") + RESULTS_SUFFIX)
    if args.resume:
        raise InputError("--resume needs a results file: give --results FILE.jsonl or --out")
    return None


def check_results_path(path: Path | None, args) -> None:
    """A results file that exists is continued with ``--resume`` or replaced with
    ``--force``; otherwise a one-line error (no command overwrites what it did not write
    this time)."""
    if path is None or not path.exists() or path.stat().st_size == 0:
        return
    if args.resume:
        return
    if args.force:
        path.unlink()
        return
    raise InputError(f"{path}: results of an earlier run exist (--resume to continue them, "
                     "--force to start afresh)")
