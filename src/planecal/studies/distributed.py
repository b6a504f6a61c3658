"""Runs on an existing distributed engine: every study (Monte Carlo, a sweep, ``plan
--measure``, validation over truths, bootstrap) is a map of a pure function over run
descriptions (an item carries its own seed), submitted here.

``Engine`` runs the map in one of three ways:

* ``Engine(jobs=1)``: in this process, item after item (dask is not imported): the
  reference every other way must reproduce exactly;
* ``Engine()`` / ``Engine(jobs=N)``: an in-process ``dask.distributed.LocalCluster`` on
  this machine, N worker *processes* (default: the CPU count) of one thread each; nothing
  to set up;
* ``Engine(scheduler="tls://HOST:8786", tls=TLSFiles(...))``: a cluster the user already
  runs, with TLS (README: a cluster of your machines)::

      export $(planecal worker-env --tls-ca CA --tls-cert CERT --tls-key KEY)
      dask scheduler --protocol tls --port 8786 ...   # on one machine
      dask worker tls://HOST:8786 --nthreads 1 ...    # on each worker, once per core

  (every worker needs planecal installed, the same version). ``worker_env_lines()`` gives
  those variables; workers started without the dask ones are counted (``untuned``) and
  named to the user through ``notify``. The address is checked before any connection
  (``planecal.studies.cluster``: tls://, or tcp:// on this machine unless ``insecure``),
  and dask's handshake with it is bounded as a whole (``connect_timeout_s``).

Quiet: no dashboard, dask's own log lines at ERROR only while the engine is open; an
unreachable scheduler (or one with no workers) is a one-line ``InputError`` after
``connect_timeout_s``. Workers run with one BLAS thread (``OPENBLAS``/``OMP``/``MKL``
``_NUM_THREADS=1``, set before the worker process starts), ``MUJOCO_GL=disable`` and
dask's ``WORKER_CONFIG`` (no profiler, slower housekeeping).
The studies reach it through ``studies.common.parallel_map``; the commands make it from
their ``--jobs`` / ``--scheduler`` options (``commands.engine_options``).

``Engine.map(fn, items, key=..., out=..., resume=...)`` submits every item and returns the
results in item order; ``Engine.as_completed`` yields ``(index, result)`` as the runs
complete. With ``out`` each result is appended to a JSON-lines file the moment it arrives
(``planecal.studies.results``: the format, and how arrays come back bit for bit), and with
``resume=True`` the items whose key is already in the file are not run again.

Numba: the twin's tick is compiled once and cached on disk (``planecal.base.paths``:
``~/.cache/planecal/numba`` by default; ``~7 s`` cold, ``~0.3 s`` to load). ``warmup``
(e.g. ``warm_twin``) runs first on one worker -- which compiles if the cache is cold and
writes it -- and only then on every other worker, which load it: a cold start compiles
once per cache folder, not once per worker.
"""
from __future__ import annotations

import functools
import importlib
import logging
import os
import signal
import time
import uuid
from contextlib import contextmanager
from typing import Any, Callable, Iterable, Iterator, Protocol, Sequence

import numpy as np

from planecal.base.errors import InputError
from planecal.base.progress import Progress, stage
from planecal.studies.cluster import (TLSFiles, check_reach, client_security, parse_address,
                                      probe, tls_env)
from planecal.studies.results import ResultsFile, canonical_key, encode
from planecal.studies.run_reports import PROGRESS_TOPIC, forward, reported

CONNECT_TIMEOUT_S = 10.0
CLOSE_TIMEOUT_S = 10.0  # each of the client's and the local cluster's close, at most
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "MUJOCO_GL": "disable"}
# dask's settings for planecal's workers: no statistical profiler (it samples the running
# task's stack every 10 ms for a dashboard planecal does not open) and the worker's
# housekeeping (event-loop health tick, system and memory monitors) at a slower pace. With
# dask's defaults a worker ran a Monte Carlo run ~10 % slower than the same run in a plain
# process (0.61 against 0.52 s, 2 workers on 2 cores); with these, 0.56 s.
WORKER_CONFIG = {"distributed.worker.profile.enabled": False,
                 "distributed.admin.tick.interval": "1s",
                 "distributed.admin.system-monitor.interval": "5s",
                 "distributed.worker.memory.monitor-interval": "1s"}
_QUIET_LOGGERS = ("distributed", "tornado", "bokeh")
WAIT_STEP_S = 0.25  # a start-up wait says how long it has waited this often


class Steps(Protocol):
    """Progress per completed item (``base.progress.Progress``), and inside the runs."""

    def step(self, k: int = 1) -> None: ...

    def within(self, k: int | None = None, n: int | None = None,
               what: str | None = None) -> None: ...


# ----- the engine -------------------------------------------------------------------------------

@contextmanager
def _quiet_logs():
    """dask's loggers at ERROR while the engine is open (restored after). distributed
    gives its modules' loggers levels of their own when it is imported (INFO for the
    scheduler and nanny), so it is imported first and every one of them is set."""
    importlib.import_module("distributed")  # its loggers exist, with their configured levels
    names = set(_QUIET_LOGGERS) | {n for n in list(logging.root.manager.loggerDict)
                                   if n.split(".")[0] in _QUIET_LOGGERS}
    saved = {n: logging.getLogger(n).level for n in names}
    for n in names:
        logging.getLogger(n).setLevel(logging.ERROR)
    try:
        yield
    finally:
        for n, lv in saved.items():
            logging.getLogger(n).setLevel(lv)


@contextmanager
def _spawn_env(env: dict):
    """``env`` in the nanny's pre-spawn environment (set before each worker process starts,
    so BLAS reads it at import), without leaving it in this process's environment."""
    import dask
    saved = {k: os.environ.get(k) for k in env}
    try:
        with dask.config.set({"distributed.nanny.pre-spawn-environ": {
                **dask.config.get("distributed.nanny.pre-spawn-environ"), **env}}):
            yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _worker_env() -> dict:
    return {k: os.environ.get(k) for k in WORKER_ENV} | {"pid": os.getpid()}


def _worker_config() -> dict:
    import dask
    return {k: dask.config.get(k, None) for k in WORKER_CONFIG}


def _config_var(key: str) -> str:
    """The environment variable dask reads ``key`` from (``DASK_`` + upper case, ``.`` as
    ``__``, ``-`` as ``_``)."""
    return "DASK_" + key.upper().replace(".", "__").replace("-", "_")


def worker_env_lines(tls: TLSFiles | None = None) -> list[str]:
    """``NAME=value`` for a worker's environment: one BLAS thread, no GL, and
    ``WORKER_CONFIG`` as dask reads it from the environment (``planecal worker-env``
    prints them, for ``export $(planecal worker-env)``); with ``tls`` also dask's TLS
    settings of a cluster member (``cluster.tls_env``)."""
    config = {**WORKER_CONFIG, **(tls_env(tls) if tls is not None else {})}
    return ([f"{k}={v}" for k, v in WORKER_ENV.items()]
            + [f"{_config_var(k)}={v}" for k, v in config.items()])


def _set_worker_env() -> None:
    """A worker's process: no GL, and no progress of its own on its stderr (a compile's,
    say): what its runs report goes to the client's bar (``run_reports``)."""
    from planecal.base.progress import set_quiet
    os.environ.setdefault("MUJOCO_GL", "disable")
    set_quiet(True)


class Engine:
    """Where a study's runs go (module docstring). A context manager::

        with Engine() as eng:                       # LocalCluster, all cores
            results = eng.map(run_one, items, key=lambda it: it[1], out="runs.jsonl")
    """

    def __init__(self, jobs: int | None = None, scheduler: str | None = None,
                 connect_timeout_s: float = CONNECT_TIMEOUT_S,
                 warmup: Callable[[], Any] | None = None,
                 notify: Callable[[str], None] | None = None,
                 tls: TLSFiles | None = None, insecure: bool = False,
                 progress: bool = False):
        if jobs is not None and jobs < 1:
            raise InputError(f"--jobs must be at least 1, got {jobs}")
        if scheduler is not None and jobs is not None:
            raise InputError("--jobs and --scheduler exclude each other (the scheduler's "
                             "workers run the jobs)")
        if scheduler is None and (tls is not None or insecure):
            raise InputError("--tls-ca/--tls-cert/--tls-key and --insecure are for "
                             "--scheduler")
        self.security = None
        if scheduler is not None:  # checked before any connection (planecal.studies.cluster)
            address = parse_address(scheduler)
            check_reach(address, insecure)
            self.security = client_security(address, tls)
            scheduler = str(address)
        self.scheduler = scheduler
        self.jobs = jobs
        self.mode = ("scheduler" if scheduler else
                     "local" if jobs == 1 else "cluster")
        self.n_workers = (os.cpu_count() or 1) if jobs is None else jobs
        self.connect_timeout_s = float(connect_timeout_s)
        self.warmup = warmup
        self.notify = notify  # a note for the user (e.g. workers without WORKER_CONFIG)
        self.untuned: int = 0  # workers of a --scheduler cluster without WORKER_CONFIG
        self.client = None
        self._cluster = None
        self._pids: list[int] = []  # the local cluster's worker processes
        self._logs = None
        self.progress = progress  # say the start-up (the workers, the warm-up) on stderr

    # -- lifecycle
    def __enter__(self) -> "Engine":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> None:
        if self.mode == "local":
            if self.warmup is not None:
                self.warmup()
            return
        if self.client is not None:
            return
        self._logs = _quiet_logs()
        self._logs.__enter__()
        try:
            what = (f"starting a local Dask cluster of {self.n_workers} worker processes"
                    if self.mode == "cluster" else f"connecting to {self.scheduler}")
            # a scheduler that does not answer is a one-line refusal: its stage is said
            # once it has answered
            with stage("engine", what, quiet=not self.progress,
                       hold=self.mode == "scheduler") as bar:
                if self.mode == "cluster":
                    self._start_cluster(bar)
                else:
                    self._connect()
                    bar.release()
                self.client.register_plugin(_env_plugin(), name="planecal-env")
                if self.mode == "scheduler":
                    configs = self.client.run(_worker_config).values()
                    self.untuned = sum(c != WORKER_CONFIG for c in configs)
                    if self.untuned and self.notify:
                        self.notify(f"{self.untuned} of the scheduler's workers run without "
                                    "planecal's dask settings (dask's profiler on: ~10 % "
                                    "slower); start them after 'export $(planecal worker-env)'")
                if self.warmup is not None:
                    self._warm(bar)
        except BaseException:
            self.close()
            raise

    def _start_cluster(self, bar: Progress) -> None:
        """The local cluster, its workers started one by one as the bar counts them."""
        from distributed import Client, LocalCluster
        import dask
        with _spawn_env(WORKER_ENV), dask.config.set(WORKER_CONFIG):
            self._cluster = LocalCluster(
                n_workers=0, threads_per_worker=1, processes=True,
                host="127.0.0.1", scheduler_port=0, dashboard_address=None,
                # no dashboard; the scheduler's plain HTTP routes (health, metrics) on a
                # free loopback port instead of 8787 (which another cluster may hold)
                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                # the workers' own logs: a worker that loses its scheduler while a stopped
                # study closes (Ctrl-C) logs a heartbeat ERROR with a traceback, a race of
                # the teardown, not news; what fails in a run reaches the client as an
                # exception (Engine.map), so only CRITICAL lines are shown
                silence_logs=logging.CRITICAL)
            self.client = Client(self._cluster, set_as_default=False)
            self._cluster.scale(self.n_workers)
            self._wait_workers(bar)
        self._pids = [int(v) for v in self.client.run(os.getpid).values()]

    def _wait_workers(self, bar: Progress) -> None:
        """Until every worker of the local cluster has joined, saying how many have."""
        t0 = time.monotonic()
        while True:
            n = len(self.client.scheduler_info(n_workers=-1)["workers"])
            bar.within(what=f"{n} of {self.n_workers} workers up after "
                            f"{time.monotonic() - t0:.0f} s")
            if n >= self.n_workers:
                return
            try:
                self.client.wait_for_workers(n + 1, timeout=WAIT_STEP_S)
            except TimeoutError:
                pass

    def _connect(self) -> None:
        from distributed import Client
        addr = self.scheduler
        probe(parse_address(addr), self.security, self.connect_timeout_s)  # bounded
        try:
            self.client = Client(addr, timeout=self.connect_timeout_s, set_as_default=False,
                                 security=self.security)
        except (OSError, TimeoutError) as e:
            raise InputError(f"--scheduler {addr}: no Dask scheduler answered within "
                             f"{self.connect_timeout_s:g} s ({type(e).__name__})") from None
        try:
            self.client.wait_for_workers(1, timeout=self.connect_timeout_s)
        except (OSError, TimeoutError):
            raise InputError(f"--scheduler {addr}: the scheduler has no workers (none joined "
                             f"within {self.connect_timeout_s:g} s); start some with "
                             f"'dask worker {addr} --nthreads 1'") from None

    def _warm(self, bar: Progress) -> None:
        """The warm-up on one worker first (it fills the on-disk caches), then on the
        others at once (they load them), the bar saying how many are done."""
        workers = sorted(self.client.scheduler_info(n_workers=-1)["workers"])
        bar.update(0, "warming up the workers (the first compiles the kernels if not cached)")
        first = self.client.submit(self.warmup, workers=[workers[0]], pure=False,
                                   key=f"planecal-warmup-{uuid.uuid4().hex}")
        t0 = time.monotonic()
        self._wait([first], len(workers), bar, t0)
        rest = [self.client.submit(self.warmup, workers=[w], pure=False,
                                   key=f"planecal-warmup-{uuid.uuid4().hex}")
                for w in workers[1:]]
        self._wait(rest, len(workers), bar, t0, 1)

    @staticmethod
    def _wait(futures, total: int, bar: Progress, t0: float, before: int = 0) -> None:
        """Until ``futures`` are done (their errors raised), saying how long since ``t0``."""
        while True:
            done = sum(f.done() for f in futures)
            bar.within(what=f"{before + done} of {total} warmed up after "
                            f"{time.monotonic() - t0:.0f} s")
            if done == len(futures):
                break
            time.sleep(WAIT_STEP_S)
        for f in futures:
            f.result()

    def close(self) -> None:
        """Close the client and the local cluster, each within ``CLOSE_TIMEOUT_S``, so a
        stopped study exits even where the scheduler no longer answers (the client's own
        default is twice dask's connect timeout, the cluster's close has none); where the
        cluster's close runs out, its worker processes are killed."""
        try:
            if self.client is not None:
                try:
                    self.client.close(timeout=CLOSE_TIMEOUT_S)
                except (TimeoutError, OSError):
                    pass  # the cluster's close below ends what is left
            if self._cluster is not None:
                try:
                    self._cluster.close(timeout=CLOSE_TIMEOUT_S)
                except (TimeoutError, OSError):
                    for pid in self._pids:
                        try:
                            os.kill(pid, signal.SIGKILL)
                        except ProcessLookupError:
                            pass
        finally:
            self.client = self._cluster = None
            self._pids = []
            if self._logs is not None:
                self._logs.__exit__(None, None, None)
                self._logs = None

    # -- facts
    @property
    def slots(self) -> int:
        """Runs that go at once (worker threads; 1 in this process)."""
        if self.mode == "local":
            return 1
        return int(sum(self.client.nthreads().values()))

    def describe(self) -> str:
        if self.mode == "local":
            return "in this process (--jobs 1)"
        if self.mode == "cluster":
            return f"local Dask cluster: {self.slots} worker processes"
        note = f" ({self.untuned} without planecal's dask settings)" if self.untuned else ""
        return f"Dask scheduler {self.scheduler}: {self.slots} worker threads{note}"

    def worker_env(self) -> list[dict]:
        """The BLAS / MuJoCo environment of each worker (for checks)."""
        if self.mode == "local":
            return [_worker_env()]
        return list(self.client.run(_worker_env).values())

    # -- the map
    def as_completed(self, fn: Callable, items: Sequence, key: Callable | None = None,
                     out=None, resume: bool = False, header: dict | None = None,
                     progress: Steps | None = None) -> Iterator[tuple[int, Any]]:
        """Yields ``(index, result)`` as runs complete: first those already in ``out``
        (with ``resume``), in item order, then the others as they finish. ``key(item)``
        (default: the index) names an item in the file; keys must be distinct."""
        items = list(items)
        keys = [i if key is None else key(it) for i, it in enumerate(items)]
        canon = [canonical_key(encode(k)) for k in keys]
        if len(set(canon)) != len(canon):
            dup = next(k for k, c in zip(keys, canon) if canon.count(c) > 1)
            raise ValueError(f"two items have the key {dup!r}")
        rf = ResultsFile(out, header, resume) if out is not None else None
        try:
            todo = []
            for i, c in enumerate(canon):
                if rf is not None and c in rf.done:
                    if progress:
                        progress.step()
                    yield i, rf.done[c][1]
                else:
                    todo.append(i)
            for i, res in self._run(fn, items, todo, progress):
                if rf is not None:
                    res = rf.append(keys[i], res)
                if progress:
                    progress.step()
                yield i, res
        finally:
            if rf is not None:
                rf.close()

    def map(self, fn: Callable, items: Iterable, key: Callable | None = None, out=None,
            resume: bool = False, header: dict | None = None,
            progress: Steps | None = None,
            on_result: Callable[[int, Any], None] | None = None) -> list:
        """``[fn(item) for item in items]`` through the engine, in item order (see
        ``as_completed``); ``on_result(index, result)`` as each one completes."""
        items = list(items)
        out_list: list = [None] * len(items)
        for i, res in self.as_completed(fn, items, key, out, resume, header, progress):
            out_list[i] = res
            if on_result:
                on_result(i, res)
        return out_list

    def _run(self, fn, items, todo, progress=None) -> Iterator[tuple[int, Any]]:
        """The runs of ``todo``; what a run ``report``s goes to ``progress`` (``within``):
        in this process the innermost open bar (``progress`` itself), from a worker through
        dask's events (``PROGRESS_TOPIC``)."""
        if not todo:
            return
        if self.mode == "local":
            for i in todo:
                yield i, fn(items[i])
            return
        if self.client is None:
            raise RuntimeError("Engine: use it as a context manager (or call start())")
        from distributed import as_completed
        tag = uuid.uuid4().hex[:12]
        name = getattr(fn, "__name__", "run")
        topic = f"{PROGRESS_TOPIC}-{tag}"
        call = fn
        if progress is not None:
            self.client.subscribe_topic(topic, functools.partial(forward, progress))
            call = functools.partial(reported, fn, topic)
        futs = {}
        for i in todo:
            f = self.client.submit(call, items[i], i, key=f"{name}-{tag}-{i}", pure=False) \
                if progress is not None else \
                self.client.submit(fn, items[i], key=f"{name}-{tag}-{i}", pure=False)
            futs[f.key] = (i, f)
        try:
            for f, res in as_completed([f for _, f in futs.values()], loop=self.client.loop,
                                       with_results=True):
                i, _ = futs.pop(f.key)
                yield i, res
        finally:
            if progress is not None:
                self.client.unsubscribe_topic(topic)
            if futs:  # stopped early (an error, Ctrl-C, the caller stopped): cancel the rest
                self.client.cancel([f for _, f in futs.values()])


def _env_plugin():
    """A worker plugin setting MUJOCO_GL=disable in every worker, including workers that
    join later (the BLAS threads must be set before a worker process starts:
    ``WORKER_ENV``). Made here: distributed is imported only when an engine uses it."""
    from distributed import WorkerPlugin

    class EnvPlugin(WorkerPlugin):
        idempotent = True

        def setup(self, worker):
            _set_worker_env()

    return EnvPlugin()


# ----- warm-ups -----------------------------------------------------------------------------

def warm_twin(scene: str = "thesis_final") -> float:
    """Import the twin and run three of its compiled ticks (numba: compiled, or loaded from
    the on-disk cache); returns the seconds it took. A warm-up for studies on the twin."""
    import time
    t0 = time.perf_counter()
    from planecal.model.scene import load_scene
    from planecal.twin import Twin
    twin = Twin(load_scene(scene), truth="nominal", seed=0)
    hold = (twin.current_counts - twin.reference_counts)[None]
    twin.run(np.repeat(hold, 3, axis=0))
    return time.perf_counter() - t0
