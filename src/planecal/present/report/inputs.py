"""What a report reads besides its result file: the result's recorded inputs (``provenance
.inputs``: role, path, sha256), the sample files, the scene. Every input the report could
not use is said in the page (a note), never silently skipped.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

from planecal.base.errors import InputError


@dataclass
class Context:
    """A report's inputs: the result document, where it came from, and the extra inputs
    given by the caller (sample files, a scene) or found in its provenance."""
    doc: dict
    out_dir: Path
    source: Path | None = None  # the result file, None for a dict
    samples: object = None  # paths (list) or a planecal.io.samples.Samples, or None
    scene: str | None = None  # scene name or path given by the caller
    used_inputs: list[dict] = field(default_factory=list)  # what the report itself read

    def record(self, role: str, path: Path) -> None:
        self.used_inputs.append({"role": role, "path": str(path), "sha256": sha256(path)})


def sha256(path: Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def recorded_inputs(ctx: Context, role: str) -> tuple[list[Path], list[str]]:
    """The paths the result's provenance records for ``role`` that exist here with the
    recorded content, and a note for each that does not. A relative path is looked up
    from the working directory, then from the result file's directory."""
    prov = ctx.doc.get("provenance")
    entries = prov.get("inputs") if isinstance(prov, dict) else None
    if not isinstance(entries, list):
        return [], []
    found, notes = [], []
    for e in entries:
        if not isinstance(e, dict) or e.get("role") != role or not e.get("path"):
            continue
        p = Path(str(e["path"]))
        candidates = [p] if p.is_absolute() else [p] + (
            [ctx.source.parent / p] if ctx.source is not None else [])
        hit = next((c for c in candidates if c.is_file()), None)
        if hit is None:
            notes.append(f"the result records {role} file {p}, which is not here")
            continue
        want = e.get("sha256")
        if want and sha256(hit) != want:
            notes.append(f"{hit} is not the {role} file the result was made from "
                         f"(its SHA-256 differs from the recorded one): not used")
            continue
        found.append(hit)
    return found, notes


def load_scene_for(ctx: Context, notes: list[str]):
    """The scene named by the caller, else by the result's provenance, else the default;
    None (with a note) if it cannot be loaded."""
    from planecal.model.scene import DEFAULT_SCENE, load_scene
    prov = ctx.doc.get("provenance") if isinstance(ctx.doc.get("provenance"), dict) else {}
    settings = ctx.doc.get("settings") if isinstance(ctx.doc.get("settings"), dict) else {}
    name = (ctx.scene or prov.get("scene") or ctx.doc.get("scene") or settings.get("scene")
            or DEFAULT_SCENE)
    try:
        scene = load_scene(name)
    except InputError as e:
        if ctx.scene:  # the caller's own choice: their error
            raise
        notes.append(f"scene {name!r} (from the result) cannot be loaded here ({e}); "
                     f"the figures that need it are left out")
        return None
    ctx.record("scene", scene.path)
    return scene
