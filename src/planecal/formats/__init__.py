"""One validated model per JSON file format planecal reads or writes (pydantic v2), the
bounded reader they share, and the JSON Schemas published in docs/schemas/.

| format                | file                         | model                  | read by                     |
|-----------------------|------------------------------|------------------------|-----------------------------|
| planecal-robot/1      | models/<robot>/robot.json    | robot.RobotFile        | planecal.model.robot.load_robot   |
| planecal-scene/1      | scenes/<name>.json           | scene.SceneFile        | planecal.model.scene.load_scene   |
| planecal-params/1     | --initial, --truth, --params | params.ParamsFile      | planecal.io.params.load_params |
| planecal-result/1     | calibrate --out              | params.ResultFile      | (as a parameter file)       |
| planecal-poses/1      | plan --out                   | poses.PosesFile        | studies.planning.load_poses |
| planecal-run/1        | RUN.tsv.json (sidecar)       | run.SidecarFile        | load_sidecar below          |
| planecal-errors/1     | models/<robot>/errors/*.json | errors.ErrorProfileFile | planecal.twin.profile       |
| planecal-shapes/1     | models/<robot>/shapes.json   | shapes.ShapesFile      | planecal.model.geometry     |

Every error is one line, ``FILE: field.path: problem`` (``planecal.base.errors.InputError``).
Sample files (TSV) are read by ``planecal.io.samples``, which shares the bounds.

Adding a format (the realistic twin's error profile is next): write its model in a module
here (small typed fields, physical checks as ``problem(...)``), add it to ``MODELS``, run
``scripts/export_schemas.py``, describe it in docs/FORMATS.md; the property tests in
tests/test_schemas_property.py then feed it random and near-valid documents.
"""
import json
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from planecal.formats.base import InputError, read_json, validate
from planecal.formats.error_profile import ERRORS_FORMAT, ErrorProfileFile
from planecal.formats.params import PARAMS_FORMAT, RESULT_FORMAT, ParamsFile, ResultFile
from planecal.formats.poses import POSES_FORMAT, PosesFile
from planecal.formats.robot import ROBOT_FORMAT, RobotFile
from planecal.formats.run import SIDECAR_FORMAT, SidecarFile
from planecal.formats.scene import SCENE_FORMAT, SceneFile
from planecal.formats.shapes import SHAPES_FORMAT, ShapesFile

# format -> model
MODELS: dict[str, type[BaseModel]] = {
    ROBOT_FORMAT: RobotFile,
    SCENE_FORMAT: SceneFile,
    PARAMS_FORMAT: ParamsFile,
    RESULT_FORMAT: ResultFile,
    POSES_FORMAT: PosesFile,
    SIDECAR_FORMAT: SidecarFile,
    ERRORS_FORMAT: ErrorProfileFile,
    SHAPES_FORMAT: ShapesFile,
}


def load_sidecar(path: str | Path) -> dict:
    """A run sidecar, validated (every field ``--resume`` uses, with its type and range),
    as the plain dict ``sampling.run`` works with. One-line InputError otherwise."""
    raw = read_json(path, "run sidecar")
    validate(SidecarFile, raw, path, "run sidecar")
    return raw


def schema_file_name(fmt: str) -> str:
    """'planecal-run/1' -> 'planecal-run-1.schema.json'."""
    return fmt.replace("/", "-") + ".schema.json"


def json_schema(fmt: str) -> dict[str, Any]:
    schema = MODELS[fmt].model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": schema_file_name(fmt), **schema}


def schema_documents() -> dict[str, str]:
    """File name -> text of every published JSON Schema (docs/schemas/)."""
    return {schema_file_name(f): json.dumps(json_schema(f), indent=2, sort_keys=True) + "\n"
            for f in MODELS}


__all__ = ["MODELS", "InputError", "load_sidecar", "read_json", "schema_documents", "validate"]
