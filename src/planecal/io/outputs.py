"""The output guard: every file and folder a command writes is checked against every file
it reads before any work starts and before anything is created.

A command declares what it reads and writes (``Files``: its inputs, and one ``Output``
per file or folder it writes; ``planecal.commands.files`` builds them from the options);
``check_files(files, force)`` refuses (one-line InputError, exit 2):

* an output that is one of the command's inputs, by path, through a symbolic link or as a
  hard link (``os.path.samefile``): ``--force`` never lets an output replace an input;
* an output that another output of the same command also writes;
* a file output that is a directory, in a missing directory, or where a file cannot be
  created (permission, a read-only mount, /proc, a name too long: a temporary file is
  made and removed beside it);
* an existing SQLite database (a cell's history, or another application's) or a file
  SQLite keeps beside one (``-wal``, ``-shm``, ``-journal``), unless the output is one
  (the history itself), ``--force`` or not: nothing recorded is lost to an output;
* an existing file that planecal did not write as this kind (``kinds``: the JSON
  ``format`` field it carries, a marker planecal writes near its start, or a test of the
  path), unless ``force``;
* a folder output that is not a folder, whose parent is missing, or that already holds
  files planecal did not write (a folder is planecal's when it is empty or its ``anchor``
  file is planecal's), unless ``force``; each file planecal writes into it (``members``:
  glob patterns) is checked as a file output.

Then an input the command line names (``named``: the values the user gave, ``cli``
passes them) that does not exist is refused, "PATH: file not found": the guard runs
before a command imports its heavy libraries, so a mistyped file name is said at once
(its reader would say the same, seconds later).

``check_output(path, inputs, fmt, force)`` is the same check for one file. Writes
themselves stay atomic (``params.save_json``).
"""
from __future__ import annotations

import errno
import fnmatch
import json
import os
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Union

from planecal.base.errors import InputError

_PROBE_BYTES = 1 << 16  # how much of an existing file is read to find its format
_FORMAT_FIRST = re.compile(rb'\s*\{\s*"format"\s*:\s*"(planecal-[a-z0-9-]+/[0-9]+)"')

# markers planecal writes near the start of its non-JSON files (the writers use these)
HTML_MARK = b'<meta name="generator" content="planecal">'
PNG_MARK = b"Software\x00planecal"  # a PNG tEXt chunk (``savefig(metadata=...)``)
STL_MARK = b"planecal mesh"  # the first bytes of a binary STL's 80-byte header
URDF_MARK = b"written by planecal"
MJCF_MARK = b"written by planecal mjcf"
YAML_MARK = b"calibrated by planecal"
RRD_MAGIC = b"RRF"  # "RRF2" in rerun 0.41; older files start "RRF0"/"RRF1"
COUNTS_TABLE_MARK = b"name\tq1\tq2\tq3\tq4\tq5\tq6\n"
SQLITE_MAGIC = b"SQLite format 3\0"  # the first 16 bytes of every SQLite database

Kind = Union[str, bytes, Callable[[Path], bool]]


@dataclass(frozen=True)
class Output:
    """A file (or, with ``folder``, a folder) a command writes.

    ``kinds``: what planecal writes there (a JSON format tag, bytes found in the first
    64 KiB, or a test of the path); an existing file of another kind is replaced only
    with ``force``. ``new``: must not exist. ``keep``: an existing one is continued
    (``--resume``), not replaced (its reader checks it). ``hint``: what the refusal of an
    existing file suggests.
    A folder's ``members`` are (glob pattern, kinds) of the files written into it; its
    ``anchor`` (a member's name) says whether the folder is planecal's; with ``parents``
    a missing folder's missing parents are made too."""
    path: Path
    what: str
    kinds: tuple = ()
    new: bool = False
    keep: bool = False
    hint: str = "use --force to replace it"
    folder: bool = False
    members: tuple = ()
    anchor: str | None = None
    parents: bool = False  # a missing folder is made with its missing parents


@dataclass
class Files:
    """What a command reads (``inputs``: paths; None entries are skipped) and writes."""
    inputs: list = field(default_factory=list)
    outputs: list[Output] = field(default_factory=list)

    def read(self, *paths, role: str | None = None) -> "Files":
        """Inputs; ``role`` names them in a refusal (e.g. "--params")."""
        self.inputs += [(p, role) for p in paths if p is not None and str(p) != ""]
        return self

    def write(self, path, what: str, kinds: Kind | tuple = (), **kw) -> "Files":
        if path is not None:
            k = kinds if isinstance(kinds, tuple) else (kinds,)
            self.outputs.append(Output(Path(path), what, k, **kw))
        return self


# ----- identity -----------------------------------------------------------------------------

def _stat(p: Path, what: str, follow: bool = True) -> os.stat_result | None:
    """``p``'s stat, None when it does not exist; a name too long, a NUL character or a
    loop of links is a one-line InputError naming ``what``."""
    try:
        return os.stat(p) if follow else os.lstat(p)
    except (FileNotFoundError, NotADirectoryError):
        return None
    except ValueError:  # an embedded NUL
        raise InputError(f"{what} {_shown(p)}: not a usable path (a NUL character)") from None
    except OSError as e:
        if e.errno == errno.ENAMETOOLONG:
            raise InputError(f"{what} {_shown(p)}: the name is too long for the file "
                             "system") from None
        if e.errno == errno.ELOOP:
            raise InputError(f"{what} {_shown(p)}: a loop of symbolic links") from None
        if e.errno == errno.EACCES:
            raise InputError(f"{what} {_shown(p)}: cannot look there (permission "
                             "denied)") from None
        raise InputError(f"{what} {_shown(p)}: {e.strerror or e}") from None


def _shown(p) -> str:
    s = str(p)
    return s if len(s) <= 120 else s[:60] + "..." + s[-40:]


def _resolved(p: Path) -> Path:
    try:
        return p.resolve()
    except (OSError, RuntimeError, ValueError):
        return p.absolute()


def _check_named(inputs, named: set[str]) -> None:
    """InputError for the first input given on the command line that does not exist (the
    others, a sidecar or a profile beside a robot, may be absent: their readers decide)."""
    for i in inputs:
        p, role = i if isinstance(i, tuple) else (i, None)
        if p is None or str(p) not in named:
            continue
        if _stat(Path(p), role or "input") is None:
            raise InputError(f"{_shown(p)}: file not found" + (f" ({role})" if role else ""))


class _Inputs:
    """The command's inputs, each by its resolved path and, when it exists, its inode."""

    def __init__(self, paths: Iterable):
        self.items = []
        for i in paths:
            i, role = i if isinstance(i, tuple) else (i, None)
            if i is None or str(i) == "":
                continue
            p = Path(i)
            try:
                st = os.stat(p)
            except (OSError, ValueError):  # missing or unreadable: its reader will say so
                st = None
            self.items.append((p, role, _resolved(p),
                               None if st is None else (st.st_dev, st.st_ino)))

    def find(self, p: Path, st: os.stat_result | None) -> str | None:
        """The input ``p`` is (its role and path, for the message), or None."""
        r = _resolved(p)
        ident = None if st is None else (st.st_dev, st.st_ino)
        for given, role, res, ino in self.items:
            if res == r or (ident is not None and ino == ident):
                return f"{role} {_shown(given)}" if role else _shown(given)
        return None


# ----- kinds --------------------------------------------------------------------------------

def file_format(path: Path) -> str | None:
    """The ``format`` field of a planecal JSON file (or of a JSON-lines file's first line),
    or None (not JSON, no field, ...)."""
    try:
        with open(path, "rb") as f:
            head = f.read(_PROBE_BYTES)
    except (OSError, ValueError):
        return None
    for text in (head, head.split(b"\n", 1)[0]):
        try:
            doc = json.loads(text)
        except ValueError:
            continue
        return doc.get("format") if isinstance(doc, dict) else None
    # a document longer than the probe (a validation of 20 truths: 330 kB): planecal writes
    # its "format" first
    m = _FORMAT_FIRST.match(head)
    return m.group(1).decode() if m else None


def _head(path: Path) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(_PROBE_BYTES)
    except (OSError, ValueError):
        return b""


def is_kind(path: Path, kinds: tuple) -> bool:
    """Whether planecal wrote ``path`` as one of ``kinds`` (``Output``)."""
    for k in kinds:
        if isinstance(k, str) and file_format(path) == k:
            return True
        if isinstance(k, bytes) and k in _head(path):
            return True
        if callable(k) and k(path):
            return True
    return False


# ----- the checks ---------------------------------------------------------------------------

def _database(p: Path) -> str | None:
    """What ``p`` is, if it is an SQLite database or a file SQLite keeps beside one."""
    if _head(p)[:len(SQLITE_MAGIC)] == SQLITE_MAGIC:
        return "an SQLite database (a cell's history, or another application's)"
    for suffix in ("-wal", "-shm", "-journal"):
        base = p.with_name(p.name[:-len(suffix)]) if p.name.endswith(suffix) else None
        if base is not None and _head(base)[:len(SQLITE_MAGIC)] == SQLITE_MAGIC:
            return f"a file SQLite keeps beside the database {_shown(base)}"
    return None


def _writable_dir(parent: Path, p: Path, what: str) -> None:
    """Create and remove a temporary file in ``parent``: the atomic write needs one there,
    and ``os.access`` says yes where the file system says no (root on /proc, a read-only
    mount)."""
    try:
        with tempfile.NamedTemporaryFile(dir=parent, prefix=f".{p.name[:64]}.", suffix=".probe"):
            pass
    except OSError as e:
        raise InputError(f"{what} {_shown(p)}: cannot write in {_shown(parent)} "
                         f"({e.strerror or type(e).__name__})") from None


def _parent(p: Path) -> Path:
    return p.parent if str(p.parent) else Path(".")


def _check_file(o: Output, inputs: _Inputs, force: bool) -> None:
    p, what = o.path, o.what
    st = _stat(p, what)
    hit = inputs.find(p, st)
    if hit is not None:
        raise InputError(f"{what} {_shown(p)}: that is an input of this command ({hit}); "
                         "write to another file")
    if st is not None and os.path.isdir(p):
        raise InputError(f"{what} {_shown(p)}: is a directory; give a file name")
    if st is None and _stat(p, what, follow=False) is not None:
        raise InputError(f"{what} {_shown(p)}: a symbolic link to nothing; remove it or give "
                         "another name")
    parent = _parent(p)
    pst = _stat(parent, what)
    if pst is None or not os.path.isdir(parent):
        raise InputError(f"{what} {_shown(p)}: directory {_shown(parent)} does not exist")
    _writable_dir(parent, p, what)
    if st is None:
        return
    if o.new:
        raise InputError(f"{what} {_shown(p)}: exists (nothing is overwritten); give a new name")
    if not os.access(p, os.W_OK):
        raise InputError(f"{what} {_shown(p)}: exists and cannot be written (permission denied)")
    if SQLITE_MAGIC not in o.kinds and _database(p):
        raise InputError(f"{what} {_shown(p)}: {_database(p)}; no output replaces it (--force "
                         "or not): give another name")
    if not o.keep and not force and not is_kind(p, o.kinds):
        raise InputError(f"{what} {_shown(p)}: exists and is not a file planecal wrote there; "
                         f"{o.hint}")


def _check_folder(o: Output, inputs: _Inputs, force: bool) -> list[Output]:
    """The folder itself; returns its existing members as file outputs to check."""
    p, what = o.path, o.what
    st = _stat(p, what)
    hit = inputs.find(p, st)
    if hit is not None:
        raise InputError(f"{what} {_shown(p)}: that is an input of this command ({hit})")
    if st is None:
        if _stat(p, what, follow=False) is not None:
            raise InputError(f"{what} {_shown(p)}: a symbolic link to nothing")
        parent = _parent(p)
        while o.parents and _stat(parent, what) is None and parent != _parent(parent):
            parent = _parent(parent)
        if _stat(parent, what) is None or not os.path.isdir(parent):
            raise InputError(f"{what} {_shown(p)}: directory {_shown(parent)} does not exist")
        _writable_dir(parent, p, what)
        return []
    if not os.path.isdir(p):
        raise InputError(f"{what} {_shown(p)}: exists and is not a directory")
    if o.new:
        raise InputError(f"{what} {_shown(p)}: exists; give a new folder (nothing is "
                         "overwritten)")
    _writable_dir(p, p / "x", what)
    try:
        names = sorted(os.listdir(p))
    except OSError as e:
        raise InputError(f"{what} {_shown(p)}: cannot list it ({e.strerror})") from None
    for name in names:  # an input inside the folder, under a name the command writes
        if any(fnmatch.fnmatchcase(name, pat) for pat, _ in o.members):
            q = p / name
            hit = inputs.find(q, _stat(q, what))
            if hit is not None:
                raise InputError(f"{what} {_shown(p)}: {name} in it is an input of this "
                                 f"command ({hit})")
    anchor_kinds = dict(o.members).get(o.anchor, ()) if o.anchor else ()
    ours = not names or (o.anchor is not None and o.anchor in names
                         and is_kind(p / o.anchor, anchor_kinds))
    if o.anchor is not None and not ours and not force:
        raise InputError(f"{what} {_shown(p)}: holds files planecal did not write there; give "
                         f"a new or empty folder ({o.hint})")
    found = []
    for name in names:
        for pattern, kinds in o.members:
            if fnmatch.fnmatchcase(name, pattern):
                member_kinds = kinds if kinds else (lambda _p: ours,)
                found.append(Output(p / name, f"{what} ({name})", member_kinds, keep=o.keep,
                                    hint=o.hint))
                break
    return found


def _check_distinct(files: list[Output]) -> None:
    seen: dict = {}
    for o in files:
        st = _stat(o.path, o.what)
        keys = [("path", _resolved(o.path))] + ([("ino", st.st_dev, st.st_ino)] if st else [])
        for k in keys:
            if k in seen and seen[k] is not o:
                raise InputError(f"{o.what} {_shown(o.path)}: {seen[k].what} writes that file "
                                 "too; give each output its own name")
            seen[k] = o


def check_files(files: Files, force: bool = False, named: Iterable[str] = ()) -> None:
    """Every output of ``files`` checked against its inputs and the others, then every
    input the command line names (``named``) exists (module docstring); InputError for
    the first that may not be written or read."""
    inputs = _Inputs(files.inputs)
    written: list[Output] = []  # every file whose name is known now
    for o in files.outputs:
        if not o.folder:
            _check_file(o, inputs, force)
            written.append(o)
            continue
        existing = _check_folder(o, inputs, force)
        for m in existing:
            _check_file(m, inputs, force)
        written += existing
        written += [Output(o.path / pat, f"{o.what} ({pat})") for pat, _ in o.members
                    if not any(c in pat for c in "*?[") and not (o.path / pat).exists()]
    _check_distinct(written)
    folders = [o for o in files.outputs if o.folder]
    for o in files.outputs:
        for f in folders:
            if not o.folder and _resolved(_parent(o.path)) == _resolved(f.path) and any(
                    fnmatch.fnmatchcase(o.path.name, pat) for pat, _ in f.members):
                raise InputError(f"{o.what} {_shown(o.path)}: {f.what} {_shown(f.path)} writes "
                                 "that file too; give each output its own name")
    _check_named(files.inputs, set(named))


def check_output(path, inputs=(), fmt: str | tuple | None = None, force: bool = False,
                 what: str = "--out") -> Path:
    """One output file ``path`` checked against ``inputs`` (module docstring); returns it."""
    kinds = (fmt,) if isinstance(fmt, (str, bytes)) else tuple(fmt or ())
    files = Files().read(*inputs).write(path, what, kinds)
    check_files(files, force)
    return Path(path)


# ----- writing ------------------------------------------------------------------------------

def make_folder(path, what: str, parents: bool = False) -> Path:
    """Create a folder output the guard passed (its parent exists, or ``parents``); one
    line if the system refuses."""
    p = Path(path)
    try:
        p.mkdir(parents=parents, exist_ok=True)
    except OSError as e:
        raise InputError(f"{what} {_shown(p)}: cannot create the folder ({e.strerror})") from None
    return p
