"""What a command says, and when, on a stub clock of its own work (issue 33: progress within
2 s on anything longer than 3 s).

The clock is not the wall's. A stub clock (``Trace.of``): each call of one of planecal's
work primitives advances it by that primitive's cost on an idle 2-core machine (``COSTS``:
CPU seconds a call, measured by ``scripts/bench_progress.py``), and nothing else does: a
trace is the lines the command prints in a run whose only time is its counted work, the
same on a loaded machine as on an idle one. Or the CPU clock of the thread that runs the
command (``Trace.cpu``), for work of no fixed cost a call (a figure's drawing): time it
spent working, not waiting for a core, nor other threads' (BLAS's, which spin while they
wait: a process's CPU clock read 1-8 s for the same fit). ``planecal.base.progress``
reads the same clock for its plain lines, and every line written to stdout or stderr is
stamped with it.

    trace = Trace.of(monkeypatch, ["check_path", "check_config"])
    code = trace.run(["plan", "--out", "p.json"])
    assert trace.longest_silence() <= LIMIT_S, trace.silences()
"""
from __future__ import annotations

import importlib
import io
import sys
import time
from dataclasses import dataclass, field

from planecal.cli import main

# CPU seconds a call (scripts/bench_progress.py on an idle 2-core machine, rounded up):
# module, owner (a class or None), function, cost
COSTS = {
    "check_config": ("planecal.safety.collision", "CollisionWorld", "check_config", 0.0003),
    "check_path": ("planecal.safety.collision", "CollisionWorld", "check_path", 0.002),
    "twin_run": ("planecal.twin.core", "Twin", "run", 0.0007),
    "solve": ("planecal.estimation.calibrate", None, "solve", 0.015),  # the one fit's
    "savefig": ("matplotlib.figure", "Figure", "savefig", 0.16),
    "iso_move": ("planecal.studies.validation.iso9283", "Mover", "go", 0.001),
}
LIMIT_S = 2.0  # the promise: something said within 2 s, and every 2 s after


@dataclass
class Trace:
    t: float = 0.0
    calls: dict = field(default_factory=dict)
    lines: list = field(default_factory=list)  # (time, "out"|"err", text)
    end: float = 0.0
    cpu_start: float | None = None  # a CPU clock's zero (None: the stub clock)

    def __call__(self) -> float:
        if self.cpu_start is not None:
            return time.thread_time() - self.cpu_start
        return self.t

    @classmethod
    def cpu(cls, monkeypatch) -> "Trace":
        """A trace on the calling thread's CPU clock (zero when ``run`` starts)."""
        from planecal.base import progress
        tr = cls(cpu_start=time.thread_time())
        monkeypatch.setattr(progress, "clock", tr, raising=False)
        return tr

    @classmethod
    def of(cls, monkeypatch, primitives) -> "Trace":
        """A trace whose clock counts ``primitives`` (keys of ``COSTS``); planecal's
        progress reads it."""
        from planecal.base import progress
        tr = cls()
        for key in primitives:
            mod, owner, name, cost = COSTS[key]
            m = importlib.import_module(mod)
            target = getattr(m, owner) if owner else m
            monkeypatch.setattr(target, name, tr._counted(getattr(target, name), key, cost))
        monkeypatch.setattr(progress, "clock", tr, raising=False)  # (older code: none)
        return tr

    def _counted(self, fn, key: str, cost: float):
        def counted(*a, **kw):
            try:
                return fn(*a, **kw)
            finally:
                self.t += cost
                self.calls[key] = self.calls.get(key, 0) + 1
        return counted

    def run(self, argv) -> int:
        """``planecal ARGV`` in this process, its stdout and stderr stamped line by line."""
        out, err = _Stamped(self, "out"), _Stamped(self, "err")
        saved = sys.stdout, sys.stderr
        sys.stdout, sys.stderr = out, err
        if self.cpu_start is not None:
            self.cpu_start = time.thread_time()
        try:
            code = main(list(argv))
        finally:
            sys.stdout, sys.stderr = saved
            out.flush_rest()
            err.flush_rest()
        self.end = self()
        return code

    def silences(self) -> list[tuple[float, str]]:
        """Each stretch without a line: (its length, the line that ended it), from the start
        to the end of the command."""
        out, last = [], 0.0
        for t, _, text in self.lines:
            out.append((t - last, text))
            last = t
        out.append((self.end - last, "(the end)"))
        return out

    def longest_silence(self) -> float:
        return max(s for s, _ in self.silences())

    def text(self, which: str = "err") -> str:
        return "\n".join(t for _, w, t in self.lines if w == which)


class _Stamped(io.TextIOBase):
    """A text stream (not a terminal) that stamps each line it is given."""

    def __init__(self, trace: Trace, which: str):
        self.trace, self.which, self.buf = trace, which, ""

    def writable(self) -> bool:
        return True

    def isatty(self) -> bool:
        return False

    def write(self, s: str) -> int:
        self.buf += s
        while "\n" in self.buf:
            line, self.buf = self.buf.split("\n", 1)
            self.trace.lines.append((self.trace(), self.which, line))
        return len(s)

    def flush_rest(self) -> None:
        if self.buf:
            self.trace.lines.append((self.trace(), self.which, self.buf))
            self.buf = ""
