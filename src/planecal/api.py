"""planecal for notebooks and scripts: the main calls with SI units and typed results.

    import planecal
    run = planecal.rehearse(samples=60, seed=1)          # a short run on the twin
    cal = planecal.calibrate(run.samples)                # -> CalibratedCell; print(cal)
    val = planecal.validate(cal, run)                    # ISO 9283 AP/RP at the tool point
    s = planecal.load_samples("RUN.tsv")                 # a sample file (mm on disk, m here)

Each call is the job the commands run (``planecal.jobs``: a run read in the cell its
sidecar records, the one calibration pipeline and its result document, ``planecal.studies``
for the twin); nothing is computed twice. Lengths are metres, angles radians;
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
    ``distance_m`` (N,) [m], plate indices ``plate`` (N,) (0-based), where they came from,
    ``direction`` (N, 6) int8: per joint the sign of its last motion into the pose (0:
    unknown; ``planecal.sampling.approach``), or None (a file without it), the cell they
    were taken in (``scene``: a run's, from its sidecar) and the sample file (``path``;
    None: samples in memory)."""
    counts: np.ndarray
    distance_m: np.ndarray
    plate: np.ndarray
    source: str = ""
    direction: np.ndarray | None = None
    scene: object = None  # planecal.model.scene.Scene
    path: Path | None = None

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
    """Read a run (``planecal.jobs.runs.read_run``: the sample file, the seed's format: six
    encoder counts, the distance in mm, an optional plate number; and its sidecar): its
    samples in the cell they were taken in (its sidecar's; a ``scene`` that contradicts it
    is refused; a file without a sidecar: ``scene``, else the default), checked against
    it. Distances are returned in metres."""
    from planecal.jobs.runs import read_run

    run = read_run(path, scene)
    s = run.samples
    return SampleSet(np.asarray(s.qe, np.int64), np.asarray(s.d_mm, float) * 1e-3,
                     np.asarray(s.plate, int), str(path), s.direction, run.scene, Path(path))


# ----- rehearsal on the twin -----------------------------------------------------------------

@dataclass(repr=False)
class Rehearsal:
    """A sampling run on the twin: its ``samples``, the world it was made in (``world``: the
    hidden truth, the robot's true geometry and phases; ``options``: the twin's error
    sources), the cell's ``truth`` (``CellParams``: joint offsets, sensor pose, planes), the
    error profile, the rejected poses by kind, and the scene."""
    samples: SampleSet
    world: object  # planecal.twin.truth.Truth
    options: object  # planecal.twin.core.TwinOptions
    scene: object  # planecal.model.scene.Scene
    errors: str
    seed: int
    truth_seed: int
    rejected: dict = field(default_factory=dict)
    tick_by_tick: bool = True

    @property
    def truth(self):
        """The cell's truth (``CellParams``)."""
        return self.world.params

    def __repr__(self) -> str:
        how = "driven tick by tick" if self.tick_by_tick else "set at rest at each pose"
        rej = ", ".join(f"{k} {v}" for k, v in self.rejected.items()) or "none"
        off = np.array2string(np.asarray(self.truth.joint_offsets) * 1e3, precision=4)
        return (f"Rehearsal on scene {self.scene.name} ({self.errors} world, seed {self.seed}, "
                f"truth seed {self.truth_seed}; twin {how})\n"
                f"  {self.samples!r}\n"
                f"  rejected poses: {rej}\n"
                f"  true joint offsets [mrad]: {off}")


def rehearse(scene=None, samples: int = 30, seed: int = 0, *, truth_seed: int | None = None,
             errors: str = "realistic", tick_by_tick: bool = True) -> Rehearsal:
    """A sampling run on the twin (``planecal.studies.rehearsal``): the sampling run's
    planner with collision checks draws ``samples`` poses (``seed``) on ``scene`` (default
    the default scene) in the world of the error profile ``errors`` ("ideal", "realistic"
    or a profile file) whose truth is drawn with ``truth_seed`` (default: ``seed``, as
    ``planecal rehearse --seed`` does). The twin is driven through the full tick loop, as
    ``planecal rehearse`` drives it (the same samples for the same seeds); with
    ``tick_by_tick=False`` it is set at rest at each pose (faster; the same poses)."""
    from planecal.studies.rehearsal import RehearsalSettings, sample_run

    sc = _scene(scene)
    for name, v, lo in (("samples", samples, 20), ("seed", seed, 0)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise InputError(f"rehearse: {name} must be an integer >= {lo}, got {v!r}")
    truth_seed = seed if truth_seed is None else truth_seed
    st = RehearsalSettings(scene=str(sc.path), samples=int(samples), seed=int(seed),
                           mode="rehearse" if tick_by_tick else "twin",
                           truth_seed=int(truth_seed), errors=errors)
    st.check()
    try:
        qe, d_m, plate, direction, rejected, world, opts = sample_run(st, 0)
    except RuntimeError as e:  # the run gave up
        raise InputError(f"rehearse: {e}") from None
    s = SampleSet(np.asarray(qe, np.int64), np.asarray(d_m, float), np.asarray(plate, int),
                  f"a rehearsal on {sc.name} (seed {seed})", direction, sc)
    return Rehearsal(s, world, opts, sc, errors, int(seed), int(truth_seed), dict(rejected),
                     tick_by_tick)


# ----- calibration ---------------------------------------------------------------------------

@dataclass(repr=False)
class CalibratedCell:
    """An identified cell, as the notebook sees it: the one calibration's result
    (``planecal.estimation.calibrate.Calibration``, in ``calibration``) with its scene and
    its result document, and the numbers a user asks first: ``params`` (``CellParams``,
    SI), per parameter ``values``, ``std`` (NaN where fixed, excluded or not identifiable)
    and ``units``; model error RMS before and after [m] (predicted - measured);
    ``calibration`` is the full ``estimation.calibrate.Calibration`` (result, base set,
    settings) and ``document`` the result file's content (``planecal calibrate --out``)."""
    params: object  # planecal.model.cell_params.CellParams
    values: dict
    std: dict
    units: dict
    rms_before_m: float
    rms_after_m: float
    max_error_m: float
    converged: bool
    scene: object
    calibration: object  # planecal.estimation.calibrate.Calibration
    document: dict

    @property
    def result(self):
        """The fit's ``planecal.estimation.fit.Result``."""
        return self.calibration.result

    @property
    def level(self) -> str:
        return self.calibration.settings.label

    def __repr__(self) -> str:
        from planecal.present.calibration import text
        return (f"Calibration on scene {self.scene.name}, level {self.level}: "
                f"{'converged' if self.converged else 'NOT converged'}\n" + text(self.document))


def calibrate(samples, scene=None, *, initial=None, level: str = "offsets",
              compliance: bool = False, free=None, weighted: bool = False,
              max_iter: int = 30) -> CalibratedCell:
    """Identify the cell from ``samples`` (a ``SampleSet``, a ``Rehearsal`` or a sample
    file path) with the calibration ``planecal calibrate`` and ``planecal demo`` run
    (``planecal.jobs.calibrate``: the same result document), starting from ``initial``
    (``CellParams``, a parameter file, or None: the scene's nominal values). ``level``:
    one of ``planecal.model.levels.LEVELS`` (offsets, full, ...; the seed's 1, 2);
    ``compliance``: J2 and J3's too; ``free``: parameter names (None: the level's default);
    ``weighted``: the weighted fit with the robot's repeatability noise model. The cell is
    the samples' (a run's sidecar, a rehearsal's scene; a ``scene`` that contradicts it is
    refused), else ``scene``, else the default."""
    from planecal.jobs.calibrate import Measured, calibrate_measured
    from planecal.jobs.cell import same_cell
    from planecal.jobs.settings import calibration_settings, fit_options

    if isinstance(samples, Rehearsal):
        samples = samples.samples
    if isinstance(samples, (str, Path)):
        samples = load_samples(samples, scene)
    if not isinstance(samples, SampleSet):
        raise InputError(f"calibrate: samples must be a SampleSet, a Rehearsal or a file, "
                         f"got {type(samples).__name__}")
    sc = _scene(scene)
    if samples.scene is not None:
        if scene is not None and not same_cell(sc, samples.scene):
            raise InputError(f"calibrate: scene {sc.name}: the samples were taken in scene "
                             f"{samples.scene.name}")
        sc = samples.scene
    if isinstance(initial, (str, Path)):
        from planecal.io.params import load_params
        initial = load_params(initial, sc.robot)
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise InputError(f"calibrate: max_iter must be a positive integer, got {max_iter!r}")
    settings = calibration_settings(level=level, compliance=compliance, free=free,
                                    options=fit_options(sc.robot, max_iter=int(max_iter),
                                                        weighted=weighted))
    done = calibrate_measured(sc, Measured(samples.counts, samples.distance_m, samples.plate,
                                           samples.direction), settings, initial,
                              [] if samples.path is None else [("samples", samples.path)])
    cal = done.calibration
    res = cal.result
    layout = res.layout
    x, sd = res.params.to_vector(layout), res.std
    return CalibratedCell(
        params=res.params, values=dict(zip(layout.names, map(float, x))),
        std=dict(zip(layout.names, map(float, sd))), units=dict(zip(layout.names, layout.units)),
        rms_before_m=res.rms_mm(True) * 1e-3, rms_after_m=res.rms_mm() * 1e-3,
        max_error_m=float(np.max(np.abs(res.residuals_m[res.used]))),
        converged=bool(res.converged), scene=sc, calibration=cal, document=done.doc)


# ----- validation ----------------------------------------------------------------------------

@dataclass(repr=False)
class Validation:
    """ISO 9283 pose accuracy (AP) and repeatability (RP) [m], the worst of P1..P5 in the
    robot's frame, in the near-sample cube: at the tool point (the laser's beam point at
    its measuring centre) and at the flange, each for the nominal model, the calibration
    (any level) and the twin's own whole true model (backlash by the approach direction:
    what repeatability and whole counts leave); the gauge-block length error (None where
    the block could not be measured: ``details["gauge_failed"]`` says why); ``details`` is
    the dict of ``planecal.studies.validation.validate`` (mm, as ``planecal validate``
    writes: the standard's cube, the level's floor, the cell frame)."""
    ap_tool_nominal_m: float
    ap_tool_calibrated_m: float
    ap_tool_oracle_m: float
    ap_flange_nominal_m: float
    ap_flange_calibrated_m: float
    ap_flange_oracle_m: float
    rp_tool_calibrated_m: float
    gauge_error_nominal_m: float | None
    gauge_error_calibrated_m: float | None
    details: dict

    def __repr__(self) -> str:
        from planecal.present.validation import format_validation
        return "Validation on the twin, in the rehearsal's world\n" + format_validation(self.details)


def validate(calibration: CalibratedCell, rehearsal: Rehearsal, *, cycles: int = 30,
             gauge_repeats: int = 10, seed: int = 0) -> Validation:
    """Validate ``calibration`` (any level) on the twin of the world ``rehearsal`` was made
    in (its truth, the robot's true geometry, the twin's error sources: as ``planecal
    validate --calibrated --truth --run``): ISO 9283 AP/RP in a cube placed among the
    rehearsal's samples, and the gauge block (``planecal.studies.validation``)."""
    from planecal.estimation.compensate import CalibratedModel
    from planecal.safety.collision import CollisionWorld
    from planecal.studies.validation import ValidationSettings
    from planecal.studies.validation import validate as run_validation

    if not isinstance(calibration, CalibratedCell) or not isinstance(rehearsal, Rehearsal):
        raise InputError("validate: needs a CalibratedCell (planecal.calibrate) and the "
                         "Rehearsal (planecal.rehearse) it was made from")
    st = ValidationSettings(cycles=int(cycles), gauge_repeats=int(gauge_repeats), seed=int(seed))
    st.check()
    sc = rehearsal.scene
    checker = CollisionWorld(sc, clearance_m=st.clearance_m)
    model = CalibratedModel(sc.robot, calibration.params, calibration.level)
    v = run_validation(sc, rehearsal.world, model, rehearsal.samples.counts, st, checker,
                       calibration.result, rehearsal.options, rehearsal.samples.direction)
    return Validation(*(None if v[k] is None else v[k] * 1e-3 for k in (
        "ap_before_tool_mm", "ap_after_tool_mm", "ap_oracle_tool_mm", "ap_before_flange_mm",
        "ap_after_flange_mm", "ap_oracle_flange_mm", "rp_after_tool_mm",
        "gauge_error_before_mm", "gauge_error_after_mm")), v)
