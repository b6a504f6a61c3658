"""The verdicts a CI job acts on: ``planecal check`` (has the cell drifted since a
calibration: ``estimation.drift``) and ``planecal compare`` (twin against real, two runs
of the same poses: ``estimation.agreement``). Every run and the result are read in their
one cell (``jobs.results.cell_of``: the sidecars, the result's provenance, --scene)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from planecal.base.errors import InputError
from planecal.jobs.results import cell_of, read_result
from planecal.jobs.runs import read_run, read_runs

MIN_REFERENCE_RUNS = 2


def reference_runs(hist, against, run, mode: str = "auto") -> list[str]:
    """The runs of the history's earlier in-control checks against the result's entry
    ``against`` (here, with the content recorded), when ``mode`` "auto" finds at least
    MIN_REFERENCE_RUNS of them; else none (the calibration's residuals)."""
    from planecal.base.paths import file_sha256
    if mode != "auto" or hist is None or against is None:
        return []
    here = Path(run).resolve()
    found: list[str] = []
    for e in hist.entries(kind="check"):
        if e.against != against or e.outcome != "in_control":
            continue
        for i in hist.get(e.id).inputs:
            p = Path(i.path)
            if (i.role == "run" and p.is_file() and p.resolve() != here
                    and str(p) not in found and file_sha256(p) == i.sha256):
                found.append(str(p))
    return found if len(found) >= MIN_REFERENCE_RUNS else []


@dataclass(frozen=True)
class CheckRequest:
    """``planecal check``'s options (the command's docstring)."""
    run: str
    against: str
    calibration_samples: tuple | None = None
    alpha: float = 0.01
    suspects: str | None = None
    reference: str = "auto"
    scene: str | None = None


@dataclass(frozen=True)
class Checked:
    """A check's verdict document, the result it checked against and the files it read."""
    verdict: dict
    result: object  # planecal.jobs.results.CalibrationResult
    calibration_paths: list
    reference_paths: list
    world: dict | list | None


def check(req: CheckRequest, hist=None, against=None) -> Checked:
    """The drift check of a short run against a result (``estimation.drift.check_run``);
    ``hist``, ``against``: the history and the result's calibrate entry (the reference
    runs of its earlier in-control checks)."""
    from planecal.estimation.drift import FittedResult, check_run, parse_suspects
    from planecal.formats.base import read_json
    from planecal.io.params import recorded_samples
    from planecal.present.drift import check_document

    doc = read_json(req.against, "calibration result")
    cal_paths = list(req.calibration_samples or recorded_samples(doc, req.against,
                                                                 "--calibration-samples"))
    if not cal_paths:
        raise InputError(f"{req.against}: records no calibration samples; give them with "
                         "--calibration-samples")
    cell = cell_of([req.run, *cal_paths], req.against, req.scene)
    result = read_result(req.against, cell)
    fr = FittedResult.of(result.doc, cell.robot, req.against)
    cal = read_runs(cal_paths, cell).samples
    run = read_run(req.run, cell)
    run_s = run.samples
    if run_s.plate.max(initial=0) >= fr.params.n_planes:
        raise InputError(f"{req.run}: samples on plate {run_s.plate.max() + 1}, the result "
                         f"holds {fr.params.n_planes} plane(s)")
    from planecal.history import consult  # a history that fails here: the calibration's
    ref_paths = consult(hist, lambda h: reference_runs(h, against, req.run, req.reference), [])
    refs = read_runs(ref_paths, cell).runs if ref_paths else ()
    chk = check_run(fr, (cal.qe, cal.d_mm * 1e-3, cal.plate),
                    (run_s.qe, run_s.d_mm * 1e-3, run_s.plate), req.alpha,
                    parse_suspects(req.suspects, fr.layout),
                    [(r.samples.qe, r.samples.d_mm * 1e-3, r.samples.plate) for r in refs])
    verdict = check_document(chk, str(req.run), str(req.against), fr.noise is not None,
                             against, ref_paths)
    rec = run.record()
    return Checked(verdict, result, cal_paths, ref_paths, rec)


@dataclass(frozen=True)
class CompareRequest:
    """``planecal compare``'s options (the command's docstring)."""
    run: str
    rehearsal: str
    params: str | None = None
    alpha: float = 0.01
    suspects: str | None = None
    repeatability_mm: float | None = None
    count_tolerance: int = 2
    scene: str | None = None


def noise(repeatability_mm, robot) -> tuple[float, dict]:
    """The noise model of a comparison: the repeatability's joint sigma and its record."""
    import numpy as np

    from planecal.estimation.noise import repeatability_sigma
    rep = repeatability_mm
    if rep is not None and not (np.isfinite(rep) and rep > 0):
        raise InputError(f"--repeatability-mm must be > 0, got {rep:g}")
    r_m = robot.repeatability_m if rep is None else rep * 1e-3
    if not r_m > 0:
        raise InputError(f"{robot.source}: the robot states no repeatability_mm; give "
                         "--repeatability-mm")
    return repeatability_sigma(robot, r_m), {
        "repeatability_mm": r_m * 1e3, "distance_sigma_um": 1.0, "quantization": True,
        "source": "--repeatability-mm" if rep is not None else "robot.json"}


@dataclass(frozen=True)
class Compared:
    """A comparison's verdict document, its cell and parameters, and where its runs were
    made (the history's world record)."""
    verdict: dict
    scene: object
    params: object
    world: dict


def compare(req: CompareRequest) -> Compared:
    """Two runs of the same poses compared sample by sample
    (``estimation.agreement.compare_runs``), the suspects through the Jacobian at --params'
    values (else the cell's nominal ones)."""
    from planecal.estimation.agreement import compare_runs, pair
    from planecal.estimation.drift import parse_suspects
    from planecal.model.levels import layout_for
    from planecal.model.scene import nominal_params
    from planecal.present.agreement import compare_document

    cell = cell_of([req.run, req.rehearsal], req.params, req.scene)
    params = read_result(req.params, cell).params if req.params else nominal_params(cell)
    runs = read_runs([req.run, req.rehearsal], cell)
    run, reh = runs.runs
    pr = pair(run.samples, reh.samples, req.count_tolerance, (str(req.run), str(req.rehearsal)))
    if pr.plate.max(initial=0) >= params.n_planes:
        raise InputError(f"{req.run}: samples on plate {pr.plate.max() + 1}, the parameters "
                         f"hold {params.n_planes} plane(s)")
    js, model = noise(req.repeatability_mm, cell.robot)
    layout = layout_for(cell.robot, params.n_planes, "full", True)
    ag = compare_runs(cell.robot, params, layout, pr, js, 1e-6, req.alpha,
                      parse_suspects(req.suspects, layout))
    model["pair_sigma_median_mm"] = float(sorted(ag.sigma_m)[len(ag.sigma_m) // 2] * 1e3)
    doc = compare_document(ag, pr, str(req.run), str(req.rehearsal), model)
    return Compared(doc, cell, params, {"run": run.record(), "rehearsal": reh.record()})
