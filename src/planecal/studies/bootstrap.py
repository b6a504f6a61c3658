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
worker fits it and whatever other sizes the study has. The fits go through
``studies.distributed.Engine`` (``studies.common.parallel_map``), each one a pure function
of its item; with a results file each fit is written as it completes (key ``[s, r]``).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.fit import Problem, solve
from planecal.model.layout import ParamLayout
from planecal.studies.common import Progress, parallel_map, table

OVERLAP_WARN = 0.3


@dataclass
class BootstrapSettings:
    sizes: tuple = (30, 50, 100, 150)
    repeats: int = 10
    seed: int = 0
    overlap_warn: float = OVERLAP_WARN


def subset_indices(n: int, size: int, r: int, seed: int) -> np.ndarray:
    """Subset r of ``size`` out of a pool of n (sorted sample indices), from its own stream
    ``default_rng([seed, size, r])``."""
    return np.sort(np.random.default_rng([seed, size, r]).choice(n, size, replace=False))


def fit_subset(item) -> dict:
    """One run of the study: item = (pool problem, size, r, seed)."""
    problem, size, r, seed = item
    return _fit_one(problem.subset(subset_indices(len(problem), size, r, seed)))


def _item_key(item) -> list:
    return [item[1], item[2]]


def pool_digest(problem: Problem) -> str:
    """sha256 of what the fits depend on (samples, initial parameters, free set, options):
    a results file written for another pool is refused."""
    h = hashlib.sha256()
    for a in (problem.qe, problem.d_m, problem.plate, problem.free,
              problem.initial.to_vector(problem.layout)):
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    h.update(repr(problem.options).encode())
    h.update(",".join(problem.layout.names).encode())
    return h.hexdigest()


def _fit_one(problem: Problem):
    try:
        res = solve(problem)
    except (ValueError, np.linalg.LinAlgError) as e:
        return {"ok": False, "error": str(e)}
    return {"ok": True, "x": res.params.to_vector(problem.layout), "std": res.std,
            "converged": res.converged, "rms_mm": res.rms_mm(),
            "not_identifiable": res.identifiability.not_identifiable}


def overlap(s: int, n: int) -> dict:
    """Expected overlap of two random s-subsets of n and the finite-population factor."""
    share = s / n
    fpc = np.sqrt((n - s) / (n - 1)) if n > 1 else 0.0
    return {"share": share, "expected_common_samples": s * s / n,
            "finite_population_factor": float(fpc)}


def check_settings(problem: Problem, st: BootstrapSettings) -> None:
    """InputError for settings the pool cannot serve (before any fit)."""
    n = len(problem)
    p = int(problem.free.sum())
    if st.repeats < 2:
        raise InputError(f"--repeats must be at least 2 to measure a spread, got {st.repeats}")
    for s in st.sizes:
        if s > n:
            raise InputError(f"--sizes: subset size {s} exceeds the pool of {n} samples")
        if s <= p:
            raise InputError(f"--sizes: subset size {s} cannot determine {p} free parameters")
    if len(set(st.sizes)) != len(st.sizes):
        raise InputError(f"--sizes: a size given twice ({', '.join(map(str, st.sizes))})")


def bootstrap(problem: Problem, settings: BootstrapSettings | None = None, engine=1,
              quiet: bool = False, results=None, resume: bool = False) -> dict:
    """The study (module docstring) on ``problem``'s samples (the pool), its initial
    parameters, free set and options; a pure function of its inputs. ``engine``: an open
    ``Engine`` or a job count (``studies.common.engine_for``); ``results``/``resume``: the
    JSON-lines file of the fits (``parallel_map``). Returns a dict with
    ``pool``, ``names``, ``free``, ``sizes``: one entry per size with per-parameter
    ``mean``, ``std``, ``std_independent``, ``min``, ``max``, ``reported_std``,
    ``overlap`` and ``warning``."""
    st = settings or BootstrapSettings()
    check_settings(problem, st)
    n = len(problem)
    names, free = problem.layout.names, problem.free
    items = [(problem, s, r, st.seed) for s in st.sizes for r in range(st.repeats)]
    where = [s for _, s, _, _ in items]
    prog = Progress("bootstrap fits", len(items), quiet=quiet)
    header = {"study": "bootstrap", "seed": st.seed, "pool": n,
              "pool_sha256": pool_digest(problem)}
    fits = parallel_map(fit_subset, items, engine, prog, key=_item_key, results=results,
                        resume=resume, header=header)
    full = _fit_one(problem)
    out = {"pool": n, "names": names, "free": problem.free_names,
           "repeats": st.repeats, "seed": st.seed,
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


def format_bootstrap(res: dict, layout: ParamLayout) -> str:
    """Terminal report: per size a table of the free parameters' spread (display units of
    the study's parameter ``layout``)."""
    lines = [f"pool: {res['pool']} samples; {res['repeats']} random subsets per size "
             f"(seed {res['seed']})"]
    for e in res["sizes"]:
        ov = e["overlap"]
        lines.append("")
        lines.append(f"subset size {e['size']}: {e['fits']} fits"
                     + (f", {e['failed']} failed" if e['failed'] else "")
                     + (f", {e['not_converged']} not converged" if e['not_converged'] else "")
                     + f"; share of pool {ov['share']:.0%}, two subsets share "
                     f"{ov['expected_common_samples']:.1f} samples on average")
        rows = []
        for nm, v in e["params"].items():
            k, unit = layout.display(nm)

            def f(x):
                return "-" if x is None or not np.isfinite(x) else f"{x * k:.4g}"
            ratio = (v["std_independent"] / v["reported_std"]
                     if v["reported_std"] else float("nan"))
            rows.append([nm, unit, f"{v['mean']:.7g}", f(v["std"]), f(v["std_independent"]),
                         f(v["min"] - v["mean"]), f(v["max"] - v["mean"]), f(v["reported_std"]),
                         "-" if not np.isfinite(ratio) else f"{ratio:.2f}"])
        if rows:
            lines.append(table(["param", "spread in", "mean (SI)", "std", "std_indep", "min-mean", "max-mean",
                                "fit_std", "indep/fit"], rows))
        if e["warning"]:
            lines.append(f"WARNING {e['warning']}")
    return "\n".join(lines)
