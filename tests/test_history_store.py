"""Issue 32: the cell's history survives anything, on SQLite and on PostgreSQL alike.

Every test that takes ``db`` runs on both backends (tests/history_db.py: a fresh SQLite
file, a fresh PostgreSQL database) with the same assertions. Real processes write at once
(eight, on a fresh history: the schema created race-free, every entry kept and numbered
once), a writer is SIGKILLed inside its transaction, a reader lists while a writer holds
its transaction, a history is locked past the wait, edited by hand (text where a number
belongs, NaN, JSON that is not, a dropped table or column, corrupt pages), foreign, newer
and older (upgraded with a backup). Each refusal is one line on stderr, no traceback; a
history failure after the work leaves the command's outputs and its verdict's exit code.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from history_db import db  # noqa: F401  (the fixture)
from planecal.cli import main
from planecal.history import Entry, History, InputRow, ParameterRow

PY = sys.executable
BASE = Path(__file__).parent / "corpus" / "base"


def entry(kind="check", **kw) -> Entry:
    return Entry(kind=kind, outcome="ok", exit_code=0, created_utc="2026-01-01T00:00:00+00:00",
                 planecal_version="test", **kw)


def cli(capsys, *argv) -> tuple[int, str, str]:
    """A command in-process: (exit code, stdout, stderr); never a traceback, and a failure
    or a history line is one line each."""
    rc = main([str(a) for a in argv])
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "Traceback" not in cap.out
    return rc, cap.out, cap.err


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def calibration_entry(n_params: int = 3) -> Entry:
    """A calibrate entry with the corpus's result as its document and its parameters."""
    from planecal.commands.history_options import parameter_rows
    doc = json.loads((BASE / "result.json").read_text())
    return entry("calibrate", cell="cell1", document=doc, result_sha256="ab" * 32,
                 summary={"level": "offsets", "samples_used": 120, "residual_rms_mm": 0.05},
                 parameters=parameter_rows(doc)[:n_params] if n_params else parameter_rows(doc),
                 inputs=[InputRow("samples", "run.tsv", "cd" * 32, 1234)])


# ----- values in and out, limits, numbering --------------------------------------------------

def test_an_entry_comes_back_as_written_on_both_backends(db):
    """Values in SI, NaN as null, inputs in the order written, a 240-character cell and a
    2**40-byte input (varchar(200) and int4 on PostgreSQL refused both), numbers never
    reused after the last entry is deleted (SQLite reused them)."""
    import numpy as np
    h = History.open(db.where)
    cell = "c" * 240
    ins = [InputRow("samples", f"s{k}.tsv", "cd" * 32, 2**40 + k) for k in (3, 1, 2)]
    n = h.add(entry("calibrate", cell=cell, summary={"rms": float("nan"), "x": np.float64(2.5)},
                    document={"a": np.array([1.0, np.inf])}, result_sha256="ab" * 32,
                    inputs=ins, parameters=[
                        ParameterRow("delta3", 1e-4, float("nan"), "rad", "fitted"),
                        ParameterRow("delta2", float("nan"), None, "rad", "fitted")]))
    m = h.add(entry("export", against=n, cell="c2"))
    e = h.get(n)
    assert e.summary == {"rms": None, "x": 2.5} and e.document == {"a": [1.0, None]}
    assert e.parameters == [ParameterRow("delta3", 1e-4, None, "rad", "fitted"),
                            ParameterRow("delta2", None, None, "rad", "fitted")]
    assert e.inputs == ins and e.cell == cell and e.problems == []
    assert h.find_result("ab" * 32) == n and h.find_result("ef" * 32) is None
    assert [x.id for x in h.entries()] == [n, m] and [x.id for x in h.entries("c2")] == [m]
    assert h.get(m).against == n
    db.execute(f"DELETE FROM entries WHERE id = {m}")
    assert h.add(entry("check")) == m + 1  # the deleted last number is not given again
    h.close()


WRITER = """
import sys, time
from pathlib import Path
from planecal.history import Entry, History, InputRow
where, tag, n, go = sys.argv[1], sys.argv[2], int(sys.argv[3]), Path(sys.argv[4])
while not go.exists():
    time.sleep(0.001)
h = History.open(where)  # all at once, on a history that does not exist yet
for i in range(n):
    h.add(Entry(kind="check", outcome="ok", exit_code=0, created_utc="t", planecal_version="t",
                note=f"{tag}-{i}", inputs=[InputRow("run", f"{tag}{i}.tsv", "0" * 64, i),
                                           InputRow("result", f"{tag}{i}.json", "1" * 64, i)]))
h.close()
"""


def test_eight_processes_record_into_a_fresh_history_at_once(db, tmp_path):
    """Eight real processes, released together on a history that does not exist yet (the
    first ones race to create it: on PostgreSQL 'relation meta already exists' lost
    entries), add ten entries each: all 80 are there, numbered 1-80 once each, each with
    its two inputs in order."""
    go = tmp_path / "go"
    procs = [subprocess.Popen([PY, "-c", WRITER, db.where, f"w{k}", "10", str(go)],
                              stderr=subprocess.PIPE, text=True) for k in range(8)]
    go.touch()
    errs = [p.communicate(timeout=300)[1] for p in procs]
    assert [p.returncode for p in procs] == [0] * 8, errs
    h = History.open(db.where, create=False)
    got = h.entries()
    assert sorted(e.note for e in got) == sorted(f"w{k}-{i}" for k in range(8) for i in range(10))
    assert [e.id for e in got] == list(range(1, 81))
    for e in got[::9]:
        tag = e.note.replace("-", "")
        assert [i.path for i in h.get(e.id).inputs] == [f"{tag}.tsv", f"{tag}.json"]
    h.close()


HOLDER = """
import sys, time
from sqlalchemy import text
from planecal.history import History
h = History.open(sys.argv[1])
with h.engine.connect().execution_options(planecal_write=True) as c, c.begin():
    if c.dialect.name == "postgresql":  # what SQLite's write lock is: no other writer
        c.exec_driver_sql("LOCK TABLE entries IN EXCLUSIVE MODE")
    c.execute(text("INSERT INTO entries (kind, created_utc, outcome, exit_code, note) "
                   "VALUES ('check', 't', 'ok', 0, 'held')"))
    n = c.execute(text("SELECT max(id) FROM entries")).scalar()
    c.execute(text("INSERT INTO inputs (entry_id, role, path) VALUES (:n, 'run', 'held.tsv')"),
              {"n": n})
    print("holding", flush=True)
    time.sleep(600)
"""


def hold(where: str) -> subprocess.Popen:
    """A writer inside its transaction (an entry and an input written, not committed, the
    write lock held), until it is killed."""
    p = subprocess.Popen([PY, "-c", HOLDER, where], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "holding"
    return p


def test_a_reader_answers_while_a_writer_holds_its_transaction(db, capsys):
    """history list and show answer at once from what is committed (every transaction took
    SQLite's write lock: list waited up to 60 s behind a writer and failed)."""
    h = History.open(db.where)
    n = h.add(calibration_entry())
    h.close()
    writer = hold(db.where)
    try:
        rc, out, _ = cli(capsys, "history", "list", "--history", db.where)
        assert rc == 0 and "1 entries" in out and "held" not in out
        rc, out, _ = cli(capsys, "history", "show", n, "--history", db.where, "--json")
        assert rc == 0 and json.loads(out)["id"] == n
    finally:
        writer.kill()
        writer.wait()


def test_a_writer_killed_in_its_transaction_loses_only_its_own_entry(db):
    h = History.open(db.where)
    before = [h.add(entry(note=f"e{k}", inputs=[InputRow("run", f"r{k}", "0" * 64, k)]))
              for k in range(3)]
    h.close()
    writer = hold(db.where)
    writer.send_signal(signal.SIGKILL)
    writer.wait()
    h = History.open(db.where)  # opens: no stale lock, nothing torn
    assert [e.note for e in h.entries()] == ["e0", "e1", "e2"]
    assert [h.get(n).inputs[0].path for n in before] == ["r0", "r1", "r2"]
    n = h.add(entry(note="after"))
    assert n > before[-1] and [e.note for e in h.entries()][-1] == "after"
    h.close()


def test_a_history_failure_after_the_work_keeps_the_outputs_and_the_verdict(db, tmp_path,
                                                                          capsys, monkeypatch):
    """A history locked past the wait: export writes its controller file and exits 3 (it
    was RunFailed, 1: the code of a failed fit); check keeps its verdict's code and JSON
    (exit 1 'drifted' beside a JSON saying in control, on a lost server). One line each."""
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "short.tsv"
    run.write_text("\n".join((BASE / "run.tsv").read_text().splitlines()[-30:]) + "\n")
    History.open(db.where).close()
    rc, out, err = cli(capsys, "check", run, "--against", BASE / "result.json", "--no-history",
                     "--json")
    assert rc in (0, 1), err
    verdict = json.loads(out)["exit_code"]
    monkeypatch.setenv("PLANECAL_HISTORY_WAIT_S", "1")
    writer = hold(db.where)
    try:
        rc, out, err = cli(capsys, "export", BASE / "result.json", "--out", "fd11.json",
                           "--history", db.where)
        assert rc == 3 and json.loads((tmp_path / "fd11.json").read_text())["qe0_counts"]
        line = one_line(err)
        assert "not recorded" in line and "locked" in line and db.where.split("/")[-1] in line
        rc, out, err = cli(capsys, "check", run, "--against", BASE / "result.json", "--json",
                           "--history", db.where)
        assert rc == verdict == json.loads(out)["exit_code"]
        assert "not recorded" in one_line(err)
    finally:
        writer.kill()
        writer.wait()
    h = History.open(db.where, create=False)
    assert h.entries() == []  # nothing half-written
    h.close()
