"""ZS-LD80 over a real pseudo-terminal: framing, decoder strictness, emulator faults.

No outcome depends on the machine's load: a reply is awaited for seconds (``T``, or 1 s
where a test waits for a timeout), and the ages of the non-blocking poll run on a fake
clock."""
from __future__ import annotations

import os
import select
import threading
import tty

import pytest

from planecal.links.laser_emulator import LaserEmulator, LaserFaults
from planecal.links.fake import ScriptedLaser
from planecal.links.zs_ld80 import (NO_READING, ZSLD80, LaserError, LaserTimeout, decode_reply,
                                    encode_reply)

T = 2.0  # the reply timeout where none is under test: a thread stalls for seconds


# --- framing -------------------------------------------------------------------------------

@pytest.mark.parametrize("frame, mm", [
    (b"+00012345678\r", 92.345678),
    (b"-00001500000\r", 78.5),
    (b"+00015000000\r", 95.0),
    (b"-00000000001\r", 79.999999),
    (b"+00000000000\r", None),   # the sensor's 0: out of range
    (b"-00000000000\r", None),
])
def test_decode_known_frames(frame, mm):
    got = decode_reply(frame)
    assert got is None if mm is None else got == pytest.approx(mm, abs=1e-9)


@pytest.mark.parametrize("frame", [
    b"", b"\r", b"+0001234567\r", b"+000123456789\r", b"+00012345678", b"+00012345678\n",
    b"00012345678+\r", b"000123456789\r", b"+0001234 678\r", b"+00012.45678\r",
    b"+0001234567a\r", b"++0012345678\r", b"ER\r", b"+00012345678\r\r", b"\xff" * 12 + b"\r",
])
def test_decode_rejects_garbage(frame):
    with pytest.raises(LaserError, match="malformed"):
        decode_reply(frame)


def test_encode_round_trip():
    assert encode_reply(92.345678) == b"+00012345678\r"
    assert encode_reply(78.5) == b"-00001500000\r"
    assert encode_reply(None) == b"+00000000000\r"
    assert encode_reply(80.0 + 1e6) == b"+00000000000\r"  # does not fit: out of range
    assert encode_reply(70.25, terminator=b"\r\n") == b"-00009750000\r\n"
    for mm in (65.000001, 80.5, 94.999999):
        assert decode_reply(encode_reply(mm)) == pytest.approx(mm, abs=1e-9)


# --- client against a bare pty: what goes on the wire --------------------------------------

@pytest.fixture
def pty_pair():
    master, slave = os.openpty()
    tty.setraw(slave)
    yield master, os.ttyname(slave)
    for fd in (master, slave):
        os.close(fd)


def _answer(master, reply, terminator=b"\r"):
    """Read one request from the master side, then write ``reply``; returns what was read."""
    got = b""
    while not got.endswith(terminator):
        if not select.select([master], [], [], 5)[0]:
            break
        got += os.read(master, 64)
    if reply:
        os.write(master, reply)
    return got


def test_request_and_reply_bytes_on_the_wire(pty_pair):
    master, port = pty_pair
    with ZSLD80(port, timeout_s=T) as laser:
        seen = {}
        t = threading.Thread(target=lambda: seen.update(req=_answer(master, b"+00012345678\r")))
        t.start()
        assert laser.read() == pytest.approx(92.345678, abs=1e-9)
        t.join(5)
        assert seen["req"] == b"M\r"


def test_configurable_command_and_terminator(pty_pair):
    master, port = pty_pair
    with ZSLD80(port, timeout_s=T, terminator=b"\n") as laser:
        got = {}
        t = threading.Thread(target=lambda: got.update(
            r=_answer(master, b"-00001500000\n", terminator=b"\n")))
        t.start()
        assert laser.read() == pytest.approx(78.5)
        t.join(5)
        assert got["r"] == b"M\n"


def test_no_reply_is_a_timeout(pty_pair):
    master, port = pty_pair
    with ZSLD80(port, timeout_s=0.1) as laser:
        with pytest.raises(LaserTimeout, match=r"no complete reply within 0.1 s \(got nothing\)"):
            laser.read()
        assert laser.counters.timeouts == 1


# --- poll: the per-tick read that never holds a tick (issue 16) -----------------------------
# A fake clock makes the ages exact; wait_s = 0: a poll takes what is there and returns.

def _request(master) -> bytes:
    """The request the client wrote (it must come: bounded wait)."""
    assert select.select([master], [], [], 5)[0], "no request"
    return os.read(master, 100)


def _poll_until_reading(laser):
    """Poll (clock standing still) until the reply written to the pty is taken in."""
    for _ in range(500):
        v = laser.poll()
        if v is not NO_READING:
            return v
        select.select([], [], [], 0.01)
    raise AssertionError("the reply never came through the pty")


def test_poll_returns_at_once_while_the_reply_is_awaited(pty_pair):
    master, port = pty_pair
    t = [0.0]
    with ZSLD80(port, timeout_s=0.1, wait_s=0.0, clock=lambda: t[0]) as laser:
        assert laser.poll() is NO_READING        # asked, nothing yet: the tick goes on
        assert _request(master) == b"M\r"
        for k in range(1, 6):                    # five more ticks, 10 ms apart
            t[0] = k / 100
            assert laser.poll() is NO_READING
        assert laser.counters.requests == 1      # one request in flight, never two
        assert laser.counters.pending_ticks == 6
        os.write(master, b"-00001500000\r")
        assert _poll_until_reading(laser) == pytest.approx(78.5)
        c = laser.counters
        assert (c.requests, c.readings, c.timeouts, c.expired) == (1, 1, 0, 0)
        t[0] = 0.07
        assert laser.poll() is NO_READING and laser.counters.requests == 2  # the next one


def test_poll_gives_a_silent_request_up_after_the_timeout(pty_pair):
    master, port = pty_pair
    t = [0.0]
    with ZSLD80(port, timeout_s=0.1, wait_s=0.0, clock=lambda: t[0]) as laser:
        for k in range(10):                      # 0 .. 90 ms: awaited
            t[0] = k / 100
            assert laser.poll() is NO_READING
        t[0] = 0.1
        with pytest.raises(LaserTimeout, match="no complete reply within 0.1 s"):
            laser.poll()
        assert laser.counters.timeouts == 1 and laser.counters.requests == 1
        t[0] = 0.11
        assert laser.poll() is NO_READING        # a new request, not a second timeout
        assert laser.counters.requests == 2 and laser.counters.timeouts == 1


def test_poll_expires_a_request_made_before_the_robot_moved(pty_pair):
    master, port = pty_pair
    t = [0.0]
    with ZSLD80(port, timeout_s=0.1, wait_s=0.0, max_age_s=0.05, clock=lambda: t[0]) as laser:
        assert laser.poll() is NO_READING
        t[0] = 0.06                              # polls 60 ms apart: the loop moved between
        assert laser.poll() is NO_READING
        c = laser.counters
        assert (c.requests, c.expired, c.timeouts) == (2, 1, 0)


def test_missing_port_is_a_laser_error(tmp_path):
    with pytest.raises(LaserError, match="cannot open serial port"):
        ZSLD80(str(tmp_path / "no-such-tty"))


# --- client against the emulator ----------------------------------------------------------

def test_readings_through_the_emulator():
    backend = ScriptedLaser([92.345678, None, 78.5, 65.0])
    with LaserEmulator(backend) as emu, ZSLD80(emu.port, timeout_s=T) as laser:
        got = [laser.read() for _ in range(8)]
        assert got[1] is None and got[5] is None
        assert got[0] == pytest.approx(92.345678, abs=1e-9)
        assert got[2] == pytest.approx(78.5) and got[3] == pytest.approx(65.0)
        assert got[4:] == got[:4] or got[4:][0] == pytest.approx(got[0])
        c = laser.counters
        assert (c.requests, c.readings, c.out_of_range, c.malformed, c.timeouts) == (8, 6, 2, 0, 0)
    # the emulator's thread updates these: read them once it has stopped
    assert emu.counters.requests == 8 and backend.reads == 8


def test_garbage_reply_is_an_error_and_the_next_read_recovers():
    backend = ScriptedLaser([90.0])
    with LaserEmulator(backend, faults=LaserFaults(garbage_every=2)) as emu, \
            ZSLD80(emu.port, timeout_s=T) as laser:
        assert laser.read() == pytest.approx(90.0)
        with pytest.raises(LaserError, match="malformed") as exc:
            laser.read()
        assert not isinstance(exc.value, LaserTimeout)
        assert emu.port in str(exc.value) and "\n" not in str(exc.value)
        assert laser.read() == pytest.approx(90.0)
        assert laser.counters.malformed == 1


def test_partial_reply_is_a_timeout():
    faults = LaserFaults(garbage_every=1, garbage=b"+00012")
    with LaserEmulator(ScriptedLaser([90.0]), faults=faults) as emu, \
            ZSLD80(emu.port, timeout_s=1.0) as laser:  # (the part comes well within it)
        with pytest.raises(LaserTimeout, match=r"got only b'\+00012'"):
            laser.read()


def test_silent_sensor_then_recovery():
    with LaserEmulator(ScriptedLaser([85.0]), faults=LaserFaults(silent_every=2)) as emu, \
            ZSLD80(emu.port, timeout_s=1.0) as laser:
        assert laser.read() == pytest.approx(85.0)
        with pytest.raises(LaserTimeout):
            laser.read()
        assert laser.read() == pytest.approx(85.0)
    assert emu.counters.silent == 1  # the thread has stopped


def test_late_reply_is_discarded_before_the_next_request():
    backend = ScriptedLaser([81.0, 82.0, 83.0])
    faults = LaserFaults(delay_every=1, delay_s=1.5)  # the reply on time has a second
    with LaserEmulator(backend, faults=faults) as emu, ZSLD80(emu.port, timeout_s=1.0) as laser:
        with pytest.raises(LaserTimeout):
            laser.read()                       # 81.0 arrives after the timeout
        # the late reply: written by the thread, then readable on the client's side
        assert emu.wait_until(lambda c: c.replies >= 1, 5)
        assert select.select([laser.fileno()], [], [], 5)[0]
        emu.faults.delay_every = 0
        assert laser.read() == pytest.approx(82.0)   # not the stale 81.0
        assert laser.counters.stale_bytes == 13


def test_unknown_commands_are_ignored():
    with LaserEmulator(ScriptedLaser([88.0])) as emu, \
            ZSLD80(emu.port, timeout_s=0.1, command=b"X") as laser:
        with pytest.raises(LaserTimeout):
            laser.read()
        # the client gave up after 0.1 s, whether or not the thread has read the line yet
        assert emu.wait_until(lambda c: c.unknown == 1, 5)
    assert emu.counters.unknown == 1 and emu.counters.requests == 0
