"""A history's schema read, checked, and created or upgraded where a command records.

``state(conn)`` says what a database holds: nothing yet (``None``), or a planecal
history's schema version, refusing (``HistoryError``, one line) what is not one: another
application's tables, a meta table that is not planecal's, a newer schema (a version or
an Alembic revision this planecal does not know), a table or a column missing (a dropped
table or column: damaged). ``prepare`` opens the engine's database for a command:
creates a new history where it may write (race-free: ``backend``), upgrades an older one
after its backup (under the write lock, checked again under it), and returns the
version it reads.
"""
from __future__ import annotations

import logging
import sys

from planecal.history import backend, schema
from planecal.history.backend import HistoryError
from planecal.history.place import Place

log = logging.getLogger(__name__)


def state(conn, place: Place) -> int | None:
    """The schema version of the history in ``conn`` (None: an empty database)."""
    from sqlalchemy import inspect, text
    insp = inspect(conn)
    names = set(insp.get_table_names())
    if not names:
        return None
    if "meta" not in names:
        shown = ", ".join(sorted(names)[:5]) + (", ..." if len(names) > 5 else "")
        raise HistoryError(place.error(
            f"not a planecal history: a database of another application (tables {shown}); "
            "planecal writes nothing there"))
    cols = {c["name"] for c in insp.get_columns("meta")}
    if not {"key", "value"} <= cols:
        raise HistoryError(place.error("not a planecal history (its meta table is not "
                                       "planecal's)"))
    meta = {str(k): v for k, v in conn.execute(text('SELECT "key", value FROM meta')).all()}
    if meta.get("format") != schema.FORMAT:
        raise HistoryError(place.error(f"not a planecal history (meta format "
                                       f"{str(meta.get('format'))[:40]!r})"))
    version = _version(meta.get("schema_version"), place)
    revision = schema.current_revision(conn)
    newer = version > schema.SCHEMA_VERSION or (revision is not None
                                                 and revision not in schema.REVISIONS)
    if newer:
        raise HistoryError(place.error(
            f"made by a newer planecal (schema version {version}"
            f"{', revision ' + revision[:20] if revision else ''}); this planecal reads "
            f"versions up to {schema.SCHEMA_VERSION}: use a newer planecal"))
    if revision is not None and schema.REVISIONS[revision] != version:
        raise HistoryError(place.error(f"damaged: meta says schema version {version}, "
                                       f"Alembic's revision {revision} is version "
                                       f"{schema.REVISIONS[revision]}"))
    for table, want in schema.COLUMNS[version].items():
        if table not in names:
            raise HistoryError(place.error(f"damaged: its table {table} is missing"))
        have = {c["name"] for c in insp.get_columns(table)}
        missing = [c for c in want if c not in have]
        if missing:
            raise HistoryError(place.error(f"damaged: table {table} has no column "
                                           f"{missing[0]}"))
    return version


def _version(text, place: Place) -> int:
    try:
        v = int(str(text))
    except ValueError:
        raise HistoryError(place.error(f"damaged: meta schema_version {str(text)[:20]!r} is "
                                       "not a version number")) from None
    if v < 1:
        raise HistoryError(place.error(f"damaged: meta schema_version {v}"))
    return v


def prepare(engine, place: Place, write: bool, new: bool = True) -> int:
    """The history in ``engine`` ready for a command (module docstring); its version.
    ``new`` False: an empty database is not made a history (a rollback needs one)."""
    with engine.connect() as conn, conn.begin():
        version = state(conn, place)
    if not write or not new:
        if version is None:
            raise HistoryError(place.error("not a planecal history yet (an empty database)"))
        return version  # an older history is read as it is
    if place.sqlite and version is None:
        raise HistoryError(place.error("an empty SQLite database, not a planecal history "
                                       "(planecal did not make it: remove it to start one)"))
    if version != schema.SCHEMA_VERSION:
        _create_or_upgrade(engine, place)
    if place.sqlite:
        _wal(engine)
    else:
        _may_insert(engine, place)
    return schema.SCHEMA_VERSION


def _may_insert(engine, place: Place) -> None:
    """PostgreSQL: a role that may only read is refused before the work, not after it."""
    from sqlalchemy import text
    with engine.connect() as conn, conn.begin():
        for t in ("entries", "inputs", "parameters"):
            if not conn.execute(text("SELECT has_table_privilege(:t, 'INSERT')"),
                                {"t": t}).scalar():
                raise HistoryError(place.error(f"cannot be written (this login may not add "
                                               f"rows to {t}: a read-only role lists and "
                                               "shows, it does not record)"))


def _create_or_upgrade(engine, place: Place) -> None:
    with engine.connect().execution_options(planecal_write=True) as conn, conn.begin():
        if not place.sqlite:
            backend.advisory_lock(conn)
        version = state(conn, place)  # again, under the lock: another may have done it
        if version is None:
            schema.create(conn)
        elif version < schema.SCHEMA_VERSION:
            where = (backend.backup_file(place, version) if place.sqlite
                     else f"schema {backend.backup_postgres(conn, version)}")
            schema.upgrade(conn, version)
            print(f"planecal: history {place.label}: upgraded from schema version {version} to "
                  f"{schema.SCHEMA_VERSION} (the version-{version} copy: {where})",
                  file=sys.stderr)


def _wal(engine) -> None:
    """A version-1 file (rollback journal) in WAL mode from now on, so readers stop waiting
    for writers; where another process holds it open, the next command that records tries
    again."""
    import sqlite3
    try:
        if str(backend.pragma(engine, "journal_mode")).lower() != "wal":
            backend.pragma(engine, "journal_mode=WAL")
    except sqlite3.Error as e:
        log.info("history: not in WAL mode yet (%s)", e)
