"""The evidence of a linear least squares with a Gaussian prior (MacKay 1992, "Bayesian
interpolation"): one step of the posterior and of its two scales, the prior's and the
noise's, towards the evidence's maximum. The reference model (``estimation.reference``)
finds both scales from the samples with it.

With rows whitened by the noise model (y = X dx + e, e ~ N(0, f)), a prior
x_k + dx_k ~ N(0, s2 std_k^2) on the terms with a finite std and the posterior covariance
C: gamma = sum_k (1 - C_kk / (s2 std_k^2)) counts the prior terms the samples determine;
the fixed point is s2 = sum_k (x_k + dx_k)^2 / std_k^2 / gamma and
f = |y - X dx|^2 / (n - free - gamma); with groups of terms (a robot's geometry, its gear
harmonics, ...) each group has its own s2, summed over its own terms.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg

SCALE_RANGE = (1e-2, 1e2)  # the prior's scale is kept within these


def evidence_step(X, y, std, x, G, g, s2, f: float, groups=None):
    """One step of the posterior of y = X dx + e (e ~ N(0, f), whitened rows), the known
    lengths' rows G dx + g ~ N(0, 1) and a prior x_k + dx_k ~ N(0, s2 std_k^2) on every term
    with a finite ``std`` (the others free): (the posterior mean's dx, its covariance, s2
    and f updated towards the evidence's maximum (MacKay's fixed point), gamma: how many
    prior terms the samples determine). ``groups``: an int per term, each group of prior
    terms with its own scale (s2 then an array over the groups); None: one scale."""
    pen = np.isfinite(std)
    grp = np.zeros(len(std), int) if groups is None else np.asarray(groups, int)
    s2v = np.atleast_1d(np.asarray(s2, float))
    Pi = np.where(pen, 1.0 / np.where(pen, std, 1.0) ** 2, 0.0) / s2v[grp]
    m = np.where(pen, -x, 0.0)
    A = X.T @ X / f + G.T @ G + np.diag(Pi)
    C = inverse(A)
    dx = C @ (X.T @ y / f - G.T @ g + Pi * m)
    det = pen * (1.0 - np.diag(C) * Pi)  # how much of each prior term the samples determine
    s2_new = s2v.copy()
    for k in range(len(s2v)):
        inside = pen & (grp == k)
        if inside.any():
            s2_new[k] = (float(np.sum(Pi[inside] * s2v[k] * (dx - m)[inside] ** 2))
                         / max(float(det[inside].sum()), 1e-3))
    s2_new = np.clip(s2_new, SCALE_RANGE[0] ** 2, SCALE_RANGE[1] ** 2)
    gamma = float(det.sum())
    e = y - X @ dx
    f_new = max(float(e @ e) / max(len(y) - int((~pen).sum()) - gamma, 1.0), 1e-6)
    return dx, C, (float(s2_new[0]) if groups is None else s2_new), f_new, gamma


def inverse(A: np.ndarray) -> np.ndarray:
    """The inverse of a symmetric positive definite A, column-scaled (its terms' units
    differ by orders of magnitude); a pseudo-inverse where it is singular."""
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    As = A / np.outer(d, d)
    try:
        Ci = scipy.linalg.cho_solve(scipy.linalg.cho_factor(As), np.eye(len(A)))
    except np.linalg.LinAlgError:
        Ci = np.linalg.pinv(As, rcond=1e-12, hermitian=True)
    return Ci / np.outer(d, d)
