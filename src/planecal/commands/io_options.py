"""What a command reads and writes, declared for the output guard (``planecal.io.outputs``).

Every command that writes a file has ``files(args) -> Files``: its inputs (the positional
files, ``--scene`` and its robot, ``--errors``, ``--poses``, ``--params``, ``--truth``, a
resumed run's recorded files, ...) and one ``Output`` per file or folder it writes. The
CLI adds ``--config`` and checks the whole declaration (``check_files``) before the
command's ``run``: nothing runs, nothing is created, when an output may not be written.
The helpers here are the shared pieces: a sample file with its sidecar, a scene with its
robot, an error profile, a Rerun recording, a report folder, a results file, a lock.
"""
from __future__ import annotations

from pathlib import Path

from planecal.base.errors import InputError
from planecal.io.outputs import HTML_MARK, PNG_MARK, RRD_MAGIC, Files, Output, file_format

SIDECAR_FORMAT = "planecal-run/1"
RESULTS_FORMAT = "planecal-results/1"


def _empty(p: Path) -> bool:
    try:
        return p.stat().st_size == 0
    except OSError:
        return False


def sample_file_is_ours(p: Path) -> bool:
    """A sample file planecal wrote: its sidecar is a run sidecar."""
    return file_format(Path(str(p) + ".json")) == SIDECAR_FORMAT


def with_sidecars(paths) -> list:
    """Sample files and the sidecars their readers may consult (the recorded world)."""
    out = []
    for p in paths or ():
        if p is not None:
            out += [p, Path(str(p) + ".json")]
    return out


def scene_inputs(name) -> list:
    """A scene (name or path) and its robot's description, as far as they can be found
    (a scene that cannot be read is its loader's error, later)."""
    from planecal.base.paths import DEFAULT_SCENE, robot_path, scene_path
    from planecal.formats.base import read_json

    try:
        path = scene_path(name or DEFAULT_SCENE)
    except InputError:
        return []
    out = [path]
    try:
        raw = read_json(path, "scene")
        ref = raw.get("robot", "mc70") if isinstance(raw, dict) else None
        if isinstance(ref, str) and ref:
            robot = robot_path(ref, relative_to=path.parent)
            out += [robot, robot.parent / "shapes.json"]
    except (InputError, OSError, ValueError):
        pass
    return out


def profile_inputs(errors, scene=None) -> list:
    """An error profile's file: the path given, or a named profile's files (the robot's
    own and the generic one). A name (``twin.profile.PROFILES``) has no suffix and no
    folder; anything else is a path."""
    if errors is None:
        errors = "realistic"
    p = Path(str(errors))
    if p.suffix or len(p.parts) > 1:
        return [p]
    from planecal.base.paths import data_folder
    out = [robot.parent / "errors" / f"{errors}.json" for robot in scene_inputs(scene)[1:2]]
    try:
        out.append(data_folder("models") / "generic" / "errors" / f"{errors}.json")
    except InputError:
        pass
    return out


def recorded_inputs(result) -> list:
    """The files a result file's provenance records (any role; relative paths from here and
    from the result's folder): a report or a compensation may read them."""
    from planecal.formats.base import read_json
    try:
        doc = read_json(result, "result")
    except InputError:
        return []  # its reader says why, later
    prov = doc.get("provenance") if isinstance(doc, dict) else None
    entries = prov.get("inputs") if isinstance(prov, dict) else None
    out = []
    for e in entries if isinstance(entries, list) else []:
        if isinstance(e, dict) and isinstance(e.get("path"), str) and e["path"]:
            p = Path(e["path"])
            out += [p] if p.is_absolute() else [p, Path(result).parent / p]
    return out


def lock_output(files: Files, path, what: str) -> None:
    """``FILE.lock`` beside a file a run writes (``sampling.runfiles.RunLock``): created
    empty and removed at the end."""
    files.write(Path(str(path) + ".lock"), f"{what}'s lock", (_empty,))


def rrd_output(files: Files, arg, what: str = "--rrd") -> None:
    """A Rerun recording (``present.rerun.recording_path``): a file (replaced only if it
    is a recording), or a generated new name in a folder (the folder checked)."""
    import os
    if arg is None:
        return
    s = str(arg)
    if s.strip() in ("", "auto", "-"):
        files.write("recordings", what, folder=True)
        return
    p = Path(s).expanduser()
    if p.is_dir() or s.endswith(("/", os.sep)):
        files.write(p, what, folder=True)
        return
    files.write(p if p.suffix else p.with_suffix(".rrd"), what, RRD_MAGIC)


REPORT_MEMBERS = (("index.html", (HTML_MARK,)), ("*.png", (PNG_MARK,)))


def report_output(files: Files, folder, what: str) -> None:
    """A report folder (``present.report.write_report``): index.html and PNG figures."""
    if folder is not None:
        files.write(folder, what, folder=True, members=REPORT_MEMBERS, anchor="index.html")


def results_output(files: Files, path, resume: bool) -> None:
    """A study's results file (``studies.results.ResultsFile``), continued with --resume,
    and its lock."""
    if path is None:
        return
    p = Path(path)
    if resume and p.is_file() and p.stat().st_size > 0 and file_format(p) != RESULTS_FORMAT:
        raise InputError(f"{p}: not a planecal results file (its first line is not "
                         f"{{\"format\": \"{RESULTS_FORMAT}\", ...}}): nothing to resume")
    files.write(path, "--results", RESULTS_FORMAT, keep=resume,
                hint="--resume continues it, --force starts afresh")
    lock_output(files, path, "--results")


__all__ = ["Files", "Output", "lock_output", "profile_inputs", "report_output",
           "recorded_inputs", "results_output", "rrd_output", "sample_file_is_ours", "scene_inputs",
           "with_sidecars"]
