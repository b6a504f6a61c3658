"""Where planecal's data and caches live (the one place that knows).

Data: the robot models (``models/<robot>/``: robot.json, the MJCF files, the error
profiles ``errors/<name>.json``) and the scenes (``scenes/<name>.json``), under one root:

* ``$PLANECAL_HOME``, if set: a folder holding models/ and scenes/ (a shop's own set);
* else the installed package's copy, ``planecal/data/`` (a wheel or ``pip install .``:
  setup.py copies the repository's models/ and scenes/ there when it builds);
* else the checkout the package runs from (an editable install, ``pip install -e .``:
  the repository's own models/ and scenes/, as edited).

A model or scene given by path is read from that path; only names are looked up here
(``robot_path``, ``scene_path``: light, so a command's files are known before anything
heavy is imported). A data folder that is missing or empty is a one-line ``InputError``
naming it.

Caches, written at run time, never into the installed package: ``cache_dir()`` is
``$PLANECAL_CACHE_DIR``, else ``$XDG_CACHE_HOME/planecal``, else ``~/.cache/planecal``.
It holds the convex-hull cache (``planecal.model.mesh``) and numba's compiled code
(``numba_cache()``; numba's own default is the ``__pycache__`` beside the source, i.e.
inside site-packages) unless ``$NUMBA_CACHE_DIR`` names another folder.
"""
from __future__ import annotations

import os
from pathlib import Path

from planecal.base.errors import InputError

DATA_FOLDERS = ("models", "scenes")
DEFAULT_ROBOT = "mc70"
DEFAULT_SCENE = "thesis_final"
_PACKAGED = Path(__file__).resolve().parents[1] / "data"  # planecal/data in an install
_CHECKOUT = Path(__file__).resolve().parents[3]  # src/planecal/base/paths.py -> the checkout


def data_root() -> Path:
    """The folder holding models/ and scenes/ (module docstring)."""
    env = os.environ.get("PLANECAL_HOME")
    if env:
        return Path(env)
    return _PACKAGED if _PACKAGED.is_dir() else _CHECKOUT


def data_path(*parts: str) -> Path:
    """A path under ``data_root()``, e.g. ``data_path("scenes", "thesis_final.json")``."""
    return data_root().joinpath(*parts)


def data_folder(name: str) -> Path:
    """``models`` or ``scenes`` under ``data_root()``; a one-line InputError if that
    folder is missing or holds nothing (a broken install, a wrong ``$PLANECAL_HOME``)."""
    if name not in DATA_FOLDERS:
        raise ValueError(f"not a data folder: {name!r} (one of {', '.join(DATA_FOLDERS)})")
    folder = data_path(name)
    try:
        empty = not any(folder.iterdir())
    except OSError:  # missing, not a folder, unreadable
        empty = None
    if empty is None or empty:
        where = ("$PLANECAL_HOME" if os.environ.get("PLANECAL_HOME")
                 else "planecal's installed data")
        problem = "is empty" if empty else "is not a readable folder"
        raise InputError(f"{folder}: {problem} ({where}; set PLANECAL_HOME to a folder "
                         "holding models/ and scenes/, or reinstall planecal)")
    return folder


def robot_path(name_or_path: str | Path, relative_to: Path | None = None) -> Path:
    """robot.json of a robot given by name (models/<name>/), by its folder or by the file;
    a relative path is taken from ``relative_to`` (a scene's folder) when given."""
    p = Path(name_or_path)
    if not p.suffix and len(p.parts) == 1 and not (relative_to or Path()).joinpath(p).is_dir():
        return data_folder("models") / str(name_or_path) / "robot.json"
    if relative_to is not None and not p.is_absolute():
        p = relative_to / p
    return p / "robot.json" if p.suffix != ".json" and p.is_dir() else p


def scene_path(name_or_path: str | Path = DEFAULT_SCENE) -> Path:
    """A scene's file: the path given (a .json, or any file that exists), else
    scenes/<name>.json."""
    p = Path(name_or_path)
    try:
        exists = p.exists()
    except (OSError, ValueError):  # a NUL character, a name too long: reading will say so
        exists = False
    if p.suffix == ".json" or exists:
        return p
    return data_folder("scenes") / f"{name_or_path}.json"


def cache_dir() -> Path:
    """Where planecal keeps what it computes once and reuses (module docstring)."""
    env = os.environ.get("PLANECAL_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "planecal"


def numba_cache() -> None:
    """Point numba's on-disk cache at ``cache_dir()/numba`` (call before ``njit(cache=True)``
    makes a function), unless the user chose a folder (``$NUMBA_CACHE_DIR``). numba falls
    back to its own places if that folder cannot be written. A compilation (the first run
    only) is said as progress (``base.progress.report_compiles``)."""
    from numba import config

    from planecal.base.progress import report_compiles
    if not config.CACHE_DIR:
        config.CACHE_DIR = str(cache_dir() / "numba")
    report_compiles(config.CACHE_DIR)


def file_sha256(path) -> str:
    """The SHA-256 of a file's bytes (hex); one-line InputError when it cannot be read."""
    import hashlib
    try:
        with open(path, "rb") as f:
            return hashlib.file_digest(f, "sha256").hexdigest()
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None
