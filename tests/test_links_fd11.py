"""FD11 RT link over real loopback UDP: wire format, client safety, emulator behaviour."""
from __future__ import annotations

import select
import socket
import threading
import time

import numpy as np
import pytest

from planecal.links.emulators import Emulators, FD11Emulator, FD11Faults, serve
from planecal.links.fake import HOME, FakeCell
from planecal.links.fd11 import (FD11Link, LinkError, StepLimitError, pack_reply, pack_request,
                                 unpack_reply, unpack_request, wrap_diff)

LO = "127.0.0.1"
T = 0.25  # generous per-reply timeout for a loaded machine


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


def link_to(port, **kw):
    kw.setdefault("timeout_s", T)
    kw.setdefault("retries", 2)
    kw.setdefault("tick_s", 0.0)
    return FD11Link(LO, port, 0, **kw)


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
        assert (link.counters.sent, link.counters.received) == (1, 1)


def test_step_limit_refuses_and_sends_nothing(peer):
    with link_to(peer.port, timeout_s=0.05, retries=0) as link:
        with pytest.raises(StepLimitError, match="joint 2 changes by 61"):
            link.exchange([0, 61, 0, 0, 0, 0])       # measured from zero before any packet
        assert link.counters.sent == 0 and link.counters.refused == 1
        with pytest.raises(LinkError):                # 60 is allowed: sent, nobody answers
            link.exchange([0, 60, 0, 0, 0, -60])
        with pytest.raises(StepLimitError, match="joint 6 changes by 61"):
            link.exchange([0, 60, 0, 0, 0, 1])        # measured from the last sent delta
        with pytest.raises(StepLimitError):
            link.exchange([0, 60, 0, 0, 0, -121])
        with pytest.raises(LinkError):
            link.exchange([0, 0, 0, 0, 0, -60])
        assert link.counters.sent == 2 and link.counters.refused == 3
        # on the wire: exactly the two allowed packets, in order
        assert peer.recv()[0] == pack_request([0, 60, 0, 0, 0, -60])
        assert peer.recv()[0] == pack_request([0, 0, 0, 0, 0, -60])
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


def test_timeout_resends_the_same_delta_then_raises(peer):
    with link_to(peer.port, timeout_s=0.05, retries=3) as link:
        with pytest.raises(LinkError, match=r"no reply after 4 attempts"):
            link.exchange([5, 0, 0, 0, 0, -5])
        packets = [peer.recv()[0] for _ in range(4)]
        assert packets == [pack_request([5, 0, 0, 0, 0, -5])] * 4
        assert peer.recv(0.1) == (None, None)
        assert link.counters.sent == 4 and link.counters.timeouts == 4


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
        time.sleep(0.05)
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
        assert link.counters.sent == link.counters.received == 26
        assert link.counters.timeouts == link.counters.stale == link.counters.dropped == 0
        assert emu.counters.ticks == 26 and not emu.tripped


def test_fixed_ports_like_the_seed(cell):
    rt, reply = free_udp_port(), free_udp_port()
    with FD11Emulator(cell, LO, rt, reply) as emu, \
            FD11Link(LO, rt, reply, timeout_s=T, tick_s=0) as link:
        assert (emu.rt_port, link.local_port) == (rt, reply)
        link.handshake()
        _, cur = link.exchange([50, 0, 0, 0, 0, 0])
        assert cur[0] == cell.reference[0] + 50


def test_lost_replies_and_requests_are_retried(cell):
    faults = FD11Faults(drop_every=3, lose_request_every=5)
    deltas = ramp(10)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, \
            link_to(emu.rt_port, timeout_s=0.08, retries=5) as link:
        results = [link.exchange(d)[1] for d in deltas]  # resending is idempotent
        assert link.counters.timeouts >= 3
        assert link.counters.received == len(deltas)
        assert emu.counters.lost >= 3
        _clean_tick_is_exact(link, emu, cell, deltas[-1])
    _answers_to_sent_deltas(results, deltas, cell.reference)


def _answers_to_sent_deltas(results, deltas, ref):
    """Without sequence numbers a late or duplicated reply can answer the next request: each
    result must be the answer to this tick's delta or an earlier one, never a later one."""
    sent = [np.zeros(6, np.int64)]
    for i, cur in enumerate(results):
        sent.append(deltas[i])
        assert any(np.array_equal(cur, ref + d) for d in sent[-4:]), (i, cur - ref)


def _clean_tick_is_exact(link, emu, cell, delta):
    emu.faults = FD11Faults()
    time.sleep(0.3)  # everything in flight arrives; the next drain discards it
    _, cur = link.exchange(delta)
    np.testing.assert_array_equal(cur, cell.reference + delta)


def test_delayed_replies_are_drained(cell):
    faults = FD11Faults(delay_every=5, delay_s=0.25)
    deltas = ramp(6)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, \
            link_to(emu.rt_port, timeout_s=0.08, retries=8) as link:
        results = [link.exchange(d)[1] for d in deltas]
        _clean_tick_is_exact(link, emu, cell, deltas[-1])
    _answers_to_sent_deltas(results, deltas, cell.reference)
    assert link.counters.timeouts >= 2 and link.counters.stale >= 2


def test_duplicated_replies_are_drained(cell):
    faults = FD11Faults(duplicate_every=1)
    deltas = ramp(20)
    with FD11Emulator(cell, LO, 0, None, faults=faults) as emu, link_to(emu.rt_port) as link:
        results = [link.exchange(d)[1] for d in deltas]
        assert emu.counters.replies == 2 * len(deltas)
        _clean_tick_is_exact(link, emu, cell, deltas[-1])
    _answers_to_sent_deltas(results, deltas, cell.reference)
    assert link.counters.stale >= len(deltas) - 1


# --- emulator alone, driven by a raw socket --------------------------------------------------

class RawClient(RawPeer):
    def __init__(self, emu):
        super().__init__()
        self.dest = (LO, emu.rt_port)

    def send(self, data, timeout=T):
        self.sock.sendto(data, self.dest)
        return self.recv(timeout)[0]


def test_emulator_ignores_invalid_packets(cell):
    with FD11Emulator(cell, LO, 0, None) as emu:
        c = RawClient(emu)
        bad = bytearray(pack_request([1, 0, 0, 0, 0, 0]))
        bad[24:28] = b"\x00\x00\x00\x00"
        for data in (b"", b"\x00" * 47, b"\x00" * 49, bytes(bad)):
            c.sock.sendto(data, c.dest)
        # the first reply is the one to the valid packet sent after the invalid ones
        assert c.send(pack_request([1, 0, 0, 0, 0, 0])) == pack_reply(
            cell.reference, cell.reference + [1, 0, 0, 0, 0, 0])
        assert emu.counters.invalid == 4 and cell.ticks == 1
        c.close()


def test_emulator_trips_silently_on_jump_over_60(cell):
    with FD11Emulator(cell, LO, 0, None) as emu:
        c = RawClient(emu)
        assert c.send(pack_request([0] * 6)) is not None
        assert c.send(pack_request([60, 0, 0, 0, 0, -60])) is not None  # exactly 60: fine
        assert c.send(pack_request([60, 0, 0, 61, 0, -60]), 0.1) is None  # joint 4 jumps 61
        assert emu.tripped and "joint 4" in emu.trip_reason and "61" in emu.trip_reason
        assert c.send(pack_request([60, 0, 0, 0, 0, -60]), 0.1) is None  # brakes: silent
        assert cell.ticks == 2 and emu.counters.ignored_tripped == 1
        emu.reset_trip()
        assert c.send(pack_request([60, 0, 0, 10, 0, -60])) is not None
        c.close()


def test_emulator_trip_hold_answers_without_moving(cell):
    with FD11Emulator(cell, LO, 0, None, trip_mode="hold") as emu:
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
            link_to(emu.rt_port, timeout_s=0.05, retries=1) as link:
        with pytest.raises(LinkError):
            link.handshake()
        assert emu.tripped and "collision with plate 0" in emu.trip_reason


def test_serve_runs_both_until_stopped(cell):
    from planecal.links.zs_ld80 import ZSLD80
    ready, stop = {}, threading.Event()
    t = threading.Thread(target=serve, args=(cell,),
                         kwargs=dict(host=LO, rt_port=0, reply_port=None, stop=stop,
                                     on_ready=lambda e: ready.update(e=e)))
    t.start()
    for _ in range(100):
        if "e" in ready:
            break
        time.sleep(0.05)
    emus: Emulators = ready["e"]
    assert any("UDP" in line for line in emus.describe())
    with link_to(emus.fd11.rt_port) as link, ZSLD80(emus.laser.port, timeout_s=T) as laser:
        link.handshake()
        link.exchange([50, 0, 0, 0, 0, 0])
        assert laser.read() == pytest.approx(80.005, abs=1e-9)
    stop.set()
    t.join(5)
    assert not t.is_alive()


def test_emulate_command_without_twin_fails_in_one_line(capsys, monkeypatch):
    import sys
    from planecal.cli import main
    monkeypatch.setitem(sys.modules, "planecal.twin", None)  # as if the twin were absent
    assert main(["emulate", "--rt-port", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "twin" in err


# --- the twin behind the wires --------------------------------------------------------------

def test_twin_over_udp_and_pty_matches_in_process_twin():
    pytest.importorskip("mujoco")
    twin_mod = pytest.importorskip("planecal.twin")
    from planecal.links.zs_ld80 import ZSLD80, decode_reply, encode_reply

    local = twin_mod.Twin("thesis_final", seed=3)     # default options: lag servo, laser noise
    remote = twin_mod.Twin("thesis_final", seed=3)
    move = ramp(20, joints=(1, 0, 0, 0, 1, -1))
    path = [np.zeros(6, np.int64)] + move + [move[-1]] * 10   # move 1000 counts, then dwell
    with Emulators(remote, host=LO, rt_port=0, reply_port=None) as emus, \
            link_to(emus.fd11.rt_port) as link, ZSLD80(emus.laser.port, timeout_s=T) as laser:
        for d in path:
            ref_w, cur_w = link.exchange(d)
            mm_w = laser.read()
            ref_l, cur_l = local.exchange(d)
            mm_l = local.read()
            np.testing.assert_array_equal(ref_w, ref_l)
            np.testing.assert_array_equal(cur_w, cur_l)
            assert mm_w == decode_reply(encode_reply(mm_l))  # identical at the wire's 1e-6 mm
        assert mm_w is not None
        assert link.counters.timeouts == 0 and laser.counters.malformed == 0
    assert remote.ticks == local.ticks == len(path)


def _default_sigint():
    """In the child: SIGINT back to its default, so Python raises KeyboardInterrupt on it
    even when the test runner was started in the background (SIGINT ignored, inherited)."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_planecal_emulate_serves_the_twin():
    pytest.importorskip("mujoco")
    twin_mod = pytest.importorskip("planecal.twin")
    import os
    import re
    import signal
    import subprocess
    import sys
    from planecal.links.zs_ld80 import ZSLD80, decode_reply, encode_reply

    env = dict(os.environ, MUJOCO_GL="disable")
    proc = subprocess.Popen([sys.executable, "-m", "planecal.cli", "emulate", "--seed", "3",
                             "--errors", "ideal", "--rt-port", "0", "--reply-port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=_default_sigint)
    guard = threading.Timer(60, proc.kill)  # never hang the suite
    guard.start()
    try:
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("running"):
                break
        text = "".join(lines)
        assert "running" in text, text + proc.stderr.read()
        port = int(re.search(r"UDP 127\.0\.0\.1:(\d+)", text).group(1))
        tty_path = re.search(r"serial device (\S+)", text).group(1)
        local = twin_mod.Twin("thesis_final", seed=3)
        with link_to(port, timeout_s=1.0) as link, ZSLD80(tty_path, timeout_s=1.0) as laser:
            for d in [np.zeros(6, np.int64)] + ramp(3, joints=(1, 0, 0, 0, 0, 0)):
                ref_w, cur_w = link.exchange(d)
                ref_l, cur_l = local.exchange(d)
                np.testing.assert_array_equal(ref_w, ref_l)
                np.testing.assert_array_equal(cur_w, cur_l)
                assert laser.read() == decode_reply(encode_reply(local.read()))
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        guard.cancel()
    assert proc.returncode == 130 and "interrupted" in err


def test_emulate_twin_is_the_profiles_world():
    """`emulate --errors` (default realistic) serves the twin rehearse would make."""
    pytest.importorskip("mujoco")
    import argparse
    from planecal.commands import emulate
    from planecal.commands.rehearse import make_twin
    from planecal.scene import load_scene
    p = argparse.ArgumentParser()
    emulate.add_arguments(p)
    scene = load_scene("thesis_final")
    for argv, errors in (([], "realistic"), (["--errors", "ideal"], "ideal")):
        got = emulate._make_twin(p.parse_args(["--seed", "3"] + argv))
        want = make_twin(scene, 3, errors)
        assert got.options == want.options
        np.testing.assert_array_equal(got.truth.joint_offsets, want.truth.joint_offsets)
        np.testing.assert_array_equal(got.true_kinematics.a, want.true_kinematics.a)
    assert emulate._make_twin(p.parse_args(["--errors", "ideal"])).options.quantization is False
