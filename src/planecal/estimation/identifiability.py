"""What the data can and cannot identify, and how well: the identifiability report and
covariance at a solution (``uncertainty``) or before any fit (``analyze``), the base set of
identifiable parameters (``select_base``), and the covariances a study compares with
(``covariances``: white, sandwich, Cramer-Rao). One place for this analysis, apart from the
solver (industrial_calibration keeps analysis/ apart from optimizations/).

Identifiability is judged on the column-scaled Jacobian (unit-norm columns, so units do not
matter): a scaled singular value below ``unidentifiable_ratio`` x the largest is a direction
the data cannot see; the parameters that make up that direction are named, and their
standard deviations are reported as missing (NaN / null), not as numbers; a parameter whose
Jacobian column vanishes is listed under ``no_effect`` as well. Directions below
``weak_ratio`` are reported as weakly identifiable. Observability indices (Sun & Hollerbach
1997) O1 = (s_1...s_p)^(1/p) / sqrt(m), O2 = s_min/s_max, O3 = s_min, O4 = s_min^2/s_max, on
the scaled Jacobian.

Covariance at a solution (on the samples used):
  sigma^2 = |r|^2 / (m - rank),  cov = sigma^2 (J^T J)^-1   (on the identifiable subspace)
and for a weighted fit (rows weighted by 1/sqrt(v_i), ``planecal.estimation.noise``)
  f = |W r|^2 / (m - rank) (the variance factor, ~1 when the noise model is right),
  cov = f (J^T W^2 J)^-1.

The base set (FIGAROH's "base parameters by QR"): the free parameters' columns scaled to
unit norm, then a rank-revealing QR with column pivoting (``scipy.linalg.qr(...,
pivoting=True)``) orders them: A P = Q R with |R_00| >= |R_11| >= ... Column k of the
pivot order adds |R_kk| of new information to the columns before it; where |R_kk| /
|R_00| falls below ``tol`` the rest are combinations of the ones before (to the data's
first order). The first ``rank`` pivots are the base set; every other candidate is left at
its initial value, with its reason:

* ``no_effect``: its column is zero (it changes no distance of these samples);
* ``combination``: its column is a combination of the base set's,
  J_e = sum_k coef_k J_k (least squares on the base columns; the coefficients unscaled to
  SI units: moving e by 1 changes every distance as moving each base parameter k by coef_k);
* ``scale``: a length that sets the arm's scale (``planecal.model.layout.scale_lengths``),
  kept unless a length reference fixes the scale.

Which member of a degenerate family stays is a choice, not a physical claim: the planes'
rotation about the base z axis, delta1 and the base frame's rotation, say, are one
direction. The choice made here, in tiers (``TIERS``), each pivoted on what the tiers before
leave unexplained: the cell's frames first (the planes and the sensor pose), then the joint
offsets, then the kinematic model (geometry, base frame, compliance), then level 3's gear
harmonics and backlash. So the planes carry delta1 and the base frame (which turn or move
every plane alike) and the sensor pose carries delta6 (its roll): a joint offset in the
base set is one a plane calibration can see, a level-2 parameter enters only for what level
1 cannot express, and a gear harmonic (J1-J3's once-per-revolution term trades with the
geometry) only for what the kinematic model cannot.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.linalg

from planecal.model.cell_params import CellParams
from planecal.model.layout import ParamLayout, level1_layout
from planecal.model.measurement import predict_with_jacobian
from planecal.model.robot import Robot
from planecal.estimation.solver import column_scales



@dataclass(frozen=True)
class Thresholds:
    """Where the report draws its lines (``FitOptions`` carries the same fields)."""
    unidentifiable_ratio: float = 1e-7
    weak_ratio: float = 1e-3
    correlation_limit: float = 0.95

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
    # its std at the noise model's level (``uncertainty``'s ``noise_var``; None: not known)
    noise_std: float | None = None


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
    poorly_determined: list[PoorlyDetermined]  # not identifiable in practice
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
    # std above its practical limit only through the residuals' model mismatch: at the
    # noise model's level within it (identifiable; their std is reported)
    mismatch_inflated: list[PoorlyDetermined] = field(default_factory=list)
    residual_over_noise: float | None = None  # the residuals' rms over the noise model's

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
        with np.errstate(invalid="ignore"):
            big = np.triu(np.abs(np.nan_to_num(c, nan=0.0)) > threshold, 1)
        return [CorrelatedPair(self.names[i], self.names[j], round(float(c[i, j]), 5))
                for i, j in zip(*np.nonzero(big))]

    def to_dict(self) -> dict:
        """{"names": [...], "matrix": [[...]]} with null where not identifiable."""
        return {"names": list(self.names),
                "matrix": [[float(v) if np.isfinite(v) else None for v in row]
                           for row in self.matrix]}


CELL_KINDS = ("sensor_origin", "sensor_angles", "plane")  # the setup's frames, not the robot's


def _practical(layout: ParamLayout, names: list[str], bad: np.ndarray, cov: np.ndarray,
               A: np.ndarray, G: np.ndarray, S: np.ndarray, v: np.ndarray | None):
    """(not identifiable in practice, inflated by mismatch): the identifiable parameters
    whose std exceeds their ``practical_std``. With the rows' noise-model variances ``v``
    a cell frame's parameter (``CELL_KINDS``: the sensor pose, the planes; they carry the
    fit, the robot's parameters are its result) is judged at that noise (the sandwich
    G A^T diag(v) A G of the column-scaled rows A, G = (A^T A)^+): within its limit there,
    it is identifiable and its reported std large only because the residuals exceed the
    noise (errors the model lacks: the realistic UR5's link geometry leaves an offsets fit
    10-15x the noise, its sensor angles 0.09-0.4 of their limit at the noise and above it
    at the residuals'), a warning. A robot parameter must meet its limit with the mismatch
    (what it is exported for)."""
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    noise = None if v is None else np.sqrt(np.maximum(np.diag(G @ (A.T * v) @ A @ G), 0)) * S
    limits = layout.practical_std(names)
    poorly, inflated = [], []
    for j, name in enumerate(names):
        if bad[j] or not std[j] > limits[j]:
            continue
        pd = PoorlyDetermined(name, float(std[j]), float(limits[j]),
                              None if noise is None else float(noise[j]))
        cell = layout.group(layout.param(name).group).kind in CELL_KINDS
        (inflated if cell and noise is not None and noise[j] <= limits[j] else poorly).append(pd)
    return poorly, inflated


def analyze(robot: Robot, qe: np.ndarray, params: CellParams, plane_index=None,
            free=None, sigma_m: float = 2e-6, options=None,
            layout: ParamLayout | None = None) -> tuple[Identifiability, Covariance]:
    """Identifiability and predicted covariance of a pose set *before* fitting: the
    Jacobian at ``params`` (e.g. the nominal values) and an assumed distance noise
    ``sigma_m`` (white: the weighted fit's options are not used here). ``free`` as for
    ``Problem.from_arrays``."""
    opt = options or Thresholds()
    layout = layout or level1_layout(params.n_planes)
    free = layout.free_mask(free)
    _, J = predict_with_jacobian(robot, qe, params, plane_index, layout)
    Jf = J[:, free]
    ident, cov, _ = uncertainty(Jf, np.zeros(len(Jf)), layout, free, opt, known_sigma_m=sigma_m)
    return ident, cov


def uncertainty(Jf: np.ndarray, r: np.ndarray, layout: ParamLayout, free: np.ndarray,
                opt=None, weights: np.ndarray | None = None,
                known_sigma_m: float | None = None, noise_var: np.ndarray | None = None):
    """Covariance and the identifiability report at a solution, for the free columns Jf of
    the Jacobian and the residuals r; ``weights`` (row weights 1/sqrt(v_i)): of the weighted
    fit (module docstring); ``known_sigma_m``: a known white noise std instead of the
    residuals' estimate (``analyze``); ``noise_var``: each row's variance under the noise
    model (``estimation.noise``; unweighted units), against which "not identifiable in
    practice" is judged (``_practical``). Returns (Identifiability, Covariance, sigma_m =
    sqrt(|r|^2 / (m - rank)) of the unweighted residuals, or the known sigma)."""
    opt, m = opt or Thresholds(), len(Jf)
    rr = float(r @ r)  # the unweighted residuals' (sigma_m)
    if weights is not None:
        Jf, r = Jf * weights[:, None], r * weights
    free_names = layout.names_of(free)
    norms = np.sqrt(np.einsum("ij,ij->j", Jf, Jf))
    no_effect = [free_names[j] for j in np.flatnonzero(norms <= 1e-10 * norms.max())]
    S = column_scales(Jf)
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
    v = None if noise_var is None else noise_var * (1.0 if weights is None else weights ** 2)
    poorly, inflated = _practical(layout, free_names, bad, cov, A, cov_scaled, S, v)
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
        mismatch_inflated=inflated,
        residual_over_noise=None if v is None else float(np.sqrt(sigma2 / np.mean(v))),
    )
    return ident, covariance, sigma_m


# ----- the base set ------------------------------------------------------------------------

DEFAULT_TOL = 1e-6  # |R_kk| / |R_00| below this: a combination of the columns before


@dataclass(frozen=True)
class Excluded:
    parameter: str
    reason: str  # "no_effect" | "combination" | "scale" | "held_out"
    combination: dict = field(default_factory=dict)  # base parameter -> coefficient (SI)


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


TIERS = (("plane", "sensor_origin", "sensor_angles"), ("joint_offsets",),
         ("joint_geometry", "base_frame", "compliance"))


def _pivoted(A: np.ndarray):
    """|diag R| and the pivot order of A's pivoted QR, and the orthonormal Q."""
    Q, R, piv = scipy.linalg.qr(A, mode="economic", pivoting=True)
    return np.abs(np.diag(R)), piv, Q


def select_base(J: np.ndarray, layout: ParamLayout, free: np.ndarray,
                tol: float = DEFAULT_TOL, weights: np.ndarray | None = None,
                tiers: tuple = TIERS) -> BaseSet:
    """The base set of identifiable parameters among ``free`` (mask over the layout) for
    the Jacobian J (N, len(layout)) of the samples at hand (module docstring). ``weights``:
    row weights (a weighted fit's), default none. ``tiers``: kinds chosen in turn (module
    docstring), each tier pivoted on what the base set of the tiers before leaves
    unexplained; the kinds no tier names come last."""
    free = np.asarray(free, bool)
    names = layout.names_of(free)
    kind_of = {p.name: g.kind for g in layout.groups for p in g.params}
    Jf = np.asarray(J, float)[:, free]
    if weights is not None:
        Jf = Jf * weights[:, None]
    norms = np.sqrt(np.einsum("ij,ij->j", Jf, Jf))
    top = norms.max() if norms.size else 0.0
    dead = norms <= 1e-12 * top if top > 0 else np.ones(len(names), bool)
    S = np.where(dead, 0.0, 1.0 / np.where(dead, 1.0, norms))
    A = Jf * S  # unit columns
    if A.shape[0] > A.shape[1]:
        # A = Q0 R0 with orthonormal Q0: every inner product of A's columns is R0's, so the
        # pivoting, projections and combinations below are the same on the small R0
        A = np.linalg.qr(A, mode="r")
    excluded = [Excluded(names[j], "no_effect") for j in np.flatnonzero(dead)]
    live = [j for j in range(len(names)) if not dead[j]]
    groups = [np.array([j for j in live if kind_of[names[j]] in kinds], int) for kinds in tiers]
    listed = {k for kinds in tiers for k in kinds}
    groups.append(np.array([j for j in live if kind_of[names[j]] not in listed], int))
    order, ratios, base_idx = [], [], []
    Qb = np.zeros((A.shape[0], 0))
    for cols in groups:
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


# ----- the covariances a study compares with ------------------------------------------------

def covariances(Jf: np.ndarray, v: np.ndarray) -> dict:
    """For the free-column Jacobian Jf (N, p) and per-sample noise variances v (N,):
    'white': mean(v) (J^T J)^-1 (the white-noise CR bound with the mean variance),
    'sandwich': the covariance of the unweighted LS estimate, 'crb': (J^T V^-1 J)^-1.
    Computed on column-scaled Jf; pseudo-inverse on the identifiable subspace."""
    S = column_scales(Jf)
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
