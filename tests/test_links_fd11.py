"""FD11 RT link over real loopback UDP: wire format, client safety, emulator behaviour.

No outcome here depends on the machine's load: a reply is awaited for seconds (``T``)
unless a test is about a timeout, and where a test injects losses with a short timeout its
counts are checked by the link's bookkeeping, which a late reply (a stalled thread) keeps
true: every resend is a lost reply, and every reply that came after its timeout is a stale
one (``c.resends == lost requests + dropped replies + c.stale``)."""
from __future__ import annotations

import select
import socket
import threading
import time
import zlib

import numpy as np
import pytest

from planecal.base.errors import InputError
from planecal.links.emulators import Emulators, FD11Emulator, FD11Faults, serve
from planecal.links.fake import HOME, FakeCell
from planecal.links.fd11 import (ContactError, FD11Link, LinkError, LinkInterrupted,
                                 StepLimitError, pack_reply, pack_request, unpack_reply,
                                 unpack_request, wrap_diff)
from planecal.links.sessions import Contact, LastSession, StateFile

LO = "127.0.0.1"
T = 2.0  # the per-reply timeout where none is under test: a thread stalls for seconds


def free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((LO, 0))
    port = s.getsockname()[1]
    s.close()
    return port


class RawPeer:
    """A bare UDP socket standing in for the FD11: sees exactly what the client sends."""

    def __init__(self, host=LO):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self.port = self.sock.getsockname()[1]

    def recv(self, timeout=T):
        if not select.select([self.sock], [], [], timeout)[0]:
            return None, None
        return self.sock.recvfrom(4096)

    def close(self):
        self.sock.close()


@pytest.fixture
def peer():
    p = RawPeer()
    yield p
    p.close()


def link_to(port, contact=None, state=None, **kw):
    """A link to ``port`` with the loaded machine's intervals, expecting ``contact``
    (default: delta 0, nothing recorded) and recording in ``state``."""
    kw.setdefault("timeout_s", T)
    kw.setdefault("silence_s", 4 * kw["timeout_s"])
    kw.setdefault("boot_timeout_s", 4 * kw["timeout_s"])
    kw.setdefault("tick_s", 0.0)
    link = FD11Link(LO, port, 0, **kw)
    if contact is not None or state is not None:
        link.expect(contact or Contact.either(), state)
    return link


def kept(delta, reference=None) -> Contact:
    """A controller stated to keep its reference, holding ``delta``."""
    last = LastSession(None, np.asarray(delta, np.int64), reference, None, None)
    return Contact.kept(last, "stated in the test")


def quiesce(link, emu, earlier=()):
    """Synchronise with the emulator's thread: every request the link (and the ``earlier``
    links, closed) sent has been handled and every reply decided on has been sent; then
    the link takes in the replies it has not seen yet (as stale). Afterwards the counts
    are exact: every reply the emulator sent was seen, as an answer or as stale."""
    def seen(k):
        return k.counters.ticks + k.counters.stale
    sent = link.counters.sent + sum(k.counters.sent for k in earlier)
    assert emu.wait_until(lambda c: c.datagrams >= sent, 5), "emulator did not see every request"
    assert emu.idle(5), "emulator did not send every reply"
    missing = emu.snapshot().replies - seen(link) - sum(seen(k) for k in earlier)
    assert link.collect_late(missing, 5) == missing
    assert emu.snapshot().replies == seen(link) + sum(seen(k) for k in earlier)


def ramp(n, step=50, joints=(1, 1, 1, -1, -1, 0)):
    """Deltas like the seed's path matrix: n rows, +-step per tick."""
    return [np.array(joints, np.int64) * step * (i + 1) for i in range(n)]


# --- packing, byte-exact ----------------------------------------------------------------

def test_request_bytes_are_little_endian_deltas_then_negatives():
    got = pack_request([1, -1, 0, 256, -2, 0x12345678])
    want = bytes.fromhex(
        "01000000" "ffffffff" "00000000" "00010000" "feffffff" "78563412"
        "ffffffff" "01000000" "00000000" "00ffffff" "02000000" "88a9cbed")
    assert got == want
    assert len(got) == 48
    np.testing.assert_array_equal(unpack_request(want), [1, -1, 0, 256, -2, 0x12345678])


def test_reply_bytes_decode_as_uint32_into_int64():
    data = bytes.fromhex(
        "00008000" * 5 + "78563412"            # reference: 8388608 x5, 0x12345678
        + "20688000" + "ffffffff" + "00000000" + "00000080" + "01000000" + "00008000")
    ref, cur = unpack_reply(data)
    assert ref.dtype == np.int64 and cur.dtype == np.int64
    np.testing.assert_array_equal(ref, [8388608] * 5 + [0x12345678])
    np.testing.assert_array_equal(cur, [8415264, 4294967295, 0, 2**31, 1, 8388608])
    assert pack_reply(ref, cur) == data


def test_wrap_safe_difference_of_uint32_counts():
    np.testing.assert_array_equal(wrap_diff([5, 0xFFFFFFFE, 8388708], [0xFFFFFFFE, 5, 8388608]),
                                  [7, -7, 100])
    # int64 values that wrapped on packing come back modulo 2**32
    ref, cur = unpack_reply(pack_reply([0] * 6, [-1, 2**32 + 3, 0, 0, 0, 0]))
    np.testing.assert_array_equal(cur[:2], [2**32 - 1, 3])
    np.testing.assert_array_equal(wrap_diff(cur, ref)[:2], [-1, 3])


def test_request_validation():
    with pytest.raises(ValueError, match="48"):
        unpack_request(b"\x00" * 47)
    bad = bytearray(pack_request([1, 2, 3, 4, 5, 6]))
    bad[24] = 0  # first negative no longer -1
    with pytest.raises(ValueError, match="negatives"):
        unpack_request(bytes(bad))
    with pytest.raises(ValueError, match="int32"):
        pack_request([-2**31, 0, 0, 0, 0, 0])  # its negative does not fit
    with pytest.raises(ValueError, match="integer"):
        pack_request([0.5, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="shape"):
        pack_request([0, 0, 0])


# --- client against a bare socket: what goes on the wire ------------------------------------

def test_handshake_sends_zero_delta_and_reads_reply_on_local_port(peer):
    with link_to(peer.port) as link:
        result = {}
        t = threading.Thread(target=lambda: result.update(r=link.handshake()))
        t.start()
        data, addr = peer.recv()
        assert data == b"\x00" * 48
        assert addr == (LO, link.local_port)  # requests leave from the reply port
        peer.sock.sendto(pack_reply(HOME, HOME + [1, 2, 3, 4, 5, 6]), addr)
        t.join(5)
        ref, cur = result["r"]
        np.testing.assert_array_equal(ref, HOME)
        np.testing.assert_array_equal(cur, HOME + [1, 2, 3, 4, 5, 6])
        np.testing.assert_array_equal(link.reference, HOME)
        assert (link.counters.sent, link.counters.ticks) == (1, 1)


def test_step_limit_refuses_and_sends_nothing(peer):
    with link_to(peer.port, timeout_s=0.05) as link:
        with pytest.raises(StepLimitError, match="joint 2 changes by 61"):
            link.exchange([0, 61, 0, 0, 0, 0])       # measured from zero before any packet
        assert link.counters.sent == 0 and link.counters.refused == 1
        with pytest.raises(LinkError):                # 60 is allowed: sent, nobody answers
            link.exchange([0, 60, 0, 0, 0, -60])
        with pytest.raises(StepLimitError, match="joint 6 changes by 61"):
            link.exchange([0, 60, 0, 0, 0, 1])        # measured from the last sent delta
        with pytest.raises(StepLimitError):
            link.exchange([0, 60, 0, 0, 0, -121])
        n_first = link.counters.sent
        with pytest.raises(LinkError):
            link.exchange([0, 0, 0, 0, 0, -60])
        assert link.counters.refused == 3
        # on the wire: only the two allowed deltas, each resent until the bound, in order
        got = [peer.recv()[0] for _ in range(link.counters.sent)]
        assert got == ([pack_request([0, 60, 0, 0, 0, -60])] * n_first
                       + [pack_request([0, 0, 0, 0, 0, -60])] * (link.counters.sent - n_first))
        assert peer.recv(0.1) == (None, None)
    with pytest.raises(ValueError, match="1..60"):
        FD11Link(LO, peer.port, 0, max_step_counts=61)
    with link_to(peer.port, max_step_counts=10) as link:
        with pytest.raises(StepLimitError, match="limit 10"):
            link.exchange([11, 0, 0, 0, 0, 0])
        assert link.counters.sent == 0


def test_bad_delta_sends_nothing(peer):
    with link_to(peer.port) as link:
        for bad in ([1, 2, 3], [0.5, 0, 0, 0, 0, 0], [np.nan] * 6):
            with pytest.raises(ValueError):
                link.exchange(bad)
        assert peer.recv(0.1) == (None, None) and link.counters.sent == 0


def test_no_reply_resends_the_same_delta_until_the_boot_timeout(peer):
    with link_to(peer.port, timeout_s=0.05, boot_timeout_s=0.3) as link:
        with pytest.raises(LinkError, match=r"no reply to the first packet \(delta "
                                            r"\[5, 0, 0, 0, 0, -5\]\) within the boot timeout "
                                            r"of 0.3 s") as exc:
            link.exchange([5, 0, 0, 0, 0, -5])
        assert "tripped on this packet" in str(exc.value) and "\n" not in str(exc.value)
        n = link.counters.sent
        assert n >= 2 and link.counters.boot_resends == n - 1
        assert link.counters.lost_replies == 0  # before first contact nothing is "lost"
        assert [peer.recv()[0] for _ in range(n)] == [pack_request([5, 0, 0, 0, 0, -5])] * n
        assert peer.recv(0.1) == (None, None)


def test_nobody_listening_is_a_boot_timeout_not_a_send_error():
    port = free_udp_port()  # closed: the kernel answers ICMP port unreachable
    with link_to(port, timeout_s=0.02, boot_timeout_s=0.2) as link:
        with pytest.raises(LinkError, match="within the boot timeout of 0.2 s"):
            link.handshake()
        assert link.counters.sent >= 2


def test_malformed_and_foreign_datagrams_are_dropped(peer):
    with link_to(peer.port) as link:
        result = {}
        t = threading.Thread(target=lambda: result.update(r=link.exchange([1] * 6)))
        t.start()
        _, addr = peer.recv()
        try:
            other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            other.bind(("127.0.0.2", 0))  # a different sender address
            other.sendto(pack_reply([7] * 6, [7] * 6), addr)
            other.close()
            n_foreign = 1
        except OSError:
            n_foreign = 0
        peer.sock.sendto(b"\x00" * 47, addr)
        peer.sock.sendto(b"\x00" * 49, addr)
        peer.sock.sendto(pack_reply(HOME, HOME + 1), addr)
        t.join(5)
        np.testing.assert_array_equal(result["r"][1], HOME + 1)
        assert link.counters.dropped == 2 + n_foreign


def test_reference_change_is_an_error(peer):
    with link_to(peer.port) as link:
        def answer(ref):
            _, addr = peer.recv()
            peer.sock.sendto(pack_reply(ref, ref), addr)
        t = threading.Thread(target=answer, args=(HOME,))
        t.start(); link.handshake(); t.join(5)
        t = threading.Thread(target=answer, args=(HOME + 1000,))
        t.start()
        with pytest.raises(LinkError, match="reference counts changed"):
            link.exchange([0] * 6)
        t.join(5)
        with pytest.raises(LinkError, match="unusable after an earlier error"):
            link.exchange([0] * 6)


def test_pacing_never_sends_faster_than_tick(peer):
    def echo():
        for _ in range(6):
            data, addr = peer.recv(5)
            peer.sock.sendto(pack_reply(HOME, HOME), addr)
    t = threading.Thread(target=echo)
    t.start()
    with link_to(peer.port, tick_s=0.03) as link:
        t0 = time.monotonic()
        for _ in range(6):
            link.exchange([0] * 6)
        assert time.monotonic() - t0 >= 5 * 0.03 - 1e-3
    t.join(5)


# --- client against the emulator --------------------------------------------------------

@pytest.fixture
def cell():
    return FakeCell(reference=HOME + np.arange(6) * 1000)


def test_path_over_emulator_matches_backend(cell):
    deltas = ramp(20) + [ramp(20)[-1]] * 5
    with FD11Emulator(cell, LO, 0, None) as emu, link_to(emu.rt_port) as link:
        ref0, cur0 = link.handshake()
        np.testing.assert_array_equal(ref0, cell.reference)
        np.testing.assert_array_equal(cur0, cell.reference)
        for d in deltas:
            ref, cur = link.exchange(d)
            np.testing.assert_array_equal(ref, cell.reference)
            np.testing.assert_array_equal(cur, cell.reference + d)
        assert len(cell.deltas) == 1 + len(deltas)
        np.testing.assert_array_equal(cell.deltas[1:], deltas)
        c = link.counters
        assert c.sent == c.ticks == 26
        assert c.lost_replies == c.resends == c.stale == c.dropped == 0
        quiesce(link, emu)
    assert emu.counters.ticks == 26 and emu.counters.sessions == 1 and not emu.tripped


def test_fixed_ports_like_the_seed(cell):
    rt, reply = free_udp_port(), free_udp_port()
    with FD11Emulator(cell, LO, rt, reply) as emu, \
            FD11Link(LO, rt, reply, timeout_s=T, silence_s=4 * T, boot_timeout_s=4 * T,
                     tick_s=0) as link:
        assert (emu.rt_port, link.local_port) == (rt, reply)
        link.handshake()
        _, cur = link.exchange([50, 0, 0, 0, 0, 0])
        assert cur[0] == cell.reference[0] + 50


def test_lost_replies_and_requests_are_resent_and_counted(cell):
    faults = FD11Faults(drop_every=3, lose_request_every=5)
    deltas = ramp(10)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, \
            link_to(emu.rt_port, timeout_s=0.25) as link:
        link.handshake()  # delta 0 first (seed 7.1.1): the reference is the robot's counts
        results = [link.exchange(d)[1] for d in deltas]  # resending is idempotent
        quiesce(link, emu)
        _clean_tick_is_exact(link, emu, cell, deltas[-1])
    c, e = link.counters, emu.counters
    assert c.ticks == 1 + len(deltas) + 1 and e.lost_requests + e.dropped_replies >= 3
    # every request that got no reply is one lost reply, and so is one whose reply came
    # after the timeout (then seen as stale; none on an idle machine)
    assert c.lost_replies == c.resends == e.lost_requests + e.dropped_replies + c.stale
    assert c.sent == c.ticks + c.resends == e.datagrams
    _answers_to_sent_deltas(results, deltas, cell.reference)


def _answers_to_sent_deltas(results, deltas, ref):
    """Without sequence numbers a late or duplicated reply can answer the next request: each
    result must be the answer to this tick's delta or an earlier one, never a later one
    (how much earlier depends on how late the replies came: the machine's load)."""
    sent = [np.zeros(6, np.int64)]
    for i, cur in enumerate(results):
        sent.append(deltas[i])
        assert any(np.array_equal(cur, ref + d) for d in sent), (i, cur - ref)


def _clean_tick_is_exact(link, emu, cell, delta):
    """Faults off, every reply in flight accounted for: the next tick is answered exactly."""
    emu.faults = FD11Faults()
    quiesce(link, emu)
    _, cur = link.exchange(delta)
    np.testing.assert_array_equal(cur, cell.reference + delta)


def test_delayed_replies_are_drained(cell):
    faults = FD11Faults(delay_every=5, delay_s=0.25)
    deltas = ramp(6)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, \
            link_to(emu.rt_port, timeout_s=0.08) as link:
        link.handshake()
        results = [link.exchange(d)[1] for d in deltas]
        _clean_tick_is_exact(link, emu, cell, deltas[-1])
    _answers_to_sent_deltas(results, deltas, cell.reference)
    assert link.counters.lost_replies >= 2 and link.counters.stale >= 2


def test_duplicated_replies_are_drained(cell):
    faults = FD11Faults(duplicate_every=1)
    deltas = ramp(20)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, link_to(emu.rt_port) as link:
        link.handshake()
        results = [link.exchange(d)[1] for d in deltas]
        quiesce(link, emu)  # waits for the emulator's thread, then counts what the link saw
        n = 1 + len(deltas)
        c = link.counters  # (a resend, after a stall of T, is one more request answered twice)
        assert emu.snapshot().replies == 2 * c.sent == 2 * (n + c.resends)
        assert c.ticks == n and c.stale == n + 2 * c.resends
        _clean_tick_is_exact(link, emu, cell, deltas[-1])
    _answers_to_sent_deltas(results, deltas, cell.reference)


# --- outages, boot, sessions: the faults of a real cell ---------------------------------------

def test_an_outage_shorter_than_the_silence_bound_is_ridden_through(cell):
    # requests 4..9 lost: six lost replies in a row, where the old client gave up after three
    faults = FD11Faults(outage_from=4, outage_requests=6)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, \
            link_to(emu.rt_port, timeout_s=0.1, silence_s=10.0) as link:
        deltas = [np.zeros(6, np.int64)] + ramp(4)
        results = [link.exchange(d)[1] for d in deltas]
        quiesce(link, emu)
    c = link.counters
    np.testing.assert_array_equal(results[-1], cell.reference + deltas[-1])
    assert emu.counters.lost_requests == 6 and c.longest_outage_s >= 6 * 0.1
    # a reply later than the timeout (a stalled thread) is one more lost reply, stale
    assert c.lost_replies == c.resends == 6 + c.stale
    assert emu.counters.ticks == 5 + c.stale and c.max_lost_in_a_row >= 6
    if c.stale == 0:  # every reply on time: the outage alone
        assert (c.outages, c.max_lost_in_a_row) == (1, 6)


def test_an_outage_longer_than_the_silence_bound_stops_the_link(cell):
    faults = FD11Faults(outage_from=3, outage_requests=10**6)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, \
            link_to(emu.rt_port, timeout_s=0.05, silence_s=0.3) as link:
        link.handshake()
        link.exchange([10, 0, 0, 0, 0, 0])
        with pytest.raises(LinkError, match=r"no reply for 0.3 s \(\d+ packets of delta "
                                            r"\[20, 0, 0, 0, 0, 0\] unanswered\); the robot "
                                            r"holds its last command"):
            link.exchange([20, 0, 0, 0, 0, 0])
        assert link.counters.lost_replies == link.counters.resends + 1 >= 2


def test_enable_dropping_during_an_outage_ends_it(cell):
    class Switch:
        def __init__(self):
            self.calls = 0

        def enabled(self):
            self.calls += 1
            return self.calls < 3

    faults = FD11Faults(outage_from=2, outage_requests=10**6)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, \
            link_to(emu.rt_port, timeout_s=0.5, silence_s=10.0, enable=Switch()) as link:
        link.handshake()
        with pytest.raises(LinkInterrupted, match="enable dropped during an outage"):
            link.exchange([10, 0, 0, 0, 0, 0])
    # asked after each lost reply; the third answer is "released": 3 lost, 2 resent
    assert (link.counters.lost_replies, link.counters.resends) == (3, 2)


def test_first_contact_waits_for_a_booting_rt_system(cell):
    """Silent for its first 4 requests (booting): first contact rides through with a boot
    timeout of its own, longer than the outage bound that applies afterwards."""
    faults = FD11Faults(boot_requests=4)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, \
            link_to(emu.rt_port, timeout_s=0.1, silence_s=0.1, boot_timeout_s=10.0) as link:
        ref, cur = link.handshake()
        np.testing.assert_array_equal(ref, cell.reference)
        quiesce(link, emu)
    c = link.counters  # (a first reply later than 0.1 s: one more resend, answered, stale)
    assert emu.counters.boot_ignored == 4 and emu.counters.ticks == 1 + c.stale
    assert c.boot_resends == 4 + c.stale and c.lost_replies == 0
    assert c.boot_wait_s >= 4 * 0.1


def test_a_boot_longer_than_the_boot_timeout_is_one_line(cell):
    faults = FD11Faults(boot_s=60.0)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, \
            link_to(emu.rt_port, timeout_s=0.05, boot_timeout_s=0.3) as link:
        with pytest.raises(LinkError, match="within the boot timeout of 0.3 s"):
            link.handshake()
        quiesce(link, emu)
    assert emu.counters.ticks == 0 and emu.counters.boot_ignored == link.counters.sent


def test_random_reply_loss_is_seeded_and_ridden_through(cell):
    """5 % of the replies lost at random (seeded): 400 ticks all answered; the emulator's
    losses are a function of the request index and the seed alone."""
    faults = FD11Faults(drop_probability=0.05, seed=11)
    hold = np.zeros(6, np.int64)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, \
            link_to(emu.rt_port, timeout_s=0.05, silence_s=10.0) as link:
        for _ in range(400):
            link.exchange(hold)
        quiesce(link, emu)
    e, c = emu.counters, link.counters
    want = np.random.default_rng(11).random(e.datagrams) < 0.05  # the same draws
    assert e.dropped_replies == int(want.sum()) >= 10
    assert c.ticks == 400 and c.sent == e.datagrams == c.ticks + c.resends
    assert c.lost_replies >= 1 and c.outages >= 1


def test_a_new_client_takes_a_fresh_reference_where_the_robot_is():
    """Reference behaviour fresh_each_client: a second client (another port) gets the
    robot's counts as the reference and delta 0 as what the controller holds; its first
    packet, delta 0, commands the robot where it stands (which first settles on the command
    the last session left, lag 3 ticks)."""
    cell = FakeCell(lag_ticks=3)
    move = ramp(10)
    with FD11Emulator(cell, LO, 0, None, reference_mode="fresh_each_client") as emu:
        with link_to(emu.rt_port) as link:
            link.handshake()
            for d in move:
                link.exchange(d)
        with link_to(emu.rt_port, Contact.fresh()) as link2:  # another port: a new client
            ref, cur = link2.handshake()
            np.testing.assert_array_equal(link2.fd11_reference, HOME + move[-1])
            np.testing.assert_array_equal(ref, HOME + move[-1])
            np.testing.assert_array_equal(cur, HOME + move[-1])
            _, cur = link2.exchange([50, 0, 0, 0, 0, 0])
            quiesce(link2, emu, [link])
    assert not emu.tripped
    e = emu.counters
    assert (e.sessions, e.fresh_references, e.settle_ticks, e.ticks) == (2, 1, 3, 1 + 10 + 2)
    np.testing.assert_array_equal(emu.reference, HOME + move[-1])
    # the backend saw one continuous command: the settle holds, then from where it stood
    np.testing.assert_array_equal(cell.deltas[-1], move[-1] + [50, 0, 0, 0, 0, 0])


def _after_silence(contact, pause_s=2.5, silence_s=1.5):
    """A session moves 4 ramp steps (to delta 200 on five joints); after ``pause_s`` (a
    second more than the controller's ``silence_s``, which a stalled thread does not reach
    within a session) another begins, expecting ``contact``."""
    cell = FakeCell()
    move = ramp(4)
    with FD11Emulator(cell, LO, 0, None, reference_mode="fresh_after_silence",
                      session_gap_s=silence_s) as emu:
        with link_to(emu.rt_port) as link:
            link.handshake()
            for d in move:
                link.exchange(d)
            quiesce(link, emu)
        time.sleep(pause_s)
        with link_to(emu.rt_port, contact, timeout_s=0.2, boot_timeout_s=2.0) as link2:
            try:
                got = link2.handshake()
            except LinkError as e:
                got = e
            if not emu.tripped:
                quiesce(link2, emu, [link])
    return emu, cell, link2, got, move


def test_a_silence_takes_a_fresh_reference_where_the_robot_is():
    emu, cell, link, got, move = _after_silence(Contact.fresh())
    ref, cur = got
    assert not emu.tripped and emu.counters.fresh_references == 1
    np.testing.assert_array_equal(link.fd11_reference, HOME + move[-1])  # the robot's counts
    np.testing.assert_array_equal(cur, HOME + move[-1])
    np.testing.assert_array_equal(cell.deltas[-1], move[-1])  # nothing moved


def test_a_fresh_reference_trips_on_the_last_delta_repeated():
    """The cell stated wrongly (keep, against a controller that takes a fresh reference
    after silence): the first packet repeats the last delta, 200 counts from the 0 the
    controller holds -- the fault of issue 25. It trips; the link says so in one line."""
    emu, cell, link, got, move = _after_silence(kept(move_last := ramp(4)[-1], HOME))
    assert isinstance(got, LinkError) and "tripped on this packet" in str(got)
    assert f"a kept reference (first delta {move_last.tolist()}" in str(got)
    assert emu.tripped and "joint 1 delta changed by 200 counts" in emu.trip_reason
    assert cell.ticks == 1 + 4  # nothing went to the robot


def test_no_pause_keeps_the_reference_for_another_client():
    """fresh_after_silence: another client address without a pause (well within the
    controller's 5 s) continues the session (the reference and the delta held are kept)."""
    emu, cell, link, got, move = _after_silence(kept(ramp(4)[-1], HOME), pause_s=0.0,
                                                silence_s=5.0)
    ref, cur = got
    assert not emu.tripped and emu.counters.fresh_references == 0
    np.testing.assert_array_equal(link.fd11_reference, HOME)
    np.testing.assert_array_equal(cur, HOME + move[-1])


def _two_sessions_kept_reference(contact):
    cell = FakeCell()
    move = ramp(10)
    with FD11Emulator(cell, LO, 0, None, reference_mode="keep") as emu:
        with link_to(emu.rt_port) as link:
            link.handshake()
            for d in move:
                link.exchange(d)
        with link_to(emu.rt_port, contact, timeout_s=0.2, boot_timeout_s=2.0) as link2:
            try:
                return emu, cell, link2, link2.handshake(), move
            except LinkError as e:
                return emu, cell, link2, e, move


def test_a_kept_reference_trips_on_a_first_delta_of_zero():
    """The cell stated wrongly (fresh, against a controller that keeps its reference): the
    first packet, 0, is the jump the statement cannot see; the controller trips on it and
    the link says so in one line."""
    emu, cell, link, got, move = _two_sessions_kept_reference(Contact.fresh())
    assert isinstance(got, LinkError) and "tripped on this packet" in str(got)
    assert "a fresh reference" in str(got)
    assert emu.tripped and "joint 1 delta changed by 500 counts" in emu.trip_reason
    assert cell.ticks == 11  # nothing went to the robot


def test_a_kept_reference_is_safe_with_the_last_delta_first():
    move_last = ramp(10)[-1]
    emu, cell, link, got, move = _two_sessions_kept_reference(kept(move_last, HOME))
    ref, cur = got
    assert not emu.tripped
    np.testing.assert_array_equal(link.fd11_reference, HOME)        # kept since boot
    np.testing.assert_array_equal(ref, HOME + move_last)            # the loop's frame
    np.testing.assert_array_equal(cur, HOME + move_last)
    np.testing.assert_array_equal(cell.deltas[-1], move_last)       # nothing moved


@pytest.mark.parametrize("stated, first_wire, held", [
    ("kept", [0] * 6, [500, 500, 500, -500, -500, 0]),   # a fresh session's first packet
    ("fresh", [500, 500, 500, -500, -500, 0], [0] * 6),  # a kept session's first packet
    ("kept", [552, 500, 500, -500, -500, 0], [500, 500, 500, -500, -500, 0]),  # 52 off
])
def test_the_first_packet_is_refused_when_it_is_not_what_the_controller_holds(
        peer, stated, first_wire, held):
    """The link is told what the controller holds (kept: the last delta, fresh: 0); a first
    packet farther than the step limit (51) from it is refused and nothing is sent, under
    either behaviour. (The loop's frame is the wire's minus what the controller holds.)"""
    contact = kept(held) if stated == "kept" else Contact.fresh()
    with link_to(peer.port, contact, max_step_counts=51, timeout_s=0.05) as link:
        loop = np.asarray(first_wire) - np.asarray(held)
        with pytest.raises(StepLimitError, match=r"the first packet, measured from what the "
                                                 r"controller holds.*nothing sent"):
            link.exchange(loop)
        assert peer.recv(0.3) == (None, None)
        assert link.counters.sent == 0 and link.counters.refused == 1
        # what the controller holds goes out: the first packet is the held delta itself
        with pytest.raises(LinkError):  # nobody answers the raw peer's end: boot timeout
            link.exchange(np.zeros(6, np.int64))
        data, _ = peer.recv()
        np.testing.assert_array_equal(unpack_request(data), held)


def test_a_first_reply_that_fits_neither_reading_is_a_contact_error():
    """The last delta recorded is 40 counts off what the controller holds (robot jogged,
    another state file): within a trip step, so no trip, but the first reply shows it."""
    cell = FakeCell(lag_ticks=3)
    with FD11Emulator(cell, LO, 0, None, reference_mode="keep") as emu:
        with link_to(emu.rt_port) as link:
            link.handshake()
            for d in ramp(4):
                link.exchange(d)
        off = ramp(4)[-1] + [0, 0, 0, 40, 0, 0]
        with link_to(emu.rt_port, kept(off), contact_tolerance_counts=30) as link2:
            with pytest.raises(ContactError, match=r"commanded - current = \[0, 0, 0, 40, 0, 0\]"
                                                   r" counts \(joint 4: 40, tolerance 30\)"):
                link2.handshake()
            with pytest.raises(LinkError, match="unusable"):
                link2.exchange([0] * 6)
            quiesce(link2, emu, [link])
    assert emu.counters.ticks == 1 + 4 + 1  # the one first packet, nothing after it
    assert emu.counters.settle_ticks == 3  # the lag, before the second session began


def test_a_kept_reference_that_changed_is_a_contact_error(peer):
    """Stated kept, recorded reference HOME; the first reply shows HOME + 7 (the RT system
    restarted): one line, nothing more sent, even though commanded - current fits."""
    with link_to(peer.port, kept([0] * 6, HOME)) as link:
        t = threading.Thread(target=lambda: peer.sock.sendto(
            pack_reply(HOME + 7, HOME + 7), peer.recv()[1]))
        t.start()
        with pytest.raises(ContactError, match=r"reference .* is not the .* the controller "
                                               r"was stated to keep .*nothing more sent"):
            link.handshake()
        t.join(5)
        assert link.counters.sent == 1


def test_the_state_file_holds_the_last_answered_delta_reference_time_and_client(tmp_path, cell):
    path = tmp_path / "fd11.state"
    assert StateFile.read(path) is None
    state = StateFile(path)
    assert not path.exists()  # created at the first packet, not before
    t0 = time.time()
    with FD11Emulator(cell, LO, 0, None, reference_mode="keep") as emu, \
            link_to(emu.rt_port, kept([7, 0, 0, 0, 0, 0], None), state) as link:
        link.handshake()
        line = path.read_bytes()
        body = line[:line.index(b" crc32=")]
        assert body.startswith(b"fd11-state/2 +0000000007" + b" +0000000000" * 5
                               + b"".join(b" %010d" % v for v in cell.reference))
        assert body.endswith(f" {link.client}".encode()) and link.client.endswith(
            f":{link.local_port}")
        assert line == body + b" crc32=%08x\n" % zlib.crc32(body)
        for d in ramp(3):
            link.exchange(d)
        last = StateFile.read(path)
    state.close()
    np.testing.assert_array_equal(last.delta, ramp(3)[-1] + [7, 0, 0, 0, 0, 0])
    np.testing.assert_array_equal(last.reference, cell.reference)
    assert last.client == link.client and t0 - 0.01 <= last.sent_at <= time.time()


def test_the_state_file_records_the_time_of_packets_nobody_answered(tmp_path, peer):
    """A packet that goes out unanswered (a booting, or tripped, controller) still counts
    for the silence: its time is recorded before it is sent; the delta stays the last
    answered one."""
    path = tmp_path / "fd11.state"
    state = StateFile(path)
    with link_to(peer.port, Contact.either(), state, timeout_s=0.1, boot_timeout_s=0.3) as link:
        t0 = time.time()
        with pytest.raises(LinkError, match="no reply to the first packet"):
            link.handshake()
        t1 = time.time()
    state.close()
    last = StateFile.read(path)
    assert last.reference is None and last.client is None and not last.delta.any()
    assert link.counters.sent >= 2  # resent every 0.1 s: the time is the last packet's
    assert t0 + 0.09 <= last.sent_at <= t1


def test_the_state_file_holds_a_delta_sent_in_an_answered_session(tmp_path, peer):
    """Once the controller has answered the session, each packet's delta is recorded as it
    goes out: a run stopped while it waits for the reply (here: none comes) has recorded
    what the controller most likely holds; the other candidate is one step away."""
    path = tmp_path / "fd11.state"
    state = StateFile(path)
    with link_to(peer.port, Contact.either(), state, timeout_s=0.1, silence_s=0.3,
                 boot_timeout_s=10.0) as link:
        t = threading.Thread(target=lambda: peer.sock.sendto(pack_reply(HOME, HOME),
                                                             peer.recv()[1]))
        t.start()
        link.handshake()
        t.join(5)
        with pytest.raises(LinkError, match="no reply for 0.3 s"):
            link.exchange([40, 0, 0, 0, 0, -40])
    state.close()
    last = StateFile.read(path)
    assert last.delta.tolist() == [40, 0, 0, 0, 0, -40]
    np.testing.assert_array_equal(last.reference, HOME)


@pytest.mark.parametrize("damage", [b"", b"fd11-state/2 +5\n", b"x" * 105,
                                    b"fd11-last-delta/1 +0000000007" + b" +0000000000" * 5
                                    + b" crc32=00000000\n"])
def test_a_damaged_state_file_is_one_line(tmp_path, damage):
    path = tmp_path / "cell.fd11"
    path.write_bytes(damage)
    with pytest.raises(InputError, match=rf"^{path}: line 1: .*FD11 state line") as exc:
        StateFile.read(path)
    assert "\n" not in str(exc.value)


def test_a_state_line_is_read_whatever_a_kill_left_after_it(tmp_path):
    """Killed between writing a shorter line and truncating the file: line 1 is whole."""
    path = tmp_path / "fd11.state"
    state = StateFile(path)
    state.sending()
    state.answered(np.arange(6), HOME, "192.168.100.200:40001")
    state.close()
    long_line = path.read_bytes()
    state = StateFile(path)
    state.answered(np.arange(6) + 1, HOME, "10.0.0.2:5556")  # shorter, then truncated
    state.close()
    short = path.read_bytes()
    path.write_bytes(short + long_line[len(short):])
    assert StateFile.read(path).delta.tolist() == [1, 2, 3, 4, 5, 6]


def test_an_older_state_line_is_read_with_time_and_client_unknown(tmp_path):
    path = tmp_path / "RUN.tsv.fd11"
    body = b"fd11-last-delta/1 +0000000007" + b" +0000000000" * 4 + b" -0000000050"
    path.write_bytes(body + b" crc32=%08x\n" % zlib.crc32(body))
    last = StateFile.read(path)
    assert last.delta.tolist() == [7, 0, 0, 0, 0, -50]
    assert (last.reference, last.sent_at, last.client) == (None, None, None)


def test_the_switch_released_stops_the_robot_until_the_next_session():
    cell = FakeCell()
    faults = FD11Faults(release_after_ticks=4)
    move = ramp(8)
    with FD11Emulator(cell, LO, 0, None, faults=faults,
                      reference_mode="fresh_each_client") as emu:
        with link_to(emu.rt_port) as link:
            link.handshake()
            curs = [link.exchange(d)[1] for d in move]
        with link_to(emu.rt_port, Contact.fresh()) as link2:
            ref, cur = link2.handshake()
            quiesce(link2, emu, [link])
    for c in curs[3:]:  # stopped after 4 ticks (the handshake and 3 steps)
        np.testing.assert_array_equal(c, HOME + move[2])
    e = emu.counters
    assert (e.released_ticks, e.max_released_gap) == (5, 250)
    # held again at the next session: the servo took up the missed commands and settled
    np.testing.assert_array_equal(cur, HOME + move[-1])
    np.testing.assert_array_equal(cell.deltas[-6:-1], move[3:])


# --- emulator alone, driven by a raw socket --------------------------------------------------

class RawClient(RawPeer):
    def __init__(self, emu):
        super().__init__()
        self.dest = (LO, emu.rt_port)

    def send(self, data, timeout=T):
        self.sock.sendto(data, self.dest)
        return self.recv(timeout)[0]


# reference "keep": the reference is the backend's, every delta passes through as sent

def test_emulator_ignores_invalid_packets(cell):
    with FD11Emulator(cell, LO, 0, None, reference_mode="keep") as emu:
        c = RawClient(emu)
        bad = bytearray(pack_request([1, 0, 0, 0, 0, 0]))
        bad[24:28] = b"\x00\x00\x00\x00"
        for data in (b"", b"\x00" * 47, b"\x00" * 49, bytes(bad)):
            c.sock.sendto(data, c.dest)
        # the first reply is the one to the valid packet sent after the invalid ones
        assert c.send(pack_request([1, 0, 0, 0, 0, 0])) == pack_reply(
            cell.reference, cell.reference + [1, 0, 0, 0, 0, 0])
        c.close()
    assert emu.counters.invalid == 4 and cell.ticks == 1


def test_emulator_trips_silently_on_jump_over_60(cell):
    with FD11Emulator(cell, LO, 0, None, reference_mode="keep") as emu:
        c = RawClient(emu)
        assert c.send(pack_request([0] * 6)) is not None
        assert c.send(pack_request([60, 0, 0, 0, 0, -60])) is not None  # exactly 60: fine
        assert c.send(pack_request([60, 0, 0, 61, 0, -60]), 0.1) is None  # joint 4 jumps 61
        assert emu.wait_until(lambda k: k.datagrams == 3, 5)  # handled, not just unanswered
        assert emu.tripped and "joint 4" in emu.trip_reason and "61" in emu.trip_reason
        assert c.send(pack_request([60, 0, 0, 0, 0, -60]), 0.1) is None  # brakes: silent
        assert emu.wait_until(lambda k: k.ignored_tripped == 1, 5)
        assert cell.ticks == 2
        emu.reset_trip()
        assert c.send(pack_request([60, 0, 0, 10, 0, -60])) is not None
        c.close()


def test_emulator_trip_hold_answers_without_moving(cell):
    with FD11Emulator(cell, LO, 0, None, trip_mode="hold", reference_mode="keep") as emu:
        c = RawClient(emu)
        c.send(pack_request([50, 0, 0, 0, 0, 0]))
        r = c.send(pack_request([200, 0, 0, 0, 0, 0]))
        assert emu.tripped and r is not None
        np.testing.assert_array_equal(unpack_reply(r)[1], cell.reference + [50, 0, 0, 0, 0, 0])
        r = c.send(pack_request([100, 0, 0, 0, 0, 0]))
        np.testing.assert_array_equal(unpack_reply(r)[1], cell.reference + [50, 0, 0, 0, 0, 0])
        np.testing.assert_array_equal(cell.deltas, [[50, 0, 0, 0, 0, 0]] * 3)
        c.close()


def test_emulator_backend_error_trips(cell):
    class Broken(FakeCell):
        def exchange(self, delta):
            raise RuntimeError("collision with plate 0")
    with FD11Emulator(Broken(), LO, 0, None) as emu, \
            link_to(emu.rt_port, timeout_s=0.05, boot_timeout_s=0.1) as link:
        with pytest.raises(LinkError):
            link.handshake()
        assert emu.wait_until(lambda k: k.datagrams >= 1, 5)
        assert emu.tripped and "collision with plate 0" in emu.trip_reason


def test_serve_runs_both_until_stopped(cell):
    from planecal.links.zs_ld80 import ZSLD80
    ready, stop, up = {}, threading.Event(), threading.Event()

    def on_ready(e):
        ready["e"] = e
        up.set()

    t = threading.Thread(target=serve, args=(cell,),
                         kwargs=dict(host=LO, rt_port=0, reply_port=None, stop=stop,
                                     on_ready=on_ready))
    t.start()
    assert up.wait(10)
    emus: Emulators = ready["e"]
    assert any("UDP" in line and "reference fresh_after_silence 2 s" in line
               for line in emus.describe())
    with link_to(emus.fd11.rt_port) as link, ZSLD80(emus.laser.port, timeout_s=T) as laser:
        link.handshake()
        link.exchange([50, 0, 0, 0, 0, 0])
        assert laser.read() == pytest.approx(80.005, abs=1e-9)
    stop.set()
    t.join(5)
    assert not t.is_alive()


# --- the twin behind the wires --------------------------------------------------------------

def test_twin_over_udp_and_pty_matches_in_process_twin():
    pytest.importorskip("mujoco")
    twin_mod = pytest.importorskip("planecal.twin")
    from planecal.links.zs_ld80 import ZSLD80, decode_reply, encode_reply

    local = twin_mod.Twin("thesis_final", seed=3)     # default options: lag servo, laser noise
    remote = twin_mod.Twin("thesis_final", seed=3)
    move = ramp(20, joints=(1, 0, 0, 0, 1, -1))
    path = [np.zeros(6, np.int64)] + move + [move[-1]] * 10   # move 1000 counts, then dwell
    # the remote twin's first tick and first ray cast build and warm up its models in the
    # emulator's thread: seconds on a loaded machine (a resend would tick it twice), so
    # bounds of seconds, not T
    with Emulators(remote, host=LO, rt_port=0, reply_port=None) as emus, \
            link_to(emus.fd11.rt_port, timeout_s=5.0, boot_timeout_s=30.0,
                    silence_s=10.0) as link, \
            ZSLD80(emus.laser.port, timeout_s=10.0) as laser:
        for d in path:
            ref_w, cur_w = link.exchange(d)
            mm_w = laser.read()
            ref_l, cur_l = local.exchange(d)
            mm_l = local.read()
            np.testing.assert_array_equal(ref_w, ref_l)
            np.testing.assert_array_equal(cur_w, cur_l)
            assert mm_w == decode_reply(encode_reply(mm_l))  # identical at the wire's 1e-6 mm
        assert mm_w is not None
        assert link.counters.lost_replies == 0 and laser.counters.malformed == 0
        resent = link.counters.resends + link.counters.boot_resends
    # a datagram resent while the emulator's first tick warmed up (a loaded machine) is a
    # tick of its own there, as on a controller: the remote twin ticks once more for each
    # (same state: the answers above are identical), never fewer
    assert local.ticks == len(path) <= remote.ticks <= len(path) + resent


def test_emulate_twin_is_the_profiles_world():
    """`emulate --errors` (default realistic) serves the twin rehearse would make."""
    pytest.importorskip("mujoco")
    import argparse
    from planecal.commands import emulate
    from planecal.twin.world import WorldRef, make_twin
    from planecal.model.scene import load_scene
    p = argparse.ArgumentParser()
    emulate.add_arguments(p)
    scene = load_scene("thesis_final")
    for argv, errors in (([], "realistic"), (["--errors", "ideal"], "ideal")):
        got = emulate._make_twin(p.parse_args(["--seed", "3"] + argv))
        want = make_twin(scene, WorldRef(errors, 3), 3)
        assert got.options == want.options
        np.testing.assert_array_equal(got.truth.joint_offsets, want.truth.joint_offsets)
        np.testing.assert_array_equal(got.true_kinematics.a, want.true_kinematics.a)
    assert emulate._make_twin(p.parse_args(["--errors", "ideal"])).options.quantization is False
