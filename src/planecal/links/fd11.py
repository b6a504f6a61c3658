"""FD11 real-time link over UDP (seed 7.1.1 and appendix C): a `RobotLink`.

Wire format (appendix C; all little-endian, no header, no sequence number)
--------------------------------------------------------------------------
request, PC -> FD11 remote port (default 5555), 48 bytes, ``struct '<12i'``::

    int32 delta[0..5]        delta counts per joint (commanded = reference + delta)
    int32 -delta[0..5]       the same six values negated (a redundancy check)

reply, FD11 -> PC local port (default 5556), 48 bytes, ``struct '<12I'``::

    uint32 reference[0..5]   FD11 reference counts (see "Sessions" below)
    uint32 current[0..5]     current encoder counts

Example: delta = (1, -1, 0, 0, 0, 0x12345678) is sent as
``01000000 ffffffff 00000000 00000000 00000000 78563412`` followed by
``ffffffff 01000000 00000000 00000000 00000000 88a9cbed``.

Ticks, lost replies, outages
----------------------------
The RT system only answers after it has received a message ("send first"): every
`exchange` sends one request and waits for one reply; one request is one 10 ms tick.
`delta` is relative to the reference, not incremental, and the robot holds its last
command, so resending the same delta is idempotent. A tick whose reply does not come
within ``timeout_s`` (the resend interval, default 20 ms) resends the *same* packet, and
keeps doing so until a reply comes or the link has been silent for ``silence_s``
(default 0.5 s, measured from the tick's first packet): then `LinkError`. Every interval
that ended without a reply is one lost reply (``counters.lost_replies``; a request lost
on the way counts the same, the client cannot tell them apart). At 5 % loss, 3 lost in a
row happen about once per 8,000 ticks; 25 in a row (0.5 s) about never (0.05**25).
The first tick of a link (first contact) waits ``boot_timeout_s`` (default 10 s) instead:
an RT system that is still booting stays silent for seconds. With ``enable`` given, an
outage also ends (`LinkInterrupted`) as soon as ``enable.enabled()`` is False.

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

Sessions and the reference (appendix C, seed 7.1.1)
----------------------------------------------------
Whether the controller keeps its reference across client sessions or takes a fresh one
is a stated property of the cell (`planecal.links.sessions`); before its first exchange
the link is told, by `expect`, what the controller holds (a `Contact`: ``held``, the last
delta it received under a kept reference, or zero under a fresh one). The first packet
is ``held`` itself, and like every packet it is refused (`StepLimitError`, nothing sent)
when it is farther than ``max_step_counts`` from what the controller holds: the first
packet is checked like any other. The first reply is then checked before any motion:
``reference + held - current`` must be within ``contact_tolerance_counts`` (60, one trip
step) on every joint, and a kept reference must be the one recorded; otherwise
`ContactError` names both readings and nothing more is sent. No reply at all to the first
packet within the boot timeout names the other possibility (a trip on that packet).

The loop never sees ``held``: `exchange` takes and returns the loop's frame, whose
reference is the commanded position at first contact (``fd11_reference + held``) and
whose first delta is zero, as in the seed. On the wire, delta + ``held`` goes out. The
FD11's reference is checked to stay constant within a link; a change (controller
restarted, new reference) raises `LinkError`, since the deltas would then move the robot
elsewhere. With a `StateFile`, the link records the time just before every packet (and,
once the controller has answered the session, the packet's delta), and the delta,
reference and client address after every reply taken.

Counts are unpacked as uint32 and returned as int64 with the same value (0..2**32-1,
no sign reinterpretation); the MC70's 24-bit encoders stay far from the wrap. Use
`wrap_diff` to subtract counts modulo 2**32.

Safety
------
The FD11 trips (encoder-jump error, brakes) when the commanded position changes by more
than 60 counts per joint in one 10 ms cycle. `FD11Link.exchange` refuses -- raises
`StepLimitError` and sends nothing -- any delta whose change from the previously *sent*
delta (the controller's held delta before the first packet) exceeds ``max_step_counts``
(at most 60; ``planecal sample`` uses robot.json's step limit, 51)
on any joint, whatever the caller. It also never sends two ticks less than ``tick_s``
apart (resends of the same delta excepted), so a fast caller cannot multiply the rate.
This is the last line of defence, independent of the step generator (<= 51 counts).
"""
from __future__ import annotations

import dataclasses
import select
import socket
import struct
import time
from typing import TYPE_CHECKING

import numpy as np

from planecal.links.errors import ContactError, LinkError, LinkInterrupted, StepLimitError
from planecal.links.sessions import Contact, StateFile, client_address

if TYPE_CHECKING:
    from planecal.links.base import EnableSignal

REQUEST = struct.Struct("<12i")
REPLY = struct.Struct("<12I")
PACKET_BYTES = 48
N_JOINTS = 6
TRIP_STEP_COUNTS = 60  # FD11 encoder-jump limit per joint per 10 ms (seed 7.1.2)
INT32_MAX = 2**31 - 1
RESEND_S = 0.02        # default resend interval: two 10 ms ticks without a reply
SILENCE_S = 0.5        # default bound on an outage after first contact
BOOT_TIMEOUT_S = 10.0  # default bound on first contact (an RT system still booting)


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


# ----- the client ----------------------------------------------------------------------------

@dataclasses.dataclass
class LinkCounters:
    """What the link saw. ``sent = ticks + resends + boot_resends`` (+ a failed last tick's)."""
    sent: int = 0          # request datagrams sent (resends included)
    ticks: int = 0         # ticks answered (a valid reply taken as the answer)
    lost_replies: int = 0  # resend intervals after first contact that ended without a reply
    resends: int = 0       # packets re-sent after first contact (same delta)
    outages: int = 0       # ticks that needed at least one resend
    max_lost_in_a_row: int = 0     # the longest outage, in lost replies
    longest_outage_s: float = 0.0  # the longest such tick, first packet to reply
    boot_resends: int = 0          # packets re-sent before first contact (RT system booting)
    boot_wait_s: float = 0.0       # first packet to first reply
    dropped: int = 0       # datagrams ignored: wrong size or wrong sender
    stale: int = 0         # valid replies not taken as an answer (late or duplicate)
    refused: int = 0       # deltas refused by the step limit (nothing sent)
    late_ticks: int = 0    # ticks sent more than ``late_s`` after they were due (RT gaps)
    max_late_s: float = 0.0  # the latest tick, seconds after it was due


class FD11Link:
    """Client of the FD11 RT system over UDP; implements `RobotLink`. See the module doc.

    ``host``/``remote_port``: where requests go. ``local_port``: the port replies arrive
    on (requests are sent from it too; 0 = any free port, see `local_port`).
    ``bind_host``: local address to bind (default: loopback if ``host`` is loopback,
    else all interfaces). ``timeout_s``: the resend interval; ``silence_s``: the longest
    outage after first contact; ``boot_timeout_s``: the longest wait for first contact.
    ``tick_s``: minimum interval between ticks (0 for emulators on a virtual clock); a tick
    sent over ``late_s`` (default half a tick) after it was due is late (the loop's gaps).
    ``max_step_counts``: refusal threshold, 1..60, for every packet (the first measured
    from what the controller holds, `expect`). ``contact_tolerance_counts``: the first
    reply's largest |commanded - current|. ``enable``: an `EnableSignal` that ends an
    outage when it drops. Before the first exchange, `expect` says what the controller
    holds (default: delta 0, nothing recorded) and gives the `StateFile` to record in.
    """

    def __init__(self, host: str, remote_port: int = 5555, local_port: int = 5556, *,
                 timeout_s: float = RESEND_S, silence_s: float = SILENCE_S,
                 boot_timeout_s: float = BOOT_TIMEOUT_S, tick_s: float = 0.01,
                 max_step_counts: int = TRIP_STEP_COUNTS, bind_host: str | None = None,
                 contact_tolerance_counts: int = TRIP_STEP_COUNTS,
                 enable: EnableSignal | None = None, late_s: float | None = None):
        if not 1 <= int(max_step_counts) <= TRIP_STEP_COUNTS:
            raise ValueError(f"max_step_counts must be in 1..{TRIP_STEP_COUNTS} "
                             f"(the FD11 trips above {TRIP_STEP_COUNTS}), got {max_step_counts}")
        if not (timeout_s > 0 and silence_s >= timeout_s and boot_timeout_s >= timeout_s
                and tick_s >= 0 and contact_tolerance_counts >= 0):
            raise ValueError("FD11Link: need timeout_s > 0, silence_s and boot_timeout_s >= "
                             "timeout_s, tick_s >= 0, contact_tolerance_counts >= 0")
        self.max_step_counts = int(max_step_counts)
        self.timeout_s = float(timeout_s)
        self.silence_s = float(silence_s)
        self.boot_timeout_s = float(boot_timeout_s)
        self.tick_s = float(tick_s)
        self.late_s = 0.5 * self.tick_s if late_s is None else float(late_s)
        self.contact_tolerance_counts = int(contact_tolerance_counts)
        self.contact = Contact.either()
        self.state: StateFile | None = None
        self.enable = enable
        self.counters = LinkCounters()
        self.reference: np.ndarray | None = None       # the loop's frame, from the first reply
        self.fd11_reference: np.ndarray | None = None  # the FD11's, from the first reply
        self.last_sent = np.zeros(N_JOINTS, dtype=np.int64)  # loop frame; zero before the first
        self._last_tick_t: float | None = None
        self._owed = 0  # replies possibly still in flight for resent packets
        self._failed: str | None = None
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
        self.client = client_address(self.remote, self.local_port, bind_host)

    def expect(self, contact: Contact, state: StateFile | None = None) -> None:
        """What the controller holds at this link's first packet (`sessions.plan_contact`),
        and the state file to record in; only before the first exchange."""
        if self.fd11_reference is not None or self.counters.sent:
            raise RuntimeError("FD11Link.expect: the session has begun")
        _as_delta(contact.held)
        self.contact = contact
        self.state = state

    @property
    def start_delta(self) -> np.ndarray:
        """The first packet's wire delta: what the controller holds (`expect`)."""
        return self.contact.held.copy()

    @property
    def local_port(self) -> int:
        """The UDP port replies are received on (useful when constructed with 0)."""
        return self._sock.getsockname()[1]

    @property
    def where(self) -> str:
        return f"FD11 at {self.remote[0]}:{self.remote[1]}"

    # --- RobotLink -----------------------------------------------------------------
    def exchange(self, delta) -> tuple[np.ndarray, np.ndarray]:
        """One tick: send ``delta`` (int counts, shape (6,), the loop's frame), return
        (reference, current) in the loop's frame (module doc, "Sessions").

        Raises `StepLimitError` (nothing sent) if any joint's delta changes by more than
        ``max_step_counts`` from the previously sent delta; `LinkError` when the link has
        been silent for ``silence_s`` (``boot_timeout_s`` at first contact); `ContactError`
        when the first reply does not fit the first packet; `LinkInterrupted` when
        ``enable`` drops during an outage.
        """
        if self._failed is not None:
            raise LinkError(f"{self.where}: link unusable after an earlier error ({self._failed})")
        d = _as_delta(delta)
        held = self.contact.held
        first = self.fd11_reference is None
        step = np.abs(d - self.last_sent)
        if np.any(step > self.max_step_counts):
            self.counters.refused += 1
            j = int(np.argmax(step))
            raise StepLimitError(
                f"FD11 delta refused: joint {j + 1} changes by {int(step[j])} counts "
                f"(limit {self.max_step_counts}) from {(self.last_sent + held).tolist()} to "
                f"{(d + held).tolist()}" + (
                    f" (the first packet, measured from what the controller holds: "
                    f"{self.contact.describe()}); nothing sent" if first and not self.counters.sent
                    else "; nothing sent"))
        wire = _as_delta(d + held)
        packet = pack_request(wire)
        self._settle()
        self._pace()
        self._drain()
        t0 = time.monotonic()
        self._note_lateness(t0)
        bound = self.boot_timeout_s if first else self.silence_s
        self._send(packet, wire)
        self.last_sent = d
        self._last_tick_t = t0
        lost = 0
        while True:
            left = t0 + bound - time.monotonic()
            reply = self._wait_reply(min(self.timeout_s, left)) if left > 0 else None
            if reply is not None:
                reply = self._freshest(reply)
                self._owed = lost  # extra packets whose replies may still come
                self._note_tick(first, lost, time.monotonic() - t0)
                answer = self._accept(reply)
                if self.state is not None:
                    self.state.answered(wire, self.fd11_reference, self.client)
                return answer
            lost += 1
            if not first:
                self.counters.lost_replies += 1
            if time.monotonic() - t0 >= bound:
                self._owed = lost
                raise LinkError(self._silent_message(first, wire, lost, bound))
            if self.enable is not None and not self.enable.enabled():
                self._owed = lost
                raise LinkInterrupted(f"{self.where}: enable dropped during an outage "
                                      f"({lost} replies lost); nothing more sent")
            self._send(packet, wire)
            if first:
                self.counters.boot_resends += 1
            else:
                self.counters.resends += 1

    def collect_late(self, n: int, timeout_s: float) -> int:
        """Wait up to ``timeout_s`` for ``n`` more valid datagrams (late replies or
        duplicates still in flight) and count them stale; returns how many came. Nothing
        is sent. (Tests use it to account for every reply a peer sent.)"""
        got = 0
        deadline = time.monotonic() + timeout_s
        while got < n:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._sock], [], [], left)[0]:
                break
            try:
                data = self._recv_valid()
            except BlockingIOError:
                continue
            if data is not None:
                self.counters.stale += 1
                got += 1
        return got

    def handshake(self) -> tuple[np.ndarray, np.ndarray]:
        """The seed's first message: delta zero (the loop's frame); returns (reference, current)."""
        return self.exchange(np.zeros(N_JOINTS, dtype=np.int64))

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> "FD11Link":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- internals -----------------------------------------------------------------
    def _silent_message(self, first: bool, wire: np.ndarray, lost: int, bound: float) -> str:
        if first:
            return (f"{self.where}: no reply to the first packet (delta {wire.tolist()}) within "
                    f"the boot timeout of {bound:g} s ({lost} packets): the RT system is not "
                    f"running, or it tripped on this packet (it assumed {self.contact.describe()}; "
                    f"a controller that does not behave so trips on it: check the teach "
                    f"pendant and the cell's statement, robot.json controller.sessions)")
        return (f"{self.where}: no reply for {bound:g} s ({lost} packets of delta "
                f"{wire.tolist()} unanswered); the robot holds its last command")

    def _note_lateness(self, t0: float) -> None:  # due: the last tick's first packet + tick_s
        if self.tick_s > 0 and self._last_tick_t is not None:
            late = t0 - (self._last_tick_t + self.tick_s)
            if late > self.late_s:
                self.counters.late_ticks += 1
            self.counters.max_late_s = max(self.counters.max_late_s, round(late, 6))

    def _note_tick(self, first: bool, lost: int, dt: float) -> None:
        c = self.counters
        if first:
            c.boot_wait_s = round(dt, 6)
        elif lost:
            c.outages += 1
            c.max_lost_in_a_row = max(c.max_lost_in_a_row, lost)
            c.longest_outage_s = max(c.longest_outage_s, round(dt, 6))

    def _send(self, packet: bytes, wire: np.ndarray) -> None:
        if self.state is not None:  # the time first: a kill can only shorten the silence
            self.state.sending(None if self.fd11_reference is None else wire)
        try:
            self._sock.sendto(packet, self.remote)
        except ConnectionRefusedError:  # ICMP "port unreachable" for an earlier packet:
            pass                        # nobody listens (yet); the next interval resends
        except OSError as e:
            raise LinkError(f"{self.where}: send failed ({e})") from None
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
                reply = data

    def _settle(self) -> None:
        """After resends, collect (as stale) up to the replies still owed, for <= timeout_s."""
        if self._owed > 0:
            self.collect_late(self._owed, self.timeout_s)
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
        fd11_ref, current = unpack_reply(data)
        self.counters.ticks += 1  # answered, whether the answer is then accepted or not
        if self.fd11_reference is None:
            self._check_first(fd11_ref, current)
            self.fd11_reference = fd11_ref.copy()
            self.reference = fd11_ref + self.contact.held
        elif not np.array_equal(fd11_ref, self.fd11_reference):
            self._failed = "the reference changed"
            raise LinkError(f"{self.where}: reference counts changed from "
                            f"{self.fd11_reference.tolist()} to {fd11_ref.tolist()}: controller "
                            f"restarted? refusing to go on")
        return self.reference.copy(), current

    def _check_first(self, fd11_ref: np.ndarray, current: np.ndarray) -> None:
        """The first reply against the contact: a kept reference is the one recorded, and
        the first packet commands where the robot is (module doc); else `ContactError`."""
        c = self.contact
        if c.reference is not None and not np.array_equal(fd11_ref, c.reference):
            self._failed = "the first reply's reference is not the kept one"
            raise ContactError(
                f"{self.where}: the first reply's reference {fd11_ref.tolist()} is not the "
                f"{c.reference.tolist()} the controller was stated to keep ({c.why}): it took "
                f"a new reference (RT system restarted, or it does not keep it); nothing more "
                f"sent (--rt-fresh if the controller took a fresh reference)")
        gap = wrap_diff(fd11_ref + c.held, current)
        worst = int(np.argmax(np.abs(gap)))
        if abs(int(gap[worst])) > self.contact_tolerance_counts:
            self._failed = "the first reply did not fit the first packet"
            raise ContactError(
                f"{self.where}: the first reply does not fit the first packet (delta "
                f"{c.held.tolist()}, {c.describe()}): commanded - current = {gap.tolist()} "
                f"counts (joint {worst + 1}: {int(gap[worst])}, tolerance "
                f"{self.contact_tolerance_counts}): the controller is not where that says "
                f"(robot moved since, another client, or the wrong statement?); nothing more "
                f"sent")
