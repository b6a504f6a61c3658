"""``--scene`` on every command: one option, one meaning. A command that reads runs or a
result takes its cell from them (``planecal.jobs.cell``: a run's sidecar, a result's
provenance) and refuses a --scene that names another; where they record none, --scene
chooses, else the default scene (thesis_final). A command that makes a new run or study
takes --scene (default thesis_final).

``run_scene_inputs`` and ``result_scene_inputs``: the scene files those records name, for
the output guard's declaration of what a command reads (``commands.io_options``)."""
from __future__ import annotations

from planecal.base.errors import InputError


def add_scene_argument(p, what: str, reads: str | None = "the run's sidecar") -> None:
    """--scene for ``what`` (e.g. "the nominal values and robot"); ``reads``: the record
    the command takes its cell from (e.g. "the runs' sidecars"), None for a command that
    makes a new run or study."""
    from planecal.base.paths import DEFAULT_SCENE
    where = (f"default: the one {reads} records (a --scene that contradicts it is "
             f"refused), else {DEFAULT_SCENE}") if reads else f"default {DEFAULT_SCENE}"
    p.add_argument("--scene", default=None if reads else DEFAULT_SCENE, metavar="NAME|FILE",
                   help=f"scene for {what} ({where})")


def _recorded(claims, flag) -> list:
    from planecal.commands.io_options import scene_inputs
    found = []
    for c in claims:
        try:
            sc = c.find() if c is not None else None
        except InputError:
            sc = None
        if sc is not None:
            found.append(str(sc.path))
    return [p for name in (found[:1] or [flag]) for p in scene_inputs(name)] + (
        scene_inputs(flag) if flag and found else [])


def run_scene_inputs(paths, flag) -> list:
    """The scene (and robot) files of the runs' recorded cell and of --scene (the runs'
    readers are imported only for a run that exists: a missing one is the guard's to say,
    before anything heavy is loaded)."""
    claims = []
    for p in paths or ():
        if not _exists(p):
            continue
        from planecal.jobs.runs import read_sidecar, run_claim
        try:
            claims.append(run_claim(p, read_sidecar(p)))
        except InputError:  # its reader says why, later
            pass
    return _recorded(claims, flag)


def result_scene_inputs(result, flag) -> list:
    """The scene (and robot) files of a result's recorded cell and of --scene."""
    if not _exists(result):
        return _recorded([], flag)
    from planecal.formats.base import read_json
    from planecal.jobs.results import result_claim
    try:
        claim = result_claim(read_json(result, "result"), str(result))
    except InputError:
        claim = None
    return _recorded([claim], flag)


def _exists(path) -> bool:
    from pathlib import Path
    try:
        return path is not None and Path(path).exists()
    except (OSError, ValueError):  # a NUL character, a name too long: its reader says so
        return False
