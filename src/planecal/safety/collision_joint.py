"""One-joint pairs of the collision checker: self pairs that one joint alone decides.

A self pair whose parts sit two bodies apart (lower body i, upper body i + 2) moves with
two joints, i + 1 and i + 2. Where one of its parts is nearly a solid of revolution about
one of those joints' axes, replace that part by its *hull of revolution*: the cylinder
about the axis that holds it in every rotation of that joint (radius the part's largest
distance from the axis, length its extent along it; a circumscribed 64-gon prism, so the
polytope holds the cylinder). Then only the other joint changes the pair's distance:

* upper part's hull about joint i + 2's axis (z_{i+1}): the hull is fixed in frame i + 1,
  and joint i + 1 alone moves it against the lower part;
* lower part's hull about joint i + 1's axis (z_i): the hull is fixed in frame i and, being
  round about that axis, in frame i + 1 too; joint i + 2 alone moves the upper part
  against it.

On the MC70 these are the wrist fork against the flange and the tool adapter (discs on
the J6 axis: J5 decides), the base against the upper arm (a column on the J1 axis: J2
decides). Their distances change slowly with the joint but are small, so the path
certification spent half of its exact distance queries on them.

Once per world, each such (pair, hull) is swept over its joint's whole range by
conservative advancement: at angle t the exact distance d to the hull gives
|d(t') - d| <= rho |t' - t| (rho: the moving object's largest distance from the joint
axis), so the interval [t, t + (d - c) / rho) is certified farther than the clearance c;
where d < c the next (c - d) / rho are surely closer than c and are skipped; near the
boundary the steps fall below ``RESOLUTION_RAD`` and the sweep walks on uncertified in
steps of that size. The certified pieces, merged, are the pair's *safe intervals*.

The hull holds the part in every configuration, so a distance to the hull is a lower
bound of the distance to the part: a configuration, or a straight joint path, whose angle
of that joint stays inside one safe interval is clear for that pair, and the checker
skips the pair there (``SafeSet.covers``). Elsewhere the pair is checked as before, so the
safe sets only accept what is certified and never reject.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

HULL_SECTIONS = 64  # sides of the circumscribed prism of a hull of revolution
RESOLUTION_RAD = 1e-3  # the sweep's smallest step [rad]
SAFETY = 0.999  # certified steps are shortened by this factor (closed intervals)


@dataclass(frozen=True)
class SafeSet:
    """Where one joint keeps one pair clear: sorted, disjoint closed intervals
    [lo[k], hi[k]] of joint ``joint`` (0-based) on which pair ``pair`` (index into the
    world's checked pairs) is certified farther than the clearance."""
    pair: int
    joint: int
    lo: np.ndarray
    hi: np.ndarray
    hull: str  # which part was replaced by its hull of revolution, for the docs/tests

    def covers(self, a: float, b: float) -> bool:
        """Are the angles between a and b (either order) all in one safe interval?"""
        lo, hi = (a, b) if a <= b else (b, a)
        k = int(np.searchsorted(self.lo, lo, side="right")) - 1
        return k >= 0 and hi <= self.hi[k]

    @property
    def safe_rad(self) -> float:
        """Total length of the safe intervals [rad]."""
        return float(np.sum(self.hi - self.lo))


def axis_distance_max(V: np.ndarray, A: np.ndarray) -> float:
    """Largest distance of points V (link frame m) from joint m's axis: in the frame that
    turns with joint m (z the axis, origin on it) they sit at A V
    (``kinematics.joint_between_links``), and the turn about z leaves the distance."""
    X = axis_coordinates(V, A)
    return float(np.hypot(X[:, 0], X[:, 1]).max())


def axis_coordinates(V: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Points V of link frame m in joint m's turning frame at joint angle 0: A V (for a
    standard DH row, Rx(alpha) V + (a, 0, d))."""
    return V @ A[:3, :3].T + A[:3, 3]


def hull_of_revolution(X: np.ndarray) -> tuple[float, float, float]:
    """(radius, z_lo, z_hi) of the cylinder about the z axis holding points X."""
    return float(np.hypot(X[:, 0], X[:, 1]).max()), float(X[:, 2].min()), float(X[:, 2].max())


def sweep(distance: Callable[[float], float], lo: float, hi: float, rho: float,
          clearance: float, c_meas: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Safe intervals of one joint over [lo, hi] (module docstring): (starts, ends,
    number of distance queries). ``distance(t)`` is the exact distance at angle t;
    a measured distance must exceed ``c_meas`` to start a certified piece."""
    starts, ends = [], []
    t, n = lo, 0
    while t <= hi:
        d = distance(t)
        n += 1
        step = SAFETY * (d - clearance) / rho if rho > 0 else np.inf
        if d > c_meas and step >= RESOLUTION_RAD:
            end = min(t + step, hi)
            if ends and ends[-1] == t:  # contiguous with the previous piece
                ends[-1] = end
            else:
                starts.append(t)
                ends.append(end)
            if end >= hi:
                break
            t = end
        elif d < clearance and rho > 0:  # d(t') <= d + rho |t' - t|: surely too close
            t += max((clearance - d) / rho, RESOLUTION_RAD)
        else:
            t += RESOLUTION_RAD
    return np.array(starts), np.array(ends), n
