"""Compensation validated on the twin (issue 13: "the compensated targets, played on the
realistic twin, land within the same AP on a validation set of targets that the
calibration never saw").

Two target sets, both played from the nominal counts (the program as it is) and from the
compensated counts (``compensate.compensate`` with the calibration's model):

* validation: ``n_targets`` joint configurations drawn uniformly in the calibrated region
  (the joint box of the calibration's samples), kept where the collision checker clears
  them; each is the flange pose the nominal model gives it (a program taught on the
  nominal model). The calibration never saw them.
* ISO 9283: P1..P5 (``validation.iso_points``) of a cube placed by ``validate``'s rule
  (``validation.cube``) on flange targets: centred on the samples' medoid flange
  position, at that sample's flange orientation, the default edge. (``validate`` itself
  commands the tool point onto its ISO points; these are flange targets, as a program's.)

Targets whose solve does not converge (the calibrated model cannot reach them: the
command refuses them) are counted in ``not_converged`` and left out of the AP. Each
target is visited ``cycles`` times in turn; the twin settles with a fresh repeatability
draw per visit and its *true* flange position is read. Per target, as ISO
9283's AP: ``|barycentre of the attained positions - commanded position|``, in two frames:

* the robot's (``robot_frame``): the true robot's frame of joint 1 at its zero mapped onto
  the nominal one's -- what a laser tracker registered to the robot's first axis sees.
  No plane calibration can see the robot's placement in the cell nor J1's zero (a turn
  about J1 turns the plates with it); this frame leaves both out. The primary figure.
* the cell's (``_cell``): the twin's world frame, both included (mm in a realistic world).
"""
from __future__ import annotations

import numpy as np

from planecal.estimation.compensate import CalibratedModel, Region, compensate
from planecal.io.targets import Targets
from planecal.model.robot import within_limits


def draw_targets(robot, region: Region, n: int, rng, checker=None, max_draws: int = 100_000):
    """``n`` joint configurations uniform in the region's joint ranges whose flange is
    within its hull (``Region.distance_m``), within the joint limits and (with ``checker``)
    collision-free: (n, 6) rad."""
    out = []
    for _ in range(max_draws):
        q = rng.uniform(region.lower, region.upper)
        if not within_limits(robot, q) or region.distance_m(q, robot)[0] > 0:
            continue
        if checker is not None and not checker.check_config(q).ok:
            continue
        out.append(q)
        if len(out) == n:
            return np.array(out)
    raise RuntimeError(f"only {len(out)} of {n} clear targets in {max_draws} draws")


def play(twin, counts: np.ndarray, cycles: int) -> np.ndarray:
    """The true flange positions (cycles, N, 3) of ``counts`` (N, 6) visited in turn,
    ``cycles`` times, each at rest with a fresh repeatability draw."""
    att = np.zeros((cycles, len(counts), 3))
    for j in range(cycles):
        for i, c in enumerate(counts):
            twin.set_counts(c)
            att[j, i] = twin.flange_pose()[:3, 3]
    return att


def accuracy(twin, comp, frame: np.ndarray, cycles: int) -> dict:
    """AP [mm] per target of a ``Compensation`` whose solve converged (the command refuses
    the others), nominal vs compensated counts, in the robot's frame ``frame`` and in the
    cell frame."""
    ok = comp.converged
    P = comp.pose[ok, :3, 3]
    Finv = np.linalg.inv(frame)
    out = {}
    for name, counts in (("nominal", comp.counts_nominal[ok]),
                         ("compensated", comp.counts_corrected[ok])):
        bary = play(twin, counts, cycles).mean(0)
        out[name] = np.linalg.norm(bary @ Finv[:3, :3].T + Finv[:3, 3] - P, axis=1) * 1e3
        out[name + "_cell"] = np.linalg.norm(bary - P, axis=1) * 1e3
    return out


def _stats(ap: dict, prefix: str) -> dict:
    out = {}
    for k, v in ap.items():
        out[f"{prefix}_{k}_mm"] = v
        out[f"{prefix}_{k}_median_mm"] = float(np.median(v))
        out[f"{prefix}_{k}_max_mm"] = float(np.max(v))
    return out


def compensation_study(scene, world, options, model: CalibratedModel, sample_counts,
                       n_targets: int = 30, cycles: int = 10, seed: int = 0,
                       checker=None) -> dict:
    """Nominal vs compensated AP on unseen targets and on ISO 9283's P1..P5 in ``world``
    (a ``twin.truth.Truth``) with the twin's ``options`` (module docstring). Figures in
    mm; keys ``validation_{nominal,compensated}[_cell]_{median,max}_mm`` and
    ``iso_...`` alike, plus the arrays per target."""
    from planecal.studies.validation import (SamplePoses, default_edge, iso_points, medoid,
                                             robot_frame)
    from planecal.twin import Twin

    robot = scene.robot
    region = Region.from_counts(robot, sample_counts, "calibration samples")
    rng = np.random.default_rng(seed)
    q = draw_targets(robot, region, n_targets, rng, checker)
    val = Targets([f"V{i + 1}" for i in range(n_targets)], np.full((n_targets, 4, 4), np.nan),
                  q, ["validation"] * n_targets, "validation set")
    sp = SamplePoses.of(scene, sample_counts)
    flanges = sp.flange[:, :3, 3]
    k = medoid(flanges)
    edge = default_edge(flanges)
    T_iso = np.repeat(sp.flange[k][None], 5, axis=0)
    T_iso[:, :3, 3] = iso_points(flanges[k], edge)
    iso = Targets([f"P{i + 1}" for i in range(5)], T_iso, np.full((5, 6), np.nan),
                  ["ISO 9283"] * 5, "ISO 9283 P1..P5")
    frame = robot_frame(robot, world)
    twin = Twin(scene, truth=world, seed=seed, options=options)
    comp_val = compensate(model, val, region)
    comp_iso = compensate(model, iso, region, q_start=sp.q[k])
    out = {"targets": n_targets, "cycles": cycles, "iso_edge_mm": edge * 1e3,
           "converged": int(comp_val.converged.sum() + comp_iso.converged.sum()),
           "not_converged": [n for c in (comp_val, comp_iso)
                             for n, ok in zip(c.names, c.converged) if not ok],
           "iso_outside_region": int(comp_iso.outside.sum()),
           "rounded_residual_max_mm": float(max(comp_val.rounded_residual_m.max(),
                                                comp_iso.rounded_residual_m.max()) * 1e3),
           "max_correction_counts": comp_val.summary()["max_correction_counts"]}
    out.update(_stats(accuracy(twin, comp_val, frame, cycles), "validation"))
    out.update(_stats(accuracy(twin, comp_iso, frame, cycles), "iso"))
    out["ratio_median"] = (out["validation_nominal_median_mm"]
                           / out["validation_compensated_median_mm"])
    return out
