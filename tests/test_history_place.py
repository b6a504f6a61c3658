"""Issue 32: where a history is, and what may never happen to it.

A password is never printed, logged or recorded, in any form a URL can carry it
(``user:pw@``, ``?password=``, a URL that does not parse, a port that is not a number); a
URL without one takes libpq's own sources (PGPASSWORD, ~/.pgpass). The history is an
input of every command that records: no output replaces it or the files SQLite keeps
beside it, ``--force`` or not (``calibrate --rrd HISTORY --force`` overwrote it), and no
output replaces another SQLite database. ``--cell`` and ``--note`` are one line within the
same limits on both backends, checked before the work.
"""
from __future__ import annotations

import hashlib
import json
import os
import stat
from pathlib import Path

import pytest

from history_db import PG_PASSWORD_ENV, db  # noqa: F401  (the fixture)
from test_history_store import BASE, calibration_entry, cli, one_line
from planecal.history import History

SECRET = "s3cr%40t-pw"  # percent-encoded "s3cr@t-pw"


@pytest.mark.parametrize("url", [
    f"postgresql://planecal:{SECRET}@127.0.0.1:1/h",
    f"postgresql+psycopg://planecal@127.0.0.1:1/h?password={SECRET}",
    f"postgresql://planecal@127.0.0.1:1/h?sslmode=disable&password={SECRET}&x=1",
    f"postgresql://planecal:{SECRET}@127.0.0.1:abc/h",  # a port that is not a number
    f"postgresql:planecal:{SECRET}@127.0.0.1/h",  # no slashes
    f"postgresql+psycopg://planecal:{SECRET}@[::1/h",  # does not parse
    f"mysql://planecal:{SECRET}@127.0.0.1/h",  # not a backend planecal keeps a history in
])
def test_a_password_is_never_shown_whatever_the_url(url, capsys, tmp_path):
    """Every form: one line, exit 2, nothing of the password (raw or decoded) on stdout or
    stderr (a ?password= was printed in every history line, a malformed URL echoed raw, a
    non-numeric port a 27-line traceback); the export's output is not written."""
    for argv in (["history", "list"],
                 ["export", BASE / "result.json", "--out", tmp_path / "fd11.json"]):
        rc, out, err = cli(capsys, *argv, "--history", url)
        assert rc == 2 and one_line(err)
        for form in (SECRET, "s3cr@t-pw", "s3cr"):
            assert form not in out + err
    assert not (tmp_path / "fd11.json").exists()


def test_the_label_keeps_what_names_the_database():
    from planecal.history.place import place_of
    p = place_of("postgresql://cell:pw@db.shop:5433/planecal?password=pw2&sslmode=require")
    assert p.label == ("postgresql+psycopg://cell:***@db.shop:5433/planecal?password=***"
                       "&sslmode=require")
    assert p.scrub("FATAL: password pw2 or pw for cell") == "FATAL: password *** or *** for cell"
    assert place_of("sqlite:///rel/h.db").path == Path("rel/h.db")


def test_a_password_in_the_url_works_and_is_never_recorded(db, capsys, tmp_path, monkeypatch):
    """On the server: the URL with the password in either form records and lists, and the
    password is in no output and nowhere in the history's own tables."""
    if db.backend != "postgresql":
        pytest.skip("a password is a server's")
    monkeypatch.delenv("PGPASSWORD")
    monkeypatch.chdir(tmp_path)
    pw = os.environ[PG_PASSWORD_ENV]
    for form in ("userinfo", "query"):
        url = db.url_with_password(form)
        rc, out, err = cli(capsys, "export", BASE / "result.json", "--out", "fd11.json",
                           "--history", url)
        assert rc == 0 and "***" in out and pw not in out + err
        rc, out, err = cli(capsys, "history", "show", "1", "--json", "--history", url)
        assert rc == 0 and pw not in out + err
    monkeypatch.setenv("PGPASSWORD", pw)
    rows = db.execute("SELECT concat_ws(' ', kind, cell, note, output, summary, document, world)"
                      " FROM entries UNION ALL SELECT concat_ws(' ', role, path) FROM inputs")
    assert rows and all(pw not in (r[0] or "") for r in rows)


def test_a_url_without_password_takes_libpqs_own_sources(db, capsys, tmp_path, monkeypatch):
    """No password in the URL: PGPASSWORD, else ~/.pgpass (libpq's), else the server's
    refusal in one line, exit 2, before any work."""
    if db.backend != "postgresql":
        pytest.skip("a password is a server's")
    pw = os.environ[PG_PASSWORD_ENV]
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.delenv("PGPASSFILE", raising=False)
    History.open(db.where).close()  # PGPASSWORD (the fixture's)
    monkeypatch.delenv("PGPASSWORD")
    rc, _, err = cli(capsys, "export", BASE / "result.json", "--out", "fd11.json", "--history",
                     db.where)
    assert rc == 2 and "password" in one_line(err) and not (tmp_path / "fd11.json").exists()
    host_port = db.where.split("@", 1)[1].split("/", 1)[0]
    pgpass = tmp_path / ".pgpass"
    pgpass.write_text(f"{host_port}:*:planecal:{pw}\n".replace("]:", "]\\:"))
    pgpass.chmod(stat.S_IRUSR | stat.S_IWUSR)
    rc, out, err = cli(capsys, "export", BASE / "result.json", "--out", "fd11.json",
                       "--history", db.where)
    assert rc == 0 and "history: entry 1 (export: ok)" in out and pw not in out + err


def test_an_unreachable_server_is_one_line_before_the_work(capsys, tmp_path):
    rc, out, err = cli(capsys, "export", BASE / "result.json", "--out", tmp_path / "fd11.json",
                       "--history", "postgresql://planecal@127.0.0.1:1/h")
    assert rc == 2 and "cannot reach the server" in one_line(err)
    assert not (tmp_path / "fd11.json").exists() and not out


# ----- the history is an input, never an output --------------------------------------------

def digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_no_output_replaces_the_history_or_another_database(tmp_path, capsys, monkeypatch):
    """calibrate --rrd HISTORY --force overwrote the history (every entry gone); now every
    output that is the history, a file SQLite keeps beside it, or any other SQLite
    database is refused before the work, --force or not, and nothing changes."""
    monkeypatch.chdir(tmp_path)
    hist = tmp_path / "planecal.db"
    h = History.open(str(hist))
    h.add(calibration_entry())
    h.close()
    monkeypatch.setenv("PLANECAL_HISTORY", str(hist))
    (tmp_path / "planecal.db-wal").write_bytes(b"")
    other = tmp_path / "other.db"
    import sqlite3
    con = sqlite3.connect(other)
    con.execute("CREATE TABLE t (x)")
    con.close()
    before = {p.name: digest(p) for p in tmp_path.iterdir()}
    run = BASE / "run.tsv"
    for argv, fragment in (
            (["calibrate", run, "--rrd", hist, "--force"], "input of this command"),
            (["calibrate", run, "--out", "planecal.db-wal", "--force"], "input of this command"),
            (["export", BASE / "result.json", "--out", hist, "--force"], "input of this command"),
            (["check", run, "--against", BASE / "result.json", "--out", hist, "--force"],
             "input of this command"),
            (["history", "rollback", "1", "--out", hist, "--force"], "input of this command"),
            (["export", BASE / "result.json", "--out", other, "--force"], "SQLite database"),
            (["rehearse", "--samples", "20", "--out", other, "--force"], "SQLite database"),
            (["export", BASE / "result.json", "--out", hist, "--force", "--no-history"],
             "SQLite database")):
        rc, out, err = cli(capsys, *argv)
        assert rc == 2 and fragment in one_line(err), (argv, err)
    assert {p.name: digest(p) for p in tmp_path.iterdir()} == before


@pytest.mark.parametrize("flag, value, why", [
    ("--note", "line1\nline2", "one line"), ("--note", "a\x1b[31m", "control"),
    ("--note", "x" * 2001, "at most 2000"), ("--cell", "c" * 201, "at most 200"),
    ("--cell", "  ", "empty")])
def test_cell_and_note_are_one_line_within_the_limits_before_the_work(db, flag, value, why,
                                                                     capsys, tmp_path):
    """A note with a newline broke the list (one entry on two lines); a 240-character cell
    failed only on PostgreSQL, after the work. The same refusal on both, before anything is
    written; the longest allowed is recorded on both."""
    out = tmp_path / "fd11.json"
    rc, _, err = cli(capsys, "export", BASE / "result.json", "--out", out, flag, value,
                     "--history", db.where)
    assert rc == 2 and why in one_line(err) and flag in err and not out.exists()
    rc, stdout, _ = cli(capsys, "export", BASE / "result.json", "--out", out, "--cell",
                        "c" * 200, "--note", "n" * 2000, "--history", db.where)
    assert rc == 0
    rc, stdout, _ = cli(capsys, "history", "show", "1", "--json", "--history", db.where)
    e = json.loads(stdout)
    assert e["cell"] == "c" * 200 and e["note"] == "n" * 2000


def test_a_read_only_role_lists_and_is_refused_before_the_work(db, capsys, tmp_path,
                                                              monkeypatch):
    """On the server, a login that may only SELECT: list and show answer; a command that
    records is refused in one line before its work (it failed after it)."""
    if db.backend != "postgresql":
        pytest.skip("a role is a server's (test_history_content reads a read-only file)")
    h = History.open(db.where)
    h.add(calibration_entry())
    h.close()
    role = "ro_" + db.where.rsplit("_", 1)[1][:12]
    name = db.where.rsplit("/", 1)[1]
    db.execute(f"CREATE ROLE {role} LOGIN PASSWORD 'ro-pw'",
               f'GRANT CONNECT ON DATABASE "{name}" TO {role}',
               f"GRANT SELECT ON ALL TABLES IN SCHEMA public TO {role}")
    try:
        monkeypatch.setenv("PGPASSWORD", "ro-pw")
        url = db.where.replace("//planecal@", f"//{role}@")
        rc, out, _ = cli(capsys, "history", "list", "--history", url)
        assert rc == 0 and "1 entries" in out
        rc, out, err = cli(capsys, "export", BASE / "result.json", "--out",
                           tmp_path / "fd11.json", "--history", url)
        assert rc == 2 and "cannot be written" in one_line(err)
        assert not (tmp_path / "fd11.json").exists()
    finally:
        monkeypatch.setenv("PGPASSWORD", os.environ[PG_PASSWORD_ENV])
        db.execute(f"DROP OWNED BY {role}", f"DROP ROLE {role}")
