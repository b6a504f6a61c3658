"""FD11 real-time link over UDP (seed 7.1.1 and appendix C): a `RobotLink`.

Wire format (appendix C; all little-endian, no header, no sequence number)
--------------------------------------------------------------------------
request, PC -> FD11 remote port (default 5555), 48 bytes, ``struct '<12i'``::

    int32 delta[0..5]        delta counts per joint (commanded = reference + delta)
    int32 -delta[0..5]       the same six values negated (a redundancy check)

reply, FD11 -> PC local port (default 5556), 48 bytes, ``struct '<12I'``::

    uint32 reference[0..5]   FD11 reference counts: the robot's counts when the RT
                             application started; constant while it runs
    uint32 current[0..5]     current encoder counts

Example: delta = (1, -1, 0, 0, 0, 0x12345678) is sent as
``01000000 ffffffff 00000000 00000000 00000000 78563412`` followed by
``ffffffff 01000000 00000000 00000000 00000000 88a9cbed``.

Protocol
--------
The RT system only answers after it has received a message ("send first"): every
`exchange` sends one request and waits for one reply; one request is one 10 ms tick.
`delta` is relative to the fixed reference, not incremental, so resending the same
delta is idempotent: on a timeout the *same* packet is resent (at most ``retries``
times, ``timeout_s`` each), then `LinkError` is raised.

Replies carry no sequence number, so they cannot be matched to their request. The
client therefore (a) drops every datagram that is not exactly 48 bytes or does not come
from the FD11's address (counted in ``dropped``), (b) drains every datagram already
queued before it sends (counted in ``stale``), (c) when a reply arrives, also takes any
further replies already queued and keeps the last (UDP on one path arrives in order, so
the last is the freshest), and (d) after a tick that needed resends, waits up to
``timeout_s`` for the replies still owed to the extra packets before it sends the next
delta. A reply later than that (or a duplicated datagram) can still be taken as the
answer to the next request: the values are then a tick or so old -- always the answer
to a delta already sent, never from a different reference.
The reference is checked to stay constant; a change (controller restarted, new
reference) raises `LinkError`, since the deltas would then move the robot elsewhere.

Counts are unpacked as uint32 and returned as int64 with the same value (0..2**32-1,
no sign reinterpretation); the MC70's 24-bit encoders stay far from the wrap. Use
`wrap_diff` to subtract counts modulo 2**32.

Safety
------
The FD11 trips (encoder-jump error, brakes) when the commanded position changes by more
than 60 counts per joint in one 10 ms cycle. `FD11Link.exchange` refuses -- raises
`StepLimitError` and sends nothing -- any delta whose change from the previously *sent*
delta (zero before the first packet) exceeds ``max_step_counts`` (at most 60) on any
joint, whatever the caller. It also never sends two ticks less than ``tick_s`` apart
(resends of the same delta excepted), so a fast caller cannot multiply the rate.
This is the last line of defence, independent of the step generator (<= 51 counts).
"""
from __future__ import annotations

import dataclasses
import select
import socket
import struct
import time

import numpy as np

REQUEST = struct.Struct("<12i")
REPLY = struct.Struct("<12I")
PACKET_BYTES = 48
N_JOINTS = 6
TRIP_STEP_COUNTS = 60  # FD11 encoder-jump limit per joint per 10 ms (seed 7.1.2)
INT32_MAX = 2**31 - 1


class LinkError(RuntimeError):
    """The FD11 link failed (no reply, reference changed, socket error). One-line message."""


class StepLimitError(LinkError):
    """A delta was refused because it changes too much from the previous one; nothing sent."""


def pack_request(delta) -> bytes:
    """48-byte request: six int32 LE deltas then their six negatives."""
    d = _as_delta(delta)
    return REQUEST.pack(*d.tolist(), *(-d).tolist())


def unpack_request(data: bytes) -> np.ndarray:
    """Parse a request; raises ValueError unless 48 bytes whose second half negates the first."""
    if len(data) != PACKET_BYTES:
        raise ValueError(f"FD11 request is {len(data)} bytes, expected {PACKET_BYTES}")
    v = REQUEST.unpack(data)
    d, neg = v[:N_JOINTS], v[N_JOINTS:]
    if any(a != -b for a, b in zip(d, neg)):
        raise ValueError(f"FD11 request negatives do not match deltas: {list(d)} vs {list(neg)}")
    return np.array(d, dtype=np.int64)


def pack_reply(reference, current) -> bytes:
    """48-byte reply: six uint32 LE reference counts then six current counts (mod 2**32)."""
    r = np.asarray(reference, dtype=np.int64).reshape(N_JOINTS) & 0xFFFFFFFF
    c = np.asarray(current, dtype=np.int64).reshape(N_JOINTS) & 0xFFFFFFFF
    return REPLY.pack(*r.tolist(), *c.tolist())


def unpack_reply(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Parse a 48-byte reply into (reference, current), int64 with the uint32 values."""
    if len(data) != PACKET_BYTES:
        raise ValueError(f"FD11 reply is {len(data)} bytes, expected {PACKET_BYTES}")
    v = np.array(REPLY.unpack(data), dtype=np.int64)
    return v[:N_JOINTS].copy(), v[N_JOINTS:].copy()


def wrap_diff(a, b) -> np.ndarray:
    """a - b for uint32 counts, wrap-safe: the result is in [-2**31, 2**31)."""
    d = (np.asarray(a, dtype=np.int64) - np.asarray(b, dtype=np.int64)) & 0xFFFFFFFF
    return np.where(d >= 2**31, d - 2**32, d)


def _as_delta(delta) -> np.ndarray:
    a = np.asarray(delta)
    if a.shape != (N_JOINTS,):
        raise ValueError(f"FD11 delta must have shape (6,), got {a.shape}")
    if not np.issubdtype(a.dtype, np.integer):
        if not (np.issubdtype(a.dtype, np.floating) and np.all(np.isfinite(a))
                and np.all(a == np.round(a))):
            raise ValueError(f"FD11 delta must be integer counts, got {a.tolist()}")
    d = a.astype(np.int64)
    if np.any(np.abs(d) > INT32_MAX):
        raise ValueError(f"FD11 delta outside int32 (+-{INT32_MAX}): {d.tolist()}")
    return d


@dataclasses.dataclass
class LinkCounters:
    sent: int = 0       # request datagrams sent (resends included)
    received: int = 0   # valid replies accepted as the answer to a tick
    timeouts: int = 0   # waits of timeout_s that ended without a valid reply
    dropped: int = 0    # datagrams ignored: wrong size or wrong sender
    stale: int = 0      # valid replies drained before a send (late or duplicate)
    refused: int = 0    # deltas refused by the step limit (nothing sent)


class FD11Link:
    """Client of the FD11 RT system over UDP; implements `RobotLink`.

    ``host``/``remote_port``: where requests go. ``local_port``: the port replies arrive
    on (requests are sent from it too; 0 = any free port, see `local_port`).
    ``bind_host``: local address to bind (default: loopback if ``host`` is loopback,
    else all interfaces). ``timeout_s``: wait for one reply; ``retries``: resends of the
    same delta before `LinkError`. ``tick_s``: minimum interval between ticks (0 for
    emulators on a virtual clock). ``max_step_counts``: refusal threshold, 1..60.
    """

    def __init__(self, host: str, remote_port: int = 5555, local_port: int = 5556, *,
                 timeout_s: float = 0.05, retries: int = 2, tick_s: float = 0.01,
                 max_step_counts: int = TRIP_STEP_COUNTS, bind_host: str | None = None):
        if not 1 <= int(max_step_counts) <= TRIP_STEP_COUNTS:
            raise ValueError(f"max_step_counts must be in 1..{TRIP_STEP_COUNTS} "
                             f"(the FD11 trips above {TRIP_STEP_COUNTS}), got {max_step_counts}")
        if timeout_s <= 0 or retries < 0 or tick_s < 0:
            raise ValueError("FD11Link: timeout_s must be > 0, retries >= 0, tick_s >= 0")
        self.max_step_counts = int(max_step_counts)
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.tick_s = float(tick_s)
        self.counters = LinkCounters()
        self.reference: np.ndarray | None = None  # from the first reply
        self.last_sent = np.zeros(N_JOINTS, dtype=np.int64)  # zero before the first packet
        self._last_tick_t: float | None = None
        self._owed = 0  # replies possibly still in flight for resent packets
        try:
            infos = socket.getaddrinfo(host, remote_port, socket.AF_INET, socket.SOCK_DGRAM)
        except OSError as e:
            raise LinkError(f"FD11 host {host!r}: cannot resolve ({e})") from None
        self.remote = infos[0][4]
        if bind_host is None:
            bind_host = "127.0.0.1" if self.remote[0].startswith("127.") else "0.0.0.0"
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((bind_host, local_port))
        except OSError as e:
            self._sock.close()
            raise LinkError(f"FD11 link: cannot bind UDP {bind_host}:{local_port} ({e})") from None
        self._sock.setblocking(False)

    @property
    def local_port(self) -> int:
        """The UDP port replies are received on (useful when constructed with 0)."""
        return self._sock.getsockname()[1]

    # --- RobotLink -----------------------------------------------------------------
    def exchange(self, delta) -> tuple[np.ndarray, np.ndarray]:
        """One tick: send ``delta`` (int counts, shape (6,)), return (reference, current).

        Raises `StepLimitError` (nothing sent) if any joint's delta changes by more than
        ``max_step_counts`` from the previously sent delta, `LinkError` on no reply.
        """
        d = _as_delta(delta)
        step = np.abs(d - self.last_sent)
        if np.any(step > self.max_step_counts):
            self.counters.refused += 1
            j = int(np.argmax(step))
            raise StepLimitError(
                f"FD11 delta refused: joint {j + 1} changes by {int(step[j])} counts "
                f"(limit {self.max_step_counts}) from {self.last_sent.tolist()} to {d.tolist()}")
        packet = pack_request(d)
        self._settle()
        self._pace()
        self._drain()
        for attempt in range(self.retries + 1):
            self._send(packet)
            if attempt == 0:
                self.last_sent = d
                self._last_tick_t = time.monotonic()
            reply = self._wait_reply(self.timeout_s)
            if reply is not None:
                reply = self._freshest(reply)
                self._owed = attempt  # extra packets whose replies may still come
                return self._accept(reply)
            self.counters.timeouts += 1
        self._owed = self.retries
        raise LinkError(f"FD11 at {self.remote[0]}:{self.remote[1]}: no reply after "
                        f"{self.retries + 1} attempts of {self.timeout_s:g} s")

    def handshake(self) -> tuple[np.ndarray, np.ndarray]:
        """The seed's first message: delta zero; returns (reference, current)."""
        return self.exchange(np.zeros(N_JOINTS, dtype=np.int64))

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> "FD11Link":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- internals -----------------------------------------------------------------
    def _send(self, packet: bytes) -> None:
        try:
            self._sock.sendto(packet, self.remote)
        except OSError as e:
            raise LinkError(f"FD11 at {self.remote[0]}:{self.remote[1]}: send failed ({e})") from None
        self.counters.sent += 1

    def _pace(self) -> None:
        if self.tick_s > 0 and self._last_tick_t is not None:
            wait = self._last_tick_t + self.tick_s - time.monotonic()
            if wait > 0:
                time.sleep(wait)

    def _recv_valid(self) -> bytes | None:
        """One queued datagram if valid, None if it was dropped; raises BlockingIOError if none."""
        try:
            data, addr = self._sock.recvfrom(4096)
        except ConnectionRefusedError:  # ICMP port unreachable from an earlier send
            return None
        if len(data) != PACKET_BYTES or addr[0] != self.remote[0]:
            self.counters.dropped += 1
            return None
        return data

    def _drain(self) -> None:
        while True:
            try:
                data = self._recv_valid()
            except BlockingIOError:
                return
            if data is not None:
                self.counters.stale += 1

    def _freshest(self, reply: bytes) -> bytes:
        """Replies arrive in order: if more are already queued, the last one is the freshest."""
        while True:
            try:
                data = self._recv_valid()
            except BlockingIOError:
                return reply
            if data is not None:
                self.counters.stale += 1
                self._owed = max(0, self._owed - 1)
                reply = data

    def _settle(self) -> None:
        """After resends, collect (as stale) up to the replies still owed, for <= timeout_s."""
        deadline = time.monotonic() + self.timeout_s
        while self._owed > 0:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._sock], [], [], left)[0]:
                break
            try:
                data = self._recv_valid()
            except BlockingIOError:
                continue
            if data is not None:
                self.counters.stale += 1
                self._owed -= 1
        self._owed = 0

    def _wait_reply(self, timeout_s: float) -> bytes | None:
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            if not select.select([self._sock], [], [], left)[0]:
                return None
            try:
                data = self._recv_valid()
            except BlockingIOError:
                continue
            if data is not None:
                return data

    def _accept(self, data: bytes) -> tuple[np.ndarray, np.ndarray]:
        reference, current = unpack_reply(data)
        if self.reference is None:
            self.reference = reference.copy()
        elif not np.array_equal(reference, self.reference):
            raise LinkError(f"FD11 reference counts changed from {self.reference.tolist()} to "
                            f"{reference.tolist()}: controller restarted? refusing to go on")
        self.counters.received += 1
        return reference, current
