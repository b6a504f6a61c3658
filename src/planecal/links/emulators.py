"""Emulators of the real cell's wires, backed by any `RobotLink` / `Laser` (e.g. the twin).

`FD11Emulator` -- the FD11 RT system on UDP (seed 7.1.1, appendix C; framing in
`planecal.links.fd11`). It listens on ``rt_port`` (default 5555). Each valid request
is one tick on a virtual clock (no sleeps): the emulator calls
``backend.exchange(delta)`` and answers (reference, current) to the sender's address at
``reply_port`` (default 5556; ``None`` = the sender's own port). The emulator never
sends unless it has received (send-first handshake).

* Validation: a request must be exactly 48 bytes with the second six int32 equal to
  the negated first six; anything else is ignored (no tick, no reply) and counted in
  ``counters.invalid``.
* Trip (like the FD11's encoder-jump error): a delta that changes by more than
  ``trip_counts`` (60) on any joint from the previous accepted delta (zero at start)
  is not applied; the emulator enters the tripped state (``tripped``, ``trip_reason``;
  brakes on). ``trip_mode='silent'`` (default): from then on nothing is answered and
  the backend is not ticked. ``trip_mode='hold'``: every request still ticks the
  backend with the last accepted delta (the robot does not move) and is answered.
  `reset_trip()` acknowledges the error, like the teach pendant.
* A backend exception also trips the emulator (reason names it).
* Fault injection (`FD11Faults`, counted on valid requests, 1-based n): lose the
  request (no tick, no reply), drop the reply (tick, no reply), delay the reply by
  ``delay_s`` wall-clock seconds, or send it twice.

`LaserEmulator` -- the ZS-LD80 on a pseudo-terminal (framing in
`planecal.links.zs_ld80`). `port` is the slave's device name for pyserial. Each
request line (``command`` + ``terminator``; CR/LF/space around it ignored) is answered
with ``encode_reply(backend.read())``; other lines are ignored and counted. Faults
(`LaserFaults`): garbage reply, no reply, delayed reply.

Both run in a background thread: ``with FD11Emulator(...) as emu:`` or start()/stop().
`Emulators` starts both on one backend with a shared lock (the twin is not
thread-safe); `serve()` runs them until interrupted (``planecal emulate``).
The backend is owned by the caller: the emulators never close it.
"""
from __future__ import annotations

import dataclasses
import os
import select
import socket
import threading
import time
import tty
from contextlib import nullcontext

import numpy as np

from planecal.links.fd11 import TRIP_STEP_COUNTS, pack_reply, unpack_request
from planecal.links.zs_ld80 import FIELD_WIDTH, encode_reply

_POLL_S = 0.05  # how often the threads look at their stop flag


def _every(n: int, k: int) -> bool:
    return k > 0 and n % k == 0


@dataclasses.dataclass
class FD11Faults:
    lose_request_every: int = 0  # request lost on the way: no tick, no reply
    drop_every: int = 0          # reply lost: tick happens, no reply
    delay_every: int = 0         # reply sent delay_s late
    delay_s: float = 0.0
    duplicate_every: int = 0     # reply sent twice


@dataclasses.dataclass
class FD11EmulatorCounters:
    datagrams: int = 0   # everything received
    invalid: int = 0     # wrong size or negatives mismatch
    ticks: int = 0       # backend.exchange calls
    replies: int = 0     # reply datagrams sent (duplicates included)
    lost: int = 0        # requests lost or replies dropped by fault injection
    ignored_tripped: int = 0


class _Served:
    """A server loop (``_serve``) in a daemon thread: start/stop and a context manager;
    ``_close`` releases the endpoint after the thread has stopped."""

    _thread_name = "emulator"

    def start(self):
        if self._thread is None:
            self._thread = threading.Thread(target=self._serve, name=self._thread_name, daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


class FD11Emulator(_Served):
    """FD11 RT server on UDP backed by ``backend`` (any RobotLink)."""

    _thread_name = "fd11-emulator"

    def __init__(self, backend, host: str = "127.0.0.1", rt_port: int = 5555,
                 reply_port: int | None = 5556, *, faults: FD11Faults | None = None,
                 trip_counts: int = TRIP_STEP_COUNTS, trip_mode: str = "silent", lock=None):
        if trip_mode not in ("silent", "hold"):
            raise ValueError(f"trip_mode must be 'silent' or 'hold', got {trip_mode!r}")
        self.backend = backend
        self.reply_port = reply_port
        self.faults = faults or FD11Faults()
        self.trip_counts = int(trip_counts)
        self.trip_mode = trip_mode
        self.counters = FD11EmulatorCounters()
        self.tripped = False
        self.trip_reason: str | None = None
        self.last_delta = np.zeros(6, dtype=np.int64)
        self._lock = lock if lock is not None else nullcontext()
        self._n_valid = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, rt_port))
        except OSError as e:
            self._sock.close()
            raise OSError(f"FD11 emulator: cannot bind UDP {host}:{rt_port} ({e})") from None
        self._sock.setblocking(False)

    @property
    def host(self) -> str:
        return self._sock.getsockname()[0]

    @property
    def rt_port(self) -> int:
        """The UDP port requests are received on (useful when constructed with 0)."""
        return self._sock.getsockname()[1]

    def reset_trip(self) -> None:
        """Acknowledge an encoder-jump error; the next delta is measured from the last accepted."""
        self.tripped = False
        self.trip_reason = None

    def handle(self, data: bytes, addr) -> list[bytes]:
        """Process one datagram; return the reply datagrams to send (also used by the thread)."""
        self.counters.datagrams += 1
        try:
            delta = unpack_request(data)
        except ValueError:
            self.counters.invalid += 1
            return []
        self._n_valid += 1
        n, f = self._n_valid, self.faults
        if _every(n, f.lose_request_every):
            self.counters.lost += 1
            return []
        if self.tripped and self.trip_mode == "silent":
            self.counters.ignored_tripped += 1
            return []
        step = np.abs(delta - self.last_delta)
        if not self.tripped and np.any(step > self.trip_counts):
            j = int(np.argmax(step))
            self.tripped = True
            self.trip_reason = (f"encoder jump error: joint {j + 1} delta changed by "
                                f"{int(step[j])} counts (> {self.trip_counts}); brakes on")
            if self.trip_mode == "silent":
                return []
        if not self.tripped:
            self.last_delta = delta
        try:
            with self._lock:
                reference, current = self.backend.exchange(self.last_delta.copy())
        except Exception as e:  # the backend failing is a fault of the robot
            self.tripped = True
            self.trip_reason = f"backend error: {type(e).__name__}: {e}"
            return []
        self.counters.ticks += 1
        if _every(n, f.drop_every):
            self.counters.lost += 1
            return []
        reply = pack_reply(reference, current)
        if _every(n, f.delay_every) and f.delay_s > 0:
            time.sleep(f.delay_s)
        return [reply, reply] if _every(n, f.duplicate_every) else [reply]

    def _serve(self) -> None:
        while not self._stop.is_set():
            if not select.select([self._sock], [], [], _POLL_S)[0]:
                continue
            try:
                data, addr = self._sock.recvfrom(4096)
            except (BlockingIOError, ConnectionRefusedError):
                continue
            except OSError:
                return
            dest = addr if self.reply_port is None else (addr[0], self.reply_port)
            for reply in self.handle(data, addr):
                try:
                    self._sock.sendto(reply, dest)
                    self.counters.replies += 1
                except OSError:
                    pass

    def _close(self) -> None:
        self._sock.close()


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
    backend_errors: int = 0


class LaserEmulator(_Served):
    """ZS-LD80 on a pty backed by ``backend`` (any Laser); `port` is the device to open."""

    _thread_name = "laser-emulator"

    def __init__(self, backend, *, faults: LaserFaults | None = None, command: bytes = b"M",
                 terminator: bytes = b"\r", field_width: int = FIELD_WIDTH, lock=None):
        self.backend = backend
        self.faults = faults or LaserFaults()
        self.command = bytes(command)
        self.terminator = bytes(terminator)
        self.field_width = int(field_width)
        self.counters = LaserEmulatorCounters()
        self._lock = lock if lock is not None else nullcontext()
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no CR/LF translation until pyserial opens it
        self.port = os.ttyname(self._slave)
        self._buf = b""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def handle(self, data: bytes) -> list[bytes]:
        """Feed received bytes; return the replies to write (also used by the thread)."""
        self._buf += data
        out = []
        while self.terminator in self._buf:
            line, self._buf = self._buf.split(self.terminator, 1)
            line = line.strip(b"\r\n ")
            if not line:
                continue
            if line != self.command:
                self.counters.unknown += 1
                continue
            self.counters.requests += 1
            reply = self._answer(self.counters.requests)
            if reply is None:
                self.counters.silent += 1
            else:
                out.append(reply)
        if len(self._buf) > 4096:  # a flood without terminators: forget it
            self._buf = b""
        return out

    def _answer(self, n: int) -> bytes | None:
        f = self.faults
        if _every(n, f.silent_every):
            return None
        if _every(n, f.garbage_every):
            return f.garbage
        try:
            with self._lock:
                mm = self.backend.read()
        except Exception:
            self.counters.backend_errors += 1
            return None
        if _every(n, f.delay_every) and f.delay_s > 0:
            time.sleep(f.delay_s)
        return encode_reply(mm, terminator=self.terminator, field_width=self.field_width)

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                if not select.select([self._master], [], [], _POLL_S)[0]:
                    continue
                data = os.read(self._master, 1024)
            except OSError:
                return
            for reply in self.handle(data):
                try:
                    os.write(self._master, reply)
                    self.counters.replies += 1
                except OSError:
                    return

    def _close(self) -> None:
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


class Emulators:
    """Both emulators on one backend pair, sharing a lock; a context manager."""

    def __init__(self, robot, laser=None, *, host: str = "127.0.0.1", rt_port: int = 5555,
                 reply_port: int | None = 5556, fd11_faults: FD11Faults | None = None,
                 laser_faults: LaserFaults | None = None, trip_mode: str = "silent"):
        self.lock = threading.Lock()
        self.fd11 = FD11Emulator(robot, host, rt_port, reply_port, faults=fd11_faults,
                                 trip_mode=trip_mode, lock=self.lock)
        try:
            self.laser = LaserEmulator(robot if laser is None else laser,
                                       faults=laser_faults, lock=self.lock)
        except Exception:
            self.fd11.stop()
            raise

    def describe(self) -> list[str]:
        reply = "the sender's port" if self.fd11.reply_port is None else f"port {self.fd11.reply_port}"
        return [f"FD11 RT emulator: UDP {self.fd11.host}:{self.fd11.rt_port} (replies to {reply})",
                f"ZS-LD80 emulator: serial device {self.laser.port}"]

    def start(self) -> "Emulators":
        self.fd11.start()
        self.laser.start()
        return self

    def stop(self) -> None:
        self.fd11.stop()
        self.laser.stop()

    def __enter__(self) -> "Emulators":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def serve(robot, laser=None, *, host: str = "127.0.0.1", rt_port: int = 5555,
          reply_port: int | None = 5556, on_ready=None, stop: threading.Event | None = None,
          **kwargs) -> None:
    """Run both emulators until ``stop`` is set or KeyboardInterrupt (re-raised).

    ``on_ready(emulators)`` is called once both listen (e.g. to print `describe()`).
    """
    stop = stop or threading.Event()
    with Emulators(robot, laser, host=host, rt_port=rt_port, reply_port=reply_port,
                   **kwargs) as emus:
        if on_ready is not None:
            on_ready(emus)
        while not stop.wait(0.2):
            pass
