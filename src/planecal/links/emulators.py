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
* Sessions: a valid request from another address than the last one, or after
  ``session_gap_s`` (2 s: longer than any outage a client rides through, 0.5 s by
  default) without any, starts a client session. Between sessions the
  robot holds its last command: the backend is ticked with it until the counts sit on it
  (at most ``settle_ticks``), as the servo would in the meantime. What the controller
  does with its reference is ``reference_mode``, in the words of robot.json's
  ``controller.sessions`` (`planecal.links.sessions`):
  ``"keep"``: the reference stays the one of the emulator's start, and a session's first
  delta is checked against the last one received, like any other (delta 0 after a
  session that moved trips it);
  ``"fresh_after_silence"`` (default): a request after ``session_gap_s`` without any takes
  the robot's current counts as the new reference (the delta it holds becomes 0, so a
  first delta other than 0 is a step of that size, and trips it above 60) -- the
  behaviour of the independent FD11 peer of issue 25;
  ``"fresh_each_client"``: the same, at a request from another client address, however
  short the silence (the same address continues its session).
  The emulator talks to its backend in the backend's own frame: backend delta = delta +
  (reference - backend reference); the backend is assumed to start at rest on its
  reference counts (the twin does).
* Trip (like the FD11's encoder-jump error): a delta that changes by more than
  ``trip_counts`` (60) on any joint from the previous accepted delta is not applied; the
  emulator enters the tripped state (``tripped``, ``trip_reason``; brakes on).
  ``trip_mode='silent'`` (default): from then on nothing is answered and the backend is
  not ticked. ``trip_mode='hold'``: every request still ticks the backend with the last
  accepted delta (the robot does not move) and is answered. `reset_trip()` acknowledges
  the error, like the teach pendant. A backend exception also trips the emulator.
* Fault injection (`FD11Faults`; every decision a function of the valid request's index
  n, 1-based, and ``seed``, so a test that sends the same requests sees the same faults):
  lose the request (no tick, no reply), drop the reply (tick, no reply) every k-th or at
  random with probability ``drop_probability``, delay the reply by ``delay_s`` wall-clock
  seconds, send it twice; stay silent while booting (the first ``boot_requests``
  requests, or for ``boot_s`` after `start`); release the dead-man switch after
  ``release_after_ticks`` backend ticks, or ``release_after_moves`` ticks that command
  motion (deterministic: the hold ticks while a pose is planned depend on the machine's
  speed) -- the robot stops following: the backend is no longer ticked and the replies
  show the counts where it stopped; the switch is held again when the next session starts.
* Counters (`FD11EmulatorCounters`) are updated by the emulator's thread: read them with
  `snapshot()`, wait for them with `wait_until(predicate, timeout_s)`, or read
  ``counters`` after `stop()` (the thread has ended).

`LaserEmulator` -- the ZS-LD80 on a pseudo-terminal (`planecal.links.laser_emulator`).

Both run in a background thread: ``with FD11Emulator(...) as emu:`` or start()/stop().
`Emulators` starts both on one backend with a shared lock (the twin is not
thread-safe); `serve()` runs them until interrupted (``planecal emulate``).
The backend is owned by the caller: the emulators never close it.
"""
from __future__ import annotations

import dataclasses
import select
import socket
import threading
import time
from contextlib import nullcontext

import numpy as np

from planecal.links.fd11 import TRIP_STEP_COUNTS, pack_reply, unpack_request
from planecal.links.laser_emulator import LaserEmulator, LaserFaults
from planecal.links.served import POLL_S, Served, every
from planecal.links.sessions import BEHAVIOURS

REFERENCE_MODES = BEHAVIOURS  # keep, fresh_after_silence, fresh_each_client
SESSION_GAP_S = 2.0  # > the client's outage bound (0.5 s): an outage it rides through is no new session
SETTLE_TICKS = 500  # 5 s of robot time: any servo lag has gone by then


@dataclasses.dataclass
class FD11Faults:
    lose_request_every: int = 0  # request lost on the way: no tick, no reply
    drop_every: int = 0          # reply lost: tick happens, no reply
    drop_probability: float = 0.0  # reply lost at random (seeded by ``seed``)
    seed: int = 0
    delay_every: int = 0         # reply sent delay_s late
    delay_s: float = 0.0
    duplicate_every: int = 0     # reply sent twice
    outage_from: int = 0         # requests outage_from .. outage_from + outage_requests - 1
    outage_requests: int = 0     # are lost (an outage of that many requests)
    boot_requests: int = 0       # the first n valid requests are not seen (RT system booting)
    boot_s: float = 0.0          # nor any in the first boot_s seconds after start()
    release_after_ticks: int = 0  # dead-man switch released after this many ticks (0: never)
    release_after_moves: int = 0  # ... or after this many moving ticks (a new delta): hold
    #                               ticks (planning, laser reads) depend on the machine's speed

    def __post_init__(self):
        if not 0.0 <= self.drop_probability < 1.0:
            raise ValueError(f"drop_probability must be in [0, 1), got {self.drop_probability}")


@dataclasses.dataclass
class FD11EmulatorCounters:
    datagrams: int = 0   # everything received
    invalid: int = 0     # wrong size or negatives mismatch
    boot_ignored: int = 0  # valid requests not seen while booting
    sessions: int = 0    # client sessions begun
    fresh_references: int = 0  # of those, the ones that took the robot's counts as reference
    max_step: int = 0    # largest |delta - the delta held| a request asked for (trips included)
    ticks: int = 0       # backend.exchange calls for requests
    moves: int = 0       # of those, the ones commanding motion (a delta other than the last)
    settle_ticks: int = 0  # backend.exchange calls between sessions (robot settling)
    queued: int = 0      # reply datagrams decided on (duplicates included)
    replies: int = 0     # reply datagrams sent (``queued`` once the thread is idle)
    send_errors: int = 0  # reply datagrams the socket refused
    lost_requests: int = 0    # requests lost by fault injection (no tick, no reply)
    dropped_replies: int = 0  # replies dropped by fault injection (tick, no reply)
    ignored_tripped: int = 0
    released_ticks: int = 0   # requests answered with the switch released (no tick)
    released_steps: int = 0   # of those, the ones whose command moved (a new delta)
    max_released_gap: int = 0  # largest |commanded - current| seen while released


class FD11Emulator(Served):
    """FD11 RT server on UDP backed by ``backend`` (any RobotLink); see the module doc."""

    _thread_name = "fd11-emulator"

    def __init__(self, backend, host: str = "127.0.0.1", rt_port: int = 5555,
                 reply_port: int | None = 5556, *, faults: FD11Faults | None = None,
                 trip_counts: int = TRIP_STEP_COUNTS, trip_mode: str = "silent", lock=None,
                 reference_mode: str = "fresh_after_silence",
                 session_gap_s: float = SESSION_GAP_S, settle_ticks: int = SETTLE_TICKS):
        if trip_mode not in ("silent", "hold"):
            raise ValueError(f"trip_mode must be 'silent' or 'hold', got {trip_mode!r}")
        if reference_mode not in REFERENCE_MODES:
            raise ValueError(f"reference_mode must be one of {REFERENCE_MODES}, "
                             f"got {reference_mode!r}")
        if not session_gap_s > 0 or settle_ticks < 0:
            raise ValueError("session_gap_s must be > 0 and settle_ticks >= 0")
        self._init_served(FD11EmulatorCounters())
        self.backend = backend
        self.reply_port = reply_port
        self.faults = faults or FD11Faults()
        self.trip_counts = int(trip_counts)
        self.trip_mode = trip_mode
        self.reference_mode = reference_mode
        self.session_gap_s = float(session_gap_s)
        self.settle_ticks = int(settle_ticks)
        self.tripped = False
        self.trip_reason: str | None = None
        self.released = False
        self.last_delta = np.zeros(6, dtype=np.int64)  # last accepted, the clients' frame
        self._lock = lock if lock is not None else nullcontext()
        self._n_valid = 0
        self._peer = None            # the current session's client address
        self._last_t = None          # when its last valid request came
        self._offset = np.zeros(6, np.int64)  # reference - backend reference
        self._b_ref: np.ndarray | None = None  # backend's reference (from its first reply)
        self._b_cur: np.ndarray | None = None  # backend's current counts (last reply)
        self._b_delta = np.zeros(6, np.int64)  # last delta the backend was ticked with
        self._release_done = False
        self._held: list[np.ndarray] = []  # commands received while released (backend frame)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, rt_port))
        except OSError as e:
            self._sock.close()
            raise OSError(f"FD11 emulator: cannot bind UDP {host}:{rt_port} ({e})") from None
        self._sock.setblocking(False)

    @property
    def faults(self) -> FD11Faults:
        return self._faults

    @faults.setter
    def faults(self, faults: FD11Faults) -> None:
        """New faults; their random stream starts over from their seed."""
        self._faults = faults
        self._rng = np.random.default_rng(faults.seed)

    @property
    def host(self) -> str:
        return self._sock.getsockname()[0]

    @property
    def rt_port(self) -> int:
        """The UDP port requests are received on (useful when constructed with 0)."""
        return self._sock.getsockname()[1]

    @property
    def reference(self) -> np.ndarray | None:
        """The reference counts the emulated FD11 reports (None before the first tick)."""
        return None if self._b_ref is None else self._b_ref + self._offset

    def reset_trip(self) -> None:
        """Acknowledge an encoder-jump error; the next delta is measured from the last accepted."""
        with self._cv:
            self.tripped = False
            self.trip_reason = None

    def handle(self, data: bytes, addr) -> list[bytes]:
        """Process one datagram; return the reply datagrams to send (delays applied here)."""
        with self._cv:
            replies, delay = self._handle(data, addr)
            self._cv.notify_all()  # counters changed: wake `wait_until`
        if delay > 0:
            time.sleep(delay)
        return replies

    def _handle(self, data: bytes, addr) -> tuple[list[bytes], float]:
        c, f = self.counters, self.faults
        c.datagrams += 1
        try:
            delta = unpack_request(data)
        except ValueError:
            c.invalid += 1
            return [], 0.0
        now = time.monotonic()
        if (self._booting(now)):
            c.boot_ignored += 1
            return [], 0.0
        self._n_valid += 1
        n = self._n_valid
        drop = f.drop_probability > 0 and self._rng.random() < f.drop_probability
        if every(n, f.lose_request_every) or (
                f.outage_requests > 0 and f.outage_from <= n < f.outage_from + f.outage_requests):
            c.lost_requests += 1
            return [], 0.0
        silent = self._last_t is not None and now - self._last_t >= self.session_gap_s
        if self._peer is None or addr != self._peer or silent:
            self._begin_session(addr, fresh=(
                self._peer is not None and not self.tripped
                and (self.reference_mode == "fresh_after_silence" and silent
                     or self.reference_mode == "fresh_each_client" and addr != self._peer)))
        self._last_t = now
        if self.tripped and self.trip_mode == "silent":
            c.ignored_tripped += 1
            return [], 0.0
        step = np.abs(delta - self.last_delta)
        c.max_step = max(c.max_step, int(step.max()))
        if not self.tripped and np.any(step > self.trip_counts):
            j = int(np.argmax(step))
            self.tripped = True
            self.trip_reason = (f"encoder jump error: joint {j + 1} delta changed by "
                                f"{int(step[j])} counts (> {self.trip_counts}); brakes on")
            if self.trip_mode == "silent":
                return [], 0.0
        moving = not self.tripped and not np.array_equal(delta, self.last_delta)
        if not self.tripped:
            self.last_delta = delta
        b_delta = self.last_delta + self._offset
        if not self.released and not self._release_done and (
                (f.release_after_ticks > 0 and c.ticks >= f.release_after_ticks)
                or (f.release_after_moves > 0 and c.moves >= f.release_after_moves)):
            self.released = True
        if self.released:  # the servo is off: the command moves on, the robot does not
            moved = not np.array_equal(self._b_delta if not self._held else self._held[-1],
                                       b_delta)
            if moved:
                c.released_steps += 1
                if len(self._held) < SETTLE_TICKS * 20:
                    self._held.append(b_delta.copy())
            reference, current = self._b_ref + self._offset, self._b_cur.copy()
            gap = int(np.max(np.abs(self._b_ref + b_delta - current)))
            c.released_ticks += 1
            c.max_released_gap = max(c.max_released_gap, gap)
        else:
            if not self._tick(b_delta):
                return [], 0.0
            c.ticks += 1
            c.moves += moving
            reference, current = self._b_ref + self._offset, self._b_cur
        if drop or every(n, f.drop_every):
            c.dropped_replies += 1
            return [], 0.0
        reply = pack_reply(reference, current)
        delay = f.delay_s if every(n, f.delay_every) else 0.0
        replies = [reply, reply] if every(n, f.duplicate_every) else [reply]
        c.queued += len(replies)
        return replies, delay

    def _booting(self, now: float) -> bool:
        f = self.faults
        if self.counters.boot_ignored < f.boot_requests and self._n_valid == 0:
            return True
        return (f.boot_s > 0 and self._started_t is not None and self._n_valid == 0
                and now - self._started_t < f.boot_s)

    def _tick(self, b_delta: np.ndarray) -> bool:
        """One backend tick; False (and tripped) if the backend failed."""
        try:
            with self._lock:
                ref, cur = self.backend.exchange(b_delta.copy())
        except Exception as e:  # the backend failing is a fault of the robot
            self.tripped = True
            self.trip_reason = f"backend error: {type(e).__name__}: {e}"
            return False
        if self._b_ref is None:
            self._b_ref = np.asarray(ref, np.int64).copy()
        self._b_cur = np.asarray(cur, np.int64).copy()
        self._b_delta = b_delta.copy()
        return True

    def _begin_session(self, addr, fresh: bool) -> None:
        self.counters.sessions += 1
        if self._peer is not None:
            if self.released:  # the operator holds the switch again before a new session
                self.released = False
                self._release_done = True
            self._settle()
        self._peer = addr
        if fresh and self._b_ref is not None:
            # a new reference: the robot's counts; the delta it holds is 0
            self.counters.fresh_references += 1
            self._offset = self._b_cur - self._b_ref
            self.last_delta = np.zeros(6, np.int64)

    def _settle(self) -> None:
        """The robot held its last command while no client was there: tick the backend with
        it until the counts sit on it (at most ``settle_ticks``)."""
        if self._b_ref is None or self.tripped:
            return
        held, self._held = self._held, []
        for d in held:  # switch held again: the servo takes up the commands it missed
            if not self._tick(d):
                return
            self.counters.settle_ticks += 1
        commanded = self._b_ref + self._b_delta
        for _ in range(self.settle_ticks):
            if np.array_equal(self._b_cur, commanded):
                break
            if not self._tick(self._b_delta):
                return
            self.counters.settle_ticks += 1

    def _serve(self) -> None:
        while not self._stop.is_set():
            if not select.select([self._sock], [], [], POLL_S)[0]:
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
                except OSError:
                    self._count("send_errors")
                    continue
                self._count("replies")

    def _close(self) -> None:
        self._sock.close()


class Emulators:
    """Both emulators on one backend pair, sharing a lock; a context manager."""

    def __init__(self, robot, laser=None, *, host: str = "127.0.0.1", rt_port: int = 5555,
                 reply_port: int | None = 5556, fd11_faults: FD11Faults | None = None,
                 laser_faults: LaserFaults | None = None, trip_mode: str = "silent",
                 reference_mode: str = "fresh_after_silence",
                 session_gap_s: float = SESSION_GAP_S):
        self.lock = threading.Lock()
        self.fd11 = FD11Emulator(robot, host, rt_port, reply_port, faults=fd11_faults,
                                 trip_mode=trip_mode, lock=self.lock,
                                 reference_mode=reference_mode, session_gap_s=session_gap_s)
        try:
            self.laser = LaserEmulator(robot if laser is None else laser,
                                       faults=laser_faults, lock=self.lock)
        except Exception:
            self.fd11.stop()
            raise

    def describe(self) -> list[str]:
        reply = "the sender's port" if self.fd11.reply_port is None else f"port {self.fd11.reply_port}"
        mode = self.fd11.reference_mode + (f" {self.fd11.session_gap_s:g} s"
                                           if self.fd11.reference_mode == "fresh_after_silence"
                                           else "")
        return [f"FD11 RT emulator: UDP {self.fd11.host}:{self.fd11.rt_port} (replies to {reply}; "
                f"reference {mode})",
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
