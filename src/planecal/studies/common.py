"""What the studies share: parallel map over pure run functions, progress on stderr,
terminal tables, the per-sample noise model of the twin and the covariance formulas
(Cramer-Rao bound, OLS sandwich) the studies compare with.

Noise model of one sample (SI): the twin's distance error is
  e_i = sum_j (dd/dq_j)_i eps_j + laser_i
with eps ~ N(0, s^2 I) the repeatability perturbation of the six joints drawn each time the
robot comes to rest (``robot.repeatability_sigma``: a 3-sigma flange spread of the
robot's repeatability, 0.07 mm for the MC70, s ~ 1.1e-5 rad) and laser_i the laser noise of
the sample value, the mean of a 100-reading buffer (std noise / 10). dd/dq_j equals the
Jacobian column of delta_j. So e_i is Gaussian, independent between samples, zero mean, but
its variance v_i = s^2 |J_delta,i|^2 + sigma_L^2 depends on the pose (heteroscedastic): the
white-noise bound sigma^2 (J^T J)^-1 is then not the covariance of the (unweighted) least
squares estimate; that is the sandwich (J^T J)^-1 J^T V J (J^T J)^-1, and the Cramer-Rao
bound for this noise is (J^T V^-1 J)^-1, which the weighted fit reaches
(``FitOptions(joint_sigma_rad=s)``; ``fit.noise_variance`` is v_i).
"""
from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from typing import Callable, Iterable

import numpy as np

from planecal.errors import InputError
from planecal.progress import Progress as ProgressBar

BUFFER_LEN = 100  # laser readings averaged into one sample (sampling.laserread)


def parse_int_list(text: str, what: str, minimum: int = 1) -> list[int]:
    """"30,50,100" -> [30, 50, 100]; InputError on anything else."""
    try:
        vals = [int(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{what}: expected comma-separated integers, got {text!r}") from None
    if not vals:
        raise InputError(f"{what}: no values in {text!r}")
    bad = [v for v in vals if v < minimum]
    if bad:
        raise InputError(f"{what}: values must be at least {minimum}, got {bad[0]}")
    return vals


def check_jobs(jobs: int | None) -> int:
    if jobs is None:
        return max(1, os.cpu_count() or 1)
    if jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {jobs}")
    return jobs


class Progress:
    """A study's progress (``planecal.progress``): runs done of ``total``."""

    def __init__(self, label: str, total: int, stream=None, quiet: bool = False):
        self.bar = None if quiet else ProgressBar(label, total, stream)
        self.done = 0

    def step(self, k: int = 1) -> None:
        self.done += k
        if self.bar is not None:
            self.bar.update(self.done)
            if self.done >= self.bar.total:
                self.bar.close()


def _init_worker():
    os.environ.setdefault("MUJOCO_GL", "disable")
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[k] = "1"


def parallel_map(fn: Callable, items: Iterable, jobs: int = 1,
                 progress: Progress | None = None) -> list:
    """[fn(item) for item in items], in order, in ``jobs`` processes (fn and the items must
    be picklable; fn a pure function of its item). jobs == 1 runs in this process."""
    items = list(items)
    out = []
    if jobs <= 1 or len(items) <= 1:
        for it in items:
            out.append(fn(it))
            if progress:
                progress.step()
        return out
    import multiprocessing as mp
    ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
    with ProcessPoolExecutor(max_workers=min(jobs, len(items)), mp_context=ctx,
                             initializer=_init_worker) as ex:
        futs = [ex.submit(fn, it) for it in items]
        for f in futs:
            out.append(f.result())
            if progress:
                progress.step()
    return out


def table(headers: list[str], rows: list[list], aligns: str | None = None) -> str:
    """A plain text table; numbers should come pre-formatted as strings."""
    cells = [[str(c) for c in r] for r in rows]
    w = [max(len(h), *(len(r[i]) for r in cells)) if cells else len(h)
         for i, h in enumerate(headers)]
    aligns = aligns or ("l" + "r" * (len(headers) - 1))

    def fmt(r):
        return "  ".join(c.ljust(w[i]) if aligns[i] == "l" else c.rjust(w[i])
                         for i, c in enumerate(r))
    return "\n".join([fmt(headers), "  ".join("-" * x for x in w)] + [fmt(r) for r in cells])


def covariances(Jf: np.ndarray, v: np.ndarray) -> dict:
    """For the free-column Jacobian Jf (N, p) and per-sample noise variances v (N,):
    'white': mean(v) (J^T J)^-1 (the white-noise CR bound with the mean variance),
    'sandwich': the covariance of the unweighted LS estimate, 'crb': (J^T V^-1 J)^-1.
    Computed on column-scaled Jf; pseudo-inverse on the identifiable subspace."""
    S = np.linalg.norm(Jf, axis=0)
    S = np.where(S > 0, 1.0 / np.where(S > 0, S, 1.0), 1.0)
    A = Jf * S
    G = A.T @ A
    Gi = _pinv_sym(G)
    white = np.mean(v) * Gi
    sand = Gi @ (A.T @ (A * v[:, None])) @ Gi
    crb = _pinv_sym(A.T @ (A / v[:, None]))
    s2 = np.outer(S, S)
    return {"white": white * s2, "sandwich": sand * s2, "crb": crb * s2}


def _pinv_sym(G: np.ndarray, rcond: float = 1e-12) -> np.ndarray:
    lam, V = np.linalg.eigh(G)
    keep = lam > rcond * lam[-1]
    return (V[:, keep] / lam[keep]) @ V[:, keep].T
