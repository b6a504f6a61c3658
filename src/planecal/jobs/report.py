"""The report job (``planecal report``): a result's page (``present.report``). A
calibration result's page recomputes the model error per sample from its runs (given, or
the ones its provenance records), so it is drawn in their one cell (``jobs.results.
cell_of``): the result's recorded scene, the runs' sidecars, --scene; a --scene that
contradicts them is refused. Where the recorded scene is not here and no --scene stands
in for it, the page says so and leaves out the figures that need it."""
from __future__ import annotations

from pathlib import Path

from planecal.jobs.cell import CellClaim


def _cell_scene(doc, result, samples, scene):
    """The scene (a path) of a calibration result's page, or ``scene`` (the page's own
    fallback) where a recorded scene is not here."""
    from planecal.io.params import recorded_samples
    from planecal.jobs.results import cell_of, result_claim
    from planecal.jobs.runs import read_sidecar, run_claim

    paths = ([Path(p) for p in samples] if samples
             else recorded_samples(doc, result, strict=False))  # the page notes the others
    claims: list[CellClaim | None] = [result_claim(doc, str(result), Path(result).parent)]
    claims += [run_claim(p, read_sidecar(p)) for p in paths if p.is_file()]
    if scene is None and any(c is not None and c.find() is None for c in claims):
        return None  # the page notes the scene it could not load
    return str(cell_of([p for p in paths if p.is_file()], result, scene).path)


def report(result, out, samples=None, scene=None) -> Path:
    """The report page of a result file into ``out``; returns index.html's path."""
    from planecal.formats.base import read_json
    from planecal.present.report import detect_kind, write_report

    doc = read_json(result, "result")
    if detect_kind(doc, str(result)) == "calibration":
        scene = _cell_scene(doc, result, samples, scene)
    return write_report(result, out, samples=samples, scene=scene)


def write_command_report(report_dir, result, samples=None, scene=None) -> None:
    """The report of a command's result (a dict or a file) into ``report_dir``, if given
    (``present.report.write_report``), in ``scene`` (a Scene, a name or a path)."""
    if not report_dir:
        return
    from planecal.present.report import write_report as write
    from planecal.model.scene import Scene
    where = str(scene.path) if isinstance(scene, Scene) else scene
    print(f"report written to {write(result, report_dir, samples=samples, scene=where)}")


