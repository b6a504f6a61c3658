"""The ZS-LD80 laser on a pseudo-terminal, backed by any `Laser` (e.g. the twin).

`LaserEmulator`: `port` is the slave's device name for pyserial (framing in
`planecal.links.zs_ld80`). Each request line (``command`` + ``terminator``; CR/LF/space
around it ignored) is answered with ``encode_reply(backend.read())``; other lines are
ignored and counted. Faults (`LaserFaults`): garbage reply, no reply, delayed reply. It
runs in a background thread (``with LaserEmulator(...)`` or start()/stop()); `Emulators`
(`planecal.links.emulators`) starts it with the FD11 emulator on one backend.
"""
from __future__ import annotations

import dataclasses
import os
import select
import time
import tty
from contextlib import nullcontext

from planecal.links.served import POLL_S, Served, every
from planecal.links.zs_ld80 import FIELD_WIDTH, encode_reply


@dataclasses.dataclass
class LaserFaults:
    garbage_every: int = 0     # answer with ``garbage`` instead of a reading
    silent_every: int = 0      # do not answer
    delay_every: int = 0       # answer delay_s late
    delay_s: float = 0.0
    garbage: bytes = b"ER?x12#\x00\xff\r"


@dataclasses.dataclass
class LaserEmulatorCounters:
    requests: int = 0
    replies: int = 0
    unknown: int = 0    # lines that are not the command
    silent: int = 0     # requests left unanswered (fault or backend error)
    queued: int = 0     # replies decided on
    send_errors: int = 0
    backend_errors: int = 0


class LaserEmulator(Served):
    """ZS-LD80 on a pty backed by ``backend`` (any Laser); `port` is the device to open."""

    _thread_name = "laser-emulator"

    def __init__(self, backend, *, faults: LaserFaults | None = None, command: bytes = b"M",
                 terminator: bytes = b"\r", field_width: int = FIELD_WIDTH, lock=None):
        self._init_served(LaserEmulatorCounters())
        self.backend = backend
        self.faults = faults or LaserFaults()
        self.command = bytes(command)
        self.terminator = bytes(terminator)
        self.field_width = int(field_width)
        self._lock = lock if lock is not None else nullcontext()
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no CR/LF translation until pyserial opens it
        self.port = os.ttyname(self._slave)
        self._buf = b""

    def handle(self, data: bytes) -> list[bytes]:
        """Feed received bytes; return the replies to write (delays applied here)."""
        with self._cv:
            out, delay = self._handle(data)
            self._cv.notify_all()  # counters changed: wake `wait_until`
        if delay > 0:
            time.sleep(delay)
        return out

    def _handle(self, data: bytes) -> tuple[list[bytes], float]:
        self._buf += data
        out, delay = [], 0.0
        while self.terminator in self._buf:
            line, self._buf = self._buf.split(self.terminator, 1)
            line = line.strip(b"\r\n ")
            if not line:
                continue
            if line != self.command:
                self.counters.unknown += 1
                continue
            self.counters.requests += 1
            n = self.counters.requests
            reply = self._answer(n)
            if reply is None:
                self.counters.silent += 1
            else:
                out.append(reply)
                self.counters.queued += 1
                if every(n, self.faults.delay_every):
                    delay = max(delay, self.faults.delay_s)
        if len(self._buf) > 4096:  # a flood without terminators: forget it
            self._buf = b""
        return out, delay

    def _answer(self, n: int) -> bytes | None:
        f = self.faults
        if every(n, f.silent_every):
            return None
        if every(n, f.garbage_every):
            return f.garbage
        try:
            with self._lock:
                mm = self.backend.read()
        except Exception:
            self.counters.backend_errors += 1
            return None
        return encode_reply(mm, terminator=self.terminator, field_width=self.field_width)

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                if not select.select([self._master], [], [], POLL_S)[0]:
                    continue
                data = os.read(self._master, 1024)
            except OSError:
                return
            for reply in self.handle(data):
                try:
                    os.write(self._master, reply)
                except OSError:
                    self._count("send_errors")
                    return
                self._count("replies")

    def _close(self) -> None:
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
