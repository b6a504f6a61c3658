"""A least-squares solver that knows nothing of the model: Gauss-Newton with an SVD
pseudo-inverse (seed 6.2.1, 7.2) or Levenberg-Marquardt, column scaling, optional prior
rows, and k-sigma outlier elimination over the rows (MuJoCo's ``minimize.py`` has the same
shape: a residual function in, the solution, a status and an iteration log out).

Prior rows (``PriorRows``: a parameter prior, a known length) join the weighted residuals
of every iteration, weighed as rows of a typical sample (``prior_weight``). The residual
function ``fun(x, rows) -> (r, J, w)`` gives, at the free parameters x, the residuals r of
the rows ``rows`` (a bool mask over all rows), their Jacobian J (len(r),
len(x)) and row weights w (None: unweighted; held for one iteration, re-evaluated at the
next). One iteration solves W J dx = -W r in the least-squares sense; iteration stops when
the mean absolute correction falls below ``improvement_limit`` (the seed's end condition,
7.2) or after ``max_iter`` corrections.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Callable, Protocol

import numpy as np

from planecal.base.progress import report


class Status(Enum):
    CONVERGED = "converged"
    MAX_ITERATIONS = "max_iterations"


@dataclass(frozen=True)
class SolverOptions:
    max_iter: int = 30
    improvement_limit: float = 1e-12
    outlier_sigma: float | None = None
    method: str = "gn"  # "gn": Gauss-Newton (SVD pseudo-inverse); "lm": Levenberg-Marquardt
    scale: bool = True  # column scaling of the Jacobian
    rcond: float = 1e-7  # pseudo-inverse cut-off relative to the largest scaled singular value
    lm_lambda0: float = 1e-3


class PriorRows(Protocol):
    """Rows that join the weighted residuals (a maximum a posteriori fit, gn only):
    ``rows(x, width) -> (P (k, width), r (k,))``, their Jacobian and values at x."""
    def rows(self, x: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]: ...


@dataclass(frozen=True)
class Prior:
    """Prior rows ``weight * (x[index] - center)`` (``PriorRows``)."""
    index: np.ndarray  # positions among the free parameters
    weight: np.ndarray
    center: np.ndarray

    def rows(self, x: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
        P = np.zeros((self.index.size, width))
        P[np.arange(self.index.size), self.index] = self.weight
        return P, self.weight * (x[self.index] - self.center)


@dataclass(frozen=True)
class Iteration:
    iteration: int
    rms_m: float  # of the rows used
    max_m: float
    samples: int  # rows used
    mean_abs_correction: float | None = None  # None for iteration 0


class Residuals(Protocol):
    def __call__(self, x: np.ndarray, rows: np.ndarray) -> tuple: ...


@dataclass(frozen=True, eq=False)
class Solution:
    x: np.ndarray
    status: Status
    iterations: int
    history: list[Iteration]
    r: np.ndarray  # at the solution, the rows used
    J: np.ndarray
    w: np.ndarray | None
    used: np.ndarray  # bool mask over the rows
    outliers: list[int]
    initial_r: np.ndarray
    initial_cost: float  # 0.5 |W r|^2 (scipy's least_squares cost)
    final_cost: float
    notes: list[str] = field(default_factory=list)

    @property
    def converged(self) -> bool:
        return self.status is Status.CONVERGED


def cost(r: np.ndarray, w: np.ndarray | None) -> float:
    rw = r if w is None else r * w
    return 0.5 * float(rw @ rw)


def column_scales(J: np.ndarray, on: bool = True) -> np.ndarray:
    """1 / |column| (1 for a zero column), or ones."""
    return _scales(np.einsum("ij,ij->j", J, J), on)


def _scales(squared_norms: np.ndarray, on: bool) -> np.ndarray:
    if not on:
        return np.ones(len(squared_norms))
    norms = np.sqrt(squared_norms)
    return np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)


def pinv_step(H: np.ndarray, g: np.ndarray, rcond: float) -> np.ndarray:
    """Minimum-norm least-squares solution of A dx = -r by the SVD pseudo-inverse, given
    the Gram matrix H = A^T A and g = A^T r of the (column-scaled) A, with singular values
    below rcond x the largest cut off. The right singular vectors and singular values come
    from the eigen-decomposition of H, 30x cheaper than an SVD of the tall A; rcond >= 1e-7
    keeps the cut above the Gram matrix's rounding floor (1e-16 relative in s^2)."""
    lam, V = np.linalg.eigh(H)
    keep = lam > (rcond ** 2) * lam[-1]
    return -(V[:, keep] @ ((V[:, keep].T @ g) / lam[keep]))


def _normal_equations(Jw: np.ndarray, rw: np.ndarray, scale: bool):
    """The column-scaled normal equations of Jw dx = -rw: (H, g, S) with H = S Jw^T Jw S,
    g = S Jw^T rw and the scales S (the columns' norms are the Gram matrix's diagonal)."""
    G = Jw.T @ Jw
    S = _scales(np.diag(G).copy(), scale)
    return G * S[:, None] * S[None, :], S * (Jw.T @ rw), S


def prior_weight(w: np.ndarray | None) -> float:
    """The weight of the prior rows beside data rows of weights ``w``: their rms (1 for
    unweighted rows). A prior row is a residual in the data's units (a distance); weighted
    rows are whitened (r / std), so a prior row joins them as a row of a typical sample."""
    return 1.0 if w is None or not len(w) else float(np.sqrt(np.mean(w ** 2)))


def _with_prior(J, r, w, x, prior: PriorRows | None):
    Jw, rw = (J, r) if w is None else (J * w[:, None], r * w)
    if prior is None:
        return Jw, rw
    P, rp = prior.rows(x, Jw.shape[1])
    if not len(rp):
        return Jw, rw
    k = prior_weight(w)
    return np.vstack([Jw, k * P]), np.concatenate([rw, k * rp])


def _lm_step(fun, x, used, H, g, rw, w, S, lam):
    c0 = rw @ rw
    for _ in range(30):
        step = np.linalg.lstsq(H + lam * np.diag(np.maximum(np.diag(H), 1e-30)), -g,
                               rcond=None)[0]
        rt = fun(x + S * step, used)[0]
        if w is not None:
            rt = rt * w
        if rt @ rt <= c0:
            return S * step, max(lam / 10, 1e-12)
        lam *= 10
    return np.zeros_like(x), lam


def _outliers(r, w, used, sigma, p):
    """Rows (indices over all) whose (standardised) residual is more than sigma std from
    the mean, if enough rows stay."""
    e = r if w is None else r * w
    bad = np.abs(e - e.mean()) > sigma * e.std()
    if bad.any() and used.sum() - bad.sum() > p + 1:
        return np.flatnonzero(used)[bad]
    return np.zeros(0, int)


def _log(it, r, used, dx=None) -> Iteration:
    return Iteration(it, float(np.sqrt(np.mean(r ** 2))), float(np.max(np.abs(r))),
                     int(used.sum()), None if dx is None else float(np.mean(np.abs(dx))))


def least_squares(fun: Callable, x0: np.ndarray, n_rows: int,
                  options: SolverOptions = SolverOptions(),
                  prior: PriorRows | None = None) -> Solution:
    """Minimise |W r(x)|^2 (+ the prior's rows) from x0 (module docstring)."""
    opt = options
    if opt.method not in ("gn", "lm"):
        raise ValueError(f"unknown method {opt.method!r} (gn or lm)")
    if prior is not None and opt.method != "gn":
        raise ValueError("a prior needs method 'gn'")
    x = np.array(x0, float)
    used = np.ones(n_rows, bool)
    outliers: list[int] = []
    lam, status, it = opt.lm_lambda0, Status.MAX_ITERATIONS, 0
    r, J, w = fun(x, used)
    initial_r, initial_cost = r.copy(), cost(r, w)
    history = [_log(0, r, used)]
    for it in range(1, opt.max_iter + 1):
        report(it, None, "fit: iteration")
        Jw, rw = _with_prior(J, r, w, x, prior)
        H, g, S = _normal_equations(Jw, rw, opt.scale)
        if opt.method == "gn":
            dx = S * pinv_step(H, g, opt.rcond)
        else:
            dx, lam = _lm_step(fun, x, used, H, g, rw, w, S, lam)
        x = x + dx
        small = float(np.mean(np.abs(dx))) < opt.improvement_limit
        if small and opt.outlier_sigma is None:
            # converged: r and J at x - dx describe x to O(|dx|), below the limit
            last = history[-1]
            history.append(Iteration(it, last.rms_m, last.max_m, last.samples,
                                     float(np.mean(np.abs(dx)))))
            status = Status.CONVERGED
            break
        r, J, w = fun(x, used)
        if opt.outlier_sigma is not None:
            bad = _outliers(r, w, used, opt.outlier_sigma, len(x))
            if bad.size:
                outliers.extend(int(i) for i in bad)
                used[bad] = False
                r, J, w = fun(x, used)
        history.append(_log(it, r, used, dx))
        if small:
            status = Status.CONVERGED
            break
    notes = [] if status is Status.CONVERGED else [
        f"stopped after {it} iterations (max_iter) before the mean correction fell below "
        f"{opt.improvement_limit:g}"]
    return Solution(x, status, it, history, r, J, w, used, sorted(outliers), initial_r,
                    initial_cost, cost(r, w), notes)
