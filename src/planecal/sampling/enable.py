"""Enable signals: whether the loop may send the next step.

On the real cell the teach pendant's dead-man switch (DMS) is not wired to the PC. What the
PC does see is its effect: with the DMS released the servo amplifiers are off and the robot
stops following the command, so the commanded counts (reference + delta) run away from the
current counts while a path is being sent. ``FollowingMonitor`` wraps the robot link,
watches that gap on every reply, and drops the enable signal before it can grow past
what a following servo ever shows.

The limit on commanded - current (derived; all per joint, in encoder counts)
--------------------------------------------------------------------------
The FD11 servo follows the command like a first-order lag (time constant tau, the twin's
``servo='lag'``): each 10 ms tick it moves g = 1 - exp(-tick / tau) of the gap
commanded - current. The FD11 takes at most 60 counts of change per tick (seed 7.1.2,
robot.json ``trip_step_counts``); a gap G is taken up by a first tick of g * G counts, so
the largest gap a servo ever takes up within that limit is

    limit = trip / g            = 60 / 0.2835 = 211 counts   (tau 30 ms, tick 10 ms)

While following at v counts a tick, the gap settles at v (1 - g) / g at each reply (126
counts at 50/tick, 129 at the step generator's largest 51) and v / g just after the next
step is sent (176, 180): below the limit, with 31 counts to spare (the limit is exceeded
in normal following only if the real tau were above 36 ms: measure it on the cell and
pass ``tau_s``). A released switch stops the robot: the gap then grows by the whole step,
51 counts a tick.

The rule: after each reply, if on any joint |commanded - current| + max_step > limit
(the next step could take the gap past the limit), the enable signal drops and nothing
more is sent. So commanded - current never exceeds the limit (211 counts), whatever the
robot does. Released at full speed, the drop comes at the first reply after the robot
stopped (gap 180 + 51 > 211) with the command 180 counts ahead; released at rest, the
next path shows it after its fourth step (gaps 51, 102, 153, 204; 204 + 51 > 211) with the
command 204 counts ahead. The old rule (600 counts for 5 ticks) let 18 steps and 849
counts through. While the robot holds still (dwell, laser read) a released switch cannot
be seen: nothing is commanded to move, so nothing can go wrong either.
``exchange`` also refuses (``NotFollowing``, nothing sent) a delta that would put the
command more than the limit ahead of the last current counts: a second line of defence
for callers that do not ask ``enabled()`` first.

A reply can be a tick old (a late UDP reply taken as the next tick's answer,
``planecal.links.fd11``); at full speed that reads as a gap of about 180 and drops the
signal: a false stop, which ends the run cleanly (``--resume`` continues it), never a
missed one.

The signal latches: once dropped it stays dropped. The run stops cleanly (the sample file
and sidecar are valid); continue with ``--resume`` once the switch is held again.
"""
from __future__ import annotations

import math

import numpy as np

SERVO_TAU_S = 0.03  # the FD11 servo's time constant as the twin models it (TwinOptions.tau_s)


class NotFollowing(RuntimeError):
    """A delta was refused: it would put the command too far ahead of the robot."""


def follow_limit_counts(trip_counts: int = 60, tau_s: float = SERVO_TAU_S,
                        tick_s: float = 0.01) -> int:
    """The largest commanded - current a first-order servo (time constant ``tau_s``) takes
    up without moving more than ``trip_counts`` in its first tick: floor(trip / g)."""
    if not (tau_s > 0 and tick_s > 0 and trip_counts > 0):
        raise ValueError("trip_counts, tau_s and tick_s must be positive")
    g = -math.expm1(-tick_s / tau_s)
    return int(math.floor(trip_counts / g + 1e-9))


class FollowingMonitor:
    """A RobotLink wrapper that is also an EnableSignal; see the module docstring.

    ``limit_counts``: the largest commanded - current ever allowed (default
    `follow_limit_counts` of ``trip_counts``, ``tau_s``, ``tick_s``); ``max_step_counts``:
    the largest step the loop sends (robot.json, 51)."""

    def __init__(self, link, limit_counts: int | None = None, *, max_step_counts: int = 51,
                 tau_s: float = SERVO_TAU_S, tick_s: float = 0.01, trip_counts: int = 60):
        if limit_counts is None:
            limit_counts = follow_limit_counts(trip_counts, tau_s, tick_s)
        if max_step_counts <= 0 or limit_counts <= max_step_counts:
            raise ValueError(f"the following limit ({limit_counts} counts) must exceed the "
                             f"largest step ({max_step_counts} counts)")
        self.link = link
        self.limit_counts = int(limit_counts)
        self.max_step_counts = int(max_step_counts)
        self._reference: np.ndarray | None = None
        self._current: np.ndarray | None = None
        self._dropped = False
        self.last_lag = 0  # |commanded - current| at the last reply, largest joint
        self.max_lag = 0   # the largest of those
        self.reason: str | None = None

    def exchange(self, delta: np.ndarray):
        delta = np.asarray(delta, np.int64)
        if self._current is not None:
            ahead = np.abs(self._reference + delta - self._current)
            if int(ahead.max()) > self.limit_counts:
                j = int(np.argmax(ahead))
                self._drop(f"a step refused: it would put the command {int(ahead[j])} counts "
                           f"ahead of joint {j + 1} (limit {self.limit_counts})")
                raise NotFollowing(self.reason)
        ref, cur = self.link.exchange(delta)
        self._reference = np.asarray(ref, np.int64)
        self._current = np.asarray(cur, np.int64)
        gap = np.abs(self._reference + delta - self._current)
        j = int(np.argmax(gap))
        self.last_lag = int(gap[j])
        self.max_lag = max(self.max_lag, self.last_lag)
        if self.last_lag + self.max_step_counts > self.limit_counts:
            self._drop(f"robot stopped following the command: joint {j + 1} is "
                       f"{self.last_lag} counts behind it, one more step could take the gap "
                       f"past {self.limit_counts} (dead-man switch released?)")
        return ref, cur

    def _drop(self, reason: str) -> None:
        if not self._dropped:
            self._dropped = True
            self.reason = reason

    def enabled(self) -> bool:
        return not self._dropped

    def close(self) -> None:
        self.link.close()
