"""`planecal view FILE [--web] [--summary]`: open a Rerun recording (.rrd).

FILE may be a directory (e.g. ``recordings/``): its newest ``.rrd`` is opened.

Opens the Rerun viewer (the ``rerun`` executable that comes with rerun-sdk, or the one
``$PLANECAL_RERUN`` names) on FILE and waits until it is closed; the viewer ends with this
command (Ctrl-C, SIGTERM, SIGHUP; on Linux also when this process is killed outright). Where no viewer can run -- no ``rerun`` executable, or no
display (Linux without $DISPLAY / $WAYLAND_DISPLAY) -- it prints one line saying how to
open the file instead and exits 1. ``--web`` serves the recording to a browser instead
(``rerun --serve-web FILE``; works without a display). ``--summary`` prints the entity
tree (entity, rows, static, components) read with rerun's own reader, then the views of
the recording's blueprint (``view:`` class, name, origin), no viewer.
Exit 2 when FILE is missing or not a recording.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from planecal.base.errors import InputError


def add_arguments(p) -> None:
    p.add_argument("file", metavar="FILE",
                   help="Rerun recording (.rrd), e.g. from --rrd; a directory: its newest .rrd")
    p.add_argument("--web", action="store_true",
                   help="serve it to a web browser (rerun --serve-web) instead of a window")
    p.add_argument("--summary", action="store_true",
                   help="print the entity tree, row counts and the blueprint's views; open no "
                        "viewer")


def find_viewer() -> str | None:
    """The ``rerun`` executable: $PLANECAL_RERUN, next to this Python (a venv's bin/), else
    on PATH."""
    if os.environ.get("PLANECAL_RERUN"):
        return os.environ["PLANECAL_RERUN"]
    here = Path(sys.executable).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    if here.is_file() and os.access(here, os.X_OK):
        return str(here)
    return shutil.which("rerun")


def has_display() -> bool:
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def run(args) -> int:
    from planecal.present.rerun.common import is_recording

    path = Path(args.file)
    if path.is_dir():  # e.g. recordings/: the newest recording in it
        found = sorted(path.glob("*.rrd"), key=lambda p: p.stat().st_mtime)
        if not found:
            raise InputError(f"{path}: no .rrd recording in this directory")
        path = found[-1]
    if not path.is_file():
        raise InputError(f"{path}: no such recording")
    if not is_recording(path):
        raise InputError(f"{path}: not a Rerun recording (.rrd)")
    if args.summary:
        from planecal.present.rerun.common import blueprint_views, summarize
        try:
            rows = summarize(path)
            views = blueprint_views(path)
        except Exception as e:  # the reader's own errors (truncated file, ...)
            raise InputError(f"{path}: cannot read the recording ({e})") from None
        for entity, n, static, comps in rows:
            print(f"{entity}\t{n}\t{'static' if static else 'temporal'}\t{', '.join(comps)}")
        for v in views:
            print(f"view:\t{v['class']}\t{v['name']}\t{v['origin']}")
        return 0
    exe = find_viewer()
    if exe is None:
        print(f"planecal view: no Rerun viewer here; install it (pip install rerun-sdk) and "
              f"run: rerun {path}")
        return 1
    if not args.web and not has_display():
        print(f"planecal view: no display here; run `rerun {path}` where there is one, or "
              f"`planecal view --web {path}` to serve it to a browser")
        return 1
    cmd = [exe, str(path)] + (["--serve-web", "--bind", "127.0.0.1"] if args.web else [])
    try:
        child = subprocess.Popen(cmd, preexec_fn=_die_with_parent if sys.platform == "linux"
                                 else None)
    except OSError as e:
        print(f"planecal view: cannot start {exe} ({e.strerror}); run: rerun {path}")
        return 1
    return _wait_ending_with_us(child)


def _die_with_parent() -> None:
    """In the child, before exec (Linux): SIGTERM when planecal's process ends, however."""
    import ctypes
    import signal
    PR_SET_PDEATHSIG = 1
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


def _wait_ending_with_us(child: subprocess.Popen) -> int:
    """Wait for the viewer; if we are told to stop, stop it first (no orphan serving a
    web viewer at full CPU after we are gone). The signal handler only records the signal
    and signals the viewer by pid: no Popen method runs inside it, because they take
    Popen's wait lock, which the interrupted wait may hold (a deadlock seen in the field:
    `timeout 20 planecal view --web` hung forever). The main loop polls and escalates."""
    import os
    import signal
    stopping: list[int] = []

    def stop(signum, frame):
        stopping.append(signum)
        try:
            os.kill(child.pid, signal.SIGTERM)
        except OSError:  # already gone
            pass

    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
        signal.signal(sig, stop)
    asked_at: float | None = None
    import time
    while True:
        try:
            rc = child.wait(timeout=0.2)
            break
        except subprocess.TimeoutExpired:
            if stopping:
                if asked_at is None:
                    asked_at = time.monotonic()
                elif time.monotonic() - asked_at > 5:  # the viewer ignored SIGTERM
                    child.kill()
    if stopping:
        raise SystemExit(128 + stopping[0])
    return rc
