"""The calibration job: runs in, a CalibrationResult out; the one pipeline ``planecal
calibrate``, ``planecal demo`` and the Python API (``planecal.calibrate``) take.

``calibrate_runs``: the runs' samples (their approach directions, their cell's known
lengths) fitted from the initial parameters with the one calibration
(``estimation.calibrate``), and the result document with its accuracy and provenance
(``CalibrationResult.of``). ``calibrate_files`` is the command: the runs read in their
cell, the report printed, the result, the HTML report and the Rerun recording written.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from planecal.base.errors import InputError
from planecal.jobs.results import CalibrationResult
from planecal.jobs.runs import Runs, read_runs


@dataclass(frozen=True)
class Measured:
    """Samples as the fit takes them (SI): counts (N, 6), distances [m], plates (0-based),
    approach directions (N, 6) or None."""
    qe: np.ndarray
    d_m: np.ndarray
    plate: np.ndarray
    direction: np.ndarray | None = None

    @classmethod
    def of(cls, samples) -> "Measured":
        """A sample file's ``io.samples.Samples`` (mm on disk)."""
        return cls(samples.qe, samples.d_mm * 1e-3, samples.plate, samples.direction)


@dataclass(frozen=True)
class Calibrated:
    """A calibration: the fit (``estimation.calibrate.Calibration``), its result, what
    it was made of (``measured``) and the runs they came from (None: samples in memory)."""
    calibration: object  # planecal.estimation.calibrate.Calibration
    result: CalibrationResult
    measured: Measured
    runs: Runs | None = None

    @property
    def doc(self) -> dict:
        return self.result.doc

    def failure(self) -> str | None:
        """Why the fit did not do its job (``Calibration.failure``), or None."""
        return self.calibration.failure()


def initial_params(path, scene):
    """The initial parameters: a parameter or result file made for the scene's robot
    (``io.params.load_params``), else the scene's nominal values."""
    from planecal.io.params import load_params
    from planecal.model.scene import nominal_params
    return nominal_params(scene) if path is None else load_params(path, scene.robot)


def calibrate_measured(scene, m: Measured, settings, initial=None, inputs=()) -> Calibrated:
    """The one calibration of ``m`` in ``scene`` (its robot, its known lengths) from
    ``initial`` (``CellParams``; None: the scene's nominal values) with ``settings``
    (``CalibrationSettings``), its accuracy (``estimation.accuracy``) and its result;
    ``inputs``: the (role, path) pairs the result's provenance records."""
    from planecal.estimation.accuracy import accuracy
    from planecal.estimation.calibrate import calibrate
    from planecal.model.scene import nominal_params

    initial = nominal_params(scene) if initial is None else initial
    if m.plate.max() >= initial.n_planes:
        raise InputError(f"samples refer to plate {m.plate.max() + 1} but the initial "
                         f"parameters hold {initial.n_planes} plane(s)")
    cal = calibrate(scene.robot, m.qe, m.d_m, initial, m.plate, settings, m.direction,
                    scene.references)
    acc = accuracy(scene.robot, cal, m.qe, m.d_m, m.plate, m.direction, scene.references,
                   scene.laser_range_mm)
    return Calibrated(cal, CalibrationResult.of(cal, scene, inputs, acc), m)


def calibrate_runs(runs: Runs, settings, initial=None, inputs=None) -> Calibrated:
    """``calibrate_measured`` of runs in their cell; ``inputs``: default the runs' sample
    files."""
    inputs = [("samples", p) for p in runs.paths] if inputs is None else inputs
    done = calibrate_measured(runs.scene, Measured.of(runs.samples), settings, initial, inputs)
    return replace(done, runs=runs)


@dataclass(frozen=True)
class CalibrateRequest:
    """``planecal calibrate``'s files: the sample files, --scene (None: the runs'),
    --initial, --out, --report, --rrd; ``settings``: the calibration's settings for the
    cell's robot (the flags', checked against it)."""
    samples: tuple[str, ...]
    settings: Callable
    scene: str | None = None
    initial: str | None = None
    out: str | None = None
    report: str | None = None
    rrd: str | None = None
    extra_inputs: tuple = field(default_factory=tuple)


def calibrate_files(req: CalibrateRequest) -> Calibrated:
    """``planecal calibrate``: the runs in their cell, the calibration, its report on
    stdout, the result file (--out), the HTML report and the recording. The outputs were
    checked before the run (the output guard)."""
    from planecal.jobs.report import write_command_report
    from planecal.present.calibration import text

    runs = read_runs(req.samples, req.scene)
    initial = initial_params(req.initial, runs.scene)
    settings = req.settings(runs.scene.robot)
    inputs = [("samples", p) for p in req.samples] + (
        [("initial", req.initial)] if req.initial else [])
    done = calibrate_runs(runs, settings, initial, inputs)
    print(text(done.doc, runs.samples.n_zero))
    if req.out:
        done.result.write(req.out)
        print(f"result written to {req.out}")
    write_command_report(req.report, req.out or done.doc, samples=list(req.samples),
                         scene=runs.scene)
    if req.rrd:
        from planecal.present.rerun import log_fit_to_file
        path = log_fit_to_file(req.rrd, done.calibration, runs.samples, runs.scene)
        print(f"recording written to {path}")
    return done
