"""`planecal rehearse` and `planecal sample` end to end (twin; FD11 and ZS-LD80 emulators)."""
import json

import numpy as np
import pytest

from planecal.cli import main
from planecal.io.params import load_params
from planecal.io.samples import read_samples
from planecal.sampling.runfiles import load_sidecar
from planecal.base.progress import Progress
from planecal.sampling.session import close_run, show_run
from planecal.sampling.run import RunStats
from wire import sample_argv

pytest.importorskip("planecal.twin")


def run_cli(argv, capsys):
    code = main(argv)
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_rehearse_writes_samples_sidecar_truth_and_summary(tmp_path, capsys):
    out, truth = tmp_path / "RUN.tsv", tmp_path / "TRUTH.json"
    code, stdout, stderr = run_cli(["rehearse", "--samples", "6", "--seed", "4", "--out", str(out),
                                    "--truth-out", str(truth)], capsys)
    assert code == 0, stderr
    summary = json.loads(stdout)
    for key in ("samples", "rejected_collision", "rejected_laser", "rejected_unreachable",
                "max_step_counts", "robot_time_s", "wall_time_s"):
        assert key in summary
    assert summary["samples"] == 6 and summary["status"] == "complete"
    assert 0 < summary["max_step_counts"] <= 51
    assert summary["robot_time_s"] == pytest.approx(summary["ticks"] * 0.01)
    s = read_samples(out)
    assert len(s) == 6 and np.all((s.d_mm > 65) & (s.d_mm < 95))
    side = load_sidecar(out)
    assert side["samples"] == 6 and side["twin"] == {"seed": 4, "exact": False,
                                                        "errors": "realistic",
                                                        "truth_seed": 4,
                                                        "truth_file": None,
                                                        "truth_sha256": None}
    assert side["settings"]["collision_checking"] is True
    t = load_params(truth)
    assert np.any(t.joint_offsets != 0)
    # stderr is not a TTY here: plain progress lines
    assert "samples 6/6" in stderr
    # no litter: the lock went with the run
    assert sorted(f.name for f in tmp_path.iterdir()) == ["RUN.tsv", "RUN.tsv.json", "TRUTH.json"]


def test_rehearse_resume_extends_the_run(tmp_path, capsys):
    out = tmp_path / "RUN.tsv"
    code, _, _ = run_cli(["rehearse", "--samples", "3", "--seed", "5", "--out", str(out)], capsys)
    assert code == 0
    first = read_samples(out)
    code, stdout, stderr = run_cli(["rehearse", "--resume", "--samples", "5", "--cone-deg", "10",
                                    "--out", str(out)], capsys)
    assert code == 0, stderr
    assert "ignoring --cone-deg" in stderr
    s = read_samples(out)
    assert len(s) == 5 and np.array_equal(s.qe[:3], first.qe)
    assert len({tuple(r) for r in s.qe}) == 5
    summary = json.loads(stdout)
    assert summary["sessions"] == 2 and summary["samples"] == 5
    # the file's direction group goes on (the new session's own directions after it)
    assert s.direction.shape == (5, 6) and np.array_equal(s.direction[:3], first.direction)


def test_resume_continues_a_file_begun_without_the_direction_group(tmp_path, capsys):
    """A run begun by a planecal that recorded no approach direction (its file without
    dir1..dir6) is continued without it: one file, one set of columns."""
    out = tmp_path / "RUN.tsv"
    assert run_cli(["rehearse", "--samples", "2", "--seed", "5", "--out", str(out)],
                   capsys)[0] == 0
    lines = out.read_text().splitlines()
    assert lines[0].endswith("Dm\tdir1\tdir2\tdir3\tdir4\tdir5\tdir6")
    out.write_text("".join("\t".join(ln.split("\t")[:7]) + "\n" for ln in lines))
    code, _, stderr = run_cli(["rehearse", "--resume", "--samples", "3", "--out", str(out)],
                              capsys)
    assert code == 0, stderr
    s = read_samples(out)
    assert len(s) == 3 and s.direction is None
    assert all(len(ln.split("\t")) == 7 for ln in out.read_text().splitlines())


@pytest.mark.parametrize("argv, msg", [
    (["--samples", "0"], "--samples: 0 is not a count (1 .. 100_000)"),
    (["--cone-deg", "95"], "cone half-angle"),
    (["--fixed-distance-mm", "120"], "laser range"),
    (["--distance-mm", "90", "70"], "LO 90.0 is above HI 70.0"),
    (["--scene", "no_such_scene"], "not found"),
    (["--resume"], "no run sidecar"),
])
def test_rehearse_bad_input_is_one_line_exit_2(tmp_path, capsys, argv, msg):
    code, stdout, stderr = run_cli(["rehearse", "--out", str(tmp_path / "R.tsv")] + argv, capsys)
    assert code == 2
    assert msg in stderr and len(stderr.strip().splitlines()) == 1


def test_rehearse_refuses_to_overwrite_a_run(tmp_path, capsys):
    out = tmp_path / "RUN.tsv"
    out.write_text("q1\tq2\tq3\tq4\tq5\tq6\tDm\n")
    code, _, stderr = run_cli(["rehearse", "--samples", "1", "--out", str(out)], capsys)
    assert code == 2 and "use --resume" in stderr


def test_a_second_run_on_the_same_file_is_refused(tmp_path, capsys):
    from planecal.sampling.runfiles import RunLock

    out = tmp_path / "RUN.tsv"
    out.write_text("q1\tq2\tq3\tq4\tq5\tq6\tDm\n1\t2\t3\t4\t5\t6\t80.0\n")
    before = out.read_bytes()
    lock = RunLock(out)  # as a run in another process holds it
    try:
        code, _, stderr = run_cli(["rehearse", "--samples", "1", "--out", str(out), "--force"],
                                  capsys)
        assert code == 2 and "another run is writing this file" in stderr
        assert out.read_bytes() == before  # nothing truncated or written
    finally:
        lock.close()
    code, _, _ = run_cli(["rehearse", "--samples", "1", "--out", str(out), "--force"], capsys)
    assert code == 0


@pytest.mark.parametrize("sig, group, code", [
    ("SIGINT", True, 130),   # Ctrl-C: the terminal signals the whole process group
    ("SIGTERM", False, 143),  # kill PID, a process manager's stop
    ("SIGTERM", True, 143),  # systemd's default: every process of the unit
    ("SIGHUP", True, 130),   # the terminal closed
])
def test_a_signal_stops_cleanly(tmp_path, sig, group, code):
    """Each signal a user or a process manager sends ends the run as Ctrl-C does: the run
    stops, the sidecar says so and names the signal, the file is valid, one line on stderr,
    no lock file left, and the forked planner process goes too (no traceback from it)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    def defaults():
        for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            signal.signal(s, signal.SIG_DFL)

    out = tmp_path / "RUN.tsv"
    p = subprocess.Popen([sys.executable, "-m", "planecal.cli", "rehearse", "--samples", "5000",
                          "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, start_new_session=True, preexec_fn=defaults)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            time.sleep(0.2)
            if out.exists() and out.read_text().count("\n") >= 4:
                break
        signum = signal.Signals[sig]
        os.killpg(p.pid, signum) if group else os.kill(p.pid, signum)
        stdout, stderr = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == code, stderr
    assert stderr.strip().splitlines()[-1] == f"planecal rehearse: interrupted ({sig})"
    assert "Traceback" not in stderr
    side = load_sidecar(out)
    assert side["status"] == "stopped" and side["stop_reason"] == f"interrupted ({sig})"
    assert len(read_samples(out)) == side["samples"] >= 3
    assert sorted(f.name for f in tmp_path.iterdir()) == ["RUN.tsv", "RUN.tsv.json"]
    deadline = time.monotonic() + 10  # the planner ends when the run's pipe closes
    while time.monotonic() < deadline:
        try:
            os.killpg(p.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        raise AssertionError("a process of the run outlived it")


def test_rehearse_with_rrd_records_the_run(tmp_path, capsys):
    rrd = tmp_path / "run.rrd"
    code, stdout, stderr = run_cli(["rehearse", "--samples", "2", "--out", str(tmp_path / "R.tsv"),
                                    "--rrd", str(rrd)], capsys)
    assert code == 0, stderr
    assert json.loads(stdout)["rrd"] == str(rrd)
    assert rrd.exists() and rrd.stat().st_size > 0


def test_sample_against_the_emulators(tmp_path, capsys):
    """The real-cell command over UDP and a pty, with the twin behind the emulators."""
    from planecal.links.emulators import Emulators
    from planecal.twin import Twin

    twin = Twin("thesis_final", seed=2)
    out = tmp_path / "RUN.tsv"
    with Emulators(twin, rt_port=0, reply_port=None) as emu:
        code, stdout, stderr = run_cli(
            sample_argv(emu.fd11.rt_port, emu.laser.port, out, "--samples", "3"), capsys)
        assert not emu.fd11.tripped
    assert code == 0, stderr
    summary = json.loads(stdout)
    assert summary["samples"] == 3 and summary["max_step_counts"] <= 51
    assert summary["link"]["lost_replies"] == 0 and summary["laser_read_errors"] == 0
    s = read_samples(out)
    assert len(s) == 3
    # the samples are the twin's: its reading at those counts (noise ~1 um)
    assert np.array_equal(s.qe[-1], twin.current_counts)
    assert abs(twin.hit().distance_m * 1e3 - s.d_mm[-1]) < 0.01
    assert load_sidecar(out)["real_cell"]["rt"] == "127.0.0.1"


def test_sample_stops_cleanly_when_the_dead_man_switch_is_released(tmp_path, capsys):
    """Behind the emulator the robot stops following after 1300 moving ticks (released):
    the command notices by the following lag, sends nothing more, exits 1, files valid."""
    from planecal.links.emulators import Emulators
    from planecal.twin import Twin

    class Released:
        def __init__(self, twin, at):
            self.twin, self.at, self.n, self.frozen = twin, at, 0, None
            self.first_move = None  # the first tick after release that commands motion
            self.moves, self.last = 0, None  # ticks commanding motion (holds vary with speed)

        def exchange(self, delta):
            self.n += 1
            self.moves += self.last is not None and np.any(np.asarray(delta) != self.last)
            self.last = np.asarray(delta).copy()
            if self.frozen is None and self.moves <= self.at:
                return self.twin.exchange(delta)
            if self.first_move is None and np.any(np.asarray(delta) != 0):
                self.first_move = self.n
            if self.frozen is None:
                self.frozen = self.twin.current_counts
            return self.twin.reference_counts, self.frozen.copy()

        def close(self):
            pass

    twin = Twin("thesis_final", seed=2)
    robot = Released(twin, 1300)  # moving ticks: on the way to the second sample
    out = tmp_path / "RUN.tsv"
    with Emulators(robot, twin, rt_port=0, reply_port=None) as emu:
        code, stdout, stderr = run_cli(
            sample_argv(emu.fd11.rt_port, emu.laser.port, out, "--samples", "5"), capsys)
    assert code == 1
    summary = json.loads(stdout)
    assert summary["status"] == "stopped" and "dead-man" in summary["stop_reason"]
    # a robot at rest cannot tell a released switch from a held one; the first commanded
    # move after the release shows it by the following lag, within ~17 ticks
    assert robot.first_move is not None
    assert robot.n - robot.first_move <= 600 // 50 + 5 + 1
    assert len(read_samples(out)) == summary["samples"] >= 1
    assert load_sidecar(out)["status"] == "stopped"


def test_sample_unreachable_controller_is_an_input_error(tmp_path, capsys):
    code, _, stderr = run_cli(["sample", "--rt", "no.such.host.invalid", "--out",
                               str(tmp_path / "R.tsv")], capsys)
    assert code == 2 and "--rt no.such.host.invalid" in stderr


def test_sample_with_a_silent_controller_stops_with_one_line(tmp_path, capsys):
    import os
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]  # bound but never answering
        master, slave = os.openpty()
        try:
            code, _, stderr = run_cli(["sample", "--rt", "127.0.0.1", "--rt-port", str(port),
                                       "--local-port", "0", "--rt-boot-timeout-s", "0.3",
                                       "--laser", os.ttyname(slave),
                                       "--out", str(tmp_path / "R.tsv")], capsys)
        finally:
            os.close(master)
            os.close(slave)
    assert code == 1 and "no reply" in stderr and "nothing sampled" in stderr
    assert len(stderr.strip().splitlines()) == 1


def test_progress_plain_lines_every_tenth():
    import io
    buf = io.StringIO()
    p = Progress("samples", 20, stream=buf)
    st = RunStats()
    for k in range(1, 21):
        st.samples = k
        show_run(p, st)
    st.status = "complete"
    close_run(p, st)
    lines = buf.getvalue().splitlines()
    assert len(lines) == 10 and lines[-1].startswith("samples 20/20  rejected 0")
    assert lines[0].startswith("samples 2/20")


def test_progress_bar_on_a_tty():
    import io

    class Tty(io.StringIO):
        def isatty(self):
            return True

    buf = Tty()
    p = Progress("samples", 4, stream=buf)
    st = RunStats()
    st.samples = 2
    show_run(p, st)
    out = buf.getvalue()  # a tqdm bar, redrawn in place
    assert out.startswith("\r") and "samples 2/4" in out and "rejected 0" in out
    st.samples, st.status, st.reason = 3, "stopped", "interrupted"
    close_run(p, st)
    assert buf.getvalue().rstrip().endswith("run stopped: interrupted")


def test_rehearse_truth_out_is_checked_before_the_run(tmp_path, capsys):
    out = tmp_path / "run.tsv"
    # the sample file itself, or a directory, as --truth-out: refused before anything runs
    assert main(["rehearse", "--samples", "3", "--out", str(out), "--truth-out", str(out)]) == 2
    assert "--truth-out" in capsys.readouterr().err and not out.exists()
    assert main(["rehearse", "--samples", "3", "--out", str(out),
                 "--truth-out", str(tmp_path)]) == 2
    assert "is a directory" in capsys.readouterr().err and not out.exists()
    # a file planecal did not write is not replaced without --force
    other = tmp_path / "notes.json"
    other.write_text('{"mine": 1}')
    assert main(["rehearse", "--samples", "3", "--out", str(out), "--truth-out", str(other)]) == 2
    assert other.read_text() == '{"mine": 1}' and not out.exists()
