"""Identification: Gauss-Newton with an SVD pseudo-inverse (seed 6.2.1, 7.2), optional
Levenberg-Marquardt damping and column scaling, k-sigma outlier elimination, a mask of
free parameters, and an honest account of what the data can and cannot identify.

A typed problem in, a typed result out: ``Problem`` (the robot, the samples in SI, the
initial parameters, the parameter layout, the free mask, ``FitOptions``), built once from
arrays or from a ``Samples`` file; ``solve(problem) -> Result`` (params, residuals, history,
``Covariance`` over the free parameters by name, ``Identifiability``). Parameters are
addressed by name through the problem's ``planecal.model.layout.ParamLayout``.

Residual r = d_model - d_measured [m]. One iteration: J dx = -r solved in the least-squares
sense on the free columns. Iteration stops after ``max_iter`` corrections or when the mean
absolute correction falls below ``improvement_limit`` (the seed's end condition, 7.2).

Uncertainty (at the solution, on the samples used):
  sigma^2 = |r|^2 / (m - rank),  cov = sigma^2 (J^T J)^-1   (on the identifiable subspace;
  rank = p unless some direction is not identifiable)
That assumes white distance noise. A robot's is not: its repeatability, projected on the
beam, gives sample i a variance v_i = s^2 |dd/dq_i|^2 + s_d^2 that depends on the pose
(docs/STUDIES.md measures the effect: on three plates the reported std is ~20 % off).
``FitOptions(joint_sigma_rad=s)`` fits by weighted least squares instead, rows weighted
by 1/sqrt(v_i) with v_i re-evaluated at each iterate (``noise_variance``), and reports
  f = |W r|^2 / (m - rank) (the variance factor, ~1 when s is right),  cov = f (J^T W^2 J)^-1
which is the Cramer-Rao bound of the noise model, scaled by what the residuals show (the
singular values, condition number and observability indices are then those of W J).
Identifiability is judged on the column-scaled Jacobian (unit-norm columns, so units do not
matter): a scaled singular value below ``unidentifiable_ratio`` x the largest is a direction
the data cannot see; the parameters that make up that direction are named, and their
standard deviations are reported as missing (NaN / null), not as numbers; a parameter whose
Jacobian column vanishes is listed under ``no_effect`` as well. Directions below
``weak_ratio`` are reported as weakly identifiable. Observability indices (Sun & Hollerbach
1997) O1 = (s_1...s_p)^(1/p) / sqrt(m), O2 = s_min/s_max, O3 = s_min, O4 = s_min^2/s_max, on
the scaled Jacobian.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np

from planecal.model.cell import CellParams, predict, predict_with_jacobian
from planecal.model.layout import ParamLayout, level1_layout
from planecal.model.robot import Robot
from planecal.io.samples import Samples


@dataclass
class FitOptions:
    max_iter: int = 30
    improvement_limit: float = 1e-12
    outlier_sigma: float | None = None
    method: str = "gn"  # "gn": Gauss-Newton (SVD pseudo-inverse); "lm": Levenberg-Marquardt
    scale: bool = True  # column scaling of the Jacobian
    rcond: float = 1e-7  # pseudo-inverse cut-off relative to the largest scaled singular value
    lm_lambda0: float = 1e-3
    unidentifiable_ratio: float = 1e-7
    weak_ratio: float = 1e-3
    correlation_limit: float = 0.95
    # weighted fit (module docstring): joint-angle std of the robot's repeatability [rad]
    # (``robot.repeatability_sigma``; None: unweighted) and the std of a sample's distance
    # from the sensor itself [m]
    joint_sigma_rad: float | None = None
    distance_sigma_m: float = 1e-6
    # a prior (maximum a posteriori; level 2): ((name, std), ...) pulls those free
    # parameters towards their initial values, weighed as if the distances had the std
    # prior_sigma_m: rows (x - x0) * prior_sigma_m / std join the distance rows (gn only)
    prior: tuple = ()
    prior_sigma_m: float = 3e-5


# ----- the problem --------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Problem:
    """One calibration problem, in SI: encoder counts ``qe`` (N, 6) int64, measured
    distances ``d_m`` (N,) [m], ``plate`` (N,) 0-based plate of each sample, the
    ``initial`` parameters, the ``layout`` of the parameter vector, the ``free`` mask over
    it and the ``options``. Checked when built (ValueError); use ``from_arrays`` or
    ``from_samples``."""
    robot: Robot
    qe: np.ndarray
    d_m: np.ndarray
    plate: np.ndarray
    initial: CellParams
    layout: ParamLayout
    free: np.ndarray
    options: FitOptions = field(default_factory=FitOptions)

    def __post_init__(self):
        qe = np.asarray(self.qe, np.int64)
        d = np.asarray(self.d_m, float)
        plate = np.asarray(self.plate, int)
        free = np.asarray(self.free, bool)
        for name, v in (("qe", qe), ("d_m", d), ("plate", plate), ("free", free)):
            object.__setattr__(self, name, v)
        N = len(d)
        if qe.shape != (N, 6) or plate.shape != (N,) or d.shape != (N,):
            raise ValueError(f"samples: counts {qe.shape}, distances {d.shape} and plates "
                             f"{plate.shape} do not match (N, 6), (N,), (N,)")
        if self.layout.n_planes != self.initial.n_planes:
            raise ValueError(f"the layout holds {self.layout.n_planes} plane(s), the initial "
                             f"parameters {self.initial.n_planes}")
        if plate.size and plate.min() < 0:
            raise ValueError(f"samples refer to plate {plate.min() + 1}: no such plate")
        if plate.size and plate.max() >= self.initial.n_planes:
            raise ValueError(f"samples refer to plate {plate.max() + 1}, parameters hold "
                             f"{self.initial.n_planes} plane(s)")
        if free.shape != (len(self.layout),):
            raise ValueError(f"free mask of {free.shape} over {len(self.layout)} parameters")
        p = int(free.sum())
        if N <= p:
            raise ValueError(f"{N} samples cannot determine {p} free parameters")
        opt = self.options
        if opt.joint_sigma_rad is not None and not (
                np.isfinite(opt.joint_sigma_rad) and opt.joint_sigma_rad >= 0
                and np.isfinite(opt.distance_sigma_m) and opt.distance_sigma_m > 0):
            raise ValueError("weighted fit: joint_sigma_rad must be finite and >= 0, "
                             "distance_sigma_m finite and > 0")

    @classmethod
    def from_arrays(cls, robot: Robot, qe, d_m, initial: CellParams, plate=None, *,
                    free=None, options: FitOptions | None = None,
                    layout: ParamLayout | None = None) -> "Problem":
        """``free``: a bool mask over the layout, parameter names (a list or the --free
        comma string, "all"), or None for the layout's default. ``layout``: default the
        level-1 layout of ``initial``'s planes."""
        layout = layout or level1_layout(initial.n_planes)
        n = len(np.asarray(d_m))
        plate = np.zeros(n, int) if plate is None else plate
        return cls(robot, qe, d_m, plate, initial, layout, free_mask(layout, free),
                   options or FitOptions())

    @classmethod
    def from_samples(cls, robot: Robot, samples: Samples, initial: CellParams, *, free=None,
                     options: FitOptions | None = None,
                     layout: ParamLayout | None = None) -> "Problem":
        """From a sample file's ``Samples`` (its mm become m here)."""
        return cls.from_arrays(robot, samples.qe, samples.d_mm * 1e-3, initial, samples.plate,
                               free=free, options=options, layout=layout)

    def __len__(self) -> int:
        return len(self.d_m)

    @property
    def free_names(self) -> list[str]:
        return self.layout.names_of(self.free)

    def subset(self, idx) -> "Problem":
        """The same problem on the samples ``idx``."""
        return replace(self, qe=self.qe[idx], d_m=self.d_m[idx], plate=self.plate[idx])


def free_mask(layout: ParamLayout, free) -> np.ndarray:
    """A free mask from a bool mask, parameter names (list or comma string) or None."""
    if free is None:
        return layout.default_free
    if isinstance(free, str):
        return layout.free_from_names(free)
    arr = np.asarray(free)
    if arr.dtype == bool:
        return arr.copy()
    return layout.free_from_names(list(free))


# ----- the result -----------------------------------------------------------------------------

@dataclass(frozen=True)
class Iteration:
    iteration: int
    rms_m: float  # of the samples used
    max_m: float
    samples: int  # used
    mean_abs_correction: float | None = None  # None for iteration 0


@dataclass(frozen=True)
class CorrelatedPair:
    a: str
    b: str
    rho: float


@dataclass(frozen=True)
class PoorlyDetermined:
    parameter: str
    std: float
    limit: float


@dataclass(frozen=True)
class WeakDirection:
    scaled_singular_ratio: float
    direction: dict  # parameter name -> component of the unit direction


@dataclass(frozen=True)
class Observability:
    O1: float
    O2: float
    O3: float
    O4: float


@dataclass(frozen=True)
class Identifiability:
    """What the data can and cannot identify (module docstring); ``dataclasses.asdict``
    gives the result file's ``identifiability`` object."""
    free: list[str]
    not_identifiable: list[str]
    no_effect: list[str]
    poorly_determined: list[PoorlyDetermined]
    unidentifiable_directions: list[dict]  # each: parameter name -> component
    weak_directions: list[WeakDirection]
    correlated_pairs: list[CorrelatedPair]
    singular_values: list[float]
    scaled_singular_values: list[float]
    condition_number_scaled: float
    observability: Observability
    sigma_mm: float
    samples: int
    rank: int
    identifiable_min_scaled_ratio: float
    weighted: bool = False
    variance_factor: float | None = None  # weighted fit only

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True, eq=False)
class Covariance:
    """Covariance of the free parameters, by name; NaN rows and columns for a parameter
    that is not identifiable (in theory or in practice)."""
    names: tuple[str, ...]
    matrix: np.ndarray  # (p, p), SI units

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"{name!r} is not a free parameter "
                           f"(free: {', '.join(self.names)})") from None

    def std(self, name: str) -> float:
        return float(self.stds[self.index(name)])

    @property
    def stds(self) -> np.ndarray:
        """Standard deviations in ``names`` order (NaN where not identifiable)."""
        return np.sqrt(np.maximum(np.diag(self.matrix), 0.0))

    def correlation(self) -> np.ndarray:
        s = self.stds
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.matrix / np.outer(s, s)

    def correlated_pairs(self, threshold: float) -> list[CorrelatedPair]:
        """The pairs whose |correlation| exceeds ``threshold``, rho rounded to 5 digits."""
        c = self.correlation()
        p = len(self.names)
        return [CorrelatedPair(self.names[i], self.names[j], round(float(c[i, j]), 5))
                for i in range(p) for j in range(i + 1, p)
                if np.isfinite(c[i, j]) and abs(c[i, j]) > threshold]

    def to_dict(self) -> dict:
        """{"names": [...], "matrix": [[...]]} with null where not identifiable."""
        return {"names": list(self.names),
                "matrix": [[float(v) if np.isfinite(v) else None for v in row]
                           for row in self.matrix]}


@dataclass(frozen=True, eq=False)
class Result:
    problem: Problem
    params: CellParams
    converged: bool
    iterations: int
    initial_cost: float  # 0.5 |W r|^2 over the samples used (scipy's least_squares cost)
    final_cost: float  # at the last evaluation (within the end condition of the solution)
    history: list[Iteration]
    residuals_m: np.ndarray  # final model - measured, all samples (outliers included)
    initial_residuals_m: np.ndarray
    used: np.ndarray  # bool mask: samples kept (not outliers)
    outliers: list[int]
    sigma_m: float
    covariance: Covariance
    identifiability: Identifiability
    notes: list[str] = field(default_factory=list)

    @property
    def layout(self) -> ParamLayout:
        return self.problem.layout

    @property
    def free(self) -> np.ndarray:
        return self.problem.free

    @property
    def initial(self) -> CellParams:
        return self.problem.initial

    @property
    def names(self) -> list[str]:
        return self.layout.names

    @property
    def std(self) -> np.ndarray:
        """Standard deviations over the whole layout; NaN for fixed or unidentifiable."""
        out = np.full(len(self.layout), np.nan)
        out[self.free] = self.covariance.stds
        return out

    @property
    def correction(self) -> np.ndarray:
        return self.params.to_vector(self.layout) - self.initial.to_vector(self.layout)

    def rms_mm(self, initial: bool = False) -> float:
        r = self.initial_residuals_m if initial else self.residuals_m
        return float(np.sqrt(np.mean(r[self.used] ** 2)) * 1e3)


# ----- the solver ---------------------------------------------------------------------------

def noise_variance(J_delta: np.ndarray, joint_sigma: float, distance_sigma_m: float) -> np.ndarray:
    """Per-sample distance noise variance [m^2]: J_delta (N, 6) the Jacobian columns of the
    six joint offsets (= dd/dq), joint_sigma the joint-angle std of the robot's
    repeatability [rad], distance_sigma_m the std of a sample from the sensor [m]."""
    return joint_sigma ** 2 * np.sum(J_delta ** 2, axis=1) + distance_sigma_m ** 2


def row_weights(J: np.ndarray, layout: ParamLayout, opt: FitOptions) -> np.ndarray | None:
    """Row weights 1/sqrt(v_i) from the full Jacobian J, or None for an unweighted fit."""
    if opt.joint_sigma_rad is None:
        return None
    return 1.0 / np.sqrt(noise_variance(J[:, layout.slice("joint_offsets")],
                                        opt.joint_sigma_rad, opt.distance_sigma_m))


def _solve_step(A: np.ndarray, r: np.ndarray, rcond: float) -> np.ndarray:
    """Minimum-norm least-squares solution of A dx = -r by the SVD pseudo-inverse, with
    singular values below rcond x the largest cut off. The right singular vectors and
    singular values come from the eigen-decomposition of the (column-scaled) Gram matrix
    A^T A, 30x cheaper than an SVD of the tall A; rcond >= 1e-7 keeps the cut above the
    Gram matrix's rounding floor (1e-16 relative in s^2)."""
    lam, V = np.linalg.eigh(A.T @ A)
    keep = lam > (rcond ** 2) * lam[-1]
    return -(V[:, keep] @ ((V[:, keep].T @ (A.T @ r)) / lam[keep]))


def _scales(J: np.ndarray, on: bool) -> np.ndarray:
    if not on:
        return np.ones(J.shape[1])
    norms = np.linalg.norm(J, axis=0)
    return np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)


def solve(problem: Problem) -> Result:
    """Fit the cell parameters to the problem's samples (module docstring)."""
    pb = problem
    opt, layout, free = pb.options, pb.layout, pb.free
    robot, qe, d_m, pidx = pb.robot, pb.qe, pb.d_m, pb.plate
    N, p = len(d_m), int(free.sum())
    x = pb.initial.to_vector(layout)
    used = np.ones(N, bool)
    history: list[Iteration] = []
    outliers: list[int] = []
    lam = opt.lm_lambda0
    iterations = 0
    converged = False

    def evaluate(xv, mask):
        """Residuals, free Jacobian columns and row weights (None: unweighted) at xv."""
        d, J = predict_with_jacobian(robot, qe[mask], CellParams.from_vector(xv, layout),
                                     pidx[mask], layout)
        return d - d_m[mask], J[:, free], row_weights(J, layout, opt)

    def cost(r, w):
        rw = r if w is None else r * w
        return 0.5 * float(rw @ rw)

    # prior rows (FitOptions.prior): positions among the free columns and their weights
    free_names = layout.names_of(free)
    pj = np.array([free_names.index(n) for n, _ in opt.prior if n in free_names], int)
    pw = np.array([opt.prior_sigma_m / sd for n, sd in opt.prior if n in free_names], float)
    if pj.size and opt.method != "gn":
        raise ValueError("a prior needs method 'gn'")
    x_prior = x[free][pj].copy()

    def with_prior(Jw, rw, xv):
        if not pj.size:
            return Jw, rw
        P = np.zeros((pj.size, Jw.shape[1]))
        P[np.arange(pj.size), pj] = pw
        return np.vstack([Jw, P]), np.concatenate([rw, pw * (xv[free][pj] - x_prior)])

    r, Jf, w = evaluate(x, used)
    initial_r = r.copy()
    initial_cost = cost(r, w)
    history.append(Iteration(0, float(np.sqrt(np.mean(r ** 2))), float(np.max(np.abs(r))),
                             int(used.sum())))
    for it in range(1, opt.max_iter + 1):
        # weighted: rows scaled by w (held for this iteration, re-evaluated at the next)
        Jw, rw = (Jf, r) if w is None else (Jf * w[:, None], r * w)
        Jw, rw = with_prior(Jw, rw, x)
        S = _scales(Jw, opt.scale)
        A = Jw * S
        if opt.method == "gn":
            dx = S * _solve_step(A, rw, opt.rcond)
        elif opt.method == "lm":
            c0 = rw @ rw
            H = A.T @ A
            g = A.T @ rw
            for _ in range(30):
                step = np.linalg.lstsq(H + lam * np.diag(np.maximum(np.diag(H), 1e-30)), -g,
                                       rcond=None)[0]
                xt = x.copy()
                xt[free] += S * step
                rt = evaluate(xt, used)[0]
                if w is not None:
                    rt = rt * w
                if rt @ rt <= c0:
                    lam = max(lam / 10, 1e-12)
                    break
                lam *= 10
            else:
                step = np.zeros(p)
            dx = S * step
        else:
            raise ValueError(f"unknown method {opt.method!r} (gn or lm)")
        x[free] += dx
        iterations = it
        mean_dx = float(np.mean(np.abs(dx)))
        if mean_dx < opt.improvement_limit and opt.outlier_sigma is None:
            # converged: r and J at x - dx describe x to O(|dx|), below the limit
            last = history[-1]
            history.append(Iteration(it, last.rms_m, last.max_m, int(used.sum()), mean_dx))
            converged = True
            break
        r, Jf, w = evaluate(x, used)
        if opt.outlier_sigma is not None:
            e = r if w is None else r * w  # weighted: standardised residuals
            dev = np.abs(e - e.mean())
            bad = dev > opt.outlier_sigma * e.std()
            if bad.any() and used.sum() - bad.sum() > p + 1:
                idx = np.flatnonzero(used)[bad]
                outliers.extend(int(i) for i in idx)
                used[idx] = False
                r, Jf, w = evaluate(x, used)
        history.append(Iteration(it, float(np.sqrt(np.mean(r ** 2))), float(np.max(np.abs(r))),
                                 int(used.sum()), mean_dx))
        if mean_dx < opt.improvement_limit:
            converged = True
            break
    params = CellParams.from_vector(x, layout)
    # residuals over all samples (outliers included), for reporting
    final_r = r if used.all() else predict(robot, qe, params, pidx) - d_m
    if pj.size:  # the posterior covariance: the prior rows join the data's
        Jp, rp = with_prior(Jf if w is None else Jf * w[:, None], r if w is None else r * w, x)
        ident, cov, sigma = uncertainty(Jp, rp, layout, free, opt)
    else:
        ident, cov, sigma = uncertainty(Jf, r, layout, free, opt, weights=w)
    notes = []
    if not converged:
        notes.append(f"stopped after {iterations} iterations (max_iter) before the mean "
                     f"correction fell below {opt.improvement_limit:g}")
    return Result(pb, params, converged, iterations, initial_cost, cost(r, w), history,
                  final_r, initial_r, used, sorted(outliers), sigma, cov, ident, notes)


def analyze(robot: Robot, qe: np.ndarray, params: CellParams, plane_index=None,
            free=None, sigma_m: float = 2e-6, options: FitOptions | None = None,
            layout: ParamLayout | None = None) -> tuple[Identifiability, Covariance]:
    """Identifiability and predicted covariance of a pose set *before* fitting: the
    Jacobian at ``params`` (e.g. the nominal values) and an assumed distance noise
    ``sigma_m`` (white: the weighted fit's options are not used here). ``free`` as for
    ``Problem.from_arrays``."""
    opt = options or FitOptions()
    layout = layout or level1_layout(params.n_planes)
    free = free_mask(layout, free)
    _, J = predict_with_jacobian(robot, qe, params, plane_index, layout)
    Jf = J[:, free]
    ident, cov, _ = uncertainty(Jf, np.zeros(len(Jf)), layout, free, opt, known_sigma_m=sigma_m)
    return ident, cov


def uncertainty(Jf: np.ndarray, r: np.ndarray, layout: ParamLayout, free: np.ndarray,
                opt: FitOptions | None = None, weights: np.ndarray | None = None,
                known_sigma_m: float | None = None):
    """Covariance and the identifiability report at a solution, for the free columns Jf of
    the Jacobian and the residuals r; ``weights`` (row weights 1/sqrt(v_i)): of the weighted
    fit (module docstring); ``known_sigma_m``: a known white noise std instead of the
    residuals' estimate (``analyze``). Returns (Identifiability, Covariance, sigma_m =
    sqrt(|r|^2 / (m - rank)) of the unweighted residuals, or the known sigma)."""
    opt = opt or FitOptions()
    m, p = Jf.shape
    rr = float(r @ r)  # the unweighted residuals' (sigma_m)
    if weights is not None:
        Jf, r = Jf * weights[:, None], r * weights
    free_names = layout.names_of(free)
    norms = np.linalg.norm(Jf, axis=0)
    no_effect = [free_names[j] for j in np.flatnonzero(norms <= 1e-10 * norms.max())]
    S = _scales(Jf, True)
    A = Jf * S
    # A = Q R: the singular values and right singular vectors of A are those of the small
    # triangular R (QR is backward stable, unlike forming A^T A), at a fraction of the cost
    R = np.linalg.qr(A, mode="r")
    _, s, Vt = np.linalg.svd(R)
    ratio = s / s[0]
    null = ratio < opt.unidentifiable_ratio
    weak = (~null) & (ratio < opt.weak_ratio)
    keep = ~null
    dof = max(m - int(keep.sum()), 1)  # the fit moves only the identifiable directions
    sigma2 = float(r @ r) / dof
    sigma_m = float(np.sqrt(rr / dof))
    if known_sigma_m is not None:
        sigma2 = sigma_m = float(known_sigma_m)
        sigma2 *= sigma2
    cov_scaled = (Vt[keep].T / s[keep] ** 2) @ Vt[keep]
    cov_scaled = 0.5 * (cov_scaled + cov_scaled.T)  # symmetric to the last bit
    cov = sigma2 * cov_scaled * np.outer(S, S)

    def direction(v):
        big = np.abs(v) >= 0.1 * np.abs(v).max()
        order = np.argsort(-np.abs(v))
        return {free_names[j]: round(float(v[j]), 4) for j in order if big[j]}

    unidentifiable = [direction(Vt[i]) for i in np.flatnonzero(null)]
    weak_dirs = [WeakDirection(float(ratio[i]), direction(Vt[i])) for i in np.flatnonzero(weak)]
    not_ident = sorted({k for d in unidentifiable for k in d}, key=free_names.index)
    bad = np.array([n in not_ident for n in free_names])
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    # identifiable in theory but not in practice: the data barely depends on it
    limits = layout.practical_std(free_names)
    poorly = [PoorlyDetermined(name, float(std[j]), float(limits[j]))
              for j, name in enumerate(free_names) if not bad[j] and std[j] > limits[j]]
    not_ident = sorted(set(not_ident) | {pd.parameter for pd in poorly}, key=free_names.index)
    bad = np.array([n in not_ident for n in free_names])
    cov[bad, :] = np.nan
    cov[:, bad] = np.nan
    covariance = Covariance(tuple(free_names), cov)
    sk = s[keep]
    ident = Identifiability(
        free=free_names,
        not_identifiable=not_ident,
        no_effect=no_effect,
        poorly_determined=poorly,
        unidentifiable_directions=unidentifiable,
        weak_directions=weak_dirs,
        correlated_pairs=covariance.correlated_pairs(opt.correlation_limit),
        singular_values=[float(v) for v in np.linalg.svd(R / S, compute_uv=False)],
        scaled_singular_values=[float(v) for v in s],
        condition_number_scaled=float(s[0] / s[-1]) if s[-1] > 0 else float("inf"),
        observability=Observability(
            O1=float(np.exp(np.mean(np.log(np.maximum(s, 1e-300)))) / np.sqrt(m)),
            O2=float(s[-1] / s[0]),
            O3=float(s[-1]),
            O4=float(s[-1] ** 2 / s[0])),
        sigma_mm=sigma_m * 1e3,
        samples=int(m),
        rank=int(keep.sum()),
        identifiable_min_scaled_ratio=float(sk[-1] / s[0]) if len(sk) else 0.0,
        weighted=weights is not None,
        variance_factor=sigma2 if weights is not None else None,
    )
    return ident, covariance, sigma_m
