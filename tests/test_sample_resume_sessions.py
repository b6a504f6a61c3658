"""Issue 25: a resume that cannot jump. `planecal sample` is stopped mid-move by SIGINT,
SIGTERM or SIGKILL and resumed, against an emulated controller of the kind each test
names: one that takes a fresh reference (the robot's counts) after 2 s of silence, as the
independent FD11 peer did, and one that keeps its reference; and on a cell that does not
state which. Every datagram the controller receives is recorded with its arrival time,
and the step each request asks for (its delta minus the delta the controller holds) is
recomputed from them alone, independently of the emulator's own count: none is above 51
counts. Each run completes, or stops before any motion with one line."""
from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pytest

from planecal.cli import main
from planecal.io.samples import read_samples
from planecal.links.emulators import FD11Emulator
from planecal.links.laser_emulator import LaserEmulator
from planecal.links.fd11 import unpack_request
from planecal.links.sessions import StateFile, default_state_path
from planecal.sampling.runfiles import load_sidecar
from wire import sample_argv, stated_scene

mujoco = pytest.importorskip("mujoco")
twin_mod = pytest.importorskip("planecal.twin")

SILENCE_S = 2.0  # the controller's (and the emulated peer's) silence before a new reference
MOVING = 300     # moving ticks before the signal: on the way to the first sample (587 of seed 2)
STEP_LIMIT = 51
EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGKILL: -signal.SIGKILL}


class RecordingFD11(FD11Emulator):
    """The emulated FD11, also keeping every datagram it receives: (arrival, sender, bytes)."""

    def __init__(self, *a, **k):
        super().__init__(*a, **k)
        self.received: list[tuple[float, tuple, bytes]] = []

    def handle(self, data, addr):
        self.received.append((time.monotonic(), addr, data))
        return super().handle(data, addr)


def steps(received, behaviour: str) -> np.ndarray:
    """Per valid request, the largest |delta - held| over the joints, from the datagrams
    alone: the controller holds delta 0 at its start and after a fresh reference (a request
    after SILENCE_S without any, or from a new client, by ``behaviour``), else the last
    delta it received."""
    held, last_t, last_addr, out = np.zeros(6, np.int64), None, None, []
    for t, addr, data in received:
        try:
            d = unpack_request(data)
        except ValueError:
            continue
        if last_t is not None and (
                behaviour == "fresh_after_silence" and t - last_t >= SILENCE_S
                or behaviour == "fresh_each_client" and addr != last_addr):
            held = np.zeros(6, np.int64)
        out.append(int(np.abs(d - held).max()))
        held, last_t, last_addr = d, t, addr
    return np.array(out, np.int64)


@contextmanager
def controller(behaviour: str, trip_mode: str = "silent"):
    """The twin (seed 2) behind a recording FD11 emulator of ``behaviour`` and a laser."""
    twin = twin_mod.Twin("thesis_final", seed=2)
    lock = threading.Lock()
    fd11 = RecordingFD11(twin, "127.0.0.1", 0, None, lock=lock, reference_mode=behaviour,
                         session_gap_s=SILENCE_S, trip_mode=trip_mode)
    laser = LaserEmulator(twin, lock=lock)
    fd11.start()
    laser.start()
    try:
        yield fd11, laser
    finally:
        fd11.stop()
        laser.stop()
        twin.close()


def _default_signals():
    """In the child: the signals at their defaults (a test runner started in the
    background ignores SIGINT, and the child would inherit that)."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


@dataclass
class Stopped:
    code: int
    err: str
    datagrams: int  # the controller's count when the process had ended


def start_and_stop(fd11, laser, out, sig, *flags) -> Stopped:
    """`planecal sample --samples 2` in a subprocess, ``sig`` once the robot has made
    MOVING moving ticks (mid-move, before the first sample)."""
    argv = sample_argv(fd11.rt_port, laser.port, out, "--samples", "2", *flags)
    proc = subprocess.Popen([sys.executable, "-m", "planecal.cli", *argv],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_default_signals)
    try:
        deadline = time.monotonic() + 120
        while not fd11.wait_until(lambda c: c.moves >= MOVING, 0.5):
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    # the last packets' replies may still be on their way: let the thread take them all
    assert fd11.idle(5)
    return Stopped(proc.returncode, err, fd11.snapshot().datagrams)


def resume(fd11, laser, out, capsys, *flags):
    """The resume, in this process: (exit code, summary or None, stderr)."""
    code = main(sample_argv(fd11.rt_port, laser.port, out, "--resume", *flags))
    cap = capsys.readouterr()
    summary = json.loads(cap.out[cap.out.index("{"):]) if "{" in cap.out else None
    return code, summary, cap.err


def check_stopped(stopped: Stopped, sig, out) -> None:
    """The interrupted run: its exit code, and a sidecar that says why (SIGKILL: none can)."""
    assert stopped.code == EXIT[sig], stopped.err
    side = load_sidecar(out)
    if sig == signal.SIGKILL:
        assert side["status"] == "running"  # nothing ran after the kill
        return
    name = signal.Signals(sig).name
    assert stopped.err.strip().splitlines()[-1] == f"planecal sample: interrupted ({name})"
    assert "Traceback" not in stopped.err
    assert side["status"] == "stopped" and side["stop_reason"] == f"interrupted ({name})"
    assert not (out.parent / (out.name + ".lock")).exists()


@pytest.mark.parametrize("behaviour, sig", [
    (b, s) for b in ("fresh_after_silence", "keep")
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL)] + [
    ("fresh_each_client", signal.SIGTERM)],
    ids=lambda v: v.name if isinstance(v, signal.Signals) else v)
def test_a_signal_mid_move_then_a_resume_never_jumps(tmp_path, capsys, behaviour, sig):
    """Stated fresh_after_silence (2 s): the resume waits until 2.5 s have passed since the
    last packet (the state file's time) and starts from delta 0 on a fresh reference.
    Stated keep: it repeats the last delta the controller answered (after SIGKILL the
    controller may hold one step more, still within 51). Both complete; no request asks
    for more than 51 counts; the controller never trips. After SIGKILL the resume comes
    late (3 s after the last packet, as in the issue: nothing left to wait). Stated
    fresh_each_client: the resume's new port is a new client, so delta 0 at once."""
    scene = stated_scene(tmp_path, behaviour,
                         SILENCE_S if behaviour == "fresh_after_silence" else None)
    out = tmp_path / "RUN.tsv"
    with controller(behaviour) as (fd11, laser):
        stopped = start_and_stop(fd11, laser, out, sig, "--scene", str(scene))
        check_stopped(stopped, sig, out)
        last = StateFile.read(default_state_path(("127.0.0.1", fd11.rt_port)))
        assert last is not None and np.abs(last.delta).max() > 1000  # far from 0: mid-move
        late = sig == signal.SIGKILL
        if late:
            time.sleep(max(0.0, fd11.received[-1][0] + SILENCE_S + 1.0 - time.monotonic()))
        t0 = time.monotonic()
        code, s, err = resume(fd11, laser, out, capsys)
        assert fd11.idle(5)
        got = steps(fd11.received, behaviour)
        c = fd11.snapshot()
    assert code == 0, err
    assert s["status"] == "complete" and s["samples"] == 2 and s["sessions"] == 2
    assert len(read_samples(out)) == 2
    assert not fd11.tripped and c.sessions == 2
    assert got.max() <= STEP_LIMIT and got.max() == c.max_step, (got.max(), c.max_step)
    assert got[stopped.datagrams] <= STEP_LIMIT  # the resume's first packet (0 as a rule)
    first = s["first_contact"]
    assert load_sidecar(out)["real_cell"]["first_contact"] == first
    # what the first reply showed: the reference the state file recorded, or a new one
    assert first["observed_reference"] == ("kept" if behaviour == "keep" else "new")
    if behaviour == "keep":
        assert first["kind"] == "kept" and s["link"]["boot_wait_s"] < 1.0
        assert c.fresh_references == 0 and first["waited_s"] == 0
    elif behaviour == "fresh_each_client":
        assert first["kind"] == "fresh" and c.fresh_references == 1 and first["waited_s"] == 0
        assert first["client"] != last.client and "note: waiting" not in err
    else:
        assert first["kind"] == "fresh" and c.fresh_references == 1
        assert 0 <= first["waited_s"] <= SILENCE_S + 0.5 and (first["waited_s"] == 0) >= late
        assert ("note: waiting" in err) == (first["waited_s"] > 0)
        # the first packet of the resume came after the whole silence and its margin
        gap = max(b[0] - a[0] for a, b in zip(fd11.received, fd11.received[1:]))
        assert gap >= SILENCE_S + 0.5 - 0.05 and time.monotonic() - t0 >= first["waited_s"]
    print(f"{behaviour} {signal.Signals(sig).name}: {len(got)} requests, largest step "
          f"{got.max()} counts, the resume's first packet a step of "
          f"{got[stopped.datagrams]} ({first['kind']}), waited {first['waited_s']} s")


def test_a_resume_on_a_cell_that_states_nothing_asks_and_sends_nothing(tmp_path, capsys):
    """The MC70's robot.json does not state what its controller does (appendix C leaves
    it open); the controller here takes a fresh reference after 2 s, as the independent
    peer did. After SIGINT mid-move the resume asks in one line, exit 2, naming --rt-fresh
    and --rt-keep, and sends nothing (no file touched, no lock left). Stated by the
    operator once 2.5 s have passed (--rt-fresh, now true), the run completes; no request
    asks for more than 51 counts."""
    out = tmp_path / "RUN.tsv"
    with controller("fresh_after_silence") as (fd11, laser):
        stopped = start_and_stop(fd11, laser, out, signal.SIGINT)
        check_stopped(stopped, signal.SIGINT, out)
        files = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
        code, s, err = resume(fd11, laser, out, capsys)
        assert code == 2 and s is None
        lines = [ln for ln in err.strip().splitlines() if not ln.startswith("note: ")]
        assert len(lines) == 1 and lines[0].startswith("planecal sample: error: "), err
        assert "mc70/robot.json: controller.sessions is not stated" in lines[0]
        assert "not stated" in lines[0] and "--rt-fresh" in lines[0] and "--rt-keep" in lines[0]
        assert fd11.snapshot().datagrams == stopped.datagrams  # nothing sent
        assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == files
        # the operator knows the controller took a fresh reference once it was silent
        quiet = fd11.received[-1][0] + SILENCE_S + 0.5 - time.monotonic()
        time.sleep(max(0.0, quiet))
        code, s, err = resume(fd11, laser, out, capsys, "--rt-fresh")
        assert fd11.idle(5)
        got = steps(fd11.received, "fresh_after_silence")
    assert code == 0, err
    assert s["status"] == "complete" and s["samples"] == 2
    assert s["first_contact"]["kind"] == "fresh" and "--rt-fresh" in s["first_contact"]["why"]
    assert not fd11.tripped and got.max() <= STEP_LIMIT and got.max() == fd11.counters.max_step
    print(f"unstated SIGINT: {len(got)} requests, largest step {got.max()} counts")


def test_a_cell_stated_wrongly_stops_after_its_first_packet(tmp_path, capsys):
    """The cell states fresh_after_silence, but the controller keeps its reference (and,
    tripped, still answers: trip mode hold). The resume waits out the silence and sends
    delta 0, which the controller measures from the last delta it holds: the jump a wrong
    statement cannot see. The first reply shows it (commanded - current is that delta):
    one line, exit 1, nothing more sent, the robot where it stood."""
    scene = stated_scene(tmp_path, "fresh_after_silence", SILENCE_S)
    out = tmp_path / "RUN.tsv"
    with controller("keep", trip_mode="hold") as (fd11, laser):
        stopped = start_and_stop(fd11, laser, out, signal.SIGTERM, "--scene", str(scene))
        check_stopped(stopped, signal.SIGTERM, out)
        held = fd11.last_delta.copy()
        code, s, err = resume(fd11, laser, out, capsys)
        assert fd11.idle(5)
        c = fd11.snapshot()
    assert code == 1 and s is None
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith(("note: ", "samples "))]
    assert len(lines) == 1, err
    assert "the first reply does not fit the first packet" in lines[0]
    assert "nothing more sent" in lines[0]
    gap = json.loads(re.search(r"commanded - current = (\[[-0-9, ]+\])", lines[0]).group(1))
    np.testing.assert_allclose(gap, -held, atol=5)  # the robot stood at the held delta
    assert c.datagrams - stopped.datagrams == 1  # the one first packet
    assert fd11.tripped and c.max_step == int(np.abs(held).max())
    print(f"wrong statement: one packet, step {c.max_step} counts, then stopped")


def test_rt_fresh_right_after_a_stop_waits_out_the_silence_and_a_complete_run_ends_at_once(
        tmp_path, capsys):
    """A cell stated fresh_after_silence (2 s); SIGINT mid-move, then at once `--resume
    --rt-fresh` (the operator's statement): the first packet of 0 still waits until the
    controller has been silent 2 s and the margin -- sent earlier, it would be measured
    from the old reference (the issue's 36,400 counts). The run completes, no request asks
    for more than 51 counts. A resume of the complete run ends before any contact
    ("nothing to do"): not one packet more, with --rt-fresh or without."""
    scene = stated_scene(tmp_path, "fresh_after_silence", SILENCE_S)
    out = tmp_path / "RUN.tsv"
    with controller("fresh_after_silence") as (fd11, laser):
        stopped = start_and_stop(fd11, laser, out, signal.SIGINT, "--scene", str(scene))
        check_stopped(stopped, signal.SIGINT, out)
        code, s, err = resume(fd11, laser, out, capsys, "--rt-fresh")
        assert fd11.idle(5)
        got = steps(fd11.received, "fresh_after_silence")
        sent = fd11.snapshot().datagrams
        for flags in ((), ("--rt-fresh",)):
            again = resume(fd11, laser, out, capsys, *flags)
            assert again[0] == 0 and again[1] is None and "nothing to do" in again[2]
        assert fd11.idle(2) and fd11.snapshot().datagrams == sent  # not one packet
    assert code == 0, err
    assert s["status"] == "complete" and s["samples"] == 2
    first = s["first_contact"]
    assert first["kind"] == "fresh" and "--rt-fresh" in first["why"]
    assert not fd11.tripped and got.max() <= STEP_LIMIT and got[stopped.datagrams] == 0
    gap = max(b[0] - a[0] for a, b in zip(fd11.received, fd11.received[1:]))
    assert gap >= SILENCE_S + 0.5 - 0.05
    # the resume decides the wait after its own start-up, which on a loaded machine can
    # outlast the silence (then nothing is left to wait: the gap above holds either way);
    # a wait is said, and no longer than the silence and its margin
    assert (first["waited_s"] > 0) == ("note: waiting" in err)
    assert first["waited_s"] <= SILENCE_S + 0.5


def test_a_resume_whose_state_file_is_missing_asks_and_sends_nothing(tmp_path, capsys,
                                                                     monkeypatch):
    """A run stopped mid-move, resumed with another $PLANECAL_STATE_DIR (another user, a
    moved home): the controller's state file is not there, but the run's sidecar records
    an earlier session. Sending delta 0 would be a guess (a jump of the last delta on a
    controller that kept its reference): the resume asks in one line (exit 2) naming
    --rt-fresh and --rt-keep, and sends nothing."""
    scene = stated_scene(tmp_path, "keep")
    out = tmp_path / "RUN.tsv"
    with controller("keep") as (fd11, laser):
        stopped = start_and_stop(fd11, laser, out, signal.SIGTERM, "--scene", str(scene))
        check_stopped(stopped, signal.SIGTERM, out)
        monkeypatch.setenv("PLANECAL_STATE_DIR", str(tmp_path / "elsewhere"))
        for flags in ((), ("--rt-keep",)):
            code, s, err = resume(fd11, laser, out, capsys, *flags)
            lines = [ln for ln in err.strip().splitlines() if not ln.startswith("note: ")]
            assert code == 2 and s is None and len(lines) == 1, err
            assert "records an earlier session" in lines[0] and "--rt-fresh" in lines[0] \
                and "--rt-keep" in lines[0]
        assert fd11.idle(1) and fd11.snapshot().datagrams == stopped.datagrams
    assert not (tmp_path / "elsewhere").exists()
