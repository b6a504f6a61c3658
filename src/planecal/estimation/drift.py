"""Has the cell drifted since a calibration? The statistics of ``planecal check`` and
``planecal history diff`` (docs/HISTORY.md states and measures them).

The check (``check_run``) compares a short run's model errors with the result's
parameters, r = predicted - measured, with the result's own model errors on its
calibration samples. Its residuals include whatever the model lacks (on a realistic
cell the residual std is set by unmodelled errors, not by noise, and they are far from
Gaussian: a few stretched poses err by 5-8 sigma), so the test makes no assumption on
their distribution. Each residual is studentized by its pose's leverage, which accounts
for the run's poses differing from the calibration's::

    calibration sample i:  a_i = |r_i| / sqrt(1 - h_i)   (fitted: the fit pulls it in)
    run sample k:          b_k = |r_k| / sqrt(1 + h_k)   (predicted: the parameters' error adds)
    h = j (J^T J)^-1 j^T,  (J^T J)^-1 = C / s^2  (the result's covariance C, residual
                                                  variance s^2, fitted parameters' rows j)

For Gaussian errors both are |N(0, s^2)|. The test is the exceedance test (Mathisen's
two-sample median test): X = the number of the m run values b_k above the median of the n
calibration values (the k-th largest a, k = ceil(n/2)). If the run's errors come from the
calibration's own error distribution (H0: no drift), whatever its shape, X follows the
negative hypergeometric distribution NHG(N = n + m, K = m, r = k) (scipy's
``nhypergeom``): the number of run values met before the k-th calibration value when the
n + m values are taken in descending order. p = P(X >= x); the run drifted when
p <= alpha. Being discrete, the test's false-alarm rate is its attained size, the largest
P(X >= x) not above alpha (``attained_alpha``), never more than alpha. Weighted results
weigh both sets of rows by the result's noise model.

The reference: a calibration's residuals are one draw of 150-odd poses, whose error scale
varies from one calibration run to the next more than independent samples would (on the
realistic twin the calibration's median |error| sits anywhere between the 38th and the
65th percentile of later runs' errors): against one result the false-alarm rate of a
check is conditional on that draw. Once a result has earlier runs that passed
(``reference_runs``, the history's in-control checks against it), they are the
reference instead: runs after one calibration are alike, and the rate comes back towards
the stated one (docs/HISTORY.md measures both: 2.5 % and 1.7 % where 0.48 % is stated).

Which parameters moved: each suspect alone (default the six joint offsets), the rest held
at the result's values, fitted to the run's residuals by generalised least squares with
the run's prediction covariance S = s^2 I + J_f C J_f^T: amount (run minus result) and
its std, z = amount / std; significant where |z| exceeds the normal quantile at
alpha / (2 K) (Bonferroni over the K suspects). What moved (``Explanation``) is chosen by
forward selection: the suspect whose fit leaves the least chi-square r^T S^-1 r first,
then (jointly with it) the next, until the test passes on what they leave or no suspect
lowers the chi-square by more than chi2_1(1 - alpha). The suspects whose fit alone leaves
a chi-square within that of the first are named as alternatives: on these poses they
explain the run as well (on one plate, delta1, delta2 and delta3 can look alike to 30
poses).

Two things the median test cannot see are refused or flagged beside it: a run too short
for the test to ever reject at alpha (even every value above the median would not:
``InputError``, with the count that could), and gross errors (``gross``): a run value
more than ``GROSS_FACTOR`` times the reference's largest studentized error. One such
sample barely moves an exceedance count (one of 30), so a run with a reading 10 mm off
would pass as in control; no drift of the model and no noise the reference showed makes
an error ten times any the calibration had, so the run is not in control (a reading or a
pose gone wrong: the laser on another surface, a plate knocked, or a drift far beyond the
calibration's scale), and the check says which samples.

``parameter_changes`` (history diff): each parameter's change between two results against
both results' std, z = (b - a) / sqrt(std_a^2 + std_b^2) (independent calibrations),
significant where |z| exceeds the normal quantile at alpha / (2 K), K parameters compared.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from planecal.base.errors import InputError
from planecal.model.cell_params import CellParams
from planecal.model.layout import ParamLayout
from planecal.model.robot import Robot

DEFAULT_ALPHA = 0.01
GROSS_FACTOR = 10.0  # a run error this many times the reference's largest is gross
JOINT_OFFSETS = tuple(f"delta{j}" for j in range(1, 7))


# ----- the result as the check reads it ---------------------------------------------------

@dataclass(frozen=True, eq=False)
class FittedResult:
    """A calibration result as its document holds it: the parameters, the layout of its
    level, the fitted (identifiable) names with their covariance ``C`` [SI], the residual
    variance ``s2`` (weighted units for a weighted result), its noise model (None:
    unweighted) and which calibration samples it used (``outliers`` excluded)."""
    robot: Robot
    params: CellParams
    layout: ParamLayout
    names: tuple[str, ...]
    C: np.ndarray
    s2: float
    noise: tuple[float, float] | None
    outliers: tuple[int, ...]
    samples_used: int

    @classmethod
    def of(cls, doc: dict, robot: Robot, where: str) -> "FittedResult":
        """From a result document (``planecal calibrate --out``); InputError naming the
        file for a parameter file or an incomplete result."""
        from planecal.io.params import params_from_dict
        from planecal.model.levels import layout_for

        cov, ident = doc.get("covariance"), doc.get("identifiability")
        if not isinstance(cov, dict) or not isinstance(ident, dict):
            raise InputError(f"{where}: not a calibration result (no covariance): a drift "
                             "check needs the fit's own residual distribution")
        params = params_from_dict(doc, where)
        layout = layout_for(robot, params.n_planes, doc.get("level") or "offsets",
                            bool(doc.get("compliance")))
        C = np.array([[np.nan if v is None else v for v in row] for row in cov["matrix"]],
                     float)
        ok = np.isfinite(np.diag(C))
        names = tuple(n for n, k in zip(cov["names"], ok) if k)
        C = C[np.ix_(ok, ok)]
        for n in names:
            layout.index(n)
        noise = None
        if ident.get("weighted"):
            st = doc.get("calibration") or {}
            if st.get("joint_sigma_rad") is None:
                raise InputError(f"{where}: a weighted result that does not record its noise "
                                 "model (made before planecal recorded it): recalibrate")
            noise = (float(st["joint_sigma_rad"]), float(st["distance_sigma_m"]))
            s2 = float(ident["variance_factor"])
        else:
            s2 = (float(ident["sigma_mm"]) * 1e-3) ** 2
        if not s2 > 0:
            raise InputError(f"{where}: the result's residual variance is 0: no distribution "
                             "to check a run against")
        return cls(robot, params, layout, names, C, s2, noise,
                   tuple(int(i) for i in doc.get("outliers") or []),
                   int(doc.get("samples_used", 0)))

    def rows(self, qe, d_m, plate) -> "Rows":
        """The model errors of samples with the result's parameters, weighted where the
        result is, with the Jacobian of the whole layout (weighted too)."""
        from planecal.estimation.noise import noise_variance
        from planecal.model.measurement import predict_with_jacobian

        pred, J = predict_with_jacobian(self.robot, np.asarray(qe, np.int64), self.params,
                                        np.asarray(plate, int), self.layout)
        r = pred - np.asarray(d_m, float)
        w = np.ones(len(r))
        if self.noise is not None:
            w = 1.0 / np.sqrt(noise_variance(J[:, self.layout.slice("joint_offsets")],
                                             *self.noise))
        Jw = J * w[:, None]
        Jf = Jw[:, self.layout.indices(self.names)]
        h = np.einsum("ij,jk,ik->i", Jf, self.C / self.s2, Jf)
        return Rows(r, r * w, Jw, Jf, h)


@dataclass(frozen=True, eq=False)
class Rows:
    """Samples' model errors: ``r`` [m] (predicted - measured), weighted ``rw``, the
    weighted Jacobian of the layout ``J`` and of the fitted parameters ``Jf``, leverages
    ``h``."""
    r: np.ndarray
    rw: np.ndarray
    J: np.ndarray
    Jf: np.ndarray
    h: np.ndarray


# ----- the test ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Exceedance:
    """The exceedance test (module docstring): ``exceed`` of the ``m`` run values above
    the calibration's median ``threshold`` (the ``k``-th largest of ``n``), its
    ``expected`` count and std under H0, ``p`` = P(X >= exceed), ``alpha`` and the
    attained false-alarm rate."""
    n: int
    m: int
    k: int
    threshold: float
    exceed: int
    expected: float
    std: float
    p: float
    alpha: float
    attained_alpha: float
    critical: int  # the fewest exceedances that reject at alpha (m + 1: none can)

    @property
    def rejected(self) -> bool:
        return self.p <= self.alpha


def exceedance_test(calibration: np.ndarray, run: np.ndarray,
                    alpha: float = DEFAULT_ALPHA) -> Exceedance:
    """The exceedance test of ``run`` values against ``calibration`` values (module
    docstring), one-sided (large run values reject)."""
    from scipy.stats import nhypergeom
    a = np.sort(np.asarray(calibration, float))[::-1]
    b = np.asarray(run, float)
    n, m = len(a), len(b)
    if n < 2 or m < 1:
        raise InputError(f"a drift check needs at least 2 calibration samples and 1 run "
                         f"sample, got {n} and {m}")
    k = (n + 1) // 2
    t = float(a[k - 1])
    x = int(np.sum(b > t))
    dist = nhypergeom(n + m, m, k)
    sf = dist.sf(np.arange(-1, m))  # sf[j] = P(X >= j)
    p = float(min(1.0, sf[x]))
    reject = np.flatnonzero(sf <= alpha)
    critical = int(reject[0]) if len(reject) else m + 1
    attained = float(sf[critical]) if critical <= m else 0.0
    return Exceedance(n, m, k, t, x, float(dist.mean()), float(dist.std()), p, float(alpha),
                      attained, critical)


@dataclass(frozen=True)
class Suspect:
    """One suspect parameter fitted alone to the run (module docstring): ``amount`` [SI]
    (the run's value minus the result's), its ``std``, ``z``, ``significant`` at the
    Bonferroni level, and the test on the residuals it leaves (``p_after``)."""
    name: str
    amount: float
    std: float
    z: float
    significant: bool
    p_after: float
    explains: bool


@dataclass(frozen=True)
class Explanation:
    """What moved (module docstring): the suspects chosen one by one, each the one that
    explains most of what the ones before leave (``names``), their joint ``amounts`` and
    ``stds`` [SI], the test's p on what they leave (``p_after``; it ``explains`` the run
    where that is in control), and the suspects that explain the run as well as the first
    (``alternatives``: these poses cannot tell them apart)."""
    names: tuple[str, ...]
    amounts: tuple[float, ...]
    stds: tuple[float, ...]
    p_after: float
    explains: bool
    alternatives: tuple[str, ...]


@dataclass(frozen=True)
class DriftCheck:
    test: Exceedance
    run_rms_m: float
    run_mean_m: float
    calibration_rms_m: float
    suspects: list[Suspect]
    explanation: Explanation | None
    no_effect: list[str] = field(default_factory=list)
    z_limit: float = math.inf
    chi2_limit: float = math.inf
    reference_runs: int = 0  # earlier in-control runs the test's reference is made of
    gross: tuple = ()  # (run sample index, model error [m], studentized value) beyond the limit
    gross_limit: float = math.inf  # studentized, in the test's units

    @property
    def drifted(self) -> bool:
        return self.test.rejected or bool(self.gross)

    @property
    def moved(self) -> list[str]:
        """The parameters that moved, the best explanation first; none for a run in
        control."""
        return list(self.explanation.names) if self.drifted and self.explanation else []


def gls(Jc: np.ndarray, rw: np.ndarray, Si: np.ndarray):
    """Amounts (run minus result), their covariance and the chi-square left, of columns
    ``Jc`` (n, k) fitted to the residuals ``rw`` (r = predicted - measured = -J amount)."""
    A = Jc.T @ Si @ Jc
    cov = np.linalg.inv(A)
    x = -cov @ (Jc.T @ Si @ rw)
    e = rw + Jc @ x
    return x, cov, float(e @ Si @ e)


def forward_selection(rw: np.ndarray, Si: np.ndarray, cols: dict, test_after,
                      chi2_limit: float) -> Explanation | None:
    """Forward selection over the suspects ``cols`` (name -> weighted column) fitted to the
    residuals ``rw`` (r = -J amount) with the inverse covariance ``Si``: add the one that
    leaves the least chi-square until ``test_after(residuals left, chi-square left,
    parameters fitted)`` passes (a p above 0) or none lowers the chi-square by more than
    ``chi2_limit``. ``test_after`` returns (p, rejected)."""
    chosen: list[str] = []
    first: dict = {}
    x = cov = None
    p_after, passed, left = 0.0, False, float(rw @ Si @ rw)
    while len(chosen) < len(cols):
        trials = {n: gls(np.column_stack([cols[c] for c in chosen + [n]]), rw, Si)
                  for n in cols if n not in chosen}
        best = min(trials, key=lambda n: trials[n][2])
        if left - trials[best][2] <= chi2_limit:
            break
        if not chosen:
            first = {n: t[2] for n, t in trials.items()}
        chosen.append(best)
        x, cov, left = trials[best]
        J = np.column_stack([cols[c] for c in chosen])
        p_after, rejected = test_after(rw + J @ x, left, len(chosen))
        passed = not rejected
        if passed:
            break
    if not chosen:
        return None
    alt = tuple(n for n, c2 in sorted(first.items(), key=lambda t: t[1])
                if n != chosen[0] and c2 - first[chosen[0]] <= chi2_limit)
    return Explanation(tuple(chosen), tuple(float(v) for v in x),
                       tuple(float(v) for v in np.sqrt(np.diag(cov))), p_after, passed, alt)


def single_fits(rw: np.ndarray, Si: np.ndarray, cols: dict, z_limit: float,
                test_after) -> list[Suspect]:
    """Each suspect of ``cols`` fitted alone (``gls``), strongest first."""
    out = []
    for n, j in cols.items():
        x, cov, left = gls(j[:, None], rw, Si)
        amount, std = float(x[0]), float(np.sqrt(cov[0, 0]))
        p, rejected = test_after(rw + j * amount, left, 1)
        out.append(Suspect(n, amount, std, amount / std, abs(amount / std) > z_limit, p,
                           not rejected))
    out.sort(key=lambda s: -s.z ** 2)
    return out


def parse_suspects(text: str | None, layout: ParamLayout) -> tuple[str, ...]:
    """--suspects: comma-separated names of ``layout`` (None: the joint offsets);
    InputError naming an unknown one and the known ones."""
    if text is None:
        return JOINT_OFFSETS
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise InputError(f"--suspects: no parameter named in {text!r}")
    for n in names:
        if n not in layout.names:
            raise InputError(f"--suspects: {n!r} is not a parameter here; known: "
                             f"{', '.join(layout.names)}")
    return names


def suspect_columns(J: np.ndarray, layout: ParamLayout, names) -> tuple[dict, list[str]]:
    """(name -> Jacobian column, the names with no effect on these samples)."""
    names = list(dict.fromkeys(names))
    norms = {n: float(np.linalg.norm(J[:, layout.index(n)])) for n in names}
    top = max(norms.values(), default=0.0)
    cols = {n: J[:, layout.index(n)] for n in names if norms[n] > 1e-12 * top}
    return cols, [n for n in names if n not in cols]


def check_run(fr: FittedResult, calibration, run, alpha: float = DEFAULT_ALPHA,
              suspects=JOINT_OFFSETS, reference_runs=()) -> DriftCheck:
    """The drift check of a ``run`` against the result ``fr`` and its ``calibration``
    samples (each a (qe, d_m, plate) triple; module docstring); with ``reference_runs``
    (earlier in-control runs, the same triples) the test's reference is their studentized
    prediction errors instead of the calibration's residuals."""
    from scipy.stats import chi2, norm
    if not 0 < alpha < 1:
        raise InputError(f"--alpha must be in (0, 1), got {alpha}")
    cal = fr.rows(*calibration)
    used = np.ones(len(cal.r), bool)
    used[[i for i in fr.outliers if i < len(used)]] = False
    if int(used.sum()) != fr.samples_used:
        raise InputError(f"the calibration samples give {int(used.sum())} samples, the result "
                         f"used {fr.samples_used}: not the samples it was made from")
    a = np.abs(cal.rw[used]) / np.sqrt(np.maximum(1.0 - cal.h[used], 1e-12))
    if len(reference_runs):
        ref = [fr.rows(*x) for x in reference_runs]
        a = np.concatenate([np.abs(r.rw) / np.sqrt(1.0 + r.h) for r in ref])
    rows = fr.rows(*run)
    Si = np.linalg.inv(fr.s2 * np.eye(len(rows.r)) + rows.Jf @ fr.C @ rows.Jf.T)
    scale = np.sqrt(1.0 + rows.h)
    b = np.abs(rows.rw) / scale
    test = exceedance_test(a, b, alpha)
    if test.critical > test.m:
        raise InputError(f"the run's {test.m} samples cannot show a drift against "
                         f"{test.n} reference values at alpha {alpha:g} (even all above the "
                         f"median is p = {all_above_p(test.n, test.m):.3g}); give at least "
                         f"{_shortest_run(test.n, alpha)} samples")
    limit = GROSS_FACTOR * float(np.max(a))
    gross = tuple((int(i), float(rows.r[i]), float(b[i])) for i in np.flatnonzero(b > limit))

    def test_after(rw, _chi2, _k):  # the test on what a fit leaves
        t = exceedance_test(a, np.abs(rw) / scale, alpha)
        return t.p, t.rejected

    cols, no_effect = suspect_columns(rows.J, fr.layout, suspects)
    z_limit = float(norm.isf(alpha / (2 * max(len(cols), 1))))
    chi2_limit = float(chi2.isf(alpha, 1))
    out = single_fits(rows.rw, Si, cols, z_limit, test_after)
    expl = (forward_selection(rows.rw, Si, cols, test_after, chi2_limit) if test.rejected
            else None)
    return DriftCheck(test, float(np.sqrt(np.mean(rows.r ** 2))), float(np.mean(rows.r)),
                      float(np.sqrt(np.mean(cal.r[used] ** 2))), out, expl, no_effect,
                      z_limit, chi2_limit, len(reference_runs), gross, limit)


def all_above_p(n: int, m: int) -> float:
    """P(X >= m): all m run values above the median of n reference values (H0)."""
    from scipy.stats import nhypergeom
    return float(nhypergeom(n + m, m, (n + 1) // 2).sf(m - 1))


def _shortest_run(n: int, alpha: float) -> int:
    """The fewest run samples whose exceedance test can reject at ``alpha``."""
    m = 1
    while all_above_p(n, m) > alpha and m < 10_000:
        m += 1
    return m


# ----- history diff -----------------------------------------------------------------------

@dataclass(frozen=True)
class Change:
    """One parameter between results A and B: values, stds (None: fixed), the change
    B - A with its std, z and whether it is significant (module docstring)."""
    name: str
    a: float
    b: float
    std_a: float | None
    std_b: float | None
    change: float
    std: float | None
    z: float | None
    significant: bool


def parameter_changes(a: dict, b: dict, alpha: float = DEFAULT_ALPHA) -> tuple[list[Change], float]:
    """Each parameter both results hold (``name -> (value, std or None)``, SI), in A's
    order: its change and significance; and the |z| limit used."""
    from scipy.stats import norm
    if not 0 < alpha < 1:
        raise InputError(f"--alpha must be in (0, 1), got {alpha}")
    names = [n for n in a if n in b]
    tested = [n for n in names if a[n][1] is not None or b[n][1] is not None]
    limit = float(norm.isf(alpha / (2 * max(len(tested), 1))))
    out = []
    for n in names:
        (va, sa), (vb, sb) = a[n], b[n]
        var = (sa or 0.0) ** 2 + (sb or 0.0) ** 2
        std = math.sqrt(var) if n in tested and var > 0 else None
        z = (vb - va) / std if std else None
        out.append(Change(n, va, vb, sa, sb, vb - va, std, z, z is not None and abs(z) > limit))
    return out, limit
