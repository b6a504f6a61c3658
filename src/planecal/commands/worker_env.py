"""planecal worker-env: the environment a Dask worker for planecal's studies starts with,
one ``NAME=value`` a line, for a cluster on other machines::

    export $(planecal worker-env)
    dask scheduler --port 8786                                # on one machine
    dask worker tcp://SCHEDULER-HOST:8786 --nthreads 1        # on each, once per core

One BLAS thread, no GL, and dask's profiler off with its housekeeping slower
(``planecal.studies.distributed.WORKER_ENV`` and ``WORKER_CONFIG``)."""
from __future__ import annotations


def add_arguments(p) -> None:
    """No options of its own."""


def run(args) -> int:
    from planecal.studies.distributed import worker_env_lines
    print("\n".join(worker_env_lines()))
    return 0
