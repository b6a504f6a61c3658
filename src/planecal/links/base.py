"""The small interfaces the sampling loop talks to, and the enable signal.

The same loop drives the in-process twin or the real cell (FD11 RT link over UDP,
ZS-LD80 over a serial port): it only ever sees these.

* ``RobotLink`` + ``Laser``: one 10 ms tick at a time (the real cell, the emulators).
* ``MoveLink``: a robot and its laser that take a whole move in one call (the twin): for
  each row of deltas one tick and, when asked, one laser reading.
* ``EnableSignal``: whether the next step may be sent; ``EnableAhead`` also reserves,
  before a move, the ticks it stays enabled for (a signal known ahead, such as the
  twin's held dead-man switch), so a whole move can be handed over in one call.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class RobotLink(Protocol):
    def exchange(self, delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One 10 ms tick: send int64[6] delta counts (commanded = reference + delta),
        return (reference_counts, current_counts), both int64[6]."""

    def close(self) -> None: ...


@runtime_checkable
class Laser(Protocol):
    def read(self) -> float | None:
        """One reading in mm; None when out of range (the sensor's raw 0)."""

    def close(self) -> None: ...


@runtime_checkable
class MoveLink(Protocol):
    def run(self, deltas: np.ndarray, read: bool = True
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One tick per row of ``deltas`` (N, 6) and, with ``read``, one laser reading per
        tick: (reference int64[6], current counts int64[N, 6], readings float[N] mm,
        NaN where none)."""

    def close(self) -> None: ...


@runtime_checkable
class EnableSignal(Protocol):
    def enabled(self) -> bool: ...


@runtime_checkable
class EnableAhead(Protocol):
    def enabled(self) -> bool: ...

    def reserve(self, ticks: int) -> int:
        """How many of the next ``ticks`` ticks may go out (0 when the signal is down);
        the caller then sends exactly that many."""


class AlwaysEnabled:
    """The twin's default dead-man switch: held."""

    def enabled(self) -> bool:
        return True

    def reserve(self, ticks: int) -> int:
        return ticks
