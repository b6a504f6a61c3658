"""The path check of the collision world (``CollisionWorld.check_path``): a straight
joint-space motion q0 -> q1 certified by conservative advancement, with the world's
bounds and steps (module docstring of ``planecal.safety.collision``: the global and local
bounds, ``_step_sizes``).

Procedure: (1a) every pair at both ends, the target first: cheap lower bounds (bounding
sphere against the static part's box, or sphere against sphere), exact distances only
where a bound is within the clearance; a measured distance <= c + ``resolution_m``
rejects the path; pairs whose end bounds already certify [0, 1] are done. (1b) the other
pairs on ``coarse_samples`` interior grid points, likewise (most rejected paths end in 1a
or 1b); a grid interval [a, b] of a pair is certified when the steps from its ends cover
it, measuring exact distances at the ends of intervals the bounds leave open.
(2) each open interval shrinks by the steps of its ends to [a', b'] and is split at its
midpoint; a', the midpoint and b' are measured exactly, and so on until every interval
is certified, a measurement rejects the path, or a pair exceeds ``max_steps``
refinement rounds ('undecided').
Rejection is always safe; acceptance means every checked pair stays farther than c
everywhere on the segment, in the nominal model with the geometry as given: no false
"clear". ``resolution_m`` ends the slow convergence of steps toward a point where the
distance touches c (a path grazing within 0.1 mm of the clearance is rejected).

Why not ``fcl.continuousCollide``: it certifies a linear or screw *rigid* motion of each
object between two poses; a link under joint interpolation follows neither, so it would
certify a different motion, and it has no clearance.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


class PathWorld(Protocol):
    """What the path check uses of its world (``collision.CollisionWorld``): the settings,
    the pairs, their kinds and rates, the frames, the safe sets, the lower bounds, the
    steps and the exact distances."""
    clearance_m: float
    resolution_m: float
    coarse_samples: int
    max_steps: int
    _pairs: np.ndarray
    _kinds: list[str]
    _W: np.ndarray

    def _frames(self, Q: np.ndarray) -> np.ndarray: ...

    def _covered(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray: ...

    def _lower_bounds(self, F: np.ndarray, idx: np.ndarray, rows: np.ndarray | None = None): ...

    def _step_sizes(self, F, cu, idx, gap, adq, L, rows=None) -> np.ndarray: ...

    def _exact(self, n: int, F: np.ndarray) -> float: ...


@dataclass(frozen=True)
class Rejection:
    """Why a path is not clear: 'self', 'environment' or 'undecided'; the distance
    measured (for 'undecided' the smallest one), the pair and the path parameter."""
    reason: str
    d: float
    n: int
    s: float


class PathCheck:
    """One path's certification (module docstring): ``run()``; ``best`` holds the smallest
    distance measured and its pair (inf, None before any). For a world with pairs and q0,
    q1 within the limits (the world checks those)."""

    def __init__(self, world: PathWorld, q0: np.ndarray, q1: np.ndarray):
        self.world = world
        self.q0, self.q1 = q0, q1
        self.c = world.clearance_m
        self.c_meas = self.c + world.resolution_m  # a measured distance must exceed this
        self.dq = q1 - q0
        self.adq = np.abs(self.dq)
        self.L = world._W @ self.adq
        self.best = (float("inf"), None)
        self.grid = np.linspace(0.0, 1.0, world.coarse_samples + 2)
        K, P = len(self.grid), len(world._pairs)
        self.Fg = world._frames(q0 + self.grid[:, None] * self.dq)
        self.D = np.zeros((K, P))  # distance or lower bound at grid point k of pair n
        self.G = np.zeros((K, P))  # the step it certifies
        self.X = np.zeros((K, P), bool)  # D is exact
        self.CU = np.zeros((K, P, 3))  # centre of the pair's moving part

    def run(self) -> Rejection | None:
        """None when every pair stays farther than the clearance on the whole path, else
        why not."""
        bad, open_pairs = self._ends()
        if bad is not None:
            return bad
        bad, unc = self._interior(open_pairs)
        if bad is not None:
            return bad
        return self._refine(unc)

    # ----- grid points -----

    def _measure(self, n: int, F: np.ndarray, s: float):
        """Exact distance of pair n at frames F, or the rejection if it is <= c_meas."""
        d = self.world._exact(n, F)
        if d < self.best[0]:
            self.best = (d, n)
        if d <= self.c_meas:
            return Rejection(self.world._kinds[n], d, n, s)
        return d

    def _bound(self, rows, cols) -> None:
        self.D[rows, cols], self.CU[rows, cols] = self.world._lower_bounds(self.Fg, cols, rows)

    def _exact(self, rows, cols) -> Rejection | None:
        for k, n in zip(rows, cols):
            if not self.X[k, n]:
                d = self._measure(int(n), self.Fg[k], float(self.grid[k]))
                if isinstance(d, Rejection):
                    return d
                self.D[k, n], self.X[k, n] = d, True
        return None

    def _steps(self, rows, cols) -> None:
        self.G[rows, cols] = self.world._step_sizes(self.Fg, self.CU[rows, cols], cols,
                                                    self.D[rows, cols] - self.c, self.adq,
                                                    self.L[cols], rows)

    def _certify(self, rows, cols, bounds: bool = True) -> Rejection | None:
        """Grid points (rows, cols): lower bounds (``bounds``) and exact distances where
        a bound is within the clearance (all of them without bounds), then the steps
        they certify; the rejection if a distance is within the clearance."""
        if bounds:
            self._bound(rows, cols)
            sel = self.D[rows, cols] <= self.c_meas
            bad = self._exact(rows[sel], cols[sel])
        else:
            bad = self._exact(rows, cols)
        if bad is None:
            self._steps(rows, cols)
        return bad

    # ----- the stages -----

    def _ends(self) -> tuple[Rejection | None, np.ndarray]:
        """1a. Both ends of every pair (the target first: colliding targets are common)
        but those a safe set certifies; exact distances where the bound is within the
        clearance. Returns the rejection or the pairs whose end steps leave the path
        open."""
        K = len(self.grid)
        cols = np.flatnonzero(~self.world._covered(self.q0, self.q1))
        bad = self._certify(np.repeat([K - 1, 0], len(cols)), np.tile(cols, 2))
        if bad is not None:
            return bad, cols
        return None, cols[~(self.G[0, cols] + self.G[K - 1, cols] > 1.0)]

    def _interior(self, R: np.ndarray) -> tuple[Rejection | None, np.ndarray]:
        """1b. The pairs R still open on the interior grid points: bounds, exact distances
        where a bound is within the clearance (most rejected paths end here), then exact
        distances at the ends of the grid intervals still open. Returns the rejection or
        the open intervals (K - 1, P) of the grid."""
        G, grid = self.G, self.grid
        K, P = self.D.shape
        unc = np.zeros((K - 1, P), bool)
        if len(R) and K > 2:
            bad = self._certify(np.repeat(np.arange(1, K - 1), len(R)), np.tile(R, K - 2))
            if bad is not None:
                return bad, unc
            h = np.diff(grid)[:, None]
            unc[:, R] = ~(G[:-1, R] + G[1:, R] > h)
            # exact distances at the ends of the grid intervals still open, test again
            ends = np.zeros((K, P), bool)
            ends[:-1] |= unc
            ends[1:] |= unc
            rows, cols = np.nonzero(ends & ~self.X)
            if len(rows):
                bad = self._certify(rows, cols, bounds=False)
                if bad is not None:
                    return bad, unc
            unc[:, R] = ~(G[:-1, R] + G[1:, R] > h)
        elif len(R):
            unc[0, R] = True
        return None, unc

    def _refine(self, unc: np.ndarray) -> Rejection | None:
        """2. The intervals still open: shrink each by the steps its ends certify and
        split the rest at its midpoint, measuring the three new points exactly, until
        none is open (None), a distance rejects the path, or a pair runs out of
        ``max_steps`` rounds ('undecided')."""
        w, G, grid = self.world, self.G, self.grid
        kk, nn = np.nonzero(unc)
        n_iv = nn
        a_iv, b_iv = grid[kk], grid[kk + 1]
        ga, gb = G[kk, nn], G[kk + 1, nn]
        evals = np.zeros(G.shape[1], int)
        while len(n_iv):
            a2, b2 = a_iv + ga, b_iv - gb
            m = (a2 + b2) / 2
            S = np.concatenate([a2, m, b2])
            nidx = np.concatenate([n_iv, n_iv, n_iv])
            np.add.at(evals, n_iv, 3)
            if np.any(evals > 3 * w.max_steps):
                k = int(np.argmax(evals[n_iv]))
                return Rejection("undecided", self.best[0], int(n_iv[k]), float(a2[k]))
            F = w._frames(self.q0 + S[:, None] * self.dq)
            _, cuN = w._lower_bounds(F, nidx)
            dN = np.empty(len(S))
            for e in range(len(S)):
                bad = self._measure(int(nidx[e]), F[e], float(S[e]))
                if isinstance(bad, Rejection):
                    return bad
                dN[e] = bad
            gN = w._step_sizes(F, cuN, nidx, dN - self.c, self.adq, self.L[nidx])
            r = len(n_iv)
            ga_new = np.concatenate([gN[:r], gN[r:2 * r]])
            gb_new = np.concatenate([gN[r:2 * r], gN[2 * r:]])
            a_new = np.concatenate([a2, m])
            b_new = np.concatenate([m, b2])
            n_new = np.concatenate([n_iv, n_iv])
            open_ = ~(ga_new + gb_new > b_new - a_new)
            n_iv, a_iv, b_iv = n_new[open_], a_new[open_], b_new[open_]
            ga, gb = ga_new[open_], gb_new[open_]
        return None
