"""What a study's run says of itself on a Dask worker, to the client's bar: the run's
``base.progress.report`` calls become dask events of a topic the engine's client
subscribes to (``Engine._run``), at most one every ``REPORT_EVERY_S`` a run, and each
event the client receives the detail of the map's ``Progress`` ("run 3: samples 45/150").
"""
from __future__ import annotations

import time
from typing import Callable

from planecal.base.progress import reporting_to

PROGRESS_TOPIC = "planecal-progress"  # a run's ``report`` from a worker, to the client's bar
REPORT_EVERY_S = 0.25  # a worker sends at most one report of a run this often


def reported(fn: Callable, topic: str, item, index: int):
    """``fn(item)`` on a worker, what it ``report``s sent to the client as an event of
    ``topic`` (at most one every ``REPORT_EVERY_S``)."""
    from distributed import get_worker
    worker = get_worker()
    last = [-REPORT_EVERY_S]

    def sink(k, n, what):
        now = time.monotonic()
        if now - last[0] >= REPORT_EVERY_S:
            last[0] = now
            worker.log_event(topic, {"run": index, "k": k, "n": n, "what": what})

    with reporting_to(sink):
        return fn(item)


def forward(progress, event) -> None:
    """A worker's report (``reported``) into the client's bar (on the client's thread)."""
    _, msg = event
    what = " ".join(s for s in (f"run {msg['run'] + 1}:", msg.get("what")) if s)
    progress.within(msg.get("k"), msg.get("n"), what)
