"""The signals a user or a process manager ends a command with: SIGINT (Ctrl-C), SIGTERM
(systemd, docker stop, kill) and SIGHUP (the terminal closed). Each ends the command as
Ctrl-C does: a `KeyboardInterrupt` raised in the main thread, so a run stops cleanly (its
sidecar ``stopped``, with the signal named), an emulator prints its counters, and the CLI
prints one line. Exit codes: 130 for SIGINT and SIGHUP, 143 for SIGTERM (128 + 15, what a
process manager expects of a terminated process)."""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

HANDLED = (signal.SIGTERM, signal.SIGHUP)  # SIGINT: Python's own KeyboardInterrupt


class Interrupted(KeyboardInterrupt):
    """A SIGTERM or SIGHUP, raised like Ctrl-C's KeyboardInterrupt."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def signal_name(e: KeyboardInterrupt) -> str:
    """The signal that ended the command: SIGTERM, SIGHUP, or SIGINT (a plain Ctrl-C)."""
    return signal.Signals(e.signum).name if isinstance(e, Interrupted) else "SIGINT"


def exit_code(e: KeyboardInterrupt) -> int:
    return 143 if isinstance(e, Interrupted) and e.signum == signal.SIGTERM else 130


def stop_reason(e: KeyboardInterrupt) -> str:
    """A run's ``stop_reason`` for it."""
    return f"interrupted ({signal_name(e)})"


def _raise(signum, frame) -> None:
    raise Interrupted(signum)


@contextmanager
def interrupt_on_signals():
    """SIGTERM and SIGHUP raise `Interrupted` in the main thread while the block runs (a
    signal the process was started ignoring, e.g. SIGHUP under nohup, stays ignored); the
    handlers before are restored after. Off the main thread it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = {}
    for sig in HANDLED:
        old = signal.getsignal(sig)
        if old is not signal.SIG_IGN:
            before[sig] = old
            signal.signal(sig, _raise)
    try:
        yield
    finally:
        for sig, old in before.items():
            signal.signal(sig, old)
