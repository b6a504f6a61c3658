"""Issue 33: every command that runs longer than 3 s says something within 2 s, and every
2 s after (stderr, plain lines off a terminal, nothing with -q).

The commands' tests trace what they print on a clock of their own work
(``progress_trace``): a stub clock that counts the calls of planecal's work primitives at
their idle cost, or the process's CPU clock where a unit has no fixed cost (a figure). No
test reads the wall's clock, so none depends on the machine's load. Measured on the code
before this change (the same traces): plan 3.30 s of silence, validate 6.80 s, a level-3
calibration's report 4.86 s; every one of them is under 1.4 s now.
"""
from __future__ import annotations

import io
import json

import numpy as np
import pytest

from planecal.base import progress as P
from planecal.base.progress import Progress, report, reporting_to, stage
from progress_trace import LIMIT_S, Trace


class Clock:
    t = 0.0

    def __call__(self):
        return self.t


@pytest.fixture
def clock(monkeypatch):
    c = Clock()
    monkeypatch.setattr(P, "clock", c)
    return c


# ----- the progress itself ----------------------------------------------------------------

def test_a_long_unit_gets_its_line(clock):
    """A study of 50 runs of 1.2 s each (montecarlo's on a loaded machine: its plain lines
    came every tenth, 5 runs, 12-19 s apart): a line after each run, the tenths too."""
    buf = io.StringIO()
    p = Progress("montecarlo", 50, stream=buf)
    times = []
    for _ in range(50):
        clock.t += 1.2
        before = buf.getvalue().count("\n")
        p.step()
        if buf.getvalue().count("\n") > before:
            times.append(clock.t)
    assert len(times) == 50 and np.diff([0.0] + times).max() == pytest.approx(1.2)
    assert buf.getvalue().splitlines()[-1] == "montecarlo 50/50"


def test_quick_units_keep_the_tenths(clock):
    """Units far quicker than a second: a line each tenth, as before (no flood)."""
    buf = io.StringIO()
    p = Progress("samples", 150, stream=buf)
    for _ in range(150):
        clock.t += 0.01
        p.step()
    assert len(buf.getvalue().splitlines()) == 10


def test_work_inside_a_unit_is_said_within_the_interval(clock):
    """``report`` from the work (a plan's candidates): the detail reaches the innermost
    open bar, and a plain line follows within ``INTERVAL_S`` while the work reports."""
    buf = io.StringIO()
    p = Progress("plan", 6, stream=buf)
    p.update(done=1, note="drawing 1500 candidate poses")
    lines_at = [clock.t]
    for k in range(1500):
        clock.t += 0.002
        n = buf.getvalue().count("\n")
        report(k, 1500, "candidate poses")
        if buf.getvalue().count("\n") > n:
            lines_at.append(clock.t)
    assert np.diff(lines_at).max() <= P.INTERVAL_S + 0.002
    assert "plan 1/6  drawing 1500 candidate poses: candidate poses 1499/1500" not in \
        buf.getvalue()  # the last detail waits for its interval ...
    p.update(note="choosing 150 D-optimal poses")  # ... and the next step clears it
    assert buf.getvalue().splitlines()[-1] == "plan 2/6  choosing 150 D-optimal poses"
    p.close()


def test_report_goes_to_the_innermost_shown_bar_or_the_sink(clock):
    outer, held, inner = io.StringIO(), io.StringIO(), io.StringIO()
    a = Progress("planning", 2, stream=outer)
    b = Progress("runs", 8, stream=held, hold=True)
    clock.t += 5
    report(3, 10, "poses planned")
    assert a.detail == "poses planned 3/10" and b.detail == ""  # a held bar is skipped
    c = Progress("inner", 0, stream=inner)
    report(what="drawing x.png")
    assert c.detail == "drawing x.png" and a.detail == "poses planned 3/10"
    c.close()
    got = []
    with reporting_to(lambda k, n, what: got.append((k, n, what))):
        report(1, 2, "samples")  # a worker's run: to the engine's sink, no bar
    assert got == [(1, 2, "samples")] and a.detail == "poses planned 3/10"
    a.close()
    b.release()
    report(4, 150, "samples")
    assert b.detail == "samples 4/150"
    b.close()
    report(1, 1, "nothing open")  # nowhere, quietly


def test_a_stage_is_said_at_once_and_quiet_with_q(clock, capsys):
    with stage("demo: calibration", "the fit, then its accuracy"):
        report(3, 10, "cross-validation: fold")
    assert capsys.readouterr().err.splitlines()[0] == "demo: calibration  the fit, then its accuracy"
    P.set_quiet(True)
    try:
        with stage("demo: calibration"):
            report(3, 10, "fold")
        Progress("x", 5).step(5)
    finally:
        P.set_quiet(False)
    assert capsys.readouterr().err == ""


def test_a_stage_bar_leaves_no_line_on_a_terminal():
    class Tty(io.StringIO):
        def isatty(self):
            return True

    buf = Tty()
    p = Progress("report (calibration)", 0, stream=buf)
    p.within(what="drawing correlation.png")
    assert "drawing correlation.png" in buf.getvalue()
    p.close()
    assert not buf.getvalue().endswith("\n")  # tqdm cleared it (leave=False)


def test_numba_compilations_are_said(capsys):
    """The first run after an install compiles the kernels (12 s of one core before the
    demo's first sample): each compilation is said, in a stage of its own where nothing
    else is open, else as the open bar's detail."""
    from numba import njit

    from planecal.base.paths import numba_cache
    numba_cache()  # installs the listener (once a process: planecal's kernels did already)

    def double(x):
        return 2 * x

    assert njit(cache=False)(double)(2) == 4
    err = capsys.readouterr().err
    assert "compiling kernels  first run only, then cached in " in err
    buf = io.StringIO()
    p = Progress("samples", 150, stream=buf)

    def triple(x):
        return 3 * x

    assert njit(cache=False)(triple)(2) == 6
    assert "functions done" in p.detail and capsys.readouterr().err == ""
    p.close()


# ----- the commands, traced on a clock of their work ---------------------------------------

def test_plan_says_its_candidates_and_its_tour(monkeypatch, tmp_path):
    """plan at its defaults (1500 candidates, 150 poses): 8.1 s of collision checks."""
    tr = Trace.of(monkeypatch, ["check_config", "check_path"])
    assert tr.run(["plan", "--out", str(tmp_path / "p.json")]) == 0
    assert tr.end > 3 * LIMIT_S  # long work, on this clock too
    assert tr.longest_silence() <= LIMIT_S, sorted(tr.silences())[-3:]
    err = tr.text()
    assert "candidate poses" in err and "poses planned" in err and "moves checked" in err


def test_validate_says_each_truths_work(monkeypatch, tmp_path):
    """validate's study in this process (--jobs 1), one truth at the defaults: the
    rehearsal's samples, the ISO 9283 cycles and the gauge block, as they go."""
    tr = Trace.of(monkeypatch, ["twin_run", "check_config", "check_path", "solve",
                                "iso_move"])
    assert tr.run(["validate", "--truth-seeds", "0", "--breakdown", "none", "--jobs", "1",
                   "--out", str(tmp_path / "v.json")]) == 0
    assert tr.end > 3 * LIMIT_S
    assert tr.longest_silence() <= LIMIT_S, sorted(tr.silences())[-3:]
    err = tr.text()
    assert "samples" in err and "ISO 9283" in err and "gauge block" in err


def test_a_reports_figures_are_said(monkeypatch, tmp_path, capsys):
    """planecal report of a level-3 result (calibrate --report draws the same page): its
    figures as it draws them, on the CPU clock of the thread that draws (a figure has no
    fixed cost: the 60-parameter correlation matrix was 3,600 texts). Before: 4.9 s of one
    core without a word (calibrate --level nonkinematic --report)."""
    from planecal.cli import main
    run, cal = tmp_path / "r.tsv", tmp_path / "c.json"
    assert main(["rehearse", "--out", str(run), "-q"]) == 0
    assert main(["calibrate", str(run), "--level", "nonkinematic", "--out", str(cal),
                 "-q", "--no-history"]) == 0
    capsys.readouterr()
    tr = Trace.cpu(monkeypatch)
    assert tr.run(["report", str(cal), "--out", str(tmp_path / "rep")]) == 0
    assert tr.longest_silence() <= LIMIT_S, sorted(tr.silences())[-3:]
    err = tr.text()
    assert err.startswith("report (calibration)") and ": drawing " in err


def test_sweep_plans_on_the_planning_bar(monkeypatch, tmp_path):
    """A sweep's planned design: the plan's own progress shows on the planning bar (the
    runs' bar is held until the runs start), then each run's samples."""
    spec = tmp_path / "spec.toml"
    spec.write_text('[grid]\nerrors = ["ideal"]\ndesign = ["planned"]\nsamples = [40]\n'
                    '[sweep]\nruns = 2\nplan_candidates = 300\n')
    tr = Trace.of(monkeypatch, ["check_config", "check_path", "twin_run", "solve"])
    monkeypatch.setattr(P, "INTERVAL_S", 0.1)  # a small sweep: lines often, to see where
    assert tr.run(["sweep", str(spec), "--out", str(tmp_path / "sw"), "--jobs", "1"]) == 0
    assert tr.longest_silence() <= LIMIT_S, sorted(tr.silences())[-3:]
    err = tr.text().splitlines()
    assert any(ln.startswith("planning 1/1  planned, 40 poses on thesis_final: ")
               and "poses planned" in ln for ln in err), err
    assert not any(ln.startswith("sweep:") and "poses planned" in ln for ln in err)
    assert any(ln.startswith("sweep: 2 runs") and "samples" in ln for ln in err)


def test_the_engine_says_its_start_and_its_workers_runs(capsys, monkeypatch):
    """A local Dask cluster: its start-up (workers up, the warm-up: montecarlo's 18 s and
    validate's 65 s before their first line under load) and what each run reports on its
    worker, forwarded to the client's bar through dask's events."""
    from planecal.studies.distributed import Engine, warm_twin
    from progress_runs import reporting_run
    monkeypatch.setattr(P, "INTERVAL_S", 0.0)  # every change a line: none missed by timing
    with Engine(jobs=2, progress=True, warmup=warm_twin) as eng:
        bar = Progress("runs", 2)
        assert eng.map(reporting_run, [3, 4], progress=bar) == [6, 8]
    err = capsys.readouterr().err
    assert "engine  starting a local Dask cluster of 2 worker processes" in err
    assert "workers up after" in err and "warmed up after" in err
    assert "  run 1: steps " in err and "  run 2: steps " in err, err


def test_a_bar_left_open_on_a_closed_stream_fails_no_work(clock):
    """A bar a failure left open (its stream closed since) took every later report of the
    process and raised 'I/O operation on closed file' inside the work: now it stops."""
    buf = io.StringIO()
    left = Progress("samples", 150, stream=buf)
    buf.close()
    clock.t += 5
    report(1, 4, "samples")  # no exception
    assert left.off and left not in P._OPEN


def test_a_command_run_with_q_in_process_leaves_progress_on(tmp_path, capsys):
    """``planecal.cli.main([..., "-q"])`` quiets that command only: a caller in the same
    process (a script, the next test) keeps its progress (it stayed quiet before, and a
    test after one such call saw none of its lines)."""
    from planecal.base.progress import quiet
    from planecal.cli import main
    assert not quiet()
    assert main(["rehearse", "--samples", "2", "--out", str(tmp_path / "r.tsv"), "-q"]) == 0
    capsys.readouterr()
    assert not quiet()
    buf = io.StringIO()
    Progress("samples", 1, stream=buf).step()
    assert buf.getvalue().strip() == "samples 1/1"
