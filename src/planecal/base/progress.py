"""Progress of long work on stderr, one way for every command: a tqdm bar on a terminal,
plain lines otherwise (every tenth of the work, at the end, and at most ``INTERVAL_S``
after the last line while work goes on), nothing with ``-q``.

    bar = Progress("samples", total=150)
    bar.update(done=12, note="rejected 3 (collision 3)  robot time 0:01:42")
    bar.close()

A study steps it once a run (``bar.step()``, closed at the total); a sampling run shows its
rejections and robot time as the note.

Work inside one unit (a plan's candidate poses, a fit's iterations, a report's figures, a
worker's run) says how far it is with ``report(k, n, what)``: a function of this module,
so the code deep down needs no progress object. It goes to the innermost open
``Progress`` of the process (its detail, after the note), or, inside a study's run on a
Dask worker, to the engine's sink (``reporting_to``; ``studies.distributed`` sends it to
the client's bar). A ``stage(label)`` is a ``Progress`` of no count, said at once: the
heading of a step that reports only its detail (``with stage("calibration"): ...``).

The promise (issue 33): every command that runs longer than 3 s says something within
2 s and every 2 s after. Work reports at least every ~0.5 s of itself; a plain line follows
within ``INTERVAL_S`` (measured with ``clock``, which a test replaces with a stub or a CPU
clock); tqdm redraws the bar at each report.
``quiet()`` / ``set_quiet(True)`` is the process-wide switch the CLI's ``-q`` sets.
"""
from __future__ import annotations

import sys
import threading
import time
from contextlib import contextmanager
from typing import Callable

_QUIET = [False]
INTERVAL_S = 1.0  # a plain line at most this long after the last one, while work reports
clock: Callable[[], float] = time.monotonic  # the plain lines' clock (tests: a stub)
_OPEN: list["Progress"] = []  # the open progress of this process, the innermost last
_SINK: list = [None]  # where ``report`` goes instead (a study's run on a worker)


def set_quiet(on: bool) -> None:
    _QUIET[0] = bool(on)


def quiet() -> bool:
    return _QUIET[0]


def report(k: int | None = None, n: int | None = None, what: str | None = None) -> None:
    """Progress inside the current unit of work: ``k`` of ``n`` (either may be None) of
    ``what``; to the engine's sink where one is set, else the innermost open ``Progress``
    that is not held (its ``within``), else nowhere."""
    sink = _SINK[0]
    if sink is not None:
        sink(k, n, what)
        return
    shown = [p for p in _OPEN if not p._held]  # a held one is not shown yet
    if shown:
        shown[-1].within(k, n, what)


@contextmanager
def reporting_to(sink: Callable):
    """``report`` goes to ``sink(k, n, what)`` inside the block (a worker's run)."""
    old = _SINK[0]
    _SINK[0] = sink
    try:
        yield
    finally:
        _SINK[0] = old


def detail_text(k: int | None, n: int | None, what: str | None) -> str:
    """'candidate poses 300/1500', 'fold 3', 'figure convergence.png'."""
    count = "" if k is None else (f"{k}/{n}" if n else f"{k}")
    return " ".join(s for s in (what, count) if s)


class Progress:
    """Progress of ``total`` units of ``label`` (module docstring); ``total`` 0: a stage
    (no count: its label, note and detail). ``stream``: default stderr; ``tty``: override
    the stream's own answer (tests)."""

    def __init__(self, label: str, total: int, stream=None, tty: bool | None = None,
                 unit: str = "", quiet: bool = False, hold: bool = False):
        self.label, self.total, self.unit = label, max(int(total), 0), unit
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self.off = quiet or _QUIET[0]
        # ``hold``: nothing shown until ``release()`` (work that may still be refused in
        # one line, e.g. a plan whose target cannot be reached)
        self._held = hold and not self.off
        self.off = self.off or self._held
        self.done = 0
        self.note = ""
        self.detail = ""
        self._printed = -1
        self._shown = ""  # the last plain line
        self._last = clock()
        self._bar = None
        self._closed = False
        self._lock = threading.RLock()  # a worker's reports arrive on the client's thread
        if self.tty and not self.off:
            self._open_bar()
        _OPEN.append(self)

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _open_bar(self) -> None:
        from tqdm import tqdm
        fmt = ("{desc} {n_fmt}/{total_fmt} {bar:24} {elapsed}<{remaining} {postfix}"
               if self.total else "{desc} {elapsed} {postfix}")
        self._bar = tqdm(total=self.total or None, initial=self.done, desc=self.label,
                         unit=self.unit or " " + self.label, file=self.stream,
                         leave=bool(self.total),  # a stage's bar goes when it is done
                         dynamic_ncols=True, mininterval=0.1, bar_format=fmt)
        self._bar.set_postfix_str(self._postfix(), refresh=True)

    def release(self) -> None:
        """Show the progress from now on (one made with ``hold``)."""
        if self._held and not self._closed:
            self._held = self.off = False
            if self.tty:
                self._open_bar()
            elif not self.total:  # a stage is said when shown
                with self._lock:
                    self._print(self.line(), clock())

    def _postfix(self) -> str:
        return self.note + (f": {self.detail}" if self.note and self.detail else self.detail)

    def line(self) -> str:
        head = f"{self.label} {self.done}/{self.total}" if self.total else self.label
        post = self._postfix()
        return head + (f"  {post}" if post else "")

    def update(self, done: int | None = None, note: str | None = None, step: int = 1) -> None:
        """Now ``done`` (or ``step`` more) of the total, with an optional note; the detail
        of the unit before is cleared."""
        with self._lock:
            done = self.done + step if done is None else int(done)
            if done != self.done or note is not None:
                self.detail = ""
            self.done = done
            if note is not None:
                self.note = note
            self._show()

    def within(self, k: int | None = None, n: int | None = None,
               what: str | None = None) -> None:
        """How far the current unit is (``report``): ``k`` of ``n`` of ``what``."""
        with self._lock:
            self.detail = detail_text(k, n, what)
            self._show()

    def _show(self) -> None:
        if self.off or self._closed:
            return
        if self._bar is not None:
            self._bar.n = self.done
            self._bar.set_postfix_str(self._postfix(), refresh=False)
            self._bar.refresh()
            return
        tenth = max(1, self.total // 10)
        now = clock()
        line = self.line()
        due = self.done != self._printed and (self.done % tenth == 0 or self.done == self.total)
        if due or (line != self._shown and now - self._last >= INTERVAL_S):
            self._print(line, now)

    def _print(self, line: str, now: float) -> None:
        self._printed, self._shown, self._last = self.done, line, now
        try:
            print(line, file=self.stream, flush=True)
        except (ValueError, OSError):  # its stream is gone (a bar left open by a failure):
            self.off = True  # the work it reports on must not fail for it
            if self in _OPEN:
                _OPEN.remove(self)

    def step(self, k: int = 1) -> None:
        """``k`` more units done (a study's run, a plan); closed when the total is done."""
        self.update(step=k)
        if self.done >= self.total:
            self.close()

    def close(self, final: str | None = None, last: bool = True) -> None:
        """The last state (and ``final``, e.g. why the work stopped, on a line of its own);
        ``last`` False: no last line (work that never started)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            if self in _OPEN:
                _OPEN.remove(self)
            if self._bar is not None:
                self._bar.close()
            elif last and not self.off and self.total and self.done != self._printed:
                self._print(self.line(), clock())
            if final and not self.off:
                print(final, file=self.stream, flush=True)


def stage(label: str, note: str | None = None, quiet: bool = False,
          hold: bool = False) -> Progress:
    """A step of no count, said at once (a plain line, or a bar with the elapsed time),
    that ``report`` details: ``with stage("calibration"): ...``. ``hold``: said only at
    ``release()`` (a step that may still end in a one-line refusal)."""
    p = Progress(label, 0, quiet=quiet, hold=hold)
    if note is not None:
        p.note = note
    with p._lock:
        if not p.off and p._bar is None:
            p._print(p.line(), clock())
    return p


_COMPILES: list = []  # the one numba compile listener of this process, once installed


def report_compiles(cache: str) -> None:
    """Say numba's compilations (the first run after an install compiles the model's and
    the twin's kernels: ~10-20 s of one core; later runs load them from ``cache``): each
    of planecal's kernels as it starts to compile, and the count of the functions compiled
    so far, to the open progress (``report``), else a ``stage`` of its own."""
    if _COMPILES:
        return
    from numba.core import event

    class Compiles(event.Listener):
        def __init__(self):
            self.depth, self.count, self.kernel, self.bar = 0, 0, "", None

        def on_start(self, ev) -> None:
            f = ev.data["dispatcher"].py_func
            name = f"{f.__module__}.{f.__qualname__}"
            if self.depth == 0 and not _OPEN and _SINK[0] is None:
                self.bar = stage("compiling kernels", f"first run only, then cached in {cache}")
            self.depth += 1
            if name.startswith("planecal."):
                self.kernel = name[len("planecal."):]
            self.say()

        def on_end(self, ev) -> None:
            self.depth -= 1
            self.count += 1
            self.say()
            if self.depth == 0 and self.bar is not None:
                self.bar.close()
                self.bar = None

        def say(self) -> None:
            report(what=f"compiling {self.kernel} ({self.count} functions done)")

    _COMPILES.append(Compiles())
    event.register("numba:compile", _COMPILES[0])
