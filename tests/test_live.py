"""Issue 24's live view (``sample --live``, ``rehearse --live``): the sampling recording's
observer and blueprint, served to a viewer while the run happens, and a real-time loop
that never waits for it.

That the loop never waits is shown without a clock: a live observer whose sink stalls
for good still takes every hook at once (the chunks it cannot send are dropped and
counted), and after its construction no hook touches the recording from the loop's
thread (only the sender does). Against ``planecal emulate``, paced, a one-
sample run with --live completes while the web viewer answers, and the stream (teed
into --rrd) holds the run.
"""
from __future__ import annotations

import json
import socket
import threading
import time
import urllib.request

import numpy as np
import pytest

from planecal.cli import main
from planecal.model.scene import load_scene
from planecal.present.rerun import SamplingObserver

rr = pytest.importorskip("rerun")
pytestmark = pytest.mark.usefixtures("rerun_home")  # rerun off the real ~/.config


class StalledRec:
    """A RecordingStream stand-in: records which thread called it; once ``stall`` is set,
    every send waits until ``release``."""

    def __init__(self):
        self.calls: list[tuple[str, str]] = []
        self.stall = threading.Event()
        self.stalled = threading.Event()
        self.release = threading.Event()

    def _note(self, what):
        self.calls.append((threading.current_thread().name, what))
        if self.stall.is_set() and threading.current_thread().name == "planecal-rerun":
            self.stalled.set()  # the sender is now held, as a stalled viewer holds it
            self.release.wait()

    def log(self, path, *a, **k):
        self._note(f"log {path}")

    def send_columns(self, path, *a, **k):
        self._note(f"send {path}")

    def set_time(self, *a, **k):
        pass

    def flush(self, *a, **k):
        self._note("flush")

    def disconnect(self):
        self._note("disconnect")


def feed(obs, ticks: int, chunk: int):
    """``ticks`` ticks in calls of ``chunk``, a sample and a rejection on the way."""
    for t in range(1, ticks + 1, chunk):
        n = min(chunk, ticks - t + 1)
        d = np.zeros((n, 6), np.int64)
        cur = np.full((n, 6), 8388608, np.int64)
        obs.on_ticks(t, d, cur[0], cur, np.full(n, 80.0))
        if t == 1 + 5 * chunk:
            obs.on_sample(0, cur[0], 80.0, 0)
            obs.on_reject(None, "laser: gave up")


def test_a_live_observer_never_waits_for_a_stalled_viewer():
    scene = load_scene("thesis_final")
    rec = StalledRec()
    obs = SamplingObserver(rec, scene, chunk_ticks=50, drop_when_behind=True)
    built = len(rec.calls)
    rec.stall.set()
    loop = threading.Thread(target=feed, args=(obs, 20_000, 50), name="rt-loop")
    loop.start()
    loop.join(60)  # a hang detector, not a timing margin: 400 calls take milliseconds
    assert not loop.is_alive(), "the real-time loop waited for the viewer"
    during = rec.calls[built:]
    # the sender reached the stalled sink (whenever the scheduler ran it: no race on that)
    assert rec.stalled.wait(60)
    rec.release.set()
    obs.close()  # (the end's summary is logged by the closing thread)
    assert obs.dropped_ticks > 0 and obs.ticks_seen + obs.dropped_ticks == 20_000
    assert {who for who, _ in during} <= {"planecal-rerun"}  # never the loop's thread


def test_a_recording_observer_keeps_every_tick():
    """Without a live view nothing is dropped: a recording waits for its sender."""
    scene = load_scene("thesis_final")
    rec = StalledRec()
    obs = SamplingObserver(rec, scene, chunk_ticks=50)
    feed(obs, 2_000, 50)
    obs.close()
    assert obs.ticks_seen == 2_000 and obs.dropped_ticks == 0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_sample_live_against_emulate(tmp_path, capsys):
    """One sample, paced (3 ms ticks), against ``planecal emulate`` with --live (the
    stream teed into --rrd): it completes; the web viewer's page answered during the run;
    the stream holds the run's samples and motion. Nothing here depends on the machine's
    load: the controller keeps its reference (a stalled process never starts a new
    session) and the link waits seconds for a reply. (That the live view adds no wait on
    the loop's thread is shown without a clock by the tests above; how many ticks come
    late at real-time pacing is the machine's, not the viewer's, and no test's.)"""
    from test_links_emulate import Emulate
    from wire import BOOT_S, LASER_TIMEOUT_S, RESEND_S, SILENCE_S
    from planecal.present.rerun import summarize
    emu = Emulate("--seed", "3", "--reference", "keep")
    grpc, web = _free_port(), _free_port()
    seen: dict = {}

    def watch():  # the web viewer's page, fetched while the run goes on
        for _ in range(600):
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=1) as r:
                    seen["status"], seen["body"] = r.status, r.read(200)
                    return
            except OSError:
                time.sleep(0.05)

    argv = ["sample", "--rt", "127.0.0.1", "--rt-port", str(emu.port), "--local-port", "0",
            "--rt-tick-s", "0.003", "--rt-resend-s", str(RESEND_S),
            "--rt-silence-s", str(SILENCE_S), "--rt-boot-timeout-s", str(BOOT_S),
            "--laser", emu.tty, "--laser-timeout-s", str(LASER_TIMEOUT_S),
            "--rt-state", str(tmp_path / "fd11.state"), "--rt-fresh", "--seed", "2",
            "--samples", "1", "--out", str(tmp_path / "live.tsv"), "--live", "--live-port",
            str(grpc), "--live-web-port", str(web), "--rrd", str(tmp_path / "live.rrd")]
    try:
        watcher = threading.Thread(target=watch)
        watcher.start()
        code = main(argv)
        watcher.join(60)
    finally:
        emu.stop()
    cap = capsys.readouterr()
    assert code == 0, cap.err
    live = json.loads(cap.out)
    assert code == 0 and live["samples"] == 1
    assert live["link"]["ticks"] > 500  # paced: a few seconds of the run for the viewer
    assert live["live"]["grpc_url"] == f"rerun+http://127.0.0.1:{grpc}/proxy"
    assert seen.get("status") == 200 and b"Rerun" in seen["body"]
    entities = {e[0] for e in summarize(tmp_path / "live.rrd")}
    assert {"/samples/points", "/robot/link_3", "/laser/beam", "/series/laser_mm"} <= entities
