"""The command line's conventions (issue 14): --version, one-line usage errors, defaults in
every help, -q, a TOML run configuration under the command line, shell completion, a closed
stdout ending quietly, planecal scenes."""
import subprocess
import sys

import pytest

from planecal.cli import COMMANDS, main


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.startswith("planecal 0.")


@pytest.mark.parametrize("argv,command", [(["rehearse", "--samples", "x", "--out", "o.tsv"],
                                           "rehearse"),
                                          (["calibrate", "s.tsv", "--bogus"], "calibrate"),
                                          (["nope"], None)])
def test_usage_errors_are_one_line_with_a_pointer_to_help(argv, command, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"(see planecal {command} --help)" in err if command else "(see planecal --help)" in err


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_help_shows_the_defaults(name, capsys):
    with pytest.raises(SystemExit) as e:
        main([name, "--help"])
    out = capsys.readouterr().out
    assert e.value.code == 0 and "--config" in out and "-q" in out and "exit codes" in out


def test_defaults_appear(capsys):
    with pytest.raises(SystemExit):
        main(["calibrate", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "--max-iter MAX_ITER at most this many corrections (default 30)" in out
    assert "--method {gn,lm}" in out and "(default: gn)" in out


def test_config_file_under_the_command_line(tmp_path, capsys):
    cfg = tmp_path / "cell.toml"
    cfg.write_text('[rehearse]\nsamples = 3\nerrors = "ideal"\nforce = true\n'
                   'distance-mm = [75, 85]\n')
    out = tmp_path / "r.tsv"
    assert main(["rehearse", "--config", str(cfg), "--out", str(out), "--samples", "2",
                 "-q"]) == 0
    import json
    s = json.loads(capsys.readouterr().out)
    assert s["samples"] == 2 and s["errors"] == "ideal"  # the command line wins
    side = json.loads((tmp_path / "r.tsv.json").read_text())
    assert side["settings"]["pose"]["distance_mm"] == [75.0, 85.0]  # from the file
    cfg.write_text("[rehearse]\nsamplez = 3\n")
    assert main(["rehearse", "--config", str(cfg), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(cfg) in err and "--samplez" in err and err.count("\n") == 1
    cfg.write_text("[rehearse\n")
    assert main(["rehearse", "--config", str(cfg), "--out", str(out)]) == 2
    assert "invalid TOML" in capsys.readouterr().err


def test_quiet_silences_progress(tmp_path, capsys):
    out = tmp_path / "r.tsv"
    assert main(["rehearse", "--samples", "3", "--errors", "ideal", "--out", str(out), "-q"]) == 0
    assert capsys.readouterr().err == ""
    assert main(["rehearse", "--samples", "3", "--errors", "ideal", "--out", str(out),
                 "--force"]) == 0
    assert "samples 3/3" in capsys.readouterr().err


def test_scenes_lists_the_cells(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for name in ("thesis_final", "three_plates", "appendix_d"):
        assert name in out
    assert "4 plates + length" in out  # three_plates and its stepped block


def test_completion_script_knows_the_commands(capsys):
    assert main(["completion", "bash"]) == 0
    out = capsys.readouterr().out
    assert "rehearse" in out and "--fixed-distance-mm" in out and "complete" in out


def test_a_closed_stdout_ends_quietly(tmp_path):
    # planecal predict ... | head -1 with more output than a pipe holds (~250 kB): the
    # writer meets the closed pipe; no BrokenPipeError traceback, exit 0
    import numpy as np
    rng = np.random.default_rng(0)
    rows = [[int(v) for v in 8388608 + rng.integers(-30000, 30000, 6)] + [80 + k * 1e-4]
            for k in range(8000)]
    big = tmp_path / "big.tsv"
    big.write_text("".join("\t".join(map(str, r)) + "\n" for r in rows))
    cmd = (f"{sys.executable} -m planecal.cli predict {big} "
           "--params examples/table10_params.json | head -1")
    r = subprocess.run(["bash", "-c", "set -o pipefail; " + cmd], capture_output=True, text=True)
    assert r.stdout.count("\n") == 1 and r.stderr == "" and r.returncode == 0


def test_view_ends_its_viewer_with_itself(tmp_path):
    # a stand-in viewer that records its pid and waits; SIGTERM to `planecal view --web`
    # ends the viewer too
    import os
    import signal
    import time
    fake = tmp_path / "rerun"
    pidfile = tmp_path / "pid"
    fake.write_text(f"#!/bin/sh\necho $$ > {pidfile}\nexec sleep 600\n")
    fake.chmod(0o755)
    rec = tmp_path / "x.rrd"
    import rerun as rr
    stream = rr.RecordingStream("planecal-test")
    stream.save(str(rec))
    stream.log("/x", rr.Points3D([[0, 0, 0]]))
    stream.flush()
    env = dict(os.environ, PLANECAL_RERUN=str(fake))
    p = subprocess.Popen([sys.executable, "-m", "planecal.cli", "view", "--web", str(rec)],
                         env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        for _ in range(200):  # bounded wait for the viewer to start
            if pidfile.exists() and pidfile.read_text().strip():
                break
            time.sleep(0.05)
        child = int(pidfile.read_text())
        os.kill(child, 0)  # it runs
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=10) == 128 + signal.SIGTERM
    finally:  # never leave planecal view behind, whatever failed
        if p.poll() is None:
            p.kill()
            p.wait()
    for _ in range(100):
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        os.kill(child, signal.SIGKILL)
        raise AssertionError("the viewer outlived planecal view")
