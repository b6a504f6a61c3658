"""Identification: Gauss-Newton with an SVD pseudo-inverse (seed 6.2.1, 7.2), optional
Levenberg-Marquardt damping and column scaling, k-sigma outlier elimination, a mask of
free parameters, and an honest account of what the data can and cannot identify.

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

from dataclasses import dataclass, field

import numpy as np

from planecal.cell import CellParams, parameter_names, predict, predict_with_jacobian
from planecal.robot import Robot


def default_free(n_planes: int) -> np.ndarray:
    """Everything but delta1 and delta6, which no plane calibration can separate from the
    plane's rotation about the base z axis and the sensor's roll (seed 6.2)."""
    free = np.ones(11 + 3 * n_planes, bool)
    free[[0, 5]] = False
    return free


def free_from_names(spec, n_planes: int) -> np.ndarray:
    """Free-parameter mask from names (a comma-separated string or a list; "all" frees
    everything); None gives ``default_free``."""
    from planecal.errors import InputError
    if not spec:
        return default_free(n_planes)
    names = parameter_names(n_planes)
    wanted = [w.strip() for w in (spec.split(",") if isinstance(spec, str) else spec)]
    mask = np.zeros(len(names), bool)
    for name in filter(None, wanted):
        if name == "all":
            mask[:] = True
        elif name in names:
            mask[names.index(name)] = True
        else:
            raise InputError(f"--free: unknown parameter {name!r}; known: {', '.join(names)}")
    return mask


@dataclass
class FitOptions:
    max_iter: int = 30
    improvement_limit: float = 1e-12
    outlier_sigma: float | None = None
    method: str = "gn"  # "gn": Gauss-Newton (SVD pseudo-inverse); "lm": Levenberg-Marquardt
    scale: bool = True  # column scaling of the Jacobian
    free: np.ndarray | None = None  # bool mask over CellParams.to_vector(); None: default_free
    rcond: float = 1e-7  # pseudo-inverse cut-off relative to the largest scaled singular value
    lm_lambda0: float = 1e-3
    unidentifiable_ratio: float = 1e-7
    weak_ratio: float = 1e-3
    correlation_limit: float = 0.95
    # a standard deviation above these says "not identifiable in practice" (std not reported)
    practical_std_rad: float = 0.01
    practical_std_m: float = 0.01
    practical_std_plane: float = 0.1  # 1/m, n~ components (|n~| ~ 1/distance to the plane)
    # weighted fit (module docstring): joint-angle std of the robot's repeatability [rad]
    # (``robot.repeatability_sigma``; None: unweighted) and the std of a sample's distance
    # from the sensor itself [m]
    joint_sigma_rad: float | None = None
    distance_sigma_m: float = 1e-6


@dataclass
class FitResult:
    params: CellParams
    initial: CellParams
    names: list[str]
    free: np.ndarray
    std: np.ndarray  # full-vector std; NaN for fixed or unidentifiable parameters
    cov: np.ndarray  # (p, p) over the free parameters (NaN rows for unidentifiable ones)
    residuals_m: np.ndarray  # final model - measured, all samples
    initial_residuals_m: np.ndarray
    used: np.ndarray  # bool mask: samples kept (not outliers)
    outliers: list[int]
    iterations: int
    history: list[dict]
    identifiability: dict
    sigma_m: float
    converged: bool = True
    notes: list[str] = field(default_factory=list)

    @property
    def correction(self) -> np.ndarray:
        return self.params.to_vector() - self.initial.to_vector()

    def rms_mm(self, initial: bool = False) -> float:
        r = self.initial_residuals_m if initial else self.residuals_m
        return float(np.sqrt(np.mean(r[self.used] ** 2)) * 1e3)


def noise_variance(J_delta: np.ndarray, joint_sigma: float, distance_sigma_m: float) -> np.ndarray:
    """Per-sample distance noise variance [m^2]: J_delta (N, 6) the Jacobian columns of the
    six joint offsets (= dd/dq), joint_sigma the joint-angle std of the robot's
    repeatability [rad], distance_sigma_m the std of a sample from the sensor [m]."""
    return joint_sigma ** 2 * np.sum(J_delta ** 2, axis=1) + distance_sigma_m ** 2


def _weights(J: np.ndarray, opt: "FitOptions") -> np.ndarray | None:
    """Row weights 1/sqrt(v_i) from the full Jacobian J (its first six columns are the
    offsets'), or None for an unweighted fit."""
    if opt.joint_sigma_rad is None:
        return None
    return 1.0 / np.sqrt(noise_variance(J[:, :6], opt.joint_sigma_rad, opt.distance_sigma_m))


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


def calibrate(robot: Robot, qe: np.ndarray, d_m: np.ndarray, initial: CellParams,
              plane_index: np.ndarray | None = None,
              options: FitOptions | None = None) -> FitResult:
    """Fit the cell parameters to samples (encoder counts qe (N,6), distances d_m (N,) [m])."""
    opt = options or FitOptions()
    qe = np.asarray(qe)
    d_m = np.asarray(d_m, float)
    N = len(d_m)
    pidx = np.zeros(N, int) if plane_index is None else np.asarray(plane_index, int)
    if pidx.size and pidx.max() >= initial.n_planes:
        raise ValueError(f"samples refer to plate {pidx.max() + 1}, parameters hold "
                         f"{initial.n_planes} plane(s)")
    names = parameter_names(initial.n_planes)
    free = default_free(initial.n_planes) if opt.free is None else np.asarray(opt.free, bool)
    p = int(free.sum())
    if N <= p:
        raise ValueError(f"{N} samples cannot determine {p} free parameters")
    x = initial.to_vector()
    used = np.ones(N, bool)
    history = []
    outliers: list[int] = []
    lam = opt.lm_lambda0
    iterations = 0
    converged = False

    if opt.joint_sigma_rad is not None and not (
            np.isfinite(opt.joint_sigma_rad) and opt.joint_sigma_rad >= 0
            and np.isfinite(opt.distance_sigma_m) and opt.distance_sigma_m > 0):
        raise ValueError("weighted fit: joint_sigma_rad must be finite and >= 0, "
                         "distance_sigma_m finite and > 0")

    def evaluate(xv, mask):
        """Residuals, free Jacobian columns and row weights (None: unweighted) at xv."""
        d, J = predict_with_jacobian(robot, qe[mask], CellParams.from_vector(xv), pidx[mask])
        return d - d_m[mask], J[:, free], _weights(J, opt)

    r, Jf, w = evaluate(x, used)
    initial_r = r.copy()
    history.append({"iteration": 0, "rms_m": float(np.sqrt(np.mean(r ** 2))),
                    "max_m": float(np.max(np.abs(r))), "samples": int(used.sum())})
    for it in range(1, opt.max_iter + 1):
        # weighted: rows scaled by w (held for this iteration, re-evaluated at the next)
        Jw, rw = (Jf, r) if w is None else (Jf * w[:, None], r * w)
        S = _scales(Jw, opt.scale)
        A = Jw * S
        if opt.method == "gn":
            dx = S * _solve_step(A, rw, opt.rcond)
        elif opt.method == "lm":
            cost = rw @ rw
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
                if rt @ rt <= cost:
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
        small = np.mean(np.abs(dx)) < opt.improvement_limit
        if small and opt.outlier_sigma is None:
            # converged: r and J at x - dx describe x to O(|dx|), below the limit
            history.append({"iteration": it, "rms_m": history[-1]["rms_m"],
                            "max_m": history[-1]["max_m"], "samples": int(used.sum()),
                            "mean_abs_correction": float(np.mean(np.abs(dx)))})
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
        history.append({"iteration": it, "rms_m": float(np.sqrt(np.mean(r ** 2))),
                        "max_m": float(np.max(np.abs(r))), "samples": int(used.sum()),
                        "mean_abs_correction": float(np.mean(np.abs(dx)))})
        if np.mean(np.abs(dx)) < opt.improvement_limit:
            converged = True
            break
    params = CellParams.from_vector(x)
    # residuals over all samples (outliers included), for reporting
    final_r = r if used.all() else predict(robot, qe, params, pidx) - d_m
    ident, std_free, cov, sigma = uncertainty(Jf, r, free, names, opt, weights=w)
    std = np.full(len(x), np.nan)
    std[free] = std_free
    notes = []
    if not converged:
        notes.append(f"stopped after {iterations} iterations (max_iter) before the mean "
                     f"correction fell below {opt.improvement_limit:g}")
    return FitResult(params, initial.copy(), names, free, std, cov, final_r, initial_r, used,
                     sorted(outliers), iterations, history, ident, sigma, converged, notes)


def analyze(robot: Robot, qe: np.ndarray, params: CellParams, plane_index=None,
            free: np.ndarray | None = None, sigma_m: float = 2e-6,
            options: FitOptions | None = None):
    """Identifiability and predicted standard deviations of a pose set *before* fitting:
    the Jacobian at ``params`` (e.g. the nominal values) and an assumed distance noise
    ``sigma_m`` (white: the weighted fit's options are not used here). Returns
    (identifiability dict, std over the full parameter vector)."""
    opt = options or FitOptions()
    free = default_free(params.n_planes) if free is None else np.asarray(free, bool)
    _, J = predict_with_jacobian(robot, qe, params, plane_index)
    Jf = J[:, free]
    m, p = Jf.shape
    ident, std_free, _, _ = uncertainty(Jf, np.zeros(m), free, parameter_names(params.n_planes),
                                        opt, known_sigma_m=sigma_m)
    std = np.full(len(free), np.nan)
    std[free] = std_free
    return ident, std


def _practical_limit(name: str, opt: FitOptions) -> float:
    if name.startswith("n"):
        return opt.practical_std_plane
    if name.startswith("o_"):
        return opt.practical_std_m
    return opt.practical_std_rad


def uncertainty(Jf: np.ndarray, r: np.ndarray, free: np.ndarray, names: list[str],
                opt: FitOptions | None = None, weights: np.ndarray | None = None,
                known_sigma_m: float | None = None):
    """Covariance, standard deviations and the identifiability report at a solution;
    ``weights`` (row weights 1/sqrt(v_i)): of the weighted fit (module docstring);
    ``known_sigma_m``: a known white noise std instead of the residuals' estimate
    (``analyze``). Returns (report, std, cov, sigma_m = sqrt(|r|^2 / (m - rank)) of the
    unweighted residuals, or the known sigma)."""
    opt = opt or FitOptions()
    m, p = Jf.shape
    rr = float(r @ r)  # the unweighted residuals' (sigma_m)
    if weights is not None:
        Jf, r = Jf * weights[:, None], r * weights
    free_names = [n for n, f in zip(names, free) if f]
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
    cov = sigma2 * cov_scaled * np.outer(S, S)

    def direction(v):
        big = np.abs(v) >= 0.1 * np.abs(v).max()
        order = np.argsort(-np.abs(v))
        return {free_names[j]: round(float(v[j]), 4) for j in order if big[j]}

    unidentifiable = [direction(Vt[i]) for i in np.flatnonzero(null)]
    weak_dirs = [{"scaled_singular_ratio": float(ratio[i]), "direction": direction(Vt[i])}
                 for i in np.flatnonzero(weak)]
    not_ident = sorted({k for d in unidentifiable for k in d}, key=free_names.index)
    bad = np.array([n in not_ident for n in free_names])
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    # identifiable in theory but not in practice: the data barely depends on it
    poorly = []
    for j, name in enumerate(free_names):
        limit = _practical_limit(name, opt)
        if not bad[j] and std[j] > limit:
            poorly.append({"parameter": name, "std": float(std[j]), "limit": limit})
    not_ident += [p_["parameter"] for p_ in poorly]
    not_ident = sorted(set(not_ident), key=free_names.index)
    bad = np.array([n in not_ident for n in free_names])
    std[bad] = np.nan
    cov[bad, :] = np.nan
    cov[:, bad] = np.nan
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    pairs = []
    for i in range(p):
        for j in range(i + 1, p):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > opt.correlation_limit:
                pairs.append({"a": free_names[i], "b": free_names[j], "rho": round(float(corr[i, j]), 5)})
    sk = s[keep]
    ident = {
        "free": free_names,
        "not_identifiable": not_ident,
        "no_effect": no_effect,
        "poorly_determined": poorly,
        "unidentifiable_directions": unidentifiable,
        "weak_directions": weak_dirs,
        "correlated_pairs": pairs,
        "singular_values": [float(v) for v in np.linalg.svd(R / S, compute_uv=False)],
        "scaled_singular_values": [float(v) for v in s],
        "condition_number_scaled": float(s[0] / s[-1]) if s[-1] > 0 else float("inf"),
        "observability": {
            "O1": float(np.exp(np.mean(np.log(np.maximum(s, 1e-300)))) / np.sqrt(m)),
            "O2": float(s[-1] / s[0]),
            "O3": float(s[-1]),
            "O4": float(s[-1] ** 2 / s[0]),
        },
        "sigma_mm": sigma_m * 1e3,
        "samples": int(m),
        "rank": int(keep.sum()),
        "identifiable_min_scaled_ratio": float(sk[-1] / s[0]) if len(sk) else 0.0,
    }
    if weights is not None:
        ident["weighted"] = True
        ident["variance_factor"] = sigma2
    return ident, std, cov, sigma_m
