"""Progress of long work on stderr, one way for every command: a tqdm bar on a terminal,
a plain line every tenth of the work (and at the end) otherwise, nothing with ``-q``.

    bar = Progress("samples", total=150)
    bar.update(done=12, note="rejected 3 (collision 3)  robot time 0:01:42")
    bar.close()

A study steps it once a run (``bar.step()``, closed at the total); a sampling run shows its
rejections and robot time as the note.
``quiet()`` / ``set_quiet(True)`` is the process-wide switch the CLI's ``-q`` sets.
"""
from __future__ import annotations

import sys

_QUIET = [False]


def set_quiet(on: bool) -> None:
    _QUIET[0] = bool(on)


def quiet() -> bool:
    return _QUIET[0]


class Progress:
    """Progress of ``total`` units of ``label`` (module docstring). ``stream``: default
    stderr; ``tty``: override the stream's own answer (tests)."""

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
        self._printed = -1
        self._bar = None
        self._closed = False
        if self.tty and not self.off:
            self._open_bar()

    def _open_bar(self) -> None:
        from tqdm import tqdm
        self._bar = tqdm(total=self.total, initial=self.done, desc=self.label,
                         unit=self.unit or " " + self.label, file=self.stream, leave=True,
                         dynamic_ncols=True, mininterval=0.1,
                         bar_format="{desc} {n_fmt}/{total_fmt} "
                         "{bar:24} {elapsed}<{remaining} {postfix}")

    def release(self) -> None:
        """Show the progress from now on (one made with ``hold``)."""
        if self._held and not self._closed:
            self._held = self.off = False
            if self.tty:
                self._open_bar()

    def line(self) -> str:
        return f"{self.label} {self.done}/{self.total}" + (f"  {self.note}" if self.note else "")

    def update(self, done: int | None = None, note: str | None = None, step: int = 1) -> None:
        """Now ``done`` (or ``step`` more) of the total, with an optional note."""
        self.done = self.done + step if done is None else int(done)
        if note is not None:
            self.note = note
        if self.off:
            return
        if self._bar is not None:
            self._bar.n = self.done
            self._bar.set_postfix_str(self.note, refresh=False)
            self._bar.refresh()
            return
        tenth = max(1, self.total // 10)
        if self.done != self._printed and (self.done % tenth == 0 or self.done == self.total):
            self._printed = self.done
            print(self.line(), file=self.stream, flush=True)

    def step(self, k: int = 1) -> None:
        """``k`` more units done (a study's run, a plan); closed when the total is done."""
        self.update(step=k)
        if self.done >= self.total:
            self.close()

    def close(self, final: str | None = None) -> None:
        """The last state (and ``final``, e.g. why the work stopped, on a line of its own)."""
        if self._closed:
            return
        self._closed = True
        if self._bar is not None:
            self._bar.close()
        elif not self.off and self.done != self._printed:
            print(self.line(), file=self.stream, flush=True)
        if final and not self.off:
            print(final, file=self.stream, flush=True)
