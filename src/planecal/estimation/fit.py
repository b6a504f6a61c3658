"""Identification: a typed problem in, a typed result out. ``Problem`` (the robot, the
samples in SI, the initial parameters, the parameter layout, the free mask, ``FitOptions``)
built once from arrays or from a ``Samples`` file; ``solve(problem) -> Result`` (params,
residuals, history, status, ``Covariance`` over the free parameters by name,
``Identifiability``). Parameters are addressed by name through the problem's
``planecal.model.layout.ParamLayout``. ``solve`` is called by one caller,
``planecal.estimation.calibrate``: every command, study and the API calibrate through it.

The residual is r = d_model - d_measured [m] (docs/FORMATS.md: "model error", one sign
everywhere). The least squares are ``planecal.estimation.solver``'s (Gauss-Newton with an
SVD pseudo-inverse, seed 6.2.1 and 7.2, or Levenberg-Marquardt; outlier elimination; prior
rows); the measurement model is ``planecal.model.measurement``'s; the uncertainty and the
identifiability report are ``planecal.estimation.identifiability``'s.

A robot's noise is not white: its repeatability, projected on the beam, gives sample i a
variance v_i that depends on the pose (``planecal.estimation.noise``; docs/STUDIES.md
measures the effect: on three plates the reported std is ~20 % off).
``FitOptions(joint_sigma_rad=s)`` fits by weighted least squares instead, rows weighted by
1/sqrt(v_i) with v_i re-evaluated at each iterate, and reports the variance factor and the
Cramer-Rao bound of the noise model scaled by it.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from planecal.estimation.identifiability import Covariance, Identifiability, uncertainty
from planecal.estimation.noise import noise_variance, row_weights
from planecal.estimation.solver import (Iteration, Prior, SolverOptions, Status, least_squares,
                                       prior_weight)
from planecal.model.cell_params import CellParams
from planecal.model.layout import ParamLayout, level1_layout
from planecal.model.measurement import (Joints, has_backlash, joints_of_counts, predict,
                                        predict_joints_with_jacobian)
from planecal.model.robot import Robot
from planecal.io.samples import Samples


@dataclass(frozen=True)
class FitOptions(SolverOptions):
    """The solver's options (``SolverOptions``: iterations, method, scaling, rcond) and
    what the fit adds: identifiability thresholds, weighting and a prior."""
    unidentifiable_ratio: float = 1e-7
    weak_ratio: float = 1e-3
    correlation_limit: float = 0.95
    # weighted fit (module docstring): joint-angle std of the robot's repeatability [rad]
    # (``robot.repeatability_sigma``; None: unweighted) and the std of a sample's distance
    # from the sensor itself [m]
    joint_sigma_rad: float | None = None
    distance_sigma_m: float = 1e-6
    # the noise model "not identifiable in practice" is judged at (identifiability's
    # ``_practical``), with distance_sigma_m: the repeatability's joint-angle std [rad]
    # (the weighted fit's joint_sigma_rad where set; None: at the residuals' level)
    noise_joint_sigma_rad: float | None = None
    # a prior (maximum a posteriori; levels 2 and 3): ((name, std), ...) pulls those free
    # parameters towards their initial values: rows (x - x0) * sigma / std join the
    # distance rows (gn only), sigma the distances' std: ``prior_sigma_m``, or None, the
    # fit's own residual level (re-solved until it agrees with the residuals it leaves:
    # a prior weighed against a noise level the data do not have pulls harder or softer
    # than its std says)
    prior: tuple = ()
    prior_sigma_m: float | None = None


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
    joints: Joints | None = None  # the counts as joint angles with their sines (derived)
    # the recorded approach direction of each joint into each sample (N, 6) in -1, 0, +1
    # (a sample file's direction columns), or None: level 3's backlash flanks
    direction: np.ndarray | None = None
    # the scene's known lengths (``model.scene.LengthReference``): prior rows on the planes
    references: tuple = ()
    # (d (N,), J (N, len(layout))) at ``initial``, where the caller has it (derived: the
    # fit's first evaluation is then not repeated)
    at_initial: tuple | None = None

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
        # a parameter with a prior is determined by it where the samples do not
        p = int((free & ~self.layout.mask(n for n, _ in self.options.prior)).sum())
        if N <= p:
            raise ValueError(f"{N} samples cannot determine {p} free parameters"
                             + (" without a prior" if self.options.prior else ""))
        opt = self.options
        if opt.joint_sigma_rad is not None and not (
                np.isfinite(opt.joint_sigma_rad) and opt.joint_sigma_rad >= 0
                and np.isfinite(opt.distance_sigma_m) and opt.distance_sigma_m > 0):
            raise ValueError("weighted fit: joint_sigma_rad must be finite and >= 0, "
                             "distance_sigma_m finite and > 0")
        if self.direction is not None:
            dirs = np.asarray(self.direction)
            if dirs.shape != (N, 6) or not np.isin(dirs, (-1, 0, 1)).all():
                raise ValueError(f"samples: approach directions of {dirs.shape} (N, 6) in "
                                 "-1, 0, +1 expected")
            object.__setattr__(self, "direction", dirs.astype(np.int8))
        if self.joints is None or len(self.joints) != N:
            object.__setattr__(self, "joints", joints_of_counts(
                self.robot, qe, self.direction,
                has_backlash(self.layout) or bool(self.initial.backlash.any())))

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
        return cls(robot, qe, d_m, plate, initial, layout, layout.free_mask(free),
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
        return replace(self, qe=self.qe[idx], d_m=self.d_m[idx], plate=self.plate[idx],
                       joints=self.joints.rows(idx),
                       direction=None if self.direction is None else self.direction[idx],
                       at_initial=None)


# ----- the result -----------------------------------------------------------------------------

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
    status: Status = Status.CONVERGED
    # the solver's last Jacobian over the free parameters (the used samples' rows) and its
    # row weights (None: unweighted): the fit to first order at its solution (``linearized``)
    jacobian: np.ndarray | None = None
    weights: np.ndarray | None = None

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


# ----- the fit -----------------------------------------------------------------------------

class _Residuals:
    """The solver's residual function over the free parameters: (r, J of the free columns,
    row weights) at the samples ``rows``; the counts turned into joint angles once. It
    keeps the joint offsets' columns of its last Jacobian (``offsets_J``): the noise
    model's rows (``_noise_var``) at the solution, without another evaluation."""

    def __init__(self, pb: Problem):
        opt, layout, free = pb.options, pb.layout, pb.free
        self.pb, self.x_all = pb, pb.initial.to_vector(layout)
        self.weighted = opt.joint_sigma_rad is not None
        self.offsets = layout.mask(layout.group("joint_offsets").names)
        noise = self.weighted or opt.noise_joint_sigma_rad is not None
        self.need = free | self.offsets if noise else free
        self.cols_f = np.flatnonzero(free[self.need])
        self.cols_o = np.flatnonzero(self.offsets[self.need]) if noise else None
        self.offsets_J: np.ndarray | None = None
        # the first call: at the initial values, every row (the caller's evaluation)
        self.first = pb.at_initial if pb.at_initial is not None and not self.weighted else None

    def __call__(self, xf, rows):
        pb, free = self.pb, self.pb.free
        if self.first is not None:
            d, J = self.first
            self.first = None
            if np.array_equal(xf, self.x_all[free]) and np.asarray(rows).all():
                if self.cols_o is not None:
                    self.offsets_J = J[:, self.offsets]
                return d - pb.d_m, J[:, free], None
        x = self.x_all.copy()
        x[free] = xf
        d, J = predict_joints_with_jacobian(pb.robot, pb.joints.rows(rows),
                                            pb.initial.with_vector(x, pb.layout),
                                            pb.plate[rows], pb.layout, self.need)
        if self.cols_o is not None:
            self.offsets_J = J[:, self.cols_o]
        if not self.weighted:
            return d - pb.d_m[rows], J[:, self.cols_f], None
        w = row_weights(self.offsets_J, pb.options.joint_sigma_rad, pb.options.distance_sigma_m)
        return d - pb.d_m[rows], J[:, self.cols_f], w


@dataclass(frozen=True, eq=False)
class FitPrior:
    """The solver's prior rows (``solver.PriorRows``) of a problem: ``FitOptions.prior``
    over the free parameters, and each known length (``model.planes.parallel_rows``: two
    plates' tilt and gap), every row weighed as a distance of std ``prior_sigma_m``."""
    param: Prior | None
    x_all: np.ndarray  # the initial values over the layout
    free: np.ndarray  # the free mask
    references: tuple  # (plane a's and b's layout positions (3,) each, separation, weights (4,))

    @classmethod
    def of(cls, layout: ParamLayout, x_all: np.ndarray, free: np.ndarray, references,
           sigma_m: float, param: Prior | None = None) -> "FitPrior":
        """The rows of ``param`` (or none) and of the scene's known lengths
        (``model.scene.LengthReference``, ``reference_rows``) weighed as distances of std
        ``sigma_m``, at the layout's values ``x_all`` with the ``free`` mask."""
        return cls(param, x_all, free,
                   tuple(reference_rows(layout, r, sigma_m) for r in references))

    def rows(self, x: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
        from planecal.model.planes import parallel_rows
        P, r = (np.zeros((0, width)), np.zeros(0)) if self.param is None \
            else self.param.rows(x, width)
        if not self.references:
            return P, r
        xa = self.x_all.copy()
        xa[self.free] = x
        col = np.where(self.free, np.cumsum(self.free) - 1, -1)
        Ps, rs = [P], [r]
        for ia, ib, sep, w in self.references:
            g, Ga, Gb = parallel_rows(xa[ia], xa[ib], sep)
            R = np.zeros((4, width))
            for idx, G in ((ia, Ga), (ib, Gb)):
                for k in range(3):
                    if col[idx[k]] >= 0:
                        R[:, col[idx[k]]] += G[:, k]
            Ps.append(R * w[:, None])
            rs.append(g * w)
        return np.vstack(Ps), np.concatenate(rs)


def _prior(pb: Problem) -> FitPrior | None:
    """``FitOptions.prior`` and the problem's known lengths as the solver's prior rows."""
    return fit_prior(pb.layout, pb.free, pb.initial, pb.options.prior, pb.references,
                     pb.options.prior_sigma_m)


def fit_prior(layout: ParamLayout, free: np.ndarray, initial: CellParams, prior: tuple,
              references: tuple, sigma_m: float) -> FitPrior | None:
    """The prior rows of a fit of the ``free`` parameters about ``initial``: ``prior``
    ((name, std), ...) and the known lengths (``references``), every row weighed as a
    distance of std ``sigma_m``; None without either. What the fit adds to its data's
    rows, and what a design predicts with (``studies.design``)."""
    names = layout.names_of(free)
    given = [(names.index(n), sd) for n, sd in prior if n in names]
    x_all = initial.to_vector(layout)
    param = None
    if given:
        idx = np.array([i for i, _ in given], int)
        param = Prior(idx, np.array([sigma_m / sd for _, sd in given]), x_all[free][idx])
    if param is None and not references:
        return None
    return FitPrior.of(layout, x_all, free, references, sigma_m, param)


def reference_rows(layout: ParamLayout, ref, sigma_m: float) -> tuple:
    """(plane a's and b's positions in the layout, the separation, the row weights) of a
    known length (``model.scene.LengthReference``), its rows weighed as distances of std
    ``sigma_m``: the tilt rows by the parallelism std, the gap row by the length's."""
    cols = layout.columns("plane")
    w = sigma_m / np.array([ref.parallel_std_rad] * 3 + [ref.std_m], float)
    return cols[ref.plates[0]], cols[ref.plates[1]], float(ref.separation_m), w


SIGMA_START_M = 3e-5  # the first guess of the distances' std, where the fit finds its own
SIGMA_PASSES = 6  # re-solves until the prior's noise level agrees with the residuals' (5 %)
TEMPER = 2.0  # the prior rows are weighed against twice the residuals' std (a tempered
# posterior: the residuals hold the robot's mismatch with the model, which is not white noise;
# on three_plates' realistic truths 0-4, 2 of the level-3 fits' tool error 1x, 2x and 3x the
# residuals gave median 0.22, 0.13, 0.14 mm over two seeds)
def _noise_var(pb: Problem, offsets_J: np.ndarray | None) -> np.ndarray | None:
    """Each used sample's variance under the noise model of ``FitOptions`` (the
    repeatability on the beam and the sensor's own, ``noise.noise_variance``) from the
    joint offsets' columns of the solver's last Jacobian (at the solution, or within the
    last step below the improvement limit), or None when the options hold no noise model."""
    opt = pb.options
    s = opt.joint_sigma_rad if opt.joint_sigma_rad is not None else opt.noise_joint_sigma_rad
    if s is None:
        return None
    return noise_variance(offsets_J, s, opt.distance_sigma_m)


def solve(problem: Problem) -> Result:
    """Fit the cell parameters to the problem's samples (module docstring). With prior rows
    and ``FitOptions.prior_sigma_m`` None, the rows are weighed by the fit's own residual
    level: solved with a first guess, then again from the solution with the residuals' std
    until the two agree within 5 %."""
    pb = problem
    if pb.options.prior_sigma_m is not None or not (pb.options.prior or pb.references):
        return _solve(pb)
    sigma, x0, passes = SIGMA_START_M, None, []
    for _ in range(SIGMA_PASSES):
        passes.append(_solve(replace(pb, options=replace(pb.options, prior_sigma_m=sigma)),
                             x0))
        r = passes[-1].residuals_m[passes[-1].used]
        dof = max(len(r) - int(pb.free.sum()), 1)
        new = max(TEMPER * float(np.sqrt(r @ r / dof)), 1e-9)
        if abs(new - sigma) <= 0.05 * sigma:
            break
        sigma, x0 = new, passes[-1].params.to_vector(pb.layout)[pb.free]
    first, last = passes[0], passes[-1]  # the whole fit: from the initial values to the last
    return replace(last, initial_cost=first.initial_cost,
                   initial_residuals_m=first.initial_residuals_m,
                   iterations=sum(p.iterations for p in passes),
                   history=[it for p in passes for it in p.history],
                   notes=last.notes + [f"prior rows weighed by the residuals' std {sigma:.3g} m "
                                       f"({len(passes)} passes)"])


def _solve(pb: Problem, x0: np.ndarray | None = None) -> Result:
    """One fit from x0 (default: the initial values' free part) with the options' prior
    weighing."""
    opt, layout, free = pb.options, pb.layout, pb.free
    prior = _prior(pb)
    start = pb.initial.to_vector(layout)[free] if x0 is None else x0
    fun = _Residuals(pb)
    sol = least_squares(fun, start, len(pb), opt, prior)
    x = pb.initial.to_vector(layout)
    x[free] = sol.x
    params = pb.initial.with_vector(x, layout)
    r, J, w = sol.r, sol.J, sol.w
    # residuals over all samples (outliers included), for reporting
    final_r = r if sol.used.all() else predict(pb.robot, pb.qe, params, pb.plate,
                                               pb.direction) - pb.d_m
    v = _noise_var(pb, fun.offsets_J)
    if prior is not None:  # the posterior covariance: the prior rows join the data's
        P, rp = prior.rows(sol.x, J.shape[1])
        wp = None if w is None else np.concatenate([w, np.full(len(P), prior_weight(w))])
        vp = None if v is None else np.concatenate([v, np.full(len(P), opt.prior_sigma_m ** 2)])
        ident, cov, sigma = uncertainty(np.vstack([J, P]), np.concatenate([r, rp]), layout,
                                        free, opt, weights=wp, noise_var=vp)
    else:
        ident, cov, sigma = uncertainty(J, r, layout, free, opt, weights=w, noise_var=v)
    return Result(pb, params, sol.converged, sol.iterations, sol.initial_cost,
                  sol.final_cost, sol.history, final_r, sol.initial_r, sol.used,
                  sol.outliers, sigma, cov, ident, sol.notes, sol.status, J, w)


@dataclass(frozen=True, eq=False)
class Linearized:
    """A fit's least squares at its solution to first order: the used samples' residuals
    ``r`` [m], their Jacobian ``X`` over the free parameters, the row weights ``w`` (None:
    unweighted) and the prior rows ``P``, ``rp`` weighed as the solver weighs them (so the
    fit minimised |w (r + X dx)|^2 + |rp + P dx|^2); ``prior_cols``: the free parameter a
    parameter-prior row holds (-1: a known length's row). What ``estimation.selection``
    refits without a fold or a family, in closed form."""
    X: np.ndarray
    r: np.ndarray
    w: np.ndarray | None
    P: np.ndarray
    rp: np.ndarray
    prior_cols: np.ndarray
    names: tuple[str, ...]
    x: np.ndarray  # the free parameters' values at the solution
    x0: np.ndarray  # and their initial values


def linearized(res: Result) -> Linearized:
    """``Linearized`` of a fit (its last Jacobian: within the last step below the
    improvement limit of the solution)."""
    pb = res.problem
    layout, free = res.layout, res.free
    x = res.params.to_vector(layout)[free]
    X = res.jacobian
    if X is None or len(X) != int(res.used.sum()):  # a Result built without the solver's
        X = predict_joints_with_jacobian(pb.robot, pb.joints.rows(res.used), res.params,
                                         pb.plate[res.used], layout, free)[1]
    prior = _prior(pb)
    p = int(free.sum())
    if prior is None:
        P, rp, cols = np.zeros((0, p)), np.zeros(0), np.zeros(0, int)
    else:
        P, rp = prior.rows(x, p)
        n_param = 0 if prior.param is None else len(prior.param.index)
        cols = np.full(len(rp), -1)
        if n_param:
            cols[:n_param] = prior.param.index
        k = prior_weight(res.weights)
        P, rp = k * P, k * rp
    return Linearized(X, res.residuals_m[res.used], res.weights, P, rp, cols,
                      tuple(layout.names_of(free)), x, res.initial.to_vector(layout)[free])
