"""Twin against real: do two runs of the same poses agree? The statistics of ``planecal
compare`` (docs/HISTORY.md).

Two runs visit the same poses (``pair``: the same number of samples, sample by sample the
same plate and the same encoder counts within a tolerance), e.g. a rehearsal on the twin
and the real cell's run of one planned pose list (``rehearse --poses`` / ``sample
--poses``). Sample i's difference is d_i = measured_run - measured_rehearsal. Where the
two worlds agree, only the noise differs: each run's sample has the variance of the one
noise model (``estimation.noise.sample_variance``: the robot's repeatability through the
pose's Jacobian, the sensor, the encoders' quantisation), so

    z_i = d_i / sqrt(v_run,i + v_rehearsal,i) ~ N(0, 1),  X = sum z_i^2 ~ chi2(m)

The verdict is the chi-square test of X: the runs differ when P(chi2(m) >= X) <= alpha
(default 0.01; a noise model above the truth only lowers the false-alarm rate: the
MC70's datasheet repeatability is 0.07 mm, its realistic twin's 0.057). Per sample, |z_i|
above the normal quantile at alpha / (2 m) (Bonferroni) is flagged. Beside it, with no
noise model: the paired t-test of the mean difference and the Wilcoxon signed-rank test
(distribution-free) of its median.

What explains a difference: the model's Jacobian by name (``estimation.drift``'s suspects,
default the joint offsets) at the rehearsal's poses, d_i ~ j_i . amount (amount = the
run's value minus the rehearsal's), weighted by 1 / (v_run + v_rehearsal): each suspect
alone, and what moved by forward selection until the chi-square test passes on what is
left (dof m - k); error sources without a parameter (gear error, backlash, compliance)
are what no suspect explains.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.drift import (DEFAULT_ALPHA, JOINT_OFFSETS, Explanation, Suspect,
                                       forward_selection, single_fits, suspect_columns)

DEFAULT_TOLERANCE_COUNTS = 2


@dataclass(frozen=True, eq=False)
class Paired:
    """Two runs' samples paired by pose: counts ``qe`` (the rehearsal's), ``plate``, the
    distances [m] of the run and of the rehearsal, and the largest count difference."""
    qe: np.ndarray
    plate: np.ndarray
    run_m: np.ndarray
    rehearsal_m: np.ndarray
    max_count_difference: int


def pair(run, rehearsal, tolerance: int = DEFAULT_TOLERANCE_COUNTS,
         names: tuple[str, str] = ("RUN", "REHEARSAL")) -> Paired:
    """The two runs' samples (``Samples``-like: qe, d_mm, plate) paired sample by sample;
    InputError naming the first sample that is not the same pose."""
    a, b = names
    if len(run.d_mm) != len(rehearsal.d_mm):
        raise InputError(f"{a}: {len(run.d_mm)} samples, {b} {len(rehearsal.d_mm)}: not two "
                         "runs of the same poses (rehearse and sample --poses POSES.json)")
    dq = np.abs(np.asarray(run.qe, np.int64) - np.asarray(rehearsal.qe, np.int64))
    bad = np.flatnonzero((dq.max(axis=1) > tolerance) |
                         (np.asarray(run.plate) != np.asarray(rehearsal.plate)))
    if len(bad):
        i = int(bad[0])
        j = int(np.argmax(dq[i]))
        what = (f"plate {run.plate[i] + 1} against {rehearsal.plate[i] + 1}"
                if run.plate[i] != rehearsal.plate[i] else
                f"J{j + 1}'s counts differ by {int(dq[i, j])} (tolerance {tolerance})")
        raise InputError(f"{a}: sample {i + 1} is not {b}'s sample {i + 1}: {what}; "
                         f"{len(bad)} of {len(dq)} samples differ (compare needs two runs "
                         "of the same poses)")
    return Paired(np.asarray(rehearsal.qe, np.int64), np.asarray(run.plate, int),
                  np.asarray(run.d_mm, float) * 1e-3, np.asarray(rehearsal.d_mm, float) * 1e-3,
                  int(dq.max(initial=0)))


@dataclass(frozen=True)
class Agreement:
    """``compare``'s figures (module docstring): per sample the difference [m], its std
    under H0 and z; the chi-square test; the paired t and Wilcoxon tests; the suspects
    and what explains the difference."""
    difference_m: np.ndarray
    sigma_m: np.ndarray
    z: np.ndarray
    z_limit: float
    flagged: list[int]
    chi2: float
    dof: int
    p: float
    alpha: float
    t_p: float
    wilcoxon_p: float
    suspects: list[Suspect]
    explanation: Explanation | None
    no_effect: list[str]
    fitted_m: np.ndarray  # the explanation's difference per sample (zeros without one)

    @property
    def agree(self) -> bool:
        return self.p > self.alpha


def compare_runs(robot, params, layout, pr: Paired, joint_sigma_rad: float,
                 distance_sigma_m: float = 1e-6, alpha: float = DEFAULT_ALPHA,
                 suspects=JOINT_OFFSETS) -> Agreement:
    """The comparison of paired runs (module docstring); the Jacobian at ``params``
    (``layout``)."""
    from scipy.stats import chi2, norm, ttest_1samp, wilcoxon

    from planecal.estimation.noise import sample_variance
    from planecal.model.measurement import predict_with_jacobian

    if not 0 < alpha < 1:
        raise InputError(f"--alpha must be in (0, 1), got {alpha}")
    m = len(pr.run_m)
    if m < 2:
        raise InputError(f"compare needs at least 2 samples, got {m}")
    _, J = predict_with_jacobian(robot, pr.qe, params, pr.plate, layout)
    v = sample_variance(robot, J[:, layout.slice("joint_offsets")], joint_sigma_rad,
                        distance_sigma_m, True)
    sigma = np.sqrt(2.0 * v)
    d = pr.run_m - pr.rehearsal_m
    z = d / sigma
    x2 = float(z @ z)
    z_limit = float(norm.isf(alpha / (2 * m)))
    w = 1.0 / sigma
    rw, Si = -d * w, np.eye(m)  # r = -J amount, in units of sigma

    def test_after(_rw, chi2_left, k):
        p = float(chi2.sf(chi2_left, max(m - k, 1)))
        return p, p <= alpha

    cols, no_effect = suspect_columns(J * w[:, None], layout, suspects)
    singles = single_fits(rw, Si, cols, float(norm.isf(alpha / (2 * max(len(cols), 1)))),
                          test_after)
    p = float(chi2.sf(x2, m))
    expl = (forward_selection(rw, Si, cols, test_after, float(chi2.isf(alpha, 1)))
            if p <= alpha else None)
    fitted = np.zeros(m)
    if expl is not None:
        fitted = J[:, layout.indices(expl.names)] @ np.array(expl.amounts)
    same = bool(np.all(d == 0))
    return Agreement(d, sigma, z, z_limit, [int(i) for i in np.flatnonzero(np.abs(z) > z_limit)],
                     x2, m, p, float(alpha),
                     1.0 if same else float(ttest_1samp(d, 0.0).pvalue),
                     1.0 if same else float(wilcoxon(d).pvalue),
                     singles, expl, no_effect, fitted)
