"""A design of sample poses and what it predicts: the D-optimal choice among candidates
(``d_optimal``), the prediction of any set of poses (``Predictor``: the free parameters'
sandwich std under the noise model, the position error at the tool point, an earlier
calibration's ``Mismatch`` beside it) and the fewest poses that meet a target
(``choose_count``). ``studies.planning`` draws the candidates and makes the plan.

Algorithm: greedy forward selection (each step adds the candidate with the largest
prediction variance a^T M^-1 a, Sherman-Morrison updates, M0 = 1e-6 I), then Fedorov
exchange passes (swap a chosen and a free candidate when it raises det M:
(1 + d_j)(1 - d_i) + d_ij^2 > 1 + tol) until no swap helps. Each candidate is used at most
once (a repeated pose only averages noise, the real run samples each pose once).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.identifiability import covariances
from planecal.estimation.noise import noise_variance
from planecal.model.measurement import predict_with_jacobian


TARGET_MARGIN = 1.25  # a target is met when the predicted figure times this is within it
TOOL_WHERE = ("the laser's beam point at the scene's standoff, robot frame, 1 sigma, rms over "
              "the candidate poses")


@dataclass(frozen=True)
class Mismatch:
    """What an earlier calibration of the cell said of its own accuracy (its ``accuracy``
    block, ``estimation.accuracy``): the predicted tool-point error with the model's
    mismatch in it (``tool_point_mm``) and from the noise model alone (``noise_only_mm``).
    Their quadratic difference is the mismatch's share (``mismatch_mm``), which the plan
    holds as it is: a model's mismatch with the robot is systematic, and more or better
    poses do not average it down (an offsets-only fit of the realistic MC70 leaves 0.3-0.9
    mm at the tool point at any sample count); only the noise's share falls with the
    design."""
    tool_point_mm: float
    noise_only_mm: float
    source: str

    @property
    def mismatch_mm(self) -> float:
        return float(np.sqrt(max(self.tool_point_mm ** 2 - self.noise_only_mm ** 2, 0.0)))

    @classmethod
    def of_result(cls, doc: dict, path: str) -> "Mismatch":
        """From a calibration result's ``accuracy`` block (``calibrate --out``)."""
        acc = doc.get("accuracy") if isinstance(doc, dict) else None
        if not isinstance(acc, dict):
            raise InputError(f"{path}: accuracy: missing (a calibration result of planecal "
                             "calibrate --out holds it)")
        vals = []
        for k in ("tool_point_mm", "noise_only_mm"):
            v = acc.get(k)
            if (isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v)
                    or v < 0):
                raise InputError(f"{path}: accuracy.{k}: a number >= 0 expected, got {v!r}")
            vals.append(float(v))
        return cls(*vals, str(path))


def d_optimal(A: np.ndarray, n: int, max_passes: int = 20, tol: float = 1e-9):
    """Indices of n rows of A (M, p) maximising det(A_S^T A_S): greedy + Fedorov exchange.
    Returns (indices, log det, passes, swaps)."""
    M, p = A.shape
    if n > M:
        raise InputError(f"cannot choose {n} poses from {M} candidates")
    Minv = np.eye(p) * 1e6
    chosen = []
    free = np.ones(M, bool)
    for _ in range(n):
        d = np.einsum("ij,jk,ik->i", A, Minv, A)
        d[~free] = -np.inf
        j = int(np.argmax(d))
        a = A[j]
        Ma = Minv @ a
        Minv -= np.outer(Ma, Ma) / (1.0 + a @ Ma)
        chosen.append(j)
        free[j] = False
    chosen = np.array(chosen)
    swaps = 0
    passes = 0
    for passes in range(1, max_passes + 1):
        improved = False
        for pos in range(n):
            G = A[chosen].T @ A[chosen]
            Minv = np.linalg.inv(G)
            i = chosen[pos]
            ai = A[i]
            MA = A @ Minv  # (M, p)
            d_all = np.einsum("ij,ij->i", MA, A)
            d_ij = MA @ ai
            gain = (1 + d_all) * (1 - d_all[i]) + d_ij ** 2
            gain[~free] = -np.inf
            j = int(np.argmax(gain))
            if gain[j] > 1 + tol:
                chosen[pos] = j
                free[i], free[j] = True, False
                swaps += 1
                improved = True
        if not improved:
            break
    sign, logdet = np.linalg.slogdet(A[chosen].T @ A[chosen])
    return chosen, float(logdet), passes, swaps


def scaled_rows(scene, qe, plate, layout, free, params=None):
    """The Jacobian (over ``layout``) at ``params`` (default the scene's nominal ones), and
    its free columns scaled to unit RMS."""
    from planecal.model.scene import nominal_params
    params = nominal_params(scene) if params is None else params
    _, J = predict_with_jacobian(scene.robot, qe, params, plate, layout)
    Jf = J[:, free]
    S = 1.0 / np.sqrt(np.mean(Jf ** 2, axis=0))
    return J, Jf * S


def design_covariances(J: np.ndarray, layout, free, joint_sigma: float,
                       laser_sigma_m: float) -> dict:
    """The free parameters' covariances (``identifiability.covariances``: white, sandwich,
    CRB) for the Jacobian J (over ``layout``) of some poses under the twin's noise model."""
    v = noise_variance(J[:, layout.slice("joint_offsets")], joint_sigma, laser_sigma_m)
    return covariances(J[:, free], v)


def predicted_std(J: np.ndarray, layout, free, joint_sigma: float, laser_sigma_m: float):
    """Sandwich and white-noise std of the free parameters for the Jacobian J (over
    ``layout``) and the twin's noise model."""
    cov = design_covariances(J, layout, free, joint_sigma, laser_sigma_m)
    return np.sqrt(np.diag(cov["sandwich"])), np.sqrt(np.diag(cov["white"]))


def tool_rows(scene, q: np.ndarray, params, layout, free) -> np.ndarray:
    """The tool point's sensitivity to each free parameter at the joint angles q: (k, 3,
    free) (``estimation.accuracy.tool_jacobian``: the beam point at the scene's standoff in
    the robot's frame; no approach direction known, backlash on gravity's side)."""
    from planecal.estimation.tool import tool_jacobian
    from planecal.model.measurement import backlash_sides
    side = backlash_sides(scene.robot, q, None)
    return tool_jacobian(scene.robot, q, side, layout, params, layout.names_of(free),
                         scene.standoff_m)


def predicted_tool_mm(T: np.ndarray, cov: np.ndarray) -> float:
    """RMS over the poses of the tool point's position error std (1 sigma, 3D) [mm] that
    the free parameters' covariance propagates to: sqrt(mean_i trace(T_i C T_i^T))."""
    var = np.einsum("kij,jl,kil->k", T, cov, T)
    return float(np.sqrt(max(np.mean(var), 0.0)) * 1e3)


class Predictor:
    """The predicted offsets' std (sandwich, the twin's noise model) and tool-point
    position error (the noise model's, and in quadrature beside it ``mismatch_mm``: an
    earlier calibration's mismatch share, ``Mismatch``) of any subset of the candidates
    (rows of J)."""

    def __init__(self, scene, J, layout, free, joint_sigma_rad, laser_sigma_m, T,
                 mismatch_mm: float = 0.0):
        self.J, self.layout, self.free = J, layout, free
        self.s, self.sig_l, self.T = joint_sigma_rad, laser_sigma_m, T
        self.mismatch_mm = mismatch_mm
        fn = layout.names_of(free)
        offsets = layout.group("joint_offsets").names
        self.offsets = [i for i, nm in enumerate(fn) if nm in offsets]

    def __call__(self, rows) -> tuple[np.ndarray, float]:
        """(sandwich std of the free parameters, predicted tool-point error [mm])."""
        return self.of_jacobian(self.J[rows])

    def of_jacobian(self, J: np.ndarray) -> tuple[np.ndarray, float]:
        """The same for the Jacobian rows J of any poses (over the same layout), e.g. the
        random run's."""
        return self.of_covariances(design_covariances(J, self.layout, self.free, self.s,
                                                      self.sig_l))

    def of_covariances(self, cov: dict) -> tuple[np.ndarray, float]:
        """The same from the poses' ``design_covariances``."""
        sand = cov["sandwich"]
        return np.sqrt(np.diag(sand)), float(np.hypot(predicted_tool_mm(self.T, sand),
                                                      self.mismatch_mm))

    def figure(self, rows, target: str) -> float:
        """The figure a target is about: the largest free offset std [urad] (``std``) or
        the tool-point error [mm] (``ap``)."""
        std, ap = self(rows)
        return float(np.max(std[self.offsets]) * 1e6) if target == "std" else ap


def choose_count(A: np.ndarray, predictor: Predictor, target: str, value: float,
                 n_min: int, n_max: int, progress=None):
    """The smallest n in [n_min, n_max] whose D-optimal design has ``predictor.figure(target)``
    times ``TARGET_MARGIN`` <= value: (n, ``d_optimal``'s result); InputError when even
    n_max misses it."""
    cache: dict = {}

    def fig(n):
        if n not in cache:
            res = d_optimal(A, n)
            cache[n] = (predictor.figure(res[0], target), res)
            if progress:
                progress.update(step=0, note=f"n={n}: predicted {cache[n][0]:.4g}")
        return cache[n][0]

    def met(n):
        return fig(n) * TARGET_MARGIN <= value

    unit = "urad" if target == "std" else "mm"
    if not met(n_max):
        raise InputError(f"--target-{target}-{unit} {value:g}: not reached with {n_max} "
                         f"samples (predicted {fig(n_max):.4g} {unit}, with the margin "
                         f"x{TARGET_MARGIN:g} {fig(n_max) * TARGET_MARGIN:.4g}); allow more "
                         f"samples (--samples is the most a target may choose) or candidates")
    if progress:  # reachable: the progress held until now is shown
        progress.release()
    lo, hi = n_min, n_max  # met(hi)
    if met(lo):
        return lo, cache[lo][1]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if met(mid):
            hi = mid
        else:
            lo = mid
    return hi, cache[hi][1]


# ----- the whole model's design: the tool point's error per robot second (issue 31) --------

def _scaled(A: np.ndarray, G: np.ndarray, H0: np.ndarray):
    """A, G, H0 in columns scaled to unit RMS (the arithmetic's conditioning; the criterion
    tr(G H^-1) is invariant) and the scales."""
    S = 1.0 / np.sqrt(np.mean(A ** 2, axis=0) + np.diag(H0) / len(A))
    return A * S, G * np.outer(S, S), H0 * np.outer(S, S), S


def tool_criterion(G: np.ndarray, H: np.ndarray) -> float:
    """tr(G H^-1): the mean square of the tool point's error over the poses G averages
    (``G = mean_i T_i^T T_i``) under the information H."""
    return float(np.trace(G @ np.linalg.inv(H)))


def budget_greedy(A: np.ndarray, G: np.ndarray, H0: np.ndarray, pose_of: np.ndarray,
                  new_s: float, read_s: float, budget_s: float, max_reads: int,
                  refresh: int = 40) -> np.ndarray:
    """Readings chosen one at a time for the largest fall of tr(G H^-1) per robot second:
    ``A`` (U, p) the readings a candidate offers (rows scaled by 1 / the noise, one per
    pose and approach side: ``pose_of`` (U,) its pose), ``H0`` the prior's information. A
    reading at a pose not yet chosen costs ``new_s`` (the travel there and the reading), one
    more at a chosen pose ``read_s``; at most ``max_reads`` at a pose, ``budget_s`` in all.
    Returns the readings (indices into A, a pose's repeated) in the order chosen. Rank-one
    updates of H^-1 (Sherman-Morrison), refreshed every ``refresh`` readings."""
    A, G, H, _ = _scaled(A, G, H0)
    n_pose = int(pose_of.max()) + 1
    reads = np.zeros(n_pose, int)
    spent, out = 0.0, []

    def fresh():
        Hi = np.linalg.inv(H)
        HA = A @ (0.5 * (Hi + Hi.T))
        return HA, HA @ G

    HA, HAG = fresh()
    while True:
        d = np.einsum("ij,ij->i", HA, A)
        gain = np.einsum("ij,ij->i", HAG, HA) / (1.0 + d)
        cost = np.where(reads[pose_of] > 0, read_s, new_s)
        ok = (spent + cost <= budget_s) & (reads[pose_of] < max_reads)
        if not ok.any():
            return np.array(out, int)
        u = int(np.argmax(np.where(ok, gain / cost, -np.inf)))
        H += np.outer(A[u], A[u])
        spent += cost[u]
        reads[pose_of[u]] += 1
        out.append(u)
        if len(out) % refresh == 0:
            HA, HAG = fresh()
        else:  # H^-1 - h h^T / (1 + d_u), h = H^-1 a_u
            h = HA[u].copy()
            Ah = (A @ h) / (1.0 + d[u])
            HA -= np.outer(Ah, h)
            HAG -= np.outer(Ah, G @ h)


def _fall(U1: np.ndarray, U2: np.ndarray, Hmi: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Per candidate (rows of U1, U2: its two readings' rows, each times the square root
    of how often it is read): how much adding them lowers tr(G Hm^-1), Hm^-1 = ``Hmi``:
    tr(K^-1 U^T Hm^-1 G Hm^-1 U), K = I + U^T Hm^-1 U (2 x 2, Woodbury)."""
    B1, B2 = U1 @ Hmi, U2 @ Hmi
    K11 = 1 + np.einsum("ij,ij->i", B1, U1)
    K22 = 1 + np.einsum("ij,ij->i", B2, U2)
    K12 = np.einsum("ij,ij->i", B1, U2)
    BG1 = B1 @ G
    Q11 = np.einsum("ij,ij->i", BG1, B1)
    Q22 = np.einsum("ij,ij->i", B2 @ G, B2)
    Q12 = np.einsum("ij,ij->i", BG1, B2)
    return (K22 * Q11 - 2 * K12 * Q12 + K11 * Q22) / (K11 * K22 - K12 ** 2)


def exchange_poses(A: np.ndarray, G: np.ndarray, H0: np.ndarray, pose_of: np.ndarray,
                   side_of: np.ndarray, units: np.ndarray, max_passes: int = 5,
                   tol: float = 1e-4) -> np.ndarray:
    """Fedorov's exchange at the level of poses: a chosen pose with all its readings is
    swapped for a pose not chosen, read as often (half from each side: ``side_of`` of each
    row of A, the rows of a pose one per side), whenever that lowers tr(G H^-1) by more
    than ``tol`` of it. A greedy choice is myopic where one reading tells little alone (a
    plate's first pose mostly fixes that plate's plane): on three_plates it left two of
    the four plates unvisited and twice the exchanged design's predicted error. Returns
    the readings (indices into A)."""
    A, G, H0, _ = _scaled(A, G, H0)
    n_pose = int(pose_of.max()) + 1
    row = {(int(p), int(s)): u for u, (p, s) in enumerate(zip(pose_of, side_of))}
    plus = np.array([row.get((p, 1), -1) for p in range(n_pose)])
    minus = np.array([row.get((p, -1), -1) for p in range(n_pose)])
    units = [int(u) for u in units]
    reads = np.bincount(pose_of[units], minlength=n_pose)
    H = H0 + A[units].T @ A[units]
    f = tool_criterion(G, H)
    both = (plus >= 0) & (minus >= 0)
    for _ in range(max_passes):
        improved = False
        for i in np.flatnonzero(reads):
            k = int(reads[i])
            Ri = A[[u for u in units if pose_of[u] == i]]
            Hmi = np.linalg.inv(H - Ri.T @ Ri)
            splits = {((k + 1) // 2, k // 2), (k // 2, (k + 1) // 2)}  # an odd one: either side
            best = None
            for kp, km in splits:
                cand = float(np.trace(G @ Hmi)) - _fall(A[plus] * np.sqrt(kp),
                                                        A[minus] * np.sqrt(km), Hmi, G)
                cand[((reads > 0) & (np.arange(n_pose) != i)) | ~both] = np.inf  # i: its sides
                j = int(np.argmin(cand))
                if best is None or cand[j] < best[0]:
                    best = (cand[j], j, kp, km)
            value, j, kp, km = best
            if value < f * (1 - tol):
                units = [u for u in units if pose_of[u] != i] + [int(plus[j])] * kp \
                    + [int(minus[j])] * km
                reads[i] = 0
                reads[j] = k
                H = H0 + A[units].T @ A[units]
                f = tool_criterion(G, H)
                improved = True
        if not improved:
            break
    return np.array(units, int)
