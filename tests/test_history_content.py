"""Issue 32: what a history holds, read back whatever was done to it, on both backends.

Hand edits (text where a number belongs, NaN, a number too large for a double, JSON that is
not, a newline in a note, a dropped table or column, corrupt pages), another
application's database, an empty file, a newer and an older schema (upgraded by a command
that records, after a backup beside it; read as it is by one that only reads). Every
refusal is one line naming the history and the cause, exit 2, and a refused history is
left as it was; a command that records is refused before its work.
"""
from __future__ import annotations

import hashlib
import json
import sqlite3
from pathlib import Path

import pytest

from history_db import db  # noqa: F401  (the fixture)
from test_history_store import BASE, calibration_entry, cli, entry, one_line
from planecal.history import History


def files_of(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()
            if p.is_file()}


def made(db) -> int:
    """A history with a calibration (entry 1, its parameters and document) and an export
    against it (entry 2)."""
    h = History.open(db.where)
    n = h.add(calibration_entry(n_params=0))
    h.add(entry("export", against=n, note="first export"))
    h.close()
    return n


# ----- hand edits: read back as what they are -----------------------------------------------

def _inf(db) -> str:
    return "9e999" if db.backend == "sqlite" else "'Infinity'::float"


EDITS = {  # name -> (SQL for the backend, what show must say, rollback refuses: any damage)
    "world-not-json": (lambda db: "UPDATE entries SET world = '{\"twin\": ' WHERE id = 1",
                       "world: not JSON", True),
    "document-not-json": (lambda db: "UPDATE entries SET document = 'NaN' WHERE id = 1",
                          "document: NaN is not a number planecal writes", True),
    "summary-nan": (lambda db: "UPDATE entries SET summary = '{\"residual_rms_mm\": NaN}' "
                               "WHERE id = 1", "summary: NaN is not a number", True),
    "summary-huge": (lambda db: "UPDATE entries SET summary = '{\"residual_rms_mm\": 1e999}' "
                                "WHERE id = 1", "summary: 1e999 is not a finite number", True),
    "value-infinite": (lambda db: f"UPDATE parameters SET value = {_inf(db)} WHERE entry_id = 1 "
                                  "AND name = 'delta3'",
                       "parameters[delta3].value: inf is not a finite number", True),
    "value-text": (lambda db: "UPDATE parameters SET value = 'abc' WHERE entry_id = 1 AND "
                              "name = 'delta3'" if db.backend == "sqlite" else
                   "UPDATE parameters SET value = 'NaN'::float WHERE entry_id = 1 AND "
                   "name = 'delta3'",
                   None, True),
    "kind-unknown": (lambda db: "UPDATE entries SET kind = 'xyz' WHERE id = 1",
                     "kind: 'xyz' is not one of", True),
}


@pytest.mark.parametrize("edit", sorted(EDITS))
def test_a_hand_edited_entry_is_shown_as_what_it_holds(db, edit, capsys, tmp_path):
    """list and show print the entry with the stored value named, never as a number (a
    stored NaN or 1e999 was listed as one; text as a number, JSON that is not, a tracebacks);
    diff and rollback refuse an entry whose values they need in one line."""
    sql, says, refused = EDITS[edit]
    made(db)
    db.execute(sql(db))
    rc, out, err = cli(capsys, "history", "list", "--history", db.where)
    assert rc == 0 and not err and len([ln for ln in out.splitlines() if ln[:1].isdigit()]) == 2
    assert "nan" not in out.lower() and "inf" not in out.lower()
    rc, out, err = cli(capsys, "history", "show", "1", "--history", db.where)
    assert rc == 0 and "DAMAGED" in out and (says is None or says in out)
    rc, out, err = cli(capsys, "history", "show", "1", "--json", "--history", db.where)
    doc = json.loads(out, parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))
    assert rc == 0 and doc["problems"]
    rc, out, err = cli(capsys, "history", "rollback", "1", "--out", tmp_path / "fd11.json",
                       "--history", db.where)
    assert (rc == 2) == refused and (rc == 0) == (not refused)
    if refused:
        assert "entry 1" in one_line(err) and not (tmp_path / "fd11.json").exists()
    assert doc["id"] == 1


def test_a_newline_in_a_stored_note_stays_on_its_line(db, capsys):
    made(db)
    db.execute("UPDATE entries SET note = 'line1' || chr(10) || 'line2' || chr(27) || '[31m' "
               "WHERE id = 2" if db.backend == "postgresql" else
               "UPDATE entries SET note = 'line1' || char(10) || 'line2' || char(27) || '[31m' "
               "WHERE id = 2")
    rc, out, _ = cli(capsys, "history", "list", "--history", db.where)
    rows = [ln for ln in out.splitlines()[2:]]
    assert rc == 0 and len(rows) == 3 and "line1\\nline2\\x1b[31m" in rows[-1]


DAMAGE = {  # name -> (SQL, the cause in the one line)
    "dropped-entries": ("DROP TABLE parameters; DROP TABLE inputs; DROP TABLE entries",
                        "table entries is missing"),
    "dropped-column": ("ALTER TABLE entries DROP COLUMN note", "table entries has no column note"),
    "dropped-meta": ("DROP TABLE meta", "not a planecal history"),
    "newer-version": ("UPDATE meta SET value = '3' WHERE key = 'schema_version'",
                      "made by a newer planecal (schema version 3"),
    "newer-revision": ("UPDATE alembic_version SET version_num = 'ffff0003'",
                       "made by a newer planecal"),
    "meta-not-planecal": ("UPDATE meta SET value = 'someone-else' WHERE key = 'format'",
                          "not a planecal history"),
}


@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_a_damaged_or_newer_history_is_one_line_and_no_command_works_on_it(db, damage, capsys,
                                                                          tmp_path):
    """A dropped table or column, a newer schema, a foreign meta table: every command is
    refused in one line, exit 2 (a 49-line traceback for a missing column; a newer history
    could not be read); the one that records is refused before its work (its output not
    written)."""
    sql, cause = DAMAGE[damage]
    made(db)
    for s in sql.split("; "):
        db.execute(s)
    for argv in (["history", "list"], ["history", "show", "1"], ["history", "diff", "1", "1"],
                 ["export", BASE / "result.json", "--out", tmp_path / "fd11.json"]):
        rc, out, err = cli(capsys, *argv, "--history", db.where)
        assert rc == 2 and cause in one_line(err) and not out, (argv, err)
    assert not (tmp_path / "fd11.json").exists()


def test_corrupt_pages_are_one_line(tmp_path, capsys):
    """SQLite pages overwritten in the middle of the file: list, show and a command that
    records are one line, exit 2 (tracebacks before)."""
    where = tmp_path / "h.db"
    h = History.open(str(where))
    for _ in range(6):
        h.add(calibration_entry(n_params=0))
    h.close()
    data = bytearray(where.read_bytes())
    page = 4096
    for k in range(2, len(data) // page, 2):
        data[k * page:k * page + 64] = b"\xa5" * 64  # the b-tree page's header
    where.write_bytes(bytes(data))
    for argv in (["history", "list"], ["history", "show", "3"]):
        rc, out, err = cli(capsys, *argv, "--history", where)
        line = one_line(err) if rc else ""
        assert rc == 2 and "damaged" in line and str(where) in line, (argv, err)
    rc, out, err = cli(capsys, "export", BASE / "result.json", "--out", tmp_path / "fd11.json",
                       "--history", where)
    line = one_line(err)  # refused before the work (2), or found in it: outputs written (3)
    assert "damaged" in line and (rc, (tmp_path / "fd11.json").exists()) in ((2, False), (3, True))


# ----- not a history: never written -------------------------------------------------------

def test_another_applications_database_is_never_written(db, tmp_path, capsys):
    """An SQLite file or a PostgreSQL database holding other tables: refused in one line by
    every command (calibrate added its tables to it and went on); not a byte changed, no
    file left beside it. An empty file (planecal did not make it) the same."""
    if db.backend == "sqlite":
        con = sqlite3.connect(db.path)
        con.execute("CREATE TABLE notes (id INTEGER PRIMARY KEY, text TEXT)")
        con.execute("INSERT INTO notes (text) VALUES ('mine')")
        con.commit()
        con.close()
        (tmp_path / "empty.db").write_bytes(b"")
    else:
        db.execute("CREATE TABLE notes (id SERIAL PRIMARY KEY, text TEXT)",
                   "INSERT INTO notes (text) VALUES ('mine')")
    before = files_of(tmp_path)
    wheres = [db.where] + ([str(tmp_path / "empty.db")] if db.backend == "sqlite" else [])
    for where in wheres:
        for argv in (["history", "list"],
                     ["export", BASE / "result.json", "--out", tmp_path / "fd11.json"],
                     ["history", "rollback", "1", "--out", tmp_path / "fd11.json"]):
            rc, out, err = cli(capsys, *argv, "--history", where)
            assert rc == 2 and "not a planecal history" in one_line(err), err
    assert files_of(tmp_path) == before
    if db.backend == "postgresql":
        tables = {r[0] for r in db.execute("SELECT tablename FROM pg_tables WHERE "
                                           "schemaname = 'public'")}
        assert tables == {"notes"}


def test_rollback_of_nothing_makes_no_history(db, tmp_path, capsys):
    """history rollback on a history that does not exist (or an empty database): one line,
    and no history made (it created planecal.db and said 'no entry 1')."""
    rc, _, err = cli(capsys, "history", "rollback", "1", "--out", tmp_path / "fd11.json",
                     "--history", db.where)
    assert rc == 2 and ("no history here yet" in one_line(err) or "empty database" in err)
    if db.backend == "sqlite":
        assert sorted(p.name for p in tmp_path.iterdir()) == []
    else:
        assert db.execute("SELECT count(*) FROM pg_tables WHERE schemaname = 'public'") == [(0,)]


# ----- an older schema ----------------------------------------------------------------------

def make_version_1(db) -> None:
    """A history as planecal wrote it before issue 32 (schema version 1: no alembic_version,
    bounded strings), with a calibration, an export and a deleted third entry."""
    import sqlalchemy as sa
    from alembic import command

    from planecal.history.schema import alembic_config
    url = f"sqlite:///{db.path}" if db.path else db.where
    engine = sa.create_engine(url, poolclass=sa.pool.NullPool)
    with engine.begin() as conn:
        command.upgrade(alembic_config(conn), "0001")
        conn.exec_driver_sql("DROP TABLE alembic_version")
    engine.dispose()
    for k in (1, 2, 3):
        db.execute("INSERT INTO entries (kind, created_utc, outcome, exit_code, cell, note) "
                   f"VALUES ('check', '2025-01-0{k}T00:00:00+00:00', 'in_control', 0, 'c', 'v1-{k}')",
                   f"INSERT INTO inputs (entry_id, role, path, sha256, bytes) VALUES ({k}, 'run', "
                   f"'r{k}.tsv', '{'0' * 64}', 10)")
    if db.backend == "postgresql":  # its foreign keys hold: the inputs go first
        db.execute("DELETE FROM inputs WHERE entry_id = 3")
    db.execute("DELETE FROM entries WHERE id = 3")


def test_an_older_history_is_upgraded_with_a_backup_beside_it(db, tmp_path, capsys,
                                                              monkeypatch):
    """A version-1 history: history list reads it as it is (nothing written); the first
    command that records upgrades it to version 2 after a copy of version 1 beside it (the
    file FILE.v1.bak; on PostgreSQL the schema planecal_backup_v1), one line says so, and
    every entry is still there, the deleted number 3 not given again (it was SCHEMA_VERSION
    1 or nothing: no migration, a newer history unreadable)."""
    monkeypatch.chdir(tmp_path)
    make_version_1(db)
    rc, out, _ = cli(capsys, "history", "list", "--history", db.where)
    assert rc == 0 and "v1-1" in out and "v1-2" in out
    assert db.execute("SELECT value FROM meta WHERE key = 'schema_version'") == [("1",)]
    rc, out, err = cli(capsys, "export", BASE / "result.json", "--out", "fd11.json",
                       "--history", db.where)
    assert rc == 0 and "history: entry 4 (export: ok)" in out
    assert "upgraded from schema version 1 to 2" in one_line(err)
    assert db.execute("SELECT value FROM meta WHERE key = 'schema_version'") == [("2",)]
    assert db.execute("SELECT version_num FROM alembic_version") == [("0002",)]
    if db.backend == "sqlite":
        backup = Path(str(db.path) + ".v1.bak")
        con = sqlite3.connect(backup)
        assert con.execute("SELECT value FROM meta WHERE key = 'schema_version'"
                           ).fetchall() == [("1",)]
        assert con.execute("SELECT note FROM entries ORDER BY id").fetchall() == [("v1-1",),
                                                                                  ("v1-2",)]
        con.close()
    else:
        assert db.execute("SELECT note FROM planecal_backup_v1.entries ORDER BY id") == [
            ("v1-1",), ("v1-2",)]
    h = History.open(db.where, create=False)
    assert [(e.id, e.note) for e in h.entries()] == [(1, "v1-1"), (2, "v1-2"), (4, None)]
    assert [i.path for i in h.get(2).inputs] == ["r2.tsv"]
    h.close()


def test_a_read_only_history_can_be_read(tmp_path, capsys):
    """The file and its folder immutable (chattr +i: not even root writes there, as on a
    read-only medium): list and show answer (every transaction took the write lock, so a
    read-only history could not even be listed); a command that records is refused in one
    line before its work."""
    import shutil
    import subprocess
    folder = tmp_path / "ro"
    folder.mkdir()
    where = folder / "h.db"
    h = History.open(str(where))
    h.add(calibration_entry())
    h.close()
    chattr = shutil.which("chattr")
    if chattr is None or subprocess.run([chattr, "+i", str(where), str(folder)],
                                        capture_output=True).returncode:
        pytest.skip("chattr +i is not available here (root on a file system that has it)")
    try:
        rc, out, _ = cli(capsys, "history", "list", "--history", where)
        assert rc == 0 and "1 entries" in out
        rc, out, _ = cli(capsys, "history", "show", "1", "--history", where)
        assert rc == 0 and "calibrate" in out
        rc, out, err = cli(capsys, "export", BASE / "result.json", "--out",
                           tmp_path / "fd11.json", "--history", where)
        assert rc == 2 and "cannot" in one_line(err) and not (tmp_path / "fd11.json").exists()
    finally:
        subprocess.run([chattr, "-i", str(where), str(folder)], check=True)
    assert sorted(p.name for p in folder.iterdir()) == ["h.db"]
