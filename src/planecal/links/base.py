"""The two small interfaces the sampling loop talks to, and the enable signal.

The same loop drives the in-process twin or the real cell (FD11 RT link over UDP,
ZS-LD80 over a serial port): it only ever sees these.
"""
from __future__ import annotations

from typing import Protocol

import numpy as np


class RobotLink(Protocol):
    def exchange(self, delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One 10 ms tick: send int64[6] delta counts (commanded = reference + delta),
        return (reference_counts, current_counts), both int64[6]."""

    def close(self) -> None: ...


class Laser(Protocol):
    def read(self) -> float | None:
        """One reading in mm; None when out of range (the sensor's raw 0)."""

    def close(self) -> None: ...


class EnableSignal(Protocol):
    def enabled(self) -> bool: ...


class AlwaysEnabled:
    """The twin's default dead-man switch: held."""

    def enabled(self) -> bool:
        return True
