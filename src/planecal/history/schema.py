"""The history's tables, its schema version and their migrations (Alembic).

Version 2 (``REVISION`` "0002")::

    meta        key, value                  format = planecal-history, schema_version = 2
    entries     id (never reused: SQLite AUTOINCREMENT, a PostgreSQL sequence), kind,
                created_utc, cell, scene, robot, robot_sha256, world (JSON),
                planecal_version, note, outcome, exit_code, against_id (-> entries.id),
                result_sha256, output, summary (JSON), document (JSON)
    inputs      id (their order), entry_id (-> entries.id), role, path, sha256, bytes (64-bit)
    parameters  id (their order), entry_id (-> entries.id), name, value, std, unit, status
    alembic_version  version_num           Alembic's revision of the schema

Every text column is unbounded on both backends (planecal checks its own limits before it
writes: ``values``); ``value`` may be null (a number that is not defined). Version 1 (what
planecal wrote before issue 32: bounded strings, 32-bit sizes on PostgreSQL, entry numbers
SQLite could reuse, rows without an order, no ``alembic_version``) is upgraded by the
migrations in ``migrations/versions`` (``0001``: version 1's tables, ``0002``: version 2),
run with Alembic's own ``command.stamp`` / ``command.upgrade`` on the history's open
transaction.
"""
from __future__ import annotations

from importlib import resources

FORMAT = "planecal-history"
SCHEMA_VERSION = 2
REVISION = "0002"
REVISIONS = {"0001": 1, "0002": 2}  # Alembic revision -> schema version
TABLES = ("meta", "entries", "inputs", "parameters")
ENTRY_COLUMNS = ("id", "kind", "created_utc", "cell", "scene", "robot", "robot_sha256",
                 "world", "planecal_version", "note", "outcome", "exit_code", "against_id",
                 "result_sha256", "output", "summary", "document")
COLUMNS = {  # every version's columns (what reading needs), by table
    1: {"meta": ("key", "value"), "entries": ENTRY_COLUMNS,
        "inputs": ("entry_id", "role", "path", "sha256", "bytes"),
        "parameters": ("entry_id", "name", "value", "std", "unit", "status")},
    2: {"meta": ("key", "value"), "entries": ENTRY_COLUMNS,
        "inputs": ("id", "entry_id", "role", "path", "sha256", "bytes"),
        "parameters": ("id", "entry_id", "name", "value", "std", "unit", "status")},
}


def tables():
    """(MetaData, meta, entries, inputs, parameters) of the current version."""
    from sqlalchemy import (BigInteger, Column, Float, ForeignKey, Index, Integer, MetaData,
                            Table, Text)
    md = MetaData()
    meta = Table("meta", md, Column("key", Text, primary_key=True),
                 Column("value", Text, nullable=False))
    entries = Table(
        "entries", md,
        Column("id", Integer, primary_key=True, autoincrement=True),
        Column("kind", Text, nullable=False), Column("created_utc", Text, nullable=False),
        Column("cell", Text), Column("scene", Text), Column("robot", Text),
        Column("robot_sha256", Text), Column("world", Text),
        Column("planecal_version", Text), Column("note", Text),
        Column("outcome", Text, nullable=False), Column("exit_code", Integer, nullable=False),
        Column("against_id", Integer, ForeignKey("entries.id")),
        Column("result_sha256", Text), Column("output", Text),
        Column("summary", Text), Column("document", Text),
        Index("entries_cell", "cell"), Index("entries_result", "result_sha256"),
        sqlite_autoincrement=True)
    inputs = Table("inputs", md,
                   Column("id", Integer, primary_key=True, autoincrement=True),
                   Column("entry_id", Integer, ForeignKey("entries.id"), nullable=False),
                   Column("role", Text, nullable=False), Column("path", Text),
                   Column("sha256", Text), Column("bytes", BigInteger),
                   Index("inputs_entry", "entry_id"))
    parameters = Table("parameters", md,
                       Column("id", Integer, primary_key=True, autoincrement=True),
                       Column("entry_id", Integer, ForeignKey("entries.id"), nullable=False),
                       Column("name", Text, nullable=False), Column("value", Float),
                       Column("std", Float), Column("unit", Text), Column("status", Text),
                       Index("parameters_entry", "entry_id"))
    return md, meta, entries, inputs, parameters


def alembic_config(connection):
    """Alembic's configuration for the history's migrations, on ``connection`` (an open
    transaction: the migrations run in it, ``migrations/env.py``)."""
    from alembic.config import Config
    cfg = Config()
    cfg.set_main_option("script_location",
                        str(resources.files("planecal.history") / "migrations"))
    cfg.attributes["connection"] = connection
    return cfg


def create(conn) -> None:
    """The current schema in an empty database (``conn``: its open transaction), stamped
    with the current revision."""
    from alembic import command
    md = tables()[0]
    md.create_all(conn)
    conn.execute(md.tables["meta"].insert(), [
        {"key": "format", "value": FORMAT}, {"key": "schema_version", "value": str(SCHEMA_VERSION)}])
    command.stamp(alembic_config(conn), REVISION)


def upgrade(conn, version: int) -> None:
    """A history of an older ``version`` brought to the current one in ``conn``'s open
    transaction: a version-1 history (no ``alembic_version`` yet) is stamped ``0001``
    first."""
    from alembic import command
    cfg = alembic_config(conn)
    if version == 1 and current_revision(conn) is None:
        command.stamp(cfg, "0001")
    command.upgrade(cfg, REVISION)


def current_revision(conn) -> str | None:
    """The ``alembic_version`` row, None without that table."""
    from sqlalchemy import inspect, text
    if not inspect(conn).has_table("alembic_version"):
        return None
    rows = conn.execute(text("SELECT version_num FROM alembic_version")).all()
    return str(rows[0][0]) if len(rows) == 1 else "?"
