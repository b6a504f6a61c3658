"""Which cell a file was made in, and the one rule that picks a command's cell.

A run's sidecar and a result's provenance record the scene they were made in (its name and
file) and its robot: a ``CellClaim``. A command that reads such files takes its cell from
them (``resolve_cell``): every claim must name the same cell, and a ``--scene`` that names
another is refused in one line (exit 2); a command reading only files that record none
(a hand-written sample or parameter file) takes ``--scene``, else the default scene.

Two scenes are the same cell when they are the same file, or files of the same content
(the parsed JSON, key order and layout aside) for the same robot description (its
SHA-256, ``model.robot.Robot.digest``): a copy of a scene file is the same cell, an
edited one is not.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from planecal.base.errors import InputError
from planecal.model.scene import DEFAULT_SCENE, Scene, load_scene


@dataclass(frozen=True)
class CellClaim:
    """What a file records of the cell it was made in: ``where`` names the record (a
    sidecar, a result file), ``name`` and ``path`` the scene (either may be missing),
    ``robot`` its robot's name, ``near`` the folder a relative path is also tried from."""
    where: str
    name: str | None = None
    path: str | None = None
    robot: str | None = None
    near: Path | None = None

    def describe(self) -> str:
        return f"scene {self.name or self.path}"

    def find(self) -> Scene | None:
        """The recorded scene, if it is here: its file (as recorded, then beside the
        record), else its name among the scenes; None when neither is found."""
        cands = []
        if self.path:
            p = Path(self.path)
            cands += [p] if p.is_absolute() or self.near is None else [p, self.near / p]
        for c in cands:
            if c.is_file():
                return load_scene(c)
        if self.name:
            try:
                return load_scene(self.name)
            except InputError:
                return None
        return None


def cell_digest(scene: Scene) -> str:
    """The cell's identity: its scene file's content (parsed) and its robot's description."""
    from planecal.formats.base import read_json
    text = json.dumps(read_json(scene.path, "scene"), sort_keys=True)
    return hashlib.sha256((text + "\0" + (scene.robot.digest or "")).encode()).hexdigest()


def same_cell(a: Scene, b: Scene) -> bool:
    """The same scene file, or the same content for the same robot (module docstring)."""
    try:
        if Path(a.path).resolve() == Path(b.path).resolve():
            return True
    except OSError:
        pass
    return cell_digest(a) == cell_digest(b)


def resolve_cell(claims, scene: str | Path | Scene | None = None,
                 default: str = DEFAULT_SCENE) -> Scene:
    """The cell of a command reading files that record theirs (``claims``; None entries:
    files that record none) and given ``scene`` (--scene: a name, a path or a loaded
    Scene). InputError (one line) where two claims disagree, where ``scene`` contradicts
    them, or where a recorded scene is not here and no ``scene`` stands in for it."""
    given = load_scene(scene) if isinstance(scene, (str, Path)) else scene
    claims = [c for c in claims if c is not None]
    found: list[tuple[CellClaim, Scene]] = []
    for c in claims:
        sc = c.find()
        if sc is None:
            if given is None or (c.name and c.name != given.name):
                raise InputError(f"{c.where}: made in {c.describe()}"
                                 f"{f' ({c.path})' if c.path else ''}, which is not here: "
                                 "give its scene file with --scene")
            sc = given  # the user says where the recorded cell is now
        if c.robot and c.robot != sc.robot.name:
            raise InputError(f"{c.where}: made with the robot {c.robot!r}, but its "
                             f"{c.describe()} is for {sc.robot.name!r}")
        found.append((c, sc))
    if not found:
        return given if given is not None else load_scene(default)
    (c0, cell), rest = found[0], found[1:]
    for c, sc in rest:
        if not same_cell(cell, sc):
            raise InputError(f"{c.where}: made in scene {sc.name}, but {c0.where} in scene "
                             f"{cell.name}: the files must be of one cell")
    if given is not None and not same_cell(given, cell):
        raise InputError(f"--scene {scene if isinstance(scene, (str, Path)) else given.name}: "
                         f"{c0.where} records scene {cell.name} ({cell.path}) for its robot "
                         f"{cell.robot.name!r}: leave --scene out, or give that scene")
    return cell
