"""Where a study's runs go, the same options on every study command (montecarlo,
bootstrap, plan --measure, validate):

    --jobs N                    1: in this process; N: a local Dask cluster of N worker
                                processes (default: one per core)
    --scheduler tls://HOST:PORT a Dask cluster the user already runs, with TLS
    --tls-ca, --tls-cert, --tls-key   the certificates for it (default: dask's settings,
                                e.g. export $(planecal worker-env --tls-...))
    --insecure                  allow a plain tcp:// scheduler that is not on this machine

and its results file (``add_results_arguments``):

    --results FILE.jsonl        each run written as it completes (default with --out
                                OUT.json: OUT.runs.jsonl next to it)
    --resume                    run only the runs not in the results file yet

A cluster on other machines (every machine with planecal installed, the same version;
certificates from a CA of the cluster's own, README: a cluster of your machines)::

    export $(planecal worker-env --tls-ca ca.pem --tls-cert cluster.pem --tls-key cluster-key.pem)
    dask scheduler --protocol tls --port 8786 --tls-ca-file ca.pem --tls-cert cluster.pem --tls-key cluster-key.pem
    dask worker tls://SCHEDULER-HOST:8786 --nthreads 1 ...  # once per core

then ``planecal montecarlo ... --scheduler tls://SCHEDULER-HOST:8786``.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, Callable

from planecal.base.errors import InputError
from planecal.commands.value_options import jobs
from planecal.studies.cluster import TLSFiles, tls_files
from planecal.studies.distributed import Engine

RESULTS_SUFFIX = ".runs.jsonl"


def add_engine_arguments(p) -> None:
    """``--jobs N``, ``--scheduler tls://HOST:PORT`` with its certificates and
    ``--insecure`` on parser ``p``."""
    g = p.add_argument_group("where the runs go (planecal.studies.distributed)")
    g.add_argument("--jobs", type=jobs, default=None, metavar="N",
                   help="1: run in this process; N: a local Dask cluster of N worker "
                        "processes, at most 4 per core (default: one per core)")
    g.add_argument("--scheduler", default=None, metavar="tls://HOST:PORT",
                   help="run on a Dask cluster you already run, with TLS (README: a "
                        "cluster of your machines); tcp:// only to one on this machine")
    add_tls_arguments(g)
    g.add_argument("--insecure", action="store_true",
                   help="allow a plain tcp:// --scheduler on another machine (it runs any "
                        "code anyone who reaches its port sends)")


def add_tls_arguments(g) -> None:
    """``--tls-ca``, ``--tls-cert``, ``--tls-key`` (dask's TLS: PEM files) on ``g``."""
    g.add_argument("--tls-ca", default=None, metavar="CA.pem",
                   help="the cluster's CA certificate (default: dask's "
                        "distributed.comm.tls.ca-file, e.g. from planecal worker-env)")
    g.add_argument("--tls-cert", default=None, metavar="CERT.pem",
                   help="this machine's certificate, signed by that CA")
    g.add_argument("--tls-key", default=None, metavar="KEY.pem",
                   help="its private key (unless the certificate file holds it)")


def tls_from_args(args) -> TLSFiles | None:
    """The ``--tls-*`` files (None if none is given); one line for a missing one."""
    return tls_files(args.tls_ca, args.tls_cert, args.tls_key)


def engine_from_args(args, warmup: Callable[[], Any] | None = None) -> Engine:
    """The ``Engine`` the options name, its scheduler address and certificates checked
    (not started: use it as a context manager; make it before any work, so a bad option is
    one line before anything is computed or written). ``warmup`` runs on every worker
    before the runs (``studies.distributed.warm_twin``)."""
    return Engine(jobs=args.jobs, scheduler=args.scheduler, warmup=warmup,
                  notify=lambda m: print(f"note: {m}", file=sys.stderr, flush=True),
                  tls=tls_from_args(args), insecure=args.insecure, progress=True)


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
