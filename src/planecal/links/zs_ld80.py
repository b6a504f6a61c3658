"""Omron ZS-LD80 laser over a serial port (seed 7.1.3): a `Laser`.

The seed only says: the PC sends the string "M", the sensor answers with a "12 byte
count" that decodes as ``mm = raw * 1e-6 + 80``, and raw 0 means out of range.

Framing (the project's interpretation of the seed)
--------------------------------------------------
request::   b"M" + terminator          terminator configurable, default b"\\r"
reply::     <sign><11 digits> b"\\r"     13 bytes, e.g. b"+00012345678\\r"

The reply field is ``field_width`` (default 12) ASCII characters: a mandatory sign
``+`` or ``-`` then decimal digits, nothing else (no spaces, no decimal point). raw is
that signed integer in 1e-6 mm (nm) from the 80 mm measuring centre:
``+00012345678`` -> 80 + 12.345678 = 92.345678 mm; ``-00001500000`` -> 78.5 mm;
``+00000000000`` -> out of range -> ``None``. (Then a true reading of exactly
80.000000 mm is indistinguishable from out of range, as on the real sensor.)

The decoder is strict: any other length, character or a missing terminator raises
`LaserError`. mm appear only here, at the sensor edge.

Two ways to read (`ZSLD80`)
---------------------------
``read()``: request, then wait up to ``timeout_s`` (0.1 s) for the reply; `LaserTimeout`
when none comes. It blocks: not for the sampling loop, whose RT link must tick every
10 ms.

``poll()``: the sampling loop's read, once per 10 ms tick; it never blocks longer than
``wait_s`` (5 ms, half a tick: the link's pacing absorbs it). If a request is pending it
takes its reply when complete; otherwise it sends a request and waits up to ``wait_s``
for the reply. It returns the reading (mm), ``None`` (the sensor's 0: out of range), or
``NO_READING`` when no reply has come yet -- not a measurement, and not out of range: the
request stays pending and a later poll takes its reply. A request pending longer than
``timeout_s`` raises `LaserTimeout` once (counted in ``timeouts``) and is given up. When
polls were more than ``max_age_s`` (50 ms, five ticks) apart, the pending request was
made at another robot position (the loop moved in between): it is given up quietly
(``expired``) and a new request sent. One request at a time, never two in flight, so a
reading answers the request made at the position the loop is polling at. Bytes already
waiting before a request (a reply to a given-up request) are discarded and counted in
``stale_bytes``.

How the loop should treat NO_READING: skip the tick -- store nothing in the stability
buffer, do not count it as out of range (400 of those in a row give a pose up; a slow
sensor is not a plate out of reach), but do count it against the reads budget
(``max_reads``), so a silent sensor still ends the laser read. A sensor that stays silent
raises `LaserTimeout` every ``timeout_s``; the caller's error limit then stops the run.
"""
from __future__ import annotations

import dataclasses
import enum
import re
import select
import time

import serial

FIELD_WIDTH = 12
CENTRE_MM = 80.0
RAW_TO_MM = 1e-6


class NoReading(enum.Enum):
    """`ZSLD80.poll` had no reply to hand over this tick (not a measurement)."""
    THIS_TICK = "no reading this tick"


NO_READING = NoReading.THIS_TICK


class LaserError(RuntimeError):
    """A laser reading failed (malformed reply, serial error). One-line message."""


class LaserTimeout(LaserError):
    """No complete reply within the timeout."""


def _field_re(width: int) -> re.Pattern:
    return re.compile(rb"[+-][0-9]{%d}" % (width - 1))


def decode_reply(frame: bytes, *, terminator: bytes = b"\r",
                 field_width: int = FIELD_WIDTH) -> float | None:
    """One reply (field + terminator) -> mm, or None for out of range; LaserError if malformed."""
    if not frame.endswith(terminator) or len(frame) != field_width + len(terminator):
        raise LaserError(f"ZS-LD80 reply {frame!r} malformed: expected sign + "
                         f"{field_width - 1} digits + {terminator!r}")
    field = frame[:field_width]
    if not _field_re(field_width).fullmatch(field):
        raise LaserError(f"ZS-LD80 reply {frame!r} malformed: expected sign + "
                         f"{field_width - 1} digits + {terminator!r}")
    raw = int(field)
    return None if raw == 0 else raw * RAW_TO_MM + CENTRE_MM


def encode_reply(mm: float | None, *, terminator: bytes = b"\r",
                 field_width: int = FIELD_WIDTH) -> bytes:
    """mm (None = out of range) -> reply frame; readings that do not fit become raw 0."""
    raw = 0 if mm is None else int(round((float(mm) - CENTRE_MM) / RAW_TO_MM))
    if abs(raw) >= 10 ** (field_width - 1):
        raw = 0
    sign = b"-" if raw < 0 else b"+"
    return sign + str(abs(raw)).encode().rjust(field_width - 1, b"0") + terminator


@dataclasses.dataclass
class LaserCounters:
    requests: int = 0
    readings: int = 0       # in-range readings returned
    out_of_range: int = 0   # raw 0 -> None
    malformed: int = 0      # LaserError other than timeout
    timeouts: int = 0       # requests given up after timeout_s (LaserTimeout raised)
    pending_ticks: int = 0  # polls that returned NO_READING
    expired: int = 0        # pending requests older than max_age_s, given up quietly
    stale_bytes: int = 0


class ZSLD80:
    """ZS-LD80 on a serial port (pyserial); implements `Laser` (``read``) and the sampling
    loop's per-tick ``poll`` (module doc).

    ``port``: device name (e.g. /dev/ttyUSB0, or a pty's slave name). ``timeout_s``: the
    longest wait for one reply. ``wait_s``: the longest a ``poll`` waits. ``max_age_s``:
    the oldest pending request whose reply ``poll`` still takes. ``command``/``terminator``:
    request is command + terminator, reply ends with terminator. ``baudrate`` etc. are
    passed to pyserial (ignored on a pty). ``clock``: monotonic seconds (tests).
    """

    def __init__(self, port: str, *, timeout_s: float = 0.1, wait_s: float = 0.005,
                 max_age_s: float = 0.05, baudrate: int = 38400, command: bytes = b"M",
                 terminator: bytes = b"\r", field_width: int = FIELD_WIDTH,
                 clock=time.monotonic, **serial_kwargs):
        if not terminator:
            raise ValueError("ZS-LD80 terminator must not be empty")
        if not (timeout_s > 0 and 0 <= wait_s <= timeout_s and max_age_s > 0):
            raise ValueError("ZS-LD80: need timeout_s > 0, 0 <= wait_s <= timeout_s, max_age_s > 0")
        self.port = port
        self.timeout_s = float(timeout_s)
        self.wait_s = float(wait_s)
        self.max_age_s = float(max_age_s)
        self.request = bytes(command) + bytes(terminator)
        self.terminator = bytes(terminator)
        self.field_width = int(field_width)
        self.counters = LaserCounters()
        self._clock = clock
        self._frame_max = self.field_width + len(self.terminator) + 16
        self._buf = b""
        self._asked: float | None = None  # when the pending request was sent
        self._polled: float | None = None  # when poll last ran
        try:
            # timeout=0: reads return what is there; this class does its own waiting
            self._ser = serial.Serial(port, baudrate=baudrate, timeout=0,
                                      write_timeout=self.timeout_s, **serial_kwargs)
        except (serial.SerialException, OSError) as e:
            raise LaserError(f"ZS-LD80: cannot open serial port {port} ({e})") from None

    # --- reading ---------------------------------------------------------------------------
    def read(self) -> float | None:
        """One reading in mm; None when out of range. Blocks up to ``timeout_s``.
        Raises LaserError / LaserTimeout."""
        self._ask()
        frame = self._collect(self.timeout_s)
        if frame is None:
            self._give_up()
        return self._decode(frame)

    def poll(self) -> float | None | NoReading:
        """The per-tick read (module doc): a reading, None (out of range) or NO_READING;
        waits at most ``wait_s``. Raises LaserTimeout when a request has been pending for
        ``timeout_s``, LaserError on a malformed reply or a serial error."""
        now = self._clock()
        last, self._polled = self._polled, now
        if self._asked is not None and last is not None and now - last > self.max_age_s:
            self.counters.expired += 1  # asked before the robot moved on: not this position
            self._asked = None
        if self._asked is None:
            self._ask()
        else:
            age = now - self._asked
            frame = self._collect(0.0)
            if frame is not None:
                return self._decode(frame)
            if age >= self.timeout_s:
                self._give_up()
        frame = self._collect(min(self.wait_s, self._asked + self.timeout_s - self._clock()))
        if frame is not None:
            return self._decode(frame)
        self.counters.pending_ticks += 1
        return NO_READING

    # --- internals -------------------------------------------------------------------------
    def _ask(self) -> None:
        self.counters.requests += 1
        try:
            waiting = self._ser.in_waiting
            if waiting:
                self.counters.stale_bytes += len(self._ser.read(waiting))
            self.counters.stale_bytes += len(self._buf)
            self._buf = b""
            self._ser.write(self.request)
            self._ser.flush()
        except (serial.SerialException, OSError) as e:
            self.counters.malformed += 1
            raise LaserError(f"ZS-LD80 on {self.port}: serial error ({e})") from None
        self._asked = self._clock()

    def _collect(self, wait_s: float) -> bytes | None:
        """Take in what has arrived, waiting up to ``wait_s`` for a complete frame (the
        terminator, or more bytes than any frame has); None when there is none yet."""
        deadline = time.monotonic() + max(0.0, wait_s)
        try:
            while True:
                waiting = self._ser.in_waiting
                if waiting:
                    self._buf += self._ser.read(waiting)
                if self.terminator in self._buf or len(self._buf) >= self._frame_max:
                    frame, sep, rest = self._buf.partition(self.terminator)
                    frame += sep
                    self._buf = rest
                    self._asked = None
                    return frame
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                select.select([self._ser.fileno()], [], [], left)
        except (serial.SerialException, OSError) as e:
            self.counters.malformed += 1
            self._asked = None
            raise LaserError(f"ZS-LD80 on {self.port}: serial error ({e})") from None

    def _give_up(self) -> None:
        self.counters.timeouts += 1
        self._asked = None
        got = f"only {self._buf!r}" if self._buf else "nothing"
        raise LaserTimeout(f"ZS-LD80 on {self.port}: no complete reply within "
                           f"{self.timeout_s:g} s (got {got})")

    def _decode(self, frame: bytes) -> float | None:
        try:
            mm = decode_reply(frame, terminator=self.terminator, field_width=self.field_width)
        except LaserError as e:
            self.counters.malformed += 1
            raise LaserError(f"ZS-LD80 on {self.port}: {str(e).removeprefix('ZS-LD80 ')}") from None
        if mm is None:
            self.counters.out_of_range += 1
        else:
            self.counters.readings += 1
        return mm

    def fileno(self) -> int:
        """The serial port's file descriptor (for ``select``: readable when bytes came)."""
        return self._ser.fileno()

    def close(self) -> None:
        self._ser.close()

    def __enter__(self) -> "ZSLD80":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
