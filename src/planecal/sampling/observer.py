"""What the sampling loop tells an observer (e.g. a Rerun recording); the loop never
depends on what it does with it."""
from __future__ import annotations

from typing import Protocol

import numpy as np


class Observer(Protocol):
    """Hooks of the sampling loop. ``q`` are joint angles [rad] (nominal encoder model),
    counts int64[6]."""

    def on_ticks(self, first_tick: int, deltas: np.ndarray, reference: np.ndarray,
                 current: np.ndarray, laser_mm: np.ndarray) -> None:
        """Ticks ``first_tick ..`` (1-based, in the driver's count): the deltas sent
        (n, 6), the reference counts, the current counts (n, 6) and the laser readings
        (n,) in mm, NaN where none was read or the laser gave none."""

    def on_sample(self, index: int, qe: np.ndarray, d_mm: float, plate: int) -> None: ...

    def on_reject(self, q_target: np.ndarray | None, reason: str) -> None: ...

    def on_path(self, kind: str, q_start: np.ndarray, q_goal: np.ndarray,
                rows: np.ndarray) -> None: ...


class RecordingObserver(Observer, Protocol):
    """An observer that writes a recording: ``path`` is the file it writes (None: a live
    view only), ``live`` where a live view is served (None: none), ``dropped_ticks`` the
    ticks of motion a live view dropped rather than hold the loop; ``close()`` finishes it
    (the commands call it when the session ends, whatever happened)."""
    path: object
    live: object
    dropped_ticks: int

    def close(self) -> None: ...


class NullObserver:
    """Does nothing; subclass it and override what you need."""

    def on_ticks(self, first_tick, deltas, reference, current, laser_mm):
        pass

    def on_sample(self, index, qe, d_mm, plate):
        pass

    def on_reject(self, q_target, reason):
        pass

    def on_path(self, kind, q_start, q_goal, rows):
        pass
