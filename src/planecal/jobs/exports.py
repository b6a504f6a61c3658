"""What a calibration result becomes outside planecal: the controller's file (``planecal
export``, ``planecal history rollback``: ``present.controller``), the calibrated URDF
(``planecal urdf``: ``io.urdf``) and a program's corrected targets (``planecal
compensate``: ``estimation.compensate``). Each reads the result in its cell
(``jobs.results``) and asks it first whether it may leave (``CalibrationResult.guard``:
a fit that did not converge or could not identify what it was asked is refused in one
line, nothing written, unless --force).
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError, RunFailed
from planecal.jobs.results import CalibrationResult, read_result


def write_controller(result: CalibrationResult, req, force: bool = False) -> dict:
    """The controller's file of ``result`` (``present.controller.ControllerFile`` ``req``):
    refused where the result may not reach a controller (``guard``); returns what was
    written."""
    from planecal.present.controller import write_controller_file
    result.guard(force, "controller file")
    return write_controller_file(result.doc, result.params, result.scene, req)


@dataclass(frozen=True)
class ExportRequest:
    """``planecal export``'s options: the result, --format (None: the robot's), --out,
    --current-qe0 (None: robot.json's), --scene (None: the result's), --force, and
    ``tag``: the result's SHA-256 (the UR file's hash)."""
    result: str
    tag: str
    fmt: str | None = None
    out: str | None = None
    current_qe0: np.ndarray | None = None
    scene: str | None = None
    force: bool = False


def export(req: ExportRequest) -> tuple[dict, CalibrationResult]:
    """The controller file of a result file: (what was written, the result)."""
    from planecal.present.controller import ControllerFile
    result = read_result(req.result, req.scene)
    file = ControllerFile(req.fmt, None if req.out is None else Path(req.out),
                          req.current_qe0, str(req.result), req.tag)
    return write_controller(result, file, req.force), result


# ----- the URDF ---------------------------------------------------------------------------------

def mesh_dir(out) -> Path:
    """The folder of a URDF's meshes: FILE_meshes/ beside it."""
    out = Path(out)
    return out.with_name(out.stem + "_meshes")


def write_meshes(scene, params, folder: Path, prefix: str):
    """STL files of the link and tool shapes (planecal.model.geometry) and their MeshRefs;
    each STL's header says planecal wrote it (``outputs.STL_MARK``)."""
    from trimesh.exchange.stl import export_stl

    from planecal.io.outputs import STL_MARK, make_folder
    from planecal.io.urdf import MeshRef
    from planecal.model.geometry import robot_link_meshes, tool_meshes
    make_folder(folder, "--out's mesh folder")
    refs = []
    for kind in ("visual", "collision"):
        for lm in robot_link_meshes(scene.robot, kind) + tool_meshes(scene, kind, sensor=params):
            mesh = lm.mesh.transformed(lm.T_body_mesh).to_trimesh()
            fname = f"{lm.name}_{kind}.stl"
            data = export_stl(mesh)
            (folder / fname).write_bytes(STL_MARK.ljust(80, b" ") + data[80:])
            refs.append(MeshRef(lm.body, kind, prefix + fname, name=f"{lm.name}_{kind}"))
    return refs


@dataclass(frozen=True)
class UrdfRequest:
    """``planecal urdf``'s options: --out, --params (None: the nominal model), --scene
    (None: the result's, else the default), --no-meshes, --mesh-prefix, --force."""
    out: str
    params: str | None = None
    scene: str | None = None
    meshes: bool = True
    mesh_prefix: str | None = None
    force: bool = False


def urdf(req: UrdfRequest) -> Path:
    """The robot as URDF (``io.urdf.urdf_text``): the nominal model of the scene, or the
    calibrated model of a result in its cell (refused where it may not leave, ``guard``);
    with its meshes. Returns the URDF's path."""
    from planecal.io.urdf import not_in_urdf, urdf_text
    from planecal.model.scene import DEFAULT_SCENE, load_scene, nominal_params

    out = Path(req.out)  # checked before the run (the output guard)
    if req.params:
        result = read_result(req.params, req.scene)
        result.guard(req.force, "URDF")
        scene, params, source = result.scene, result.params, f"calibrated: {req.params}"
    else:
        scene = load_scene(req.scene or DEFAULT_SCENE)
        params, source = nominal_params(scene), f"nominal: scene {scene.name}"
    text = urdf_text(scene.robot, params, meshes=[], source=source)  # a bad model: nothing written
    refs = []
    if req.meshes:
        folder = mesh_dir(out)
        prefix = req.mesh_prefix if req.mesh_prefix is not None else folder.name + "/"
        refs = write_meshes(scene, params, folder, prefix)
        text = urdf_text(scene.robot, params, meshes=refs, source=source)
    out.write_text(text, encoding="utf-8")
    left = not_in_urdf(params)
    if left:
        print(f"note: {req.params} also corrects {', '.join(left)}: a URDF is a fixed chain "
              f"and cannot hold {'it' if len(left) == 1 else 'them'}, so {out} does not "
              "(planecal compensate corrects a program's targets with the joints' errors)",
              file=sys.stderr)
    print(f"URDF written to {out} ({source}"
          + (f"; {len(refs)} meshes in {out.stem}_meshes/" if refs else "") + ")")
    return out


# ----- compensated targets ----------------------------------------------------------------------

@dataclass(frozen=True)
class CompensateRequest:
    """``planecal compensate``'s options: the targets, --params, --out, --samples (None:
    the result's recorded ones), --robot (a check: the result's robot), --allow-outside,
    --frame, --force."""
    targets: str
    params: str
    out: str
    samples: tuple | None = None
    robot: str | None = None
    allow_outside: bool = False
    frame: str = "robot"
    force: bool = False


def _region(req: CompensateRequest, result: CalibrationResult):
    """The calibrated region of the result's samples (given, or recorded in it), read in
    the result's cell."""
    from planecal.estimation.compensate import Region
    from planecal.io.params import recorded_samples
    from planecal.jobs.runs import read_runs
    paths = ([Path(s) for s in req.samples] if req.samples
             else recorded_samples(result.doc, req.params))
    if not paths:
        raise InputError(f"{req.params}: records no sample files (no provenance): give the "
                         "calibration's samples with --samples (they define the calibrated "
                         "region)")
    claim = result.claim  # the runs must be of the result's cell
    runs = read_runs(paths, None, [claim]) if claim else read_runs(paths, result.scene)
    return Region.from_counts(result.robot, runs.samples.qe,
                              ", ".join(str(p) for p in paths)), paths


def compensate(req: CompensateRequest) -> dict:
    """Each target's joint counts at which the result's calibrated model puts the flange
    where the nominal model says the target is (``estimation.compensate``), written to
    --out; targets outside the calibrated region refused unless --allow-outside. Returns
    the summary."""
    from planecal.estimation.compensate import compensate as solve
    from planecal.io.params import save_json
    from planecal.io.targets import read_targets, write_counts_table
    from planecal.jobs.predict import robot_agrees
    from planecal.present.compensation import compensated_document, compensation_text

    out = Path(req.out)  # checked before the run (the output guard)
    result = read_result(req.params)
    robot_agrees(req.robot, result.scene, req.params)
    result.guard(req.force, "corrected targets")
    model = result.model()
    region, sample_paths = _region(req, result)
    targets = read_targets(req.targets, result.robot)
    comp = solve(model, targets, region, frame=req.frame)
    s = comp.summary()
    bad = [comp.names[i] for i in np.flatnonzero(~comp.converged)]
    if bad:
        raise RunFailed(f"the calibrated model's inverse did not converge for {len(bad)} "
                        f"target(s) ({', '.join(bad[:5])}); nothing written")
    text, outside = compensation_text(s, model, region, req.params)
    if outside and not req.allow_outside:
        raise InputError(f"{req.targets}: {outside}: refused (--allow-outside writes them)")
    print(text)
    if out.suffix.lower() == ".json":
        save_json(out, compensated_document(
            comp, model, region, {"targets": str(req.targets), "params": str(req.params),
                                  "samples": [str(p) for p in sample_paths]}, req.frame))
    else:
        write_counts_table(out, comp)
    print(f"corrected targets written to {out}")
    return s
