"""The twin's own whole true model, inverted: what ``planecal validate`` calls the oracle,
the floor of a model that knows every error source of the world.

``TrueModel(twin, standoff_m)`` finds the encoder counts at which the twin's deterministic
map puts its true tool point (the beam point at the measuring centre, of the true sensor
pose) on a target, with the flange at a target orientation, the pose approached from a
given direction. The map is the twin's own:

* counts -> joint row: ``Twin.joint_map``, the tick's ``joint_row`` with the world's true
  joint offsets, gear error (its harmonics and phases), gravity compliance (its stiffness,
  the links' masses and the payload) and, given each joint's approach direction, its
  backlash on the flank that direction (or gravity above the preload) leaves it on;
  without what depends on the rest (repeatability, the motors' sub-count draw);
* joint row -> flange and sensor: MuJoCo's sites on the world's model (the true link
  geometry, base and flange frames, the true sensor pose).

It shares no code with the calibration's model (``planecal.model.measurement``,
``estimation.compensate``): its Jacobian is central differences in counts, its forward
kinematics MuJoCo's, so a floor measured with it cannot share a bug with a calibration.
What it leaves when the twin drives there: the rounding to whole counts, repeatability
and quantisation, a flank the approach direction does not predict (a joint at its preload's
edge; a detour's last leg), and thermal growth, which the map does not follow (it is the
map at the twin's start). Without a direction it does not know the backlash (it leaves
it: what it did before issue 31).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

TOL_M = 1e-10  # solved: the tool point within 0.1 nm of the target ...
TOL_RAD = 1e-10  # ... and the flange within 0.1 nrad of its orientation
MAX_ITER = 20
STEP_COUNTS = 1.0  # the central differences' step (the map is smooth over many counts)


class TrueModel:
    """The twin's whole true model (module docstring). ``tool_in_flange``: the true tool
    point in the true flange frame (3,) [m]."""

    def __init__(self, twin, standoff_m: float):
        self.twin, self.standoff_m = twin, float(standoff_m)
        F, _ = self.pose(twin.current_counts)
        tool = self.tool_point(twin.current_counts)
        self.tool_in_flange = F[:3, :3].T @ (tool - F[:3, 3])

    def pose(self, counts, direction=None) -> tuple[np.ndarray, np.ndarray]:
        """(flange, sensor) 4x4 in the cell frame at ``counts`` (fractional allowed),
        approached from ``direction`` (``Twin.joint_map``; None: no backlash)."""
        return self.twin.site_poses_at(self.twin.joint_map(counts, direction))

    def tool_point(self, counts, direction=None) -> np.ndarray:
        _, S = self.pose(counts, direction)
        return S[:3, 3] + self.standoff_m * S[:3, 2]

    def tool_points(self, counts, direction=None) -> np.ndarray:
        """(N, 3): the true tool point at each row of ``counts`` (N, 6), each approached
        from its row of ``direction`` (N, 6; None: no backlash), cell frame."""
        d = [None] * len(counts) if direction is None else direction
        return np.array([self.tool_point(c, di) for c, di in zip(counts, d)])

    def _error(self, x, R, p, direction=None) -> np.ndarray:
        F, S = self.pose(x, direction)
        tool = S[:3, 3] + self.standoff_m * S[:3, 2]
        return np.concatenate([p - tool, Rotation.from_matrix(R @ F[:3, :3].T).as_rotvec()])

    def solve(self, R: np.ndarray, p: np.ndarray, x0,
              direction=None) -> tuple[np.ndarray, bool, int]:
        """Fractional counts (6,) with the true flange's rotation R and the true tool point
        at p (cell frame), approached from ``direction``, by Newton from ``x0`` on central
        differences: (counts, converged, iterations)."""
        x = np.asarray(x0, float).copy()
        h = STEP_COUNTS
        for it in range(MAX_ITER + 1):
            e = self._error(x, R, p, direction)
            if np.linalg.norm(e[:3]) < TOL_M and np.linalg.norm(e[3:]) < TOL_RAD:
                return x, True, it
            if it == MAX_ITER:
                break
            J = np.empty((6, 6))
            for j in range(6):
                d = np.zeros(6)
                d[j] = h
                J[:, j] = (self._error(x + d, R, p, direction)
                           - self._error(x - d, R, p, direction)) / (2 * h)
            x -= np.linalg.solve(J, e)
        return x, False, MAX_ITER

    def command(self, R: np.ndarray, p: np.ndarray, counts0,
                direction=None) -> tuple[np.ndarray | None, float]:
        """Whole counts for the target (``solve``, rounded) approached from ``direction``,
        and the tool point's distance from p there [m] (the rounding's share of the
        floor); (None, nan) if it did not converge."""
        x, ok, _ = self.solve(R, p, counts0, direction)
        if not ok:
            return None, float("nan")
        c = np.rint(x).astype(np.int64)
        return c, float(np.linalg.norm(self.tool_point(c, direction) - p))
