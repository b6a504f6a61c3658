"""planecal for notebooks and scripts: the main calls with SI units and typed results.

    import planecal
    run = planecal.rehearse(samples=60, seed=1)          # a short run on the twin
    cal = planecal.calibrate(run.samples)                # -> Calibration; print(cal)
    val = planecal.validate(cal, run)                    # ISO 9283 AP/RP, gauge block
    s = planecal.load_samples("RUN.tsv")                 # a sample file (mm on disk, m here)

Each call wraps the code the commands use (``planecal.io.samples``, ``planecal.estimation.fit``,
``planecal.studies``); nothing is computed twice. Lengths are metres, angles radians;
the results print a readable summary (``repr``). Imports are lazy: ``import planecal``
loads none of this.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError


def _scene(scene):
    """A loaded scene from a name, a path or a Scene."""
    from planecal.model.scene import DEFAULT_SCENE, load_scene

    if scene is None:
        scene = DEFAULT_SCENE
    return load_scene(scene) if isinstance(scene, (str, Path)) else scene


def _mm(x_m: float) -> str:
    return f"{x_m * 1e3:.4f} mm"


# ----- samples -------------------------------------------------------------------------------

@dataclass(repr=False)
class SampleSet:
    """Samples in SI: encoder counts ``counts`` (N, 6) int64, measured distances
    ``distance_m`` (N,) [m], plate indices ``plate`` (N,) (0-based) and where they came
    from."""
    counts: np.ndarray
    distance_m: np.ndarray
    plate: np.ndarray
    source: str = ""

    def __len__(self) -> int:
        return len(self.distance_m)

    def __repr__(self) -> str:
        n = len(self)
        if not n:
            return f"SampleSet: no samples ({self.source})"
        plates = ", ".join(f"plate {k + 1}: {c}" for k, c in
                           zip(*np.unique(self.plate, return_counts=True)))
        return (f"SampleSet: {n} samples from {self.source or '?'}; distance "
                f"{self.distance_m.min() * 1e3:.2f} to {self.distance_m.max() * 1e3:.2f} mm; "
                f"{plates}")


def load_samples(path, scene=None) -> SampleSet:
    """Read a sample file (the seed's format: six encoder counts, the distance in mm, an
    optional plate number; ``planecal.io.samples.read_samples``). With ``scene`` the counts
    are checked against its robot. Distances are returned in metres."""
    from planecal.io.samples import read_samples

    s = read_samples(path, None if scene is None else _scene(scene))
    return SampleSet(np.asarray(s.qe, np.int64), np.asarray(s.d_mm, float) * 1e-3,
                     np.asarray(s.plate, int), str(path))


# ----- rehearsal on the twin -----------------------------------------------------------------

@dataclass(repr=False)
class Rehearsal:
    """A sampling run on the twin: its ``samples``, the twin's hidden ``truth``
    (``CellParams``: joint offsets, sensor pose, planes), the world's error profile, the
    rejected poses by kind, and the scene."""
    samples: SampleSet
    truth: object  # planecal.model.cell.CellParams
    scene: object  # planecal.model.scene.Scene
    errors: str
    seed: int
    truth_seed: int
    rejected: dict = field(default_factory=dict)
    tick_by_tick: bool = False

    def __repr__(self) -> str:
        how = "driven tick by tick" if self.tick_by_tick else "set at rest at each pose"
        rej = ", ".join(f"{k} {v}" for k, v in self.rejected.items()) or "none"
        off = np.array2string(np.asarray(self.truth.joint_offsets) * 1e3, precision=4)
        return (f"Rehearsal on scene {self.scene.name} ({self.errors} world, seed {self.seed}, "
                f"truth seed {self.truth_seed}; twin {how})\n"
                f"  {self.samples!r}\n"
                f"  rejected poses: {rej}\n"
                f"  true joint offsets [mrad]: {off}")


def rehearse(scene=None, samples: int = 30, seed: int = 0, *, truth_seed: int = 0,
             errors: str = "realistic", tick_by_tick: bool = False) -> Rehearsal:
    """A sampling run on the twin, as ``planecal montecarlo`` runs one
    (``planecal.studies.montecarlo``): the sampling run's planner with collision checks
    draws ``samples`` poses (``seed``) on ``scene`` (default the default scene); the twin
    (world: error profile ``errors`` "ideal", "realistic" or a profile file, truth drawn
    with ``truth_seed``) is set at rest at each pose, or with ``tick_by_tick`` driven
    there through the full tick loop (``planecal rehearse`` without the CLI; slower)."""
    from planecal.studies.montecarlo import (MCSettings, rehearse_samples, twin_samples,
                                             world_for)

    sc = _scene(scene)
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 20:
        raise InputError(f"rehearse: samples must be an integer >= 20, got {samples!r}")
    # runs=2: the settings describe a study (check() wants 2 runs); only run 0 is drawn
    st = MCSettings(scene=str(sc.path), samples=int(samples), runs=2, seed=int(seed),
                    mode="rehearse" if tick_by_tick else "twin", truth_seed=int(truth_seed),
                    errors=errors)
    st.check()
    world, opts = world_for(st, 0)
    run = rehearse_samples if tick_by_tick else twin_samples
    try:
        qe, d_m, plate, rejected = run(sc, world, st, int(seed), opts)
    except RuntimeError as e:  # the run gave up
        raise InputError(f"rehearse: {e}") from None
    s = SampleSet(np.asarray(qe, np.int64), np.asarray(d_m, float), np.asarray(plate, int),
                  f"a rehearsal on {sc.name} (seed {seed})")
    return Rehearsal(s, world.params, sc, errors, int(seed), int(truth_seed), dict(rejected),
                     tick_by_tick)


# ----- calibration ---------------------------------------------------------------------------

@dataclass(repr=False)
class Calibration:
    """An identified cell: ``params`` (``CellParams``, SI), per parameter ``values``,
    ``std`` (NaN where fixed or not identifiable) and ``units``; model error RMS before
    and after [m]; ``result`` is the full ``planecal.estimation.fit.Result`` (covariance,
    identifiability, history)."""
    params: object  # planecal.model.cell.CellParams
    values: dict
    std: dict
    units: dict
    rms_before_m: float
    rms_after_m: float
    max_error_m: float
    iterations: int
    converged: bool
    samples_used: int
    outliers: list
    not_identifiable: list
    warnings: list
    scene: object
    result: object  # planecal.estimation.fit.Result

    def __repr__(self) -> str:
        lines = [f"Calibration on scene {self.scene.name}: "
                 f"{'converged' if self.converged else 'NOT converged'} in {self.iterations} "
                 f"iterations; {self.samples_used} samples used"
                 + (f", outliers {self.outliers}" if self.outliers else ""),
                 f"  model error RMS {_mm(self.rms_before_m)} -> {_mm(self.rms_after_m)}; "
                 f"max |error| after {_mm(self.max_error_m)}",
                 f"  {'parameter':<10} {'value':>14} {'std':>11}  unit"]
        for n, v in self.values.items():
            sd = self.std[n]
            sds = ("not ident." if n in self.not_identifiable else "fixed") \
                if not np.isfinite(sd) else f"{sd:.3e}"
            lines.append(f"  {n:<10} {v:>14.7g} {sds:>11}  {self.units[n]}")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def calibrate(samples, scene=None, *, initial=None, free=None, max_iter: int = 30,
              weighted: bool = False) -> Calibration:
    """Identify the cell from ``samples`` (a ``SampleSet``, a ``Rehearsal`` or a sample
    file path) with ``planecal.estimation.fit.solve``, starting from ``initial`` (``CellParams``, a
    parameter file, or None: the scene's nominal values). ``free``: parameter names (or
    None: all but delta1 and delta6). ``weighted``: the weighted fit with the robot's
    repeatability noise model. ``scene`` defaults to the rehearsal's or the default."""
    from planecal.estimation.fit import FitOptions, Problem, solve
    from planecal.model.scene import nominal_params

    if isinstance(samples, Rehearsal):
        scene = samples.scene if scene is None else scene
        samples = samples.samples
    sc = _scene(scene)
    if isinstance(samples, (str, Path)):
        samples = load_samples(samples, sc)
    if not isinstance(samples, SampleSet):
        raise InputError(f"calibrate: samples must be a SampleSet, a Rehearsal or a file, "
                         f"got {type(samples).__name__}")
    if isinstance(initial, (str, Path)):
        from planecal.io.params import load_params
        initial = load_params(initial)
    initial = nominal_params(sc) if initial is None else initial
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise InputError(f"calibrate: max_iter must be a positive integer, got {max_iter!r}")
    opts = {"max_iter": int(max_iter)}
    if weighted:
        from planecal.model.robot import repeatability_sigma
        opts["joint_sigma_rad"] = repeatability_sigma(sc.robot, sc.robot.repeatability_m)
    try:
        problem = Problem.from_arrays(sc.robot, samples.counts, samples.distance_m, initial,
                                      samples.plate, free=free, options=FitOptions(**opts))
    except ValueError as e:
        raise InputError(f"calibrate: {e}") from None
    res = solve(problem)
    layout = res.layout
    x, sd = res.params.to_vector(layout), res.std
    ident = res.identifiability
    warnings = ([f"not identifiable: {', '.join(ident.not_identifiable)} (fix them with "
                 f"free=..., or sample more varied poses)"] if ident.not_identifiable else []) \
        + [f"strongly correlated: {p.a} ~ {p.b} (rho {p.rho:+.3f})"
           for p in ident.correlated_pairs] + list(res.notes)
    return Calibration(
        params=res.params, values=dict(zip(layout.names, map(float, x))),
        std=dict(zip(layout.names, map(float, sd))), units=dict(zip(layout.names, layout.units)),
        rms_before_m=res.rms_mm(True) * 1e-3, rms_after_m=res.rms_mm() * 1e-3,
        max_error_m=float(np.max(np.abs(res.residuals_m[res.used]))),
        iterations=int(res.iterations), converged=bool(res.converged),
        samples_used=int(np.sum(res.used)), outliers=list(res.outliers),
        not_identifiable=list(ident.not_identifiable), warnings=warnings, scene=sc, result=res)


# ----- validation ----------------------------------------------------------------------------

@dataclass(repr=False)
class Validation:
    """ISO 9283 pose accuracy (AP) and repeatability (RP) over P1..P5, and the gauge-block
    length error, with the nominal and the calibrated model [m]; ``details`` is the dict
    of ``planecal.studies.validation.validate`` (mm, as ``planecal validate`` writes)."""
    ap_nominal_m: float
    ap_calibrated_m: float
    rp_m: float
    gauge_error_nominal_m: float
    gauge_error_calibrated_m: float
    details: dict

    def __repr__(self) -> str:
        ratio = self.ap_nominal_m / self.ap_calibrated_m if self.ap_calibrated_m > 0 else \
            float("inf")
        return (f"Validation (ISO 9283 on the twin, {self.details['settings']['cycles']} cycles)\n"
                f"  AP: nominal {_mm(self.ap_nominal_m)}, calibrated {_mm(self.ap_calibrated_m)} "
                f"({ratio:.1f}x better); RP {_mm(self.rp_m)}\n"
                f"  gauge block error: nominal {self.gauge_error_nominal_m * 1e3:+.4f} mm, "
                f"calibrated {self.gauge_error_calibrated_m * 1e3:+.4f} mm")


def validate(calibration: Calibration, rehearsal: Rehearsal, *, cycles: int = 30,
             gauge_repeats: int = 10, seed: int = 0) -> Validation:
    """Validate ``calibration`` on a twin whose cell is ``rehearsal``'s truth (robot.json's
    geometry, as ``planecal validate --calibrated``): ISO 9283 AP/RP in a cube placed by
    the rehearsal's samples, and the gauge block (``planecal.studies.validation``)."""
    from planecal.safety.collision import CollisionWorld
    from planecal.studies.validation import ValidationSettings
    from planecal.studies.validation import validate as run_validation

    if not isinstance(calibration, Calibration) or not isinstance(rehearsal, Rehearsal):
        raise InputError("validate: needs a Calibration (planecal.calibrate) and the "
                         "Rehearsal (planecal.rehearse) it was made from")
    st = ValidationSettings(cycles=int(cycles), gauge_repeats=int(gauge_repeats), seed=int(seed))
    st.check()
    sc = rehearsal.scene
    checker = CollisionWorld(sc, clearance_m=st.clearance_m)
    v = run_validation(sc, rehearsal.truth, calibration.params, rehearsal.samples.counts, st,
                       checker, calibration.result)
    return Validation(v["ap_before_mm"] * 1e-3, v["ap_after_mm"] * 1e-3, v["rp_mm"] * 1e-3,
                      v["gauge_error_before_mm"] * 1e-3, v["gauge_error_after_mm"] * 1e-3, v)
