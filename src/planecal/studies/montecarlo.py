"""Monte Carlo on the twin: repeated runs with fresh poses and noise, one calibration each,
compared with the truth and with the Cramer-Rao bound.

One run (``run_one``, a pure function of (settings, run index)) samples (a rehearsal,
``studies.rehearsal``: its modes, world and noise), calibrates from the scene's nominal
parameters with the one calibration (``estimation.calibrate``, at any level) and evaluates,
at the truth and on the run's own samples, the covariances of
``estimation.identifiability.covariances``. At level full each run chooses its own base
set: a parameter's statistics are over the runs that fitted it.

The Cramer-Rao bound and the chi-square describe the noise (repeatability, quantisation,
laser noise). A realistic world also has errors the fit's model does not (geometry,
compliance, gear error, backlash, laser linearity): its residuals exceed the noise, and the
offsets absorb part of those errors, differently for every set of poses. The analysis
reports that as it is (``analyze``: ``world``, ``mismatch``); it does not widen the bound.
A scene's known lengths (two plates' separation) join the samples' rows in the bounds at
their declared std, as they join the fit.

Summary (``analyze``) per free parameter: bias, empirical std, and, as the RMS over runs
of each run's value: the white-noise bound ``mean(v) (J^T J)^-1``, the sandwich (the true
covariance of the unweighted fit under the noise model), the Cramer-Rao bound
``(J^T V^-1 J)^-1`` and the std the fit reports. Chi-square: per run
T = e^T C^-1 e over the identifiable free joint offsets with C the fit's reported
covariance (and, separately, with the sandwich); T ~ chi2(k) if the reported covariance is
honest: the mean must be within 3 standard errors of k and a KS test against chi2(k)
must not reject at 1 %.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.calibrate import CalibrationSettings, calibrate
from planecal.estimation.fit import FitOptions, FitPrior
from planecal.estimation.identifiability import covariances, uncertainty
from planecal.estimation.noise import sample_variance
from planecal.model.layout import ParamLayout
from planecal.model.levels import layout_for as level_layout
from planecal.model.measurement import predict_with_jacobian
from planecal.base.progress import Progress
from planecal.studies.common import cached_profile, cached_scene, parallel_map
from planecal.studies.rehearsal import RehearsalSettings, sample_run
from planecal.twin.world import MISMATCH, sources_on, true_params

FORMAT = "planecal-montecarlo/1"
TARGET_RATIO = 0.15  # issue 6: empirical spread within 15 % of the bound
TARGET_BIAS = 0.2  # bias under a fifth of the bound
# settings added after results files existed: left out of a results file's header while
# at their defaults, so a file written before them still resumes
LATER = {"level": "offsets", "compliance": False, "geometry_prior": None, "free_scale": False}


@dataclass(frozen=True)
class MCSettings(RehearsalSettings):
    """A Monte Carlo study: a rehearsal (``RehearsalSettings``) repeated ``runs`` times,
    each calibrated as ``calibration()`` says."""
    runs: int = 20
    free: tuple | None = None  # parameter names; None: the level's default
    weighted: bool = False  # fit by weighted least squares with the world's noise model
    level: str = "offsets"
    compliance: bool = False
    geometry_prior: tuple | None = None  # (m, rad), level full
    free_scale: bool = False

    def check(self) -> None:
        super().check()
        if self.runs < 2:
            raise InputError(f"--runs must be at least 2, got {self.runs}")
        if self.weighted and self.quantization:
            raise InputError("--weighted with --quantization: the weighted fit's noise model "
                             "(repeatability + sensor) has no quantisation term")
        self.calibration().check()

    def calibration(self, options: FitOptions | None = None) -> CalibrationSettings:
        return CalibrationSettings(self.level, self.compliance, self.free, self.geometry_prior,
                                   self.free_scale, options or FitOptions())

    def layout(self) -> ParamLayout:
        """The parameter layout of the study's level on its scene."""
        return level_layout(cached_scene(self.scene).robot, len(cached_scene(self.scene).plates),
                            self.level, self.compliance)

    def candidates(self) -> list[str]:
        """The parameters a run may fit (each run's base set is among them)."""
        from planecal.estimation.calibrate import candidates
        layout = self.layout()
        return layout.names_of(candidates(cached_scene(self.scene).robot, layout,
                                          self.calibration())[0])

    def header(self) -> dict:
        """The results file's header: the settings, the later ones only where set."""
        d = asdict(self)
        for k, v in LATER.items():
            if d.get(k) == v:
                d.pop(k)
        return d


def truth_for(st: MCSettings, k: int):
    """Run k's cell truth (a ``CellParams``: what the offsets are compared with)."""
    return st.world(k)[0].params


# ----- one run --------------------------------------------------------------------------------

def _with_references(Jf, v, layout, free, truth, references):
    """The samples' rows (Jacobian over the free parameters, variances) and the scene's
    known lengths' (``estimation.fit.FitPrior``: two plates' tilt and gap at the truth, at
    their declared std): the information the fit has, which the bounds describe."""
    if not references:
        return Jf, v
    sigma = float(np.sqrt(np.mean(v)))  # the rows weighed as distances of this std
    x = truth.to_vector(layout)
    P, _ = FitPrior.of(layout, x, free, references, sigma).rows(x[free], Jf.shape[1])
    return np.vstack([Jf, P]), np.concatenate([v, np.full(len(P), sigma ** 2)])


def run_one(job) -> dict:
    """One Monte Carlo run: job = (settings, k). Pure function of (settings, k)."""
    from planecal.model.scene import nominal_params

    st, k = job
    scene = cached_scene(st.scene)
    robot = scene.robot
    seed = st.seed + k
    try:
        qe, d, plate, direction, rejected, world, opts = sample_run(st, k)
    except RuntimeError as e:  # the run gave up (e.g. 500 poses rejected in a row)
        return {"k": k, "seed": seed, "failed": str(e)}
    s, sample_sigma = st.joint_sigma(), st.sample_sigma_m()
    weights = {"joint_sigma_rad": s, "distance_sigma_m": max(sample_sigma, 1e-9)} \
        if st.weighted else {}
    cal = calibrate(robot, qe, d, nominal_params(scene), plate,
                    st.calibration(FitOptions(**weights)), direction, scene.references)
    fit = cal.result
    layout, free = fit.layout, fit.free
    truth = true_params(robot, world, opts)
    # noise model and bounds at the truth, on this run's samples
    _, J = predict_with_jacobian(robot, qe, truth, plate, layout)
    v = sample_variance(robot, J[:, layout.slice("joint_offsets")], s, sample_sigma,
                        st.quantized())
    Jb, vb = _with_references(J[:, free], v, layout, free, truth, scene.references)
    cov = covariances(Jb, vb)
    # identifiability with every parameter of the layout free, at the truth
    every = np.ones(len(layout), bool)
    ident_all, _, _ = uncertainty(J, np.sqrt(v), layout, every)
    # over the candidates: NaN where this run's base set left a parameter out
    names = st.candidates()
    pos = {n: i for i, n in enumerate(layout.names_of(free))}

    def over(vec):
        return np.array([vec[pos[n]] if n in pos else np.nan for n in names])

    def over2(M):
        idx = [pos.get(n) for n in names]
        out = np.full((len(names), len(names)), np.nan)
        for a, i in enumerate(idx):
            for b, j in enumerate(idx):
                if i is not None and j is not None:
                    out[a, b] = M[i, j]
        return out
    x, xt = fit.params.to_vector(layout), truth.to_vector(layout)
    return {
        "k": k, "seed": seed, "samples": int(len(d)), "rejected": rejected,
        "err": over((x - xt)[free]), "reported_cov": over2(fit.covariance.matrix),
        "reported_std": over(fit.covariance.stds),
        "white_var": over(np.diag(cov["white"])), "sandwich_var": over(np.diag(cov["sandwich"])),
        "crb_var": over(np.diag(cov["crb"])), "sandwich_cov": over2(cov["sandwich"]),
        "crb_cov": over2(cov["crb"]),
        "sigma_model_mm": float(np.sqrt(np.mean(v)) * 1e3),
        "sigma_fit_mm": float(fit.sigma_m * 1e3), "rms_mm": fit.rms_mm(),
        "max_residual_mm": float(np.abs(fit.residuals_m).max() * 1e3),
        "converged": bool(fit.converged), "iterations": int(fit.iterations),
        "not_identifiable": fit.identifiability.not_identifiable,
        "not_identifiable_all_free": ident_all.not_identifiable,
        "truth": over(xt[free]),
    }


def run_many(st: MCSettings, engine=1, quiet: bool = False, label: str | None = None,
             results=None, resume: bool = False):
    """The runs of ``st`` in run order, through ``engine`` (``studies.common.engine_for``:
    an open ``Engine``, or a job count); run k is ``run_one((st, k))`` on whichever worker,
    its seed ``st.seed + k``. ``results``: the JSON-lines file each run is written to as it
    completes (key k, header the settings); ``resume`` runs only the k not in it yet."""
    st.check()
    # the scene's name, not the path a command resolved it to (issue 33)
    prog = Progress(label or f"montecarlo {cached_scene(st.scene).name} N={st.samples}",
                    st.runs, quiet=quiet)
    return parallel_map(run_one, [(st, k) for k in range(st.runs)], engine, prog,
                        key=_run_key, results=results, resume=resume,
                        header={"format": FORMAT, "settings": st.header()})


def _run_key(item) -> int:
    return item[1]


# ----- analysis ---------------------------------------------------------------------------------

def _chi2(errs, covs, idx):
    from scipy import stats
    T = []
    for e, C in zip(errs, covs):
        Ci = C[np.ix_(idx, idx)]
        if not np.all(np.isfinite(Ci)):
            continue
        ei = e[idx]
        T.append(float(ei @ np.linalg.solve(Ci, ei)))
    T = np.array(T)
    kdim = len(idx)
    values = T.tolist()
    R = len(T)
    if R < 2 or kdim == 0:
        return None
    se = np.sqrt(2 * kdim / R)
    ks = stats.kstest(T, "chi2", args=(kdim,))
    q95 = stats.chi2.ppf(0.95, kdim)
    ok = bool(abs(T.mean() - kdim) < 3 * se and ks.pvalue > 0.01)
    return {"dof": kdim, "runs": R, "mean": float(T.mean()), "expected": kdim,
            "standard_error": float(se), "ks_pvalue": float(ks.pvalue),
            "share_below_chi2_95": float(np.mean(T < q95)), "passes": ok, "values": values}


def _parameter_stats(runs: list[dict], fnames: list[str]) -> dict:
    """Per candidate fitted in at least two runs: bias, empirical std, the bounds' RMS over
    the runs (white, sandwich, Cramer-Rao), the reported std and their ratios."""
    R = len(runs)
    E = np.array([r["err"] for r in runs], float)
    n_fit = np.isfinite(E).sum(0)
    with np.errstate(invalid="ignore", divide="ignore"):
        bias = np.nansum(E, 0) / np.maximum(n_fit, 1)
        emp = np.sqrt(np.nansum((E - bias) ** 2, 0) / np.maximum(n_fit - 1, 1))
    emp[n_fit < 2] = np.nan

    def rms(key):
        A = np.array([r[key] for r in runs], float)
        return np.sqrt(np.nansum(A, 0) / np.maximum(np.isfinite(A).sum(0), 1))
    white, sand, crb = rms("white_var"), rms("sandwich_var"), rms("crb_var")
    # errors normalised by each run's own bound: std 1 if the bound holds run by run; its
    # standard error stays 1/sqrt(2(R-1)) however much the designs (and bounds) vary
    with np.errstate(invalid="ignore"):
        Z = E / np.sqrt(np.array([r["crb_var"] for r in runs], float))
    # the fit reports no std (NaN) for a parameter it finds not identifiable in that run;
    # in a world with model mismatch its residual sigma is larger and a weak parameter
    # (phi_z) exceeds its practical limit in every run: no std to average (NaN, counted)
    rep2 = np.array([np.asarray(r["reported_std"], float) ** 2 for r in runs])
    n_rep = np.isfinite(rep2).sum(0)
    rep = np.full(rep2.shape[1], np.nan)
    has = n_rep > 0
    rep[has] = np.sqrt(np.nansum(rep2[:, has], axis=0) / n_rep[has])
    params = {}
    for i, n in enumerate(fnames):
        if n_fit[i] < 2:  # fitted in fewer than two runs: no spread to compare
            continue
        params[n] = {
            "runs_fitted": int(n_fit[i]), "bias": float(bias[i]),
            "empirical_std": float(emp[i]), "crb_white_std": float(white[i]),
            "sandwich_std": float(sand[i]), "crb_std": float(crb[i]),
            "reported_std": float(rep[i]), "reported_in_runs": int(n_rep[i]),
            "ratio_emp_to_crb_white": float(emp[i] / white[i]),
            "ratio_emp_to_sandwich": float(emp[i] / sand[i]),
            "ratio_emp_to_crb": float(emp[i] / crb[i]),
            "normalized_std": float(np.nanstd(Z[:, i], ddof=1)),
            "ratio_emp_to_reported": float(emp[i] / rep[i]),
            "bias_over_crb": float(abs(bias[i]) / crb[i]),
            "bias_t": float(bias[i] / (emp[i] / np.sqrt(R))),
        }
    return params, E, n_fit


def _chi2_checks(runs: list[dict], fnames: list[str], n_fit, weighted: bool):
    """(offsets checked, chi-square of the offsets with the reported and the sandwich
    covariance, chi-square of every parameter fitted in all runs)."""
    R = len(runs)

    def steady(i, n):
        return n_fit[i] == R and all(n not in r["not_identifiable"] for r in runs)
    offsets = [f"delta{j}" for j in range(1, 7)]
    off = [i for i, n in enumerate(fnames) if n in offsets and steady(i, n)]
    errs = [r["err"] for r in runs]
    chi_rep = _chi2(errs, [r["reported_cov"] for r in runs], off)
    # the sandwich is the unweighted estimator's covariance: no check of a weighted fit
    chi_sand = None if weighted else _chi2(errs, [r["sandwich_cov"] for r in runs], off)
    chi_all = _chi2(errs, [r["reported_cov"] for r in runs],
                    [i for i, n in enumerate(fnames) if steady(i, n)])
    return [fnames[i] for i in off], chi_rep, chi_sand, chi_all


def _verdict(params: dict, offs: list[str], chi_rep) -> dict:
    def each(ok):
        return {n: bool(ok(params[n])) for n in offs}
    return {
        "efficient_within_15pct_of_crb": each(
            lambda p: abs(p["ratio_emp_to_crb"] - 1) <= TARGET_RATIO),
        "within_15pct_of_white_crb": each(
            lambda p: abs(p["ratio_emp_to_crb_white"] - 1) <= TARGET_RATIO),
        "reported_std_within_15pct": each(
            lambda p: abs(p["ratio_emp_to_reported"] - 1) <= TARGET_RATIO),
        "bias_under_fifth_of_crb": each(lambda p: p["bias_over_crb"] < TARGET_BIAS),
        "chi2_passes": None if chi_rep is None else chi_rep["passes"],
    }


def analyze(runs: list[dict], st: MCSettings) -> dict:
    """The study's summary over its runs (module docstring); a parameter's statistics are
    over the runs that fitted it (at level full each run has its own base set)."""
    names = st.layout().names
    fnames = st.candidates()
    failed = [{"seed": r["seed"], "reason": r["failed"]} for r in runs if "failed" in r]
    runs = [r for r in runs if "failed" not in r]
    if len(runs) < 2:
        raise InputError(f"only {len(runs)} of {len(runs) + len(failed)} runs completed")
    R = len(runs)
    params, E, n_fit = _parameter_stats(runs, fnames)
    offs, chi_rep, chi_sand, chi_all = _chi2_checks(runs, fnames, n_fit, st.weighted)
    rej = {k: int(sum(r["rejected"].get(k, 0) for r in runs))
           for k in ("collision", "laser", "unreachable")}
    return {
        "format": FORMAT, "world": _world_summary(st, runs),
        "settings": _settings_dict(st), "runs": R, "free": fnames, "params": params,
        "offsets": offs,
        "relative_standard_error_of_std": 1.0 / np.sqrt(2 * (R - 1)),  # of a std, R runs
        "chi2_offsets_reported": chi_rep, "chi2_offsets_sandwich": chi_sand,
        "chi2_all_reported": chi_all, "verdict": _verdict(params, offs, chi_rep),
        "sigma_model_mm": float(np.mean([r["sigma_model_mm"] for r in runs])),
        "sigma_fit_mm": float(np.mean([r["sigma_fit_mm"] for r in runs])),
        "not_converged": int(sum(not r["converged"] for r in runs)),
        "rejected_total": rej,
        "not_identifiable_all_free": sorted(
            {n for r in runs for n in r["not_identifiable_all_free"]}, key=names.index),
        "samples_per_run": float(np.mean([r["samples"] for r in runs])),
        "failed_runs": failed,
        "run_errors": [[None if not np.isfinite(v) else float(v) for v in row] for row in E],
        "run_crb_std": [[None if not np.isfinite(v) else float(np.sqrt(v))
                         for v in r["crb_var"]] for r in runs],
    }


def _world_summary(st: MCSettings, runs: list[dict]) -> dict:
    """The world the runs sampled in (profile, its error sources, the effective noise) and
    how far the fit's residuals exceed the noise (the model mismatch)."""
    scene = cached_scene(st.scene)
    opts = st.options()
    if st.mode == "synthetic":
        on = ["noise"]
    else:
        on = sources_on(scene.robot, st.world(0)[0], opts)
    rep = opts.repeatability_mm
    sig_model = float(np.mean([r["sigma_model_mm"] for r in runs]))
    sig_fit = float(np.mean([r["sigma_fit_mm"] for r in runs]))
    mx = np.array([r["max_residual_mm"] for r in runs])
    return {"errors": str(st.errors), "profile": str(cached_profile(st.scene, st.errors).path),
            "sources": on, "model_mismatch": [f for f in on if f in MISMATCH],
            "laser_noise_mm": opts.laser_noise_mm,
            "repeatability_mm": scene.robot.repeatability_m * 1e3 if rep is None else rep,
            "quantization": st.quantized(),
            "sigma_fit_over_model": sig_fit / sig_model if sig_model > 0 else float("inf"),
            "max_residual_mm": {"median": float(np.median(mx)), "min": float(mx.min()),
                                "max": float(mx.max())}}


def _settings_dict(st: MCSettings) -> dict:
    d = asdict(st)
    d["poses"] = None if st.poses is None else len(st.poses)
    d["calibration"] = st.calibration().to_dict()
    return d


def slope_study(st: MCSettings, sample_counts: list[int], engine=1, quiet=False,
                results=None, resume: bool = False) -> dict:
    """Empirical and CR spread of the offsets vs the number of samples, and the log-log
    slope (N^-1/2 expected) fitted over ``sample_counts``. ``results(n)``: the results
    file of the point with n samples (``run_many``)."""
    rows = []
    for n in sample_counts:
        s = replace(st, samples=n)
        res = analyze(run_many(s, engine, quiet, label=f"slope N={n}",
                               results=None if results is None else results(n),
                               resume=resume), s)
        rows.append({"samples": n, **{p: {"empirical_std": res["params"][p]["empirical_std"],
                                          "crb_std": res["params"][p]["crb_std"]}
                                      for p in res["offsets"]}})
    offs = [k for k in rows[0] if k != "samples"]
    logn = np.log([r["samples"] for r in rows])
    slopes = {}
    for p in offs:
        ye = np.log([r[p]["empirical_std"] for r in rows])
        yc = np.log([r[p]["crb_std"] for r in rows])
        slopes[p] = {"empirical": float(np.polyfit(logn, ye, 1)[0]),
                     "crb": float(np.polyfit(logn, yc, 1)[0])}
    return {"scene": st.scene, "sample_counts": list(sample_counts), "runs_per_point": st.runs,
            "rows": rows, "slopes": slopes}
