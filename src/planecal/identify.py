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
  J_e = sum_k coef_k J_k, from R_11 coef = R_12 (the coefficients unscaled to SI units:
  moving e by 1 changes every distance as moving each base parameter k by coef_k).

Which member of a degenerate family stays is the pivoting's choice (the one with the most
new information first), not a physical claim: delta1 and the planes' rotation about the
base z axis, say, are one direction, and either can carry it.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.linalg

from planecal.layout import ParamLayout

DEFAULT_TOL = 1e-6  # |R_kk| / |R_00| below this: a combination of the columns before


@dataclass(frozen=True)
class Excluded:
    parameter: str
    reason: str  # "no_effect" | "combination"
    combination: dict = field(default_factory=dict)  # base parameter -> coefficient (SI)

    def describe(self) -> str:
        if self.reason == "no_effect":
            return f"{self.parameter}: no effect on any distance of these samples"
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


def select_base(J: np.ndarray, layout: ParamLayout, free: np.ndarray,
                tol: float = DEFAULT_TOL, weights: np.ndarray | None = None) -> BaseSet:
    """The base set of identifiable parameters among ``free`` (mask over the layout) for
    the Jacobian J (N, len(layout)) of the samples at hand (module docstring). ``weights``:
    row weights (a weighted fit's), default none."""
    free = np.asarray(free, bool)
    names = layout.names_of(free)
    Jf = np.asarray(J, float)[:, free]
    if weights is not None:
        Jf = Jf * weights[:, None]
    norms = np.linalg.norm(Jf, axis=0)
    top = norms.max() if norms.size else 0.0
    dead = norms <= 1e-12 * top if top > 0 else np.ones(len(names), bool)
    S = np.where(dead, 0.0, 1.0 / np.where(dead, 1.0, norms))
    A = Jf * S
    live = np.flatnonzero(~dead)
    excluded = [Excluded(names[j], "no_effect") for j in np.flatnonzero(dead)]
    if live.size == 0:
        return BaseSet(names, [], excluded, 0, [], [], tol)
    R, piv = scipy.linalg.qr(A[:, live], mode="r", pivoting=True)
    diag = np.abs(np.diag(R))
    ratios = diag / diag[0]
    # pivoting makes |R_kk| non-increasing: the rank is the first ratio below tol
    rank = int(np.argmax(ratios < tol)) if np.any(ratios < tol) else len(ratios)
    order = live[piv]
    base_idx = order[:rank]
    R11, R12 = R[:rank, :rank], R[:rank, rank:len(live)]
    coef = scipy.linalg.solve_triangular(R11, R12) if R12.size else np.zeros((rank, 0))
    for c, j in enumerate(order[rank:]):
        # A_j = sum_k coef_k A_k  ->  J_j = sum_k coef_k (S_k / S_j) J_k
        ck = coef[:, c] * S[base_idx] / S[j]
        big = np.abs(coef[:, c]) >= 1e-3 * max(np.abs(coef[:, c]).max(), 1e-300)
        comb = {names[base_idx[k]]: float(ck[k])
                for k in np.argsort(-np.abs(coef[:, c])) if big[k]}
        excluded.append(Excluded(names[j], "combination", comb))
    base_set = set(names[k] for k in base_idx)
    base = [n for n in names if n in base_set]
    excluded.sort(key=lambda e: names.index(e.parameter))
    return BaseSet(names, base, excluded, rank, [float(v) for v in ratios],
                   [names[k] for k in order], tol)
