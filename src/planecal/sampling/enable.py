"""Enable signals: whether the loop may send the next step.

On the real cell the teach pendant's dead-man switch (DMS) is not wired to the PC. What the
PC does see is its effect: with the DMS released the servo amplifiers are off and the robot
stops following the command, so the commanded counts (reference + delta) run away from the
current counts while a path is being sent. ``FollowingMonitor`` wraps the robot link,
watches that lag on every reply, and drops the enable signal when the lag exceeds
``tolerance_counts`` on any joint for ``ticks`` replies in a row.

- Normal following lag of the FD11 servo at 50 counts/tick is a few hundred counts at most;
  the default 600 counts for 5 ticks leaves margin (both are settings of ``planecal sample``).
- While the robot holds still (dwell, laser read) a released DMS cannot be seen: nothing is
  commanded to move, so nothing can go wrong either. It is seen within about
  tolerance/50 + ticks = 17 ticks (0.17 s) of the next path starting; by then the command
  is at most ~850 counts (< 0.03 rad) ahead, and nothing more is sent.
- The signal latches: once dropped it stays dropped. The run stops cleanly (the sample file
  and sidecar are valid); restart with ``--resume``, which re-reads the FD11 reference
  wherever the robot stands.
"""
from __future__ import annotations

import numpy as np


class FollowingMonitor:
    """A RobotLink wrapper that is also an EnableSignal; see the module docstring."""

    def __init__(self, link, tolerance_counts: int = 600, ticks: int = 5):
        if tolerance_counts <= 0 or ticks <= 0:
            raise ValueError("tolerance and tick count must be positive")
        self.link = link
        self.tolerance_counts = int(tolerance_counts)
        self.ticks = int(ticks)
        self._over = 0
        self._dropped = False
        self.last_lag = 0
        self.reason: str | None = None

    def exchange(self, delta: np.ndarray):
        ref, cur = self.link.exchange(delta)
        lag = int(np.max(np.abs(ref.astype(np.int64) + delta - cur)))
        self.last_lag = lag
        if lag > self.tolerance_counts:
            self._over += 1
            if self._over >= self.ticks and not self._dropped:
                self._dropped = True
                self.reason = (f"robot stopped following the command: lag {lag} counts > "
                               f"{self.tolerance_counts} for {self._over} ticks "
                               f"(dead-man switch released?)")
        else:
            self._over = 0
        return ref, cur

    def enabled(self) -> bool:
        return not self._dropped

    def close(self) -> None:
        self.link.close()
