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
`LaserError`; no complete reply within ``timeout_s`` raises `LaserTimeout` (a
`LaserError`). The caller counts them; `ZSLD80.counters` counts them too. Bytes
already waiting before a request (a late reply to an earlier one) are discarded and
counted in ``stale_bytes``. mm appear only here, at the sensor edge.
"""
from __future__ import annotations

import dataclasses
import re

import serial

FIELD_WIDTH = 12
CENTRE_MM = 80.0
RAW_TO_MM = 1e-6


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
    timeouts: int = 0
    stale_bytes: int = 0


class ZSLD80:
    """ZS-LD80 on a serial port (pyserial); implements `Laser`.

    ``port``: device name (e.g. /dev/ttyUSB0, or a pty's slave name). ``timeout_s``:
    wait for one complete reply. ``command``/``terminator``: request is command +
    terminator, reply ends with terminator. ``baudrate`` etc. are passed to pyserial
    (ignored on a pty).
    """

    def __init__(self, port: str, *, timeout_s: float = 0.1, baudrate: int = 38400,
                 command: bytes = b"M", terminator: bytes = b"\r",
                 field_width: int = FIELD_WIDTH, **serial_kwargs):
        if not terminator:
            raise ValueError("ZS-LD80 terminator must not be empty")
        self.port = port
        self.timeout_s = float(timeout_s)
        self.request = bytes(command) + bytes(terminator)
        self.terminator = bytes(terminator)
        self.field_width = int(field_width)
        self.counters = LaserCounters()
        try:
            self._ser = serial.Serial(port, baudrate=baudrate, timeout=self.timeout_s,
                                      write_timeout=self.timeout_s, **serial_kwargs)
        except (serial.SerialException, OSError) as e:
            raise LaserError(f"ZS-LD80: cannot open serial port {port} ({e})") from None

    def read(self) -> float | None:
        """One reading in mm; None when out of range. Raises LaserError / LaserTimeout."""
        self.counters.requests += 1
        try:
            waiting = self._ser.in_waiting
            if waiting:
                self.counters.stale_bytes += len(self._ser.read(waiting))
            self._ser.write(self.request)
            self._ser.flush()
            frame = self._ser.read_until(self.terminator,
                                         size=self.field_width + len(self.terminator) + 16)
        except (serial.SerialException, OSError) as e:
            self.counters.malformed += 1
            raise LaserError(f"ZS-LD80 on {self.port}: serial error ({e})") from None
        if not frame.endswith(self.terminator) and len(frame) <= self.field_width:
            self.counters.timeouts += 1
            got = f"only {frame!r}" if frame else "nothing"
            raise LaserTimeout(f"ZS-LD80 on {self.port}: no complete reply within "
                               f"{self.timeout_s:g} s (got {got})")
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

    def close(self) -> None:
        self._ser.close()

    def __enter__(self) -> "ZSLD80":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
