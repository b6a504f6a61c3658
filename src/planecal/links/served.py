"""The emulators' server loop: a thread serving one endpoint, with counters a test or
the CLI reads safely (`planecal.links.emulators`, `planecal.links.laser_emulator`)."""
from __future__ import annotations

import dataclasses
import threading
import time
from typing import Callable

POLL_S = 0.05  # how often the threads look at their stop flag


def every(n: int, k: int) -> bool:
    return k > 0 and n % k == 0


class Served:
    """A server loop (``_serve``) in a daemon thread: start/stop and a context manager;
    ``_close`` releases the endpoint after the thread has stopped. ``_cv`` guards
    ``counters``: the thread updates them holding it."""

    _thread_name = "emulator"

    def _init_served(self, counters) -> None:
        self.counters = counters
        self._cv = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._started_t: float | None = None

    def start(self):
        if self._thread is None:
            self._started_t = time.monotonic()
            self._thread = threading.Thread(target=self._serve, name=self._thread_name, daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._close()

    def snapshot(self):
        """A consistent copy of the counters."""
        with self._cv:
            return dataclasses.replace(self.counters)

    def wait_until(self, predicate: Callable, timeout_s: float) -> bool:
        """Wait until ``predicate(counters)`` holds (True) or ``timeout_s`` passed (False)."""
        with self._cv:
            return self._cv.wait_for(lambda: predicate(self.counters), timeout_s)

    def idle(self, timeout_s: float) -> bool:
        """Wait until every reply decided on has been sent (or refused by the socket)."""
        return self.wait_until(lambda c: c.replies + c.send_errors == c.queued, timeout_s)

    def _count(self, name: str, k: int = 1) -> None:
        with self._cv:
            setattr(self.counters, name, getattr(self.counters, name) + k)
            self._cv.notify_all()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
