"""Opening a history: the engine of its backend, its schema checked, created or upgraded.

SQLite (a file): WAL mode, so readers never wait for a writer and a writer never waits
for readers. A transaction that writes begins ``IMMEDIATE`` (the write lock first, waited
for up to ``place.wait_s()``); one that reads begins deferred and takes no lock a writer
waits for. A command that only reads opens the file read-only (``mode=ro``: nothing it
does can change the file); a history that cannot be written at all (a read-only folder,
no ``-wal`` beside it: everything is in the file) is read as the file stands
(``immutable``). A new history is made whole in a temporary file beside it and linked
into place (``os.link`` fails where another process made it first: that one is used), so
any number of first writers leave one history and every entry.

PostgreSQL (a URL; psycopg 3): the schema is created or upgraded in one transaction under
an advisory lock, so first writers do not race on it; ``connect_timeout``,
``lock_timeout`` and ``statement_timeout`` bound every wait by the same
``place.wait_s()``.

An older schema is upgraded by a command that records (``schema.upgrade``; Alembic), after
a backup beside it: the SQLite file copied to ``FILE.v1.bak`` (SQLite's backup API, under
the write lock), on PostgreSQL the tables copied into the schema
``planecal_backup_v1``. A command that only reads reads an older history as it is. Every
failure is a ``HistoryError``: one line naming the history (no password) and the cause.
"""
from __future__ import annotations

import errno
import os
import secrets
from pathlib import Path
from urllib.parse import quote

from planecal.base.errors import InputError
from planecal.history import schema
from planecal.history.place import Place, wait_s
from planecal.io.outputs import SQLITE_MAGIC
ADVISORY_KEY = 0x706C616E6563616C  # "planecal": the schema's advisory lock on PostgreSQL


_LOCKED = ("database is locked", "lock timeout", "canceling statement")
_READ_ONLY = ("readonly", "read-only", "permission denied")
_DAMAGED = ("malformed", "not a database", "no such table", "no such column", "decode")


class HistoryError(InputError):
    """A history that cannot be opened, read or written: one line naming it and the cause
    (``Place.error``)."""


def failure(place: Place, e: BaseException, doing: str) -> HistoryError:
    """A driver's or the system's error as one line about ``place``."""
    orig = getattr(e, "orig", None) or e
    text = str(orig).strip() or type(orig).__name__
    first = text.splitlines()[0]
    first = first if len(first) <= 200 else first[:197] + "..."
    low = first.lower()
    if any(k in low for k in _LOCKED):
        why = f"locked: another process held it longer than {wait_s():g} s ({first})"
    elif any(k in low for k in _READ_ONLY):
        why = f"cannot be written ({first})"
    elif any(k in low for k in _DAMAGED) or (not place.sqlite and "does not exist" in low
                                               and not low.startswith("connection")):
        why = f"damaged ({first})"
    elif not place.sqlite:
        why = f"cannot reach the server ({first})"
    else:
        why = first
    return HistoryError(place.error(f"{doing}: {why}"))


# ----- SQLite ---------------------------------------------------------------------------------

def check_file(place: Place, inputs, write: bool, new: bool = True) -> None:
    """A history file checked before anything is opened: for a command that records, the
    output guard's checks (not one of its inputs, not a directory, a folder that exists and
    can be written, a file that can be written); for one that reads, a file that is there.
    An existing file must be an SQLite database (its first 16 bytes)."""
    from planecal.io.outputs import check_output
    p = place.path
    if write:
        check_output(p, inputs, (SQLITE_MAGIC,), force=True, what="--history")
    if (not write or not new) and not p.exists():
        raise HistoryError(place.error("no history here yet (commands that calibrate, "
                                       "validate, export, check or compare make one)"))
    elif p.is_dir():
        raise HistoryError(place.error("is a directory; give the history's file"))
    if not p.exists():
        return
    try:
        with open(p, "rb") as f:
            head = f.read(len(SQLITE_MAGIC))
    except OSError as e:
        raise HistoryError(place.error(f"cannot read ({e.strerror})")) from None
    if not head:
        raise HistoryError(place.error("an empty file, not a planecal history (planecal "
                                       "did not make it: remove it to start one here)"))
    if head != SQLITE_MAGIC:
        raise HistoryError(place.error("not an SQLite database (a history is one)"))


def sqlite_engine(path: Path, write: bool, immutable: bool = False):
    """An engine on the file: read-write (writes begin IMMEDIATE) or read-only."""
    from sqlalchemy import create_engine, event
    if write:
        url = f"sqlite+pysqlite:///{path}"
    else:
        opts = "mode=ro&immutable=1" if immutable else "mode=ro"
        url = f"sqlite+pysqlite:///file:{quote(str(path))}?{opts}&uri=true"
    engine = create_engine(url, connect_args={"timeout": wait_s()})

    @event.listens_for(engine, "connect")
    def _connect(dbapi_connection, _record):
        dbapi_connection.isolation_level = None  # planecal, not the driver, begins
        # text that is not UTF-8 (a hand's, a damaged page) is read, marked, not a failure
        dbapi_connection.text_factory = lambda b: b.decode("utf-8", "replace")

    @event.listens_for(engine, "begin")
    def _begin(conn):
        write_tx = conn.get_execution_options().get("planecal_write", False)
        conn.exec_driver_sql("BEGIN IMMEDIATE" if write_tx else "BEGIN")
    return engine


def pragma(engine, text: str):
    """An SQLite PRAGMA outside any transaction (the driver's connection, autocommit)."""
    raw = engine.raw_connection()
    try:
        row = raw.driver_connection.execute(f"PRAGMA {text}").fetchone()
    finally:
        raw.close()
    return None if row is None else row[0]


def create_file(place: Place) -> None:
    """A new history at ``place.path``, made whole beside it and linked into place; where
    another process made it first, nothing (its history is used)."""
    p = place.path.absolute()
    tmp = p.with_name(f".{p.name[:80]}.{os.getpid()}.{secrets.token_hex(4)}.new")
    try:
        engine = sqlite_engine(tmp, True)
        try:
            pragma(engine, "journal_mode=WAL")
            with engine.connect().execution_options(planecal_write=True) as conn, conn.begin():
                schema.create(conn)
        finally:
            engine.dispose()
        try:
            os.link(tmp, p)
        except FileExistsError:
            pass
        except OSError as e:  # a file system without hard links: one creator at a time
            if e.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV):
                raise
            from filelock import FileLock
            with FileLock(str(p) + ".lock", timeout=wait_s()):
                if not p.exists():
                    os.replace(tmp, p)
    except OSError as e:
        raise HistoryError(place.error(f"cannot create the history ({e.strerror or e})")) \
            from None
    finally:
        for suffix in ("", "-wal", "-shm", "-journal"):
            Path(str(tmp) + suffix).unlink(missing_ok=True)


def backup_name(path: Path, version: int) -> Path:
    """``FILE.vN.bak`` beside the file, numbered where that is taken."""
    base = path.with_name(f"{path.name}.v{version}.bak")
    k, out = 1, base
    while out.exists():
        k += 1
        out = base.with_name(f"{base.name}.{k}")
    return out


def backup_file(place: Place, version: int) -> Path:
    """The history file copied whole beside it (SQLite's backup API; the caller holds the
    write lock, so nothing changes meanwhile)."""
    import sqlite3
    out = backup_name(place.path, version)
    src = sqlite3.connect(f"file:{quote(str(place.path.absolute()))}?mode=ro", uri=True,
                          timeout=wait_s())
    try:
        dst = sqlite3.connect(out)
        try:
            src.backup(dst)
        finally:
            dst.close()
    finally:
        src.close()
    return out


# ----- PostgreSQL -----------------------------------------------------------------------------

def postgres_engine(place: Place):
    from sqlalchemy import create_engine
    ms = int(wait_s() * 1000)
    try:
        import psycopg  # noqa: F401
    except ImportError:
        raise HistoryError(place.error("PostgreSQL needs psycopg 3: pip install "
                                       "'planecal[postgresql]'")) from None
    return create_engine(place.url, pool_size=1, pool_pre_ping=True, connect_args={
        "connect_timeout": max(2, int(wait_s())),
        "options": f"-c lock_timeout={ms} -c statement_timeout={ms}",
        "application_name": "planecal"})


def backup_postgres(conn, version: int) -> str:
    """The history's tables copied into a schema of their own, ``planecal_backup_vN``."""
    from sqlalchemy import inspect, text
    names = set(inspect(conn).get_schema_names())
    name, k = f"planecal_backup_v{version}", 1
    while name in names:
        k += 1
        name = f"planecal_backup_v{version}_{k}"
    conn.execute(text(f'CREATE SCHEMA "{name}"'))
    for t in (*schema.TABLES, "alembic_version"):
        if inspect(conn).has_table(t):
            conn.execute(text(f'CREATE TABLE "{name}"."{t}" AS TABLE "{t}"'))
    return name


def advisory_lock(conn) -> None:
    from sqlalchemy import text
    conn.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": ADVISORY_KEY})
