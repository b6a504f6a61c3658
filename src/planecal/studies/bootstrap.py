"""Subset resampling of one sample pool (seed 9.3, "Result analysis").

From a pool of n samples draw ``repeats`` random subsets (without replacement within a
subset) of each size s, calibrate each from the same initial parameters, and report per
size and parameter the mean, the spread (std, min, max) and the mean of the std each fit
reports for itself.

Overlap (the seed's own caveat: 10 subsets of 200 out of 500 "become similar"): two
random subsets of size s from n share on average s^2/n samples, a share s/n of each.
Relative to the pool's own estimate, the spread of subset estimates is that of
independent sets times sqrt((n - s)/(n - 1)) (finite-population correction, exact for a
linear estimator): it shrinks to zero as s -> n however good or bad the calibration is.
Each size reports the observed std and the std corrected by that factor (what
independent sets of size s would show); above ``overlap_warn`` (0.3) the size is flagged.

Reproducible wherever it runs: subset r of size s is drawn, by the run itself, from the
random stream ``default_rng([seed, s, r])``: fixed by its cell (the size) and r, whatever
worker fits it and whatever other sizes the study has. Each subset is calibrated by the one
calibration (``estimation.calibrate``) with the study's ``CalibrationSettings`` (any level;
at level full each subset chooses its own base set). The fits go through
``studies.distributed.Engine`` (``studies.common.parallel_map``), each one a pure function
of its item; with a results file each fit is written as it completes (key ``[s, r]``).

Sizes: by default those of (30, 50, 100, 150) strictly between the free parameters and the
pool (a subset as large as the pool is the pool: every fit the same, no spread).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.calibrate import CalibrationSettings, calibrate
from planecal.model.cell_params import CellParams
from planecal.model.layout import ParamLayout
from planecal.model.levels import layout_for
from planecal.model.robot import Robot
from planecal.base.progress import Progress
from planecal.studies.common import parallel_map

OVERLAP_WARN = 0.3
DEFAULT_SIZES = (30, 50, 100, 150)


@dataclass
class BootstrapSettings:
    sizes: tuple | None = None  # None: DEFAULT_SIZES below the pool (``default_sizes``)
    repeats: int = 10
    seed: int = 0
    overlap_warn: float = OVERLAP_WARN


@dataclass(frozen=True, eq=False)
class Pool:
    """The samples every subset is drawn from, the initial parameters and how to calibrate."""
    robot: Robot
    qe: np.ndarray
    d_m: np.ndarray
    plate: np.ndarray
    initial: CellParams
    calibration: CalibrationSettings
    direction: np.ndarray | None = None  # the samples' approach directions (level 3)
    references: tuple = ()  # the scene's known lengths

    def __len__(self) -> int:
        return len(self.d_m)

    @property
    def layout(self) -> ParamLayout:
        return layout_for(self.robot, self.initial.n_planes, self.calibration.level,
                          self.calibration.compliance)

    @property
    def free(self) -> np.ndarray:
        """The candidates (the base set of each fit is among them)."""
        return self.layout.free_mask(self.calibration.free)

    def subset(self, idx) -> "Pool":
        return Pool(self.robot, self.qe[idx], self.d_m[idx], self.plate[idx], self.initial,
                    self.calibration,
                    None if self.direction is None else self.direction[idx], self.references)


def default_sizes(n: int, p: int) -> tuple:
    """DEFAULT_SIZES strictly between p free parameters and a pool of n; where fewer than
    two remain, 30 %, 50 % and 70 % of the pool."""
    sizes = [s for s in DEFAULT_SIZES if p < s < n]
    if len(sizes) < 2:
        sizes = sorted({int(round(f * n)) for f in (0.3, 0.5, 0.7)} - {n})
        sizes = [s for s in sizes if p < s < n]
    return tuple(sizes)


def subset_indices(n: int, size: int, r: int, seed: int) -> np.ndarray:
    """Subset r of ``size`` out of a pool of n (sorted sample indices), from its own stream
    ``default_rng([seed, size, r])``."""
    return np.sort(np.random.default_rng([seed, size, r]).choice(n, size, replace=False))


def fit_subset(item) -> dict:
    """One run of the study: item = (pool, size, r, seed)."""
    pool, size, r, seed = item
    return _fit_one(pool.subset(subset_indices(len(pool), size, r, seed)))


def _item_key(item) -> list:
    return [item[1], item[2]]


def pool_digest(pool: Pool) -> str:
    """sha256 of what the fits depend on (samples, initial parameters, calibration
    settings): a results file written for another pool is refused."""
    h = hashlib.sha256()
    extra = () if pool.direction is None else (pool.direction,)
    for a in (pool.qe, pool.d_m, pool.plate, pool.free, pool.initial.to_vector(pool.layout),
              *extra):
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    h.update(repr(pool.calibration).encode())
    if pool.references:  # (a pool without any hashes as before: its results still resume)
        h.update(repr(pool.references).encode())
    h.update(",".join(pool.layout.names).encode())
    return h.hexdigest()


def _fit_one(pool: Pool):
    try:
        res = calibrate(pool.robot, pool.qe, pool.d_m, pool.initial, pool.plate,
                        pool.calibration, pool.direction, pool.references).result
    except (InputError, np.linalg.LinAlgError) as e:
        return {"ok": False, "error": str(e)}
    return {"ok": True, "x": res.params.to_vector(res.layout), "std": res.std,
            "converged": res.converged, "rms_mm": res.rms_mm(),
            "not_identifiable": res.identifiability.not_identifiable}


def overlap(s: int, n: int) -> dict:
    """Expected overlap of two random s-subsets of n and the finite-population factor."""
    share = s / n
    fpc = np.sqrt((n - s) / (n - 1)) if n > 1 else 0.0
    return {"share": share, "expected_common_samples": s * s / n,
            "finite_population_factor": float(fpc)}


def check_settings(pool: Pool, st: BootstrapSettings) -> BootstrapSettings:
    """The settings with their sizes (default: ``default_sizes``); InputError for settings
    the pool cannot serve (before any fit)."""
    n = len(pool)
    p = int(pool.free.sum())
    if st.repeats < 2:
        raise InputError(f"--repeats must be at least 2 to measure a spread, got {st.repeats}")
    if st.sizes is None:
        st = BootstrapSettings(default_sizes(n, p), st.repeats, st.seed, st.overlap_warn)
        if not st.sizes:
            raise InputError(f"a pool of {n} samples leaves no subset size between the "
                             f"{p} free parameters and the pool: give --sizes or more samples")
    for s in st.sizes:
        if s >= n:
            raise InputError(f"--sizes: subset size {s} is not below the pool of {n} samples "
                             "(a subset as large as the pool is the pool: no spread)")
        if s <= p:
            raise InputError(f"--sizes: subset size {s} cannot determine {p} free parameters")
    if len(set(st.sizes)) != len(st.sizes):
        raise InputError(f"--sizes: a size given twice ({', '.join(map(str, st.sizes))})")
    return st


def bootstrap(pool: Pool, settings: BootstrapSettings | None = None, engine=1,
              quiet: bool = False, results=None, resume: bool = False) -> dict:
    """The study (module docstring) on ``pool``'s samples, its initial parameters and
    calibration settings; a pure function of its inputs. ``engine``: an open
    ``Engine`` or a job count (``studies.common.engine_for``); ``results``/``resume``: the
    JSON-lines file of the fits (``parallel_map``). Returns a dict with
    ``pool``, ``names``, ``free``, ``sizes``: one entry per size with per-parameter
    ``mean``, ``std``, ``std_independent``, ``min``, ``max``, ``reported_std``,
    ``overlap`` and ``warning``."""
    st = check_settings(pool, settings or BootstrapSettings())
    n = len(pool)
    names, free = pool.layout.names, pool.free
    items = [(pool, s, r, st.seed) for s in st.sizes for r in range(st.repeats)]
    where = [s for _, s, _, _ in items]
    prog = Progress("bootstrap fits", len(items), quiet=quiet)
    header = {"study": "bootstrap", "seed": st.seed, "pool": n,
              "pool_sha256": pool_digest(pool)}
    fits = parallel_map(fit_subset, items, engine, prog, key=_item_key, results=results,
                        resume=resume, header=header)
    full = _fit_one(pool)
    out = {"pool": n, "names": names, "free": pool.layout.names_of(free),
           "repeats": st.repeats, "seed": st.seed, "calibration": pool.calibration.to_dict(),
           "pool_fit": {"x": full.get("x"), "std": full.get("std")} if full["ok"] else None,
           "sizes": []}
    for s in st.sizes:
        rs = [r for r, w in zip(fits, where) if w == s]
        ok = [r for r in rs if r["ok"]]
        ov = overlap(s, n)
        entry = {"size": s, "fits": len(ok), "failed": len(rs) - len(ok),
                 "not_converged": sum(1 for r in ok if not r["converged"]),
                 "overlap": ov, "warning": None, "params": {}}
        if ov["share"] > st.overlap_warn:
            entry["warning"] = (
                f"subsets of {s} from a pool of {n}: each is {ov['share']:.0%} of the pool; two "
                f"share {ov['expected_common_samples']:.0f} samples on average, so their spread "
                f"is {ov['finite_population_factor']:.2f} x that of independent sets (shown "
                f"corrected in std_indep); use a bigger pool or smaller subsets")
        if len(ok) >= 2:
            X = np.array([r["x"] for r in ok])
            SD = np.array([r["std"] for r in ok])
            mean, sd = X.mean(0), X.std(0, ddof=1)
            fpc = ov["finite_population_factor"]
            indep = sd / fpc if fpc > 0 else np.full_like(sd, np.nan)
            fin = np.isfinite(SD)
            cnt = fin.sum(0)
            rep = np.where(cnt > 0, np.where(fin, SD, 0.0).sum(0) / np.maximum(cnt, 1), np.nan)
            for i, nm in enumerate(names):
                if not free[i]:
                    continue
                entry["params"][nm] = {
                    "mean": float(mean[i]), "std": float(sd[i]),
                    "std_independent": float(indep[i]), "min": float(X[:, i].min()),
                    "max": float(X[:, i].max()),
                    "reported_std": None if not np.isfinite(rep[i]) else float(rep[i])}
        out["sizes"].append(entry)
    return out
