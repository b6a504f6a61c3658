"""The approach direction: per joint, the sign of its last motion, followed from the
robot's measured (current) encoder counts of every tick (``driver.Driver`` feeds it).

A joint's motion is its joint-side motion through the encoder model
(``planecal.model.encoder``): from one tick's counts to the next, dq = M (counts - previous
counts), M = C diag(1/g) (the gains and the wrist coupling), so a J4 or J5 motor turning
moves J5 and J6 on the joint side even when their own motors stand still. When dq_j is
nonzero, joint j's side becomes its sign (+1, -1); a joint that did not move keeps its
side; 0 means it has not moved since the tracker began (a new driver: a run's session, a
resumed session), so its side is unknown. This is the rule the twin's backlash follows
(``planecal.twin.ticks``, step 4), with dq summed in the same order, so the two agree bit
for bit; on the real robot it is the side the gears were last driven to.

A sample records the sides when its laser reading is taken (``collect.Acquired``): the
whole path into the pose counts, detour legs included, not the difference between one
sample's counts and the last's.
"""
from __future__ import annotations

import numpy as np


class ApproachTracker:
    """The sides (-1, 0, +1 per joint) of the last joint-side motion seen (module
    docstring). ``follow(rows)`` takes the measured counts of consecutive ticks."""

    def __init__(self, coupling: np.ndarray, gains: np.ndarray):
        self.M = np.asarray(coupling, float) / np.asarray(gains, float)[None, :]
        self.n = len(self.M)
        self._side = np.zeros(self.n, np.int8)
        self._last: np.ndarray | None = None

    @classmethod
    def for_robot(cls, robot) -> "ApproachTracker":
        return cls(robot.coupling, robot.gains)

    @property
    def side(self) -> np.ndarray:
        """A copy of the current sides, int8 (n_joints,)."""
        return self._side.copy()

    def follow(self, rows: np.ndarray) -> None:
        """The measured counts (k, n) of the next k ticks, in order."""
        rows = np.asarray(rows, np.int64).reshape(-1, self.n)
        if not len(rows):
            return
        steps = np.diff(rows if self._last is None else np.vstack([self._last, rows]), axis=0)
        self._last = rows[-1].copy()
        if not steps.any():
            return
        x = steps.astype(float)
        dq = np.zeros(x.shape)
        for c in range(self.n):  # column by column, as the twin's tick sums (bit for bit)
            dq += x[:, c:c + 1] * self.M[None, :, c]
        moved = dq != 0.0
        joints = np.flatnonzero(moved.any(axis=0))
        last = len(dq) - 1 - np.argmax(moved[::-1, joints], axis=0)
        self._side[joints] = np.sign(dq[last, joints]).astype(np.int8)


APPROACH_TICKS = 4  # a chosen approach's last leg: every motor this many steps of the robot
# (the MC70: 200 counts, 3.6-8.2 mrad a joint, far more than the reducers' lost motion, at
# most 1 arcmin = 291 urad, docs/ERRORS.md), longer than a servo's lag behind a move at the
# robot's step (the realistic twin's 30 ms: 3 ticks, 150 counts), so each motor's last
# motion is the leg's whatever the move before it did


def approach_point(robot, q: np.ndarray, side: int, qe0=None):
    """Where a move into joint angles ``q`` that ends with every joint moving towards
    ``side`` (+1: each joint's last motion positive, -1: negative) starts its last leg:
    (joint angles, counts), every motor ``APPROACH_TICKS`` of the robot's step short of
    q's counts, on the side that moves its joint towards ``side`` (the wrist's coupling
    adds a percent of the other motors' motion). None where a joint would not move
    towards ``side`` on the leg."""
    from planecal.model.encoder import counts_to_joints, joints_to_counts
    c = joints_to_counts(robot, q, qe0)
    gains = np.asarray(robot.gains, float)
    dc = (-np.sign(side) * np.sign(gains) * APPROACH_TICKS * robot.step_counts).astype(np.int64)
    moved = (np.asarray(robot.coupling, float) / gains[None, :]) @ (-dc).astype(float)
    if np.any(np.sign(moved) != np.sign(side)):
        return None
    ca = c + dc
    return counts_to_joints(robot, ca, qe0), ca
