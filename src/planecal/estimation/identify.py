"""Which parameters the data can identify: a base set chosen from the Jacobian of the
samples at hand (issue 13, item 2; FIGAROH's "base parameters by QR").

The columns of the free parameters are scaled to unit norm (units and magnitudes do not
matter), then a rank-revealing QR with column pivoting (``scipy.linalg.qr(...,
pivoting=True)``) orders them: A P = Q R with |R_00| >= |R_11| >= ... Column k of the
pivot order adds |R_kk| of new information to the columns before it; where |R_kk| /
|R_00| falls below ``tol`` the rest are combinations of the ones before (to the data's
first order). The first ``rank`` pivots are the base set, the fit frees them only; every
other free parameter is left at its initial value, with its reason:

* ``no_effect``: its column is zero (it changes no distance of these samples);
* ``combination``: its column is a combination of the base set's,
  J_e = sum_k coef_k J_k (least squares on the base columns; the coefficients unscaled to
  SI units: moving e by 1 changes every distance as moving each base parameter k by coef_k).

Which member of a degenerate family stays is a choice, not a physical claim: delta1 and
the planes' rotation about the base z axis, say, are one direction, and either can carry
it. The choice made here: level 1's parameters first (pivoted among themselves), then the
rest pivoted on what those leave unexplained (``prefer``). So the planes carry the base
frame (which moves every plane alike) and a level-2 parameter enters the base set only
for what level 1 cannot express: a prior towards the nominal geometry
(``FitOptions.prior``) then acts on the robot, not on a stand-in for the planes.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.linalg

from planecal.model.layout import ParamLayout

DEFAULT_TOL = 1e-6  # |R_kk| / |R_00| below this: a combination of the columns before


@dataclass(frozen=True)
class Excluded:
    parameter: str
    reason: str  # "no_effect" | "combination" | "scale"
    combination: dict = field(default_factory=dict)  # base parameter -> coefficient (SI)

    def describe(self) -> str:
        if self.reason == "no_effect":
            return f"{self.parameter}: no effect on any distance of these samples"
        if self.reason == "scale":
            return (f"{self.parameter}: sets the arm's scale, which a distance sensor reads "
                    "only through its own gain: kept at robot.json's value (--free-scale "
                    "frees it where a length reference fixes the scale)")
        mix = " ".join(f"{v:+.4g}*{k}" for k, v in self.combination.items())
        return f"{self.parameter}: a combination of others (acts as {mix})"


@dataclass(frozen=True)
class BaseSet:
    free: list[str]  # the candidates (the free parameters before the selection)
    base: list[str]  # the identifiable base set, in layout order
    excluded: list[Excluded]
    rank: int
    r_ratios: list[float]  # |R_kk| / |R_00| in pivot order
    pivot_order: list[str]
    tol: float

    def to_dict(self) -> dict:
        return asdict(self)

    def mask(self, layout: ParamLayout) -> np.ndarray:
        return layout.mask(self.base)


LEVEL1_KINDS = ("joint_offsets", "sensor_origin", "sensor_angles", "plane")


def _pivoted(A: np.ndarray):
    """|diag R| and the pivot order of A's pivoted QR, and the orthonormal Q."""
    Q, R, piv = scipy.linalg.qr(A, mode="economic", pivoting=True)
    return np.abs(np.diag(R)), piv, Q


def select_base(J: np.ndarray, layout: ParamLayout, free: np.ndarray,
                tol: float = DEFAULT_TOL, weights: np.ndarray | None = None,
                prefer: tuple[str, ...] = LEVEL1_KINDS) -> BaseSet:
    """The base set of identifiable parameters among ``free`` (mask over the layout) for
    the Jacobian J (N, len(layout)) of the samples at hand (module docstring). ``weights``:
    row weights (a weighted fit's), default none. ``prefer``: kinds chosen first (level
    1's: the planes, sensor and offsets carry what they can, so that the base frame and
    d1, which move every plane alike, are the ones named as combinations of the planes);
    the other columns are pivoted on what the preferred base set leaves unexplained."""
    free = np.asarray(free, bool)
    names = layout.names_of(free)
    kind_of = {p.name: g.kind for g in layout.groups for p in g.params}
    Jf = np.asarray(J, float)[:, free]
    if weights is not None:
        Jf = Jf * weights[:, None]
    norms = np.linalg.norm(Jf, axis=0)
    top = norms.max() if norms.size else 0.0
    dead = norms <= 1e-12 * top if top > 0 else np.ones(len(names), bool)
    S = np.where(dead, 0.0, 1.0 / np.where(dead, 1.0, norms))
    A = Jf * S  # unit columns
    excluded = [Excluded(names[j], "no_effect") for j in np.flatnonzero(dead)]
    first = np.array([j for j in range(len(names)) if not dead[j] and kind_of[names[j]] in prefer], int)
    second = np.array([j for j in range(len(names)) if not dead[j] and kind_of[names[j]] not in prefer], int)
    order, ratios, base_idx = [], [], []
    Qb = np.zeros((A.shape[0], 0))
    for cols in (first, second):
        if cols.size == 0:
            continue
        B = A[:, cols] - Qb @ (Qb.T @ A[:, cols])  # what the base set so far leaves
        diag, piv, Q = _pivoted(B)
        rk = diag >= tol  # columns have unit norm: |R_kk| is the share of new information
        # pivoting makes |R_kk| non-increasing: the rank is the first ratio below tol
        r = int(np.argmax(~rk)) if not rk.all() else len(diag)
        base_idx.extend(cols[piv[:r]])
        order.extend(cols[piv])
        ratios.extend(float(v) for v in diag)
        Qb = np.hstack([Qb, Q[:, :r]])
    base_idx = np.array(base_idx, int)
    rank = len(base_idx)
    Ab = A[:, base_idx]
    for j in order:
        if j in set(base_idx.tolist()):
            continue
        coef = np.linalg.lstsq(Ab, A[:, j], rcond=None)[0]
        # A_j = sum_k coef_k A_k  ->  J_j = sum_k coef_k (S_k / S_j) J_k
        ck = coef * S[base_idx] / S[j]
        big = np.abs(coef) >= 1e-3 * max(np.abs(coef).max(), 1e-300)
        comb = {names[base_idx[k]]: float(ck[k]) for k in np.argsort(-np.abs(coef)) if big[k]}
        excluded.append(Excluded(names[j], "combination", comb))
    base_set = set(names[k] for k in base_idx)
    base = [n for n in names if n in base_set]
    excluded.sort(key=lambda e: names.index(e.parameter))
    return BaseSet(names, base, excluded, rank, ratios, [names[k] for k in order], tol)
