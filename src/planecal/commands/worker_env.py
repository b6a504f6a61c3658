"""planecal worker-env: the environment a Dask worker for planecal's studies starts with,
one ``NAME=value`` a line, for a cluster on other machines (README: a cluster of your
machines)::

    export $(planecal worker-env --tls-ca ca.pem --tls-cert cluster.pem --tls-key cluster-key.pem)
    dask scheduler --protocol tls --port 8786 ...             # on one machine
    dask worker tls://SCHEDULER-HOST:8786 --nthreads 1 ...    # on each, once per core

One BLAS thread, no GL, and dask's profiler off with its housekeeping slower
(``planecal.studies.distributed.WORKER_ENV`` and ``WORKER_CONFIG``). With ``--tls-ca``,
``--tls-cert`` (and ``--tls-key``) also dask's TLS settings, the same certificate for the
scheduler, the worker and a client (``DASK_DISTRIBUTED__COMM__TLS__*``, absolute paths),
and ``DASK_DISTRIBUTED__COMM__REQUIRE_ENCRYPTION=True``: in that environment dask refuses
plain tcp:// (``planecal.studies.cluster``)."""
from __future__ import annotations

from planecal.commands.engine_options import add_tls_arguments


def add_arguments(p) -> None:
    add_tls_arguments(p)


def run(args) -> int:
    from planecal.base.errors import InputError
    from planecal.commands.engine_options import tls_from_args
    from planecal.studies.distributed import worker_env_lines

    tls = tls_from_args(args)
    if tls is not None:  # PEM files that load, and a key that matches the certificate
        from planecal.studies.cluster import check_certificates
        check_certificates(str(tls.ca), str(tls.cert), None if tls.key is None else str(tls.key),
                           "--tls-ca/--tls-cert/--tls-key")
    lines = worker_env_lines(tls)
    spaced = next((ln for ln in lines if any(c.isspace() for c in ln)), None)
    if spaced is not None:  # export $(...) splits at blanks
        raise InputError(f"{spaced.split('=', 1)[1]}: a path with a blank cannot pass "
                         "through export $(planecal worker-env ...); move or link the file")
    print("\n".join(lines))
    return 0
