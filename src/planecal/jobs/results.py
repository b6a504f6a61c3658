"""The CalibrationResult: a calibration's result document, read and written here only.

One writer (``CalibrationResult.of``: the one calibration's document,
``present.calibration.document``, with its accuracy and its provenance, checked against
``formats.params.ResultFile``; ``write`` puts it in a file) and one reader (``read_result``
of a file, ``from_document`` of a history entry's copy): the parameters, the level, the
layout by name, the covariance, the encoder offsets, the robot and the scene it was made
in (its provenance: ``jobs.cell``), its status. A parameter file (the same keys without
the fit's report: ``--initial``, a truth file, the seed's Table 10) is read alike; it
records no cell.

Before a result reaches a controller (export's files, ``urdf --params``, ``compensate``,
``history rollback``) its writer asks ``refusal()``: why the result is not a calibration
a controller may take, or None. The reasons are the functions of ``REFUSALS``, each
reading the document only; ``guard`` refuses in one line (exit 2) unless --force, which
says on stderr what it overrides.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from planecal.base.errors import InputError, RunFailed
from planecal.jobs.cell import CellClaim, resolve_cell
from planecal.model.cell_params import CellParams
from planecal.model.scene import Scene


def result_claim(doc, where: str, near: Path | None = None) -> CellClaim | None:
    """The cell a result's provenance records (None: a parameter file, or a result that
    records none)."""
    prov = doc.get("provenance") if isinstance(doc, dict) else None
    if not isinstance(prov, dict):
        return None
    path = next((str(i["path"]) for i in prov.get("inputs") or []
                 if isinstance(i, dict) and i.get("role") == "scene" and i.get("path")), None)
    name = prov.get("scene") if isinstance(prov.get("scene"), str) else None
    rec = doc.get("robot")
    robot = rec.get("name") if isinstance(rec, dict) else prov.get("robot")
    if not (name or path):
        return None
    return CellClaim(where, name, path, robot if isinstance(robot, str) else None, near)


@dataclass(frozen=True)
class CalibrationResult:
    """A result (or parameter) document with its parameters and its cell; ``source``
    names it in messages (its path, "history entry N")."""
    doc: dict
    params: CellParams
    scene: Scene
    source: str

    @classmethod
    def of(cls, cal, scene: Scene, inputs, accuracy=None) -> "CalibrationResult":
        """The result of the one calibration ``cal`` in ``scene``: its document
        (``present.calibration.document``) with its ``accuracy`` figures
        (``estimation.accuracy.Accuracy``) and the provenance of ``inputs`` ((role, path)
        pairs) with the scene's and the robot's files."""
        from planecal.formats.params import provenance, result_document
        from planecal.present.calibration import document

        try:
            doc = result_document(document(cal, scene.robot, accuracy),
                                  provenance([*inputs, ("scene", Path(scene.path).resolve()),
                                              ("robot", scene.robot.source)],
                                             scene.name, scene.robot.name))
        except ValueError as e:  # a fit that ended outside any plausible cell
            raise RunFailed(f"the fit ended outside any plausible cell ({e}): samples of "
                            f"another cell than scene {scene.name}? (a run's sidecar names "
                            "its cell; give --scene for a file without one)") from None
        return cls(doc, cal.result.params, scene, "calibration")

    @classmethod
    def from_document(cls, doc, where: str, scene=None,
                      near: Path | None = None) -> "CalibrationResult":
        """A result or parameter document (a file's, a history entry's) in the cell it
        records (``jobs.cell.resolve_cell`` with ``scene``: --scene, or the cell of runs
        read beside it); made for that cell's robot (``io.params.check_robot``), else
        refused."""
        from planecal.io.params import check_robot, params_from_dict

        cell = resolve_cell([result_claim(doc, where, near)], scene)
        check_robot(doc, cell.robot, where)
        return cls(doc, params_from_dict(doc, where), cell, where)

    def write(self, path) -> None:
        """The result file (``io.params.save_json``: atomic, null for undefined numbers)."""
        from planecal.io.params import save_json
        save_json(path, self.doc)

    # -- what the document says -------------------------------------------------------------
    @property
    def is_result(self) -> bool:
        """A calibration's result (a fit's report), not a bare parameter file."""
        return isinstance(self.doc.get("identifiability"), dict) or "converged" in self.doc

    @property
    def level(self) -> str:
        """'offsets', 'full + compliance', ... (``present.calibration.label``)."""
        from planecal.present.calibration import label
        return label(self.doc)

    @property
    def model_level(self) -> str:
        """The level of the calibrated model (``estimation.compensate.CalibratedModel``)."""
        lv = self.doc.get("level")
        if isinstance(lv, str):
            return lv
        return "full" if self.doc.get("kinematics") is not None else "offsets"

    @property
    def status(self) -> str:
        """The fit's status: "converged", "not_identifiable", "max_iterations" (results
        written before the status said so: from ``converged``); "parameters" for a
        parameter file."""
        st = self.doc.get("status")
        if isinstance(st, str):
            return st
        if not self.is_result:
            return "parameters"
        return "converged" if self.doc.get("converged") else "max_iterations"

    @property
    def not_identifiable(self) -> list[str]:
        ident = self.doc.get("identifiability")
        bad = ident.get("not_identifiable") if isinstance(ident, dict) else None
        return [str(n) for n in bad] if isinstance(bad, list) else []

    @property
    def provenance(self) -> dict | None:
        p = self.doc.get("provenance")
        return p if isinstance(p, dict) else None

    @property
    def robot(self):
        return self.scene.robot

    @property
    def claim(self) -> CellClaim | None:
        """The cell the result records (what runs read beside it must agree with)."""
        return result_claim(self.doc, self.source)

    def model(self):
        """The calibrated model (``estimation.compensate.CalibratedModel``)."""
        from planecal.estimation.compensate import CalibratedModel
        return CalibratedModel(self.scene.robot, self.params, self.model_level)

    # -- may a controller take it -------------------------------------------------------------
    def refusal(self) -> str | None:
        """Why this result must not reach a controller (the first of ``REFUSALS`` that
        finds a reason), or None."""
        for reason in REFUSALS:
            why = reason(self)
            if why:
                return why
        return None

    def guard(self, force: bool, what: str) -> None:
        """Before writing ``what`` (a controller file, a URDF, corrected targets) from
        this result: InputError with ``refusal()`` (nothing written), or with ``force``
        a note on stderr saying what it overrides."""
        why = self.refusal()
        if why is None:
            return
        if not force:
            raise InputError(f"{self.source}: {why}: not a calibration to use; no {what} "
                             "written (--force writes it anyway)")
        print(f"note: --force: writing {what} from {self.source} although {why}",
              file=sys.stderr)


def not_a_calibration(r: CalibrationResult) -> str | None:
    """A fit that did not do what it was asked: not converged, or a free parameter the
    samples could not identify (its value is an arbitrary one of many)."""
    if not r.is_result:
        return None
    if r.doc.get("converged") is False or r.status == "max_iterations":
        return f"the fit did not converge (status {r.status})"
    bad = r.not_identifiable
    if bad:
        return f"the samples could not identify {', '.join(bad)} (status {r.status})"
    return None


def worse_than_simpler(r: CalibrationResult) -> str | None:
    """A calibration its verdict found no better at the tool than a simpler level's
    (``estimation.verdict.refusal``)."""
    from planecal.estimation.verdict import refusal
    return refusal(r.doc) if r.is_result else None


# Every reason a result may not reach a controller: each reads the result, returns a line
# or None (``CalibrationResult.refusal`` asks them in order).
REFUSALS: tuple[Callable[[CalibrationResult], str | None], ...] = (not_a_calibration,
                                                                   worse_than_simpler)


def cell_of(run_paths, result_path=None, scene=None):
    """The one cell of runs and a result read together: their sidecars, the result's
    provenance and ``scene`` must agree (``jobs.cell.resolve_cell``)."""
    from planecal.formats.base import read_json
    from planecal.jobs.runs import read_sidecar, run_claim

    claims = [run_claim(p, read_sidecar(p)) for p in run_paths]
    if result_path is not None:
        doc = read_json(result_path, "calibration result")
        claims.append(result_claim(doc, str(result_path), Path(result_path).parent))
    return resolve_cell(claims, scene)


def read_runs_and_result(run_paths, result_path, scene=None):
    """(``jobs.runs.Runs``, ``CalibrationResult``) of one cell (``cell_of``)."""
    from planecal.jobs.runs import read_runs

    cell = cell_of(run_paths, result_path, scene)
    return read_runs(run_paths, cell), read_result(result_path, cell)


def read_result(path, scene=None) -> CalibrationResult:
    """A result (or parameter) file (``CalibrationResult.from_document``)."""
    from planecal.formats.base import read_json
    doc = read_json(path, "calibration result")
    if not isinstance(doc, dict):
        from planecal.io.params import params_from_dict
        params_from_dict(doc, str(path))  # says what the file is not, in one line
    return CalibrationResult.from_document(doc, str(path), scene, Path(path).parent)
