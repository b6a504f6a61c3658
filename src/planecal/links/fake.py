"""Tiny deterministic in-process backends for tests of the links and emulators.

`FakeCell` implements both `RobotLink` and `Laser` (like the twin) without physics:
the robot follows the commanded counts after ``lag_ticks`` ticks, and the laser reads a
linear function of the current counts, quantised to the sensor's 1e-6 mm.
"""
from __future__ import annotations

import threading
from collections import deque

import numpy as np

HOME = np.full(6, 8388608, dtype=np.int64)


class FakeCell:
    """RobotLink + Laser. ``reference``: counts at start (default home).

    ``laser_mm(current) -> float | None`` overrides the default reading
    ``80 + 1e-4 * sum(current - reference)`` mm, out of range (None) beyond +-15 mm.
    Records every delta received in ``deltas``; ``ticks`` counts exchanges.
    """

    def __init__(self, reference=None, lag_ticks: int = 0, laser_mm=None):
        self.reference = HOME.copy() if reference is None else np.asarray(reference, np.int64).copy()
        self.lag_ticks = int(lag_ticks)
        self.laser_mm = laser_mm
        self.deltas: list[np.ndarray] = []
        self.ticks = 0
        self.reads = 0
        self.closed = False
        self._pipe: deque = deque([np.zeros(6, np.int64)] * self.lag_ticks)
        self.current = self.reference.copy()
        self._lock = threading.Lock()

    def exchange(self, delta) -> tuple[np.ndarray, np.ndarray]:
        d = np.asarray(delta, dtype=np.int64).reshape(6).copy()
        with self._lock:
            self.deltas.append(d)
            self.ticks += 1
            self._pipe.append(d)
            self.current = self.reference + self._pipe.popleft()
            return self.reference.copy(), self.current.copy()

    def read(self) -> float | None:
        with self._lock:
            self.reads += 1
            cur = self.current.copy()
        if self.laser_mm is not None:
            return self.laser_mm(cur)
        mm = 80.0 + 1e-4 * float(np.sum(cur - self.reference))
        return round(mm, 6) if abs(mm - 80.0) <= 15.0 else None

    def close(self) -> None:
        self.closed = True


class ScriptedLaser:
    """Laser returning the given readings in turn (cycling); None = out of range."""

    def __init__(self, readings):
        self.readings = list(readings)
        self.reads = 0

    def read(self) -> float | None:
        v = self.readings[self.reads % len(self.readings)]
        self.reads += 1
        return v

    def close(self) -> None:
        pass
