"""Step generator (seed 7.1.2): a synchronized, integer joint-space interpolator in
encoder counts.

The FD11 takes, every 10 ms tick, a delta (commanded = reference + delta) and trips with an
encoder-jump error when consecutive deltas differ by 60 counts or more on any joint. A path
from delta ``start`` to delta ``goal`` (int64[6]) is cut into

    n = ceil(max_j |goal_j - start_j| / nominal)

ticks, ``nominal`` the robot's step (``Robot.step_counts``: one count below robot.json's
``controller.max_step_counts``; the MC70's FD11: 50 counts, its trip at 60); row k (k = 1..n) is ``start + round(dq * k / n)`` with round-half-up in exact integer
arithmetic (cumulative rounding, no drift): every joint moves in proportion, all of them
arrive on tick n, the last row is exactly ``goal``. A step is the difference of two
roundings of values |dq|/n <= nominal apart, each off by at most 1/2, so it is strictly
less than nominal + 1 in magnitude: at most ``nominal`` counts (the MC70: 50, within the
seed's 51; the seed rounds the number of via-points down and the step size up, hence its
51).

At the goal the last row is repeated ``dwell`` times (the seed's 5 identical deltas, 50 ms at
100 Hz) before the laser is read.
"""
from __future__ import annotations

import numpy as np

MAX_STEP = 51  # the seed's step limit of the FD11 (the MC70's robot.json)
DWELL_TICKS = 5
COUNT_LIMIT = 1 << 24


def n_steps(start, goal, nominal: int) -> int:
    """Number of ticks to go from ``start`` to ``goal`` (0 when they are equal)."""
    dq = np.asarray(goal, np.int64) - np.asarray(start, np.int64)
    m = int(np.max(np.abs(dq))) if dq.size else 0
    return -(-m // int(nominal))


def step_path(start, goal, nominal: int, dwell: int = 0) -> np.ndarray:
    """Rows of absolute deltas (n + dwell, 6) int64 to send, one per tick, from ``start``
    (the last delta sent, not included) to ``goal`` (included, then repeated ``dwell``
    times). With start == goal only the dwell rows are returned."""
    start = np.asarray(start, np.int64)
    goal = np.asarray(goal, np.int64)
    if start.shape != goal.shape:
        raise ValueError("start and goal must have the same shape")
    if nominal < 1:
        raise ValueError("nominal step must be at least 1 count")
    dq = goal - start
    n = n_steps(start, goal, nominal)
    k = np.arange(1, n + 1, dtype=np.int64)[:, None]
    # round(dq * k / n), half up, in integers: floor((2 dq k + n) / (2 n))
    rows = start + (2 * dq * k + n) // (2 * n) if n else np.zeros((0,) + start.shape, np.int64)
    if dwell:
        rows = np.concatenate([rows, np.repeat(goal[None], dwell, axis=0)])
    return rows


def max_step(start, rows) -> int:
    """Largest per-joint change between consecutive rows (``start`` precedes row 0)."""
    rows = np.asarray(rows, np.int64)
    if len(rows) == 0:
        return 0
    full = np.concatenate([np.asarray(start, np.int64)[None], rows])
    return int(np.max(np.abs(np.diff(full, axis=0))))
