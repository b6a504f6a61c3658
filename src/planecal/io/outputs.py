"""Output files, checked before any work starts: a command never writes over one of its
own inputs, into a directory that is not there, or over a file it did not write.

``check_output(path, inputs, fmt, force)`` refuses (one-line InputError):
* an output that is one of the command's inputs (the same file, by path or inode);
* a directory, a path in a missing directory, or a directory planecal cannot write to;
* an existing file that is not a planecal file of the same kind (``fmt``: the JSON
  ``format`` field it carries), unless ``force``: a result file may be replaced by a new
  result, nothing else is.
Writes themselves stay atomic (``params.save_json``).
"""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from planecal.base.errors import InputError

_PROBE_BYTES = 1 << 16  # how much of an existing file is read to find its format


def _same(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and a.samefile(b))
    except OSError:
        return False


def file_format(path: Path) -> str | None:
    """The ``format`` field of a planecal JSON file, or None (not JSON, no field, ...)."""
    try:
        with open(path, "rb") as f:
            head = f.read(_PROBE_BYTES)
        doc = json.loads(head)
    except (OSError, ValueError):
        return None
    return doc.get("format") if isinstance(doc, dict) else None


def _probe(parent: Path, p: Path, what: str) -> None:
    """Create and remove a temporary file beside the output: the atomic write needs one
    there, and ``os.access`` says yes where the file system says no (root on /proc, a
    read-only mount)."""
    try:
        with tempfile.NamedTemporaryFile(dir=parent, prefix=f".{p.name[:64]}.", suffix=".probe"):
            pass
    except OSError as e:
        raise InputError(f"{what} {p}: cannot write in {parent} "
                         f"({e.strerror or type(e).__name__})") from None


def check_output(path, inputs=(), fmt: str | tuple | None = None, force: bool = False,
                 what: str = "--out") -> Path:
    """The output ``path`` if it may be written (module docstring), else InputError."""
    p = Path(path)
    for i in inputs:
        if i is not None and _same(p, Path(i)):
            raise InputError(f"{what} {p}: that is an input of this command ({i}); "
                             "write the result to another file")
    if p.is_dir():
        raise InputError(f"{what} {p}: is a directory; give a file name")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{what} {p}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise InputError(f"{what} {p}: cannot write in {parent} (permission denied)")
    _probe(parent, p, what)
    if p.exists():
        if not os.access(p, os.W_OK):
            raise InputError(f"{what} {p}: exists and cannot be written (permission denied)")
        kinds = (fmt,) if isinstance(fmt, str) else tuple(fmt or ())
        if not force and file_format(p) not in kinds:
            raise InputError(f"{what} {p}: exists and is not a file this command wrote; "
                             "use --force to replace it")
    return p
