"""Laser read (seed 7.1.3): wait for a stable distance, one reading per 10 ms tick.

Every tick the loop sends the hold delta to the robot link (so the RT link keeps running)
and reads the laser once. The readings are asked for in blocks (``take(n)``: n ticks, one
reading each), each block as long as the fewest ticks before anything can be decided (the
buffer cannot be full, or cannot lose its extremes, or the out-of-range count cannot
reach its limit, before then), and the block is then read one reading after the other:
the same ticks go out, and the same sample comes out, as reading tick by tick. In-range readings go into a circular buffer of ``buffer_len``
(100) readings; out-of-range readings (the ZS-LD80's 0, ``None`` here) are not stored and
do not clear the buffer.

- **sample**: as soon as the buffer is full and its spread max - min is below ``spread_mm``
  (0.005 mm), the sample value is the buffer's *mean* (the seed does not say which value it
  keeps; the mean of 100 readings that agree within 5 um is the least noisy choice).
- **give up, out of range**: ``max_out_of_range`` (400) out-of-range readings in a row
  (reason ``"out_of_range"``).
- **give up, not stable**: ``max_reads`` (1000) readings in all without a stable buffer, so a
  noisy sensor cannot hang the run (reason ``"not_stable"``, the last spread is reported).

The laser never holds a tick (issue 16): on the real cell the read is a per-tick poll
(``ZSLD80.poll``, at most 5 ms), and a tick whose reply has not come yet gives
``NO_READING_MM`` (-inf): not a measurement and not out of range. It is skipped -- nothing
stored, the out-of-range run not advanced (a slow sensor is not a plate out of reach) --
but it counts as a read against ``max_reads``, so a silent sensor still ends the read
(and its timeouts, ``--laser-error-limit``, the run). The hold delta goes out on every one
of those ticks: the RT link keeps its 10 ms rhythm while the reply is awaited.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np


NO_READING_MM = float("-inf")  # a tick whose laser reply has not come yet (module doc)


@dataclass
class LaserSettings:
    buffer_len: int = 100
    spread_mm: float = 0.005
    max_out_of_range: int = 400
    max_reads: int = 1000

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class LaserResult:
    value_mm: float | None  # buffer mean, or None when given up
    reason: str  # "stable", "out_of_range" or "not_stable"
    reads: int  # readings (= ticks) used
    spread_mm: float | None  # spread of the final buffer (None if it never filled)
    out_of_range: int  # out-of-range readings in all

    @property
    def ok(self) -> bool:
        return self.value_mm is not None

    def describe(self) -> str:
        if self.ok:
            return f"stable after {self.reads} reads: {self.value_mm:.4f} mm"
        if self.reason == "out_of_range":
            return f"gave up: {self.out_of_range} out-of-range reads in a row"
        spread = "never filled" if self.spread_mm is None else f"{self.spread_mm * 1e3:.1f} um"
        return f"gave up: not stable within {self.reads} reads (buffer spread {spread})"


def read_stable(take: Callable[[int], np.ndarray],
                settings: LaserSettings | None = None) -> LaserResult:
    """Read ``take(n)`` (n ticks holding still, one reading each: an array of n readings
    in mm, NaN or 0 for none, ``NO_READING_MM`` for a reply not come yet; it may raise to
    stop the run) until the reading is stable or the reader gives up; see the module
    docstring."""
    s = settings or LaserSettings()
    n = s.buffer_len
    buf = np.empty(n)
    filled = head = in_a_row = out_total = reads = 0
    spread = None
    while reads < s.max_reads:
        if filled < n:
            need = n - filled
        else:  # full, not stable: the oldest readings that must leave before it can be
            old = np.roll(buf, -head)  # oldest first
            top = np.maximum.accumulate(old[::-1])[::-1]
            low = np.minimum.accumulate(old[::-1])[::-1]
            ok = np.flatnonzero(top[1:] - low[1:] < s.spread_mm)
            need = int(ok[0]) + 1 if ok.size else n
        need = min(need, s.max_out_of_range - in_a_row, s.max_reads - reads)
        for v in take(need):
            reads += 1
            if v == NO_READING_MM:  # no reply yet this tick: skipped, but a read
                continue
            if not v == v or v == 0.0:  # NaN (none) or the sensor's 0
                in_a_row += 1
                out_total += 1
                if in_a_row >= s.max_out_of_range:
                    return LaserResult(None, "out_of_range", reads, spread, out_total)
                continue
            in_a_row = 0
            buf[head] = v
            head = (head + 1) % n
            if filled < n:
                filled += 1
                if filled < n:
                    continue
            spread = float(buf.max() - buf.min())
            if spread < s.spread_mm:
                return LaserResult(float(buf.mean()), "stable", reads, spread, out_total)
    return LaserResult(None, "not_stable", s.max_reads, spread, out_total)
