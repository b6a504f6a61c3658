"""A cell's history in an embedded database (SQLAlchemy Core): SQLite by default, a server
database (PostgreSQL, ...) by URL for a shop with many cells. docs/HISTORY.md describes the
tables; in short::

    meta        key, value                  the schema's format and version
    entries     id, kind, created_utc, cell, scene, robot, robot_sha256, world (JSON),
                planecal_version, note, outcome, exit_code, against_id (-> entries.id),
                result_sha256, output, summary (JSON), document (JSON)
    inputs      entry_id (-> entries.id), role, path, sha256, bytes
    parameters  entry_id (-> entries.id), name, value, std, unit, status

An entry is one command's record (``Entry``): calibrate, validate, export, check, compare,
rollback. Its number (``id``) is the database's, unique in the history and never reused.
``add`` writes an entry with its inputs and parameters in one transaction: a reader sees
all of it or none. On SQLite every transaction begins ``IMMEDIATE`` (it takes the write
lock first) and waits up to ``BUSY_TIMEOUT_S`` for another process's transaction to end,
so two commands writing one history at once both land, one after the other; the schema is
created the same way, so two first writers do not race to create it.

JSON columns hold no NaN or infinity (null instead) and no numpy types (``to_json``).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from planecal.base.errors import InputError, RunFailed

FORMAT = "planecal-history"
SCHEMA_VERSION = 1
DEFAULT_FILE = "planecal.db"
ENV = "PLANECAL_HISTORY"
BUSY_TIMEOUT_S = 60.0
KINDS = ("calibrate", "validate", "export", "check", "compare", "rollback")
SQLITE_MAGIC = b"SQLite format 3\0"


@dataclass(frozen=True)
class ParameterRow:
    """One parameter of a calibration entry, by name, in SI units (``std`` None: fixed or
    not identifiable)."""
    name: str
    value: float
    std: float | None
    unit: str
    status: str


@dataclass(frozen=True)
class InputRow:
    role: str
    path: str
    sha256: str
    bytes: int


@dataclass
class Entry:
    """One command's record. ``outcome``: ok, failed, in_control, drifted, agree, differ;
    ``against``: the entry it refers to (the calibration a check, an export or a rollback
    read); ``result_sha256``: the result file it wrote (calibrate) or read (the others);
    ``world``: where the data was made (a twin's world, the real cell); ``summary``: a few
    figures; ``document``: the whole result (calibrate: the result file's JSON)."""
    kind: str
    outcome: str
    exit_code: int
    created_utc: str
    planecal_version: str
    cell: str | None = None
    scene: str | None = None
    robot: str | None = None
    robot_sha256: str | None = None
    world: dict | list | None = None
    note: str | None = None
    against: int | None = None
    result_sha256: str | None = None
    output: str | None = None
    summary: dict = field(default_factory=dict)
    document: dict | None = None
    inputs: list[InputRow] = field(default_factory=list)
    parameters: list[ParameterRow] = field(default_factory=list)
    id: int | None = None


def clean(v):
    """``v`` with numpy scalars and arrays as Python values and NaN/inf as None (JSON)."""
    if isinstance(v, dict):
        return {str(k): clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [clean(x) for x in v]
    if hasattr(v, "tolist") and not isinstance(v, (str, bytes)):  # numpy arrays, scalars
        return clean(v.tolist())
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def to_json(v) -> str | None:
    return None if v is None else json.dumps(clean(v), allow_nan=False, sort_keys=False)


def from_json(text):
    return None if text is None else json.loads(text)


def _tables():
    from sqlalchemy import (Column, Float, ForeignKey, Index, Integer, MetaData, String,
                            Table, Text)
    md = MetaData()
    meta = Table("meta", md, Column("key", String(64), primary_key=True),
                 Column("value", Text, nullable=False))
    entries = Table(
        "entries", md,
        Column("id", Integer, primary_key=True, autoincrement=True),
        Column("kind", String(16), nullable=False),
        Column("created_utc", String(40), nullable=False),
        Column("cell", String(200)), Column("scene", Text), Column("robot", String(200)),
        Column("robot_sha256", String(64)), Column("world", Text),
        Column("planecal_version", String(40)), Column("note", Text),
        Column("outcome", String(32), nullable=False),
        Column("exit_code", Integer, nullable=False),
        Column("against_id", Integer, ForeignKey("entries.id")),
        Column("result_sha256", String(64)), Column("output", Text),
        Column("summary", Text), Column("document", Text),
        Index("entries_cell", "cell"), Index("entries_result", "result_sha256"))
    inputs = Table("inputs", md,
                   Column("entry_id", Integer, ForeignKey("entries.id"), nullable=False),
                   Column("role", String(40), nullable=False), Column("path", Text),
                   Column("sha256", String(64)), Column("bytes", Integer),
                   Index("inputs_entry", "entry_id"))
    parameters = Table("parameters", md,
                       Column("entry_id", Integer, ForeignKey("entries.id"), nullable=False),
                       Column("name", String(40), nullable=False),
                       Column("value", Float, nullable=False), Column("std", Float),
                       Column("unit", String(20)), Column("status", String(60)),
                       Index("parameters_entry", "entry_id"))
    return md, meta, entries, inputs, parameters


def location(arg: str | None) -> str:
    """The history a command uses: ``--history``, else ``$PLANECAL_HISTORY``, else
    ``planecal.db`` in the working folder."""
    if arg:
        return str(arg)
    return os.environ.get(ENV) or DEFAULT_FILE


def is_url(where: str) -> bool:
    return "://" in where


def check_file(where: str, inputs=()) -> Path:
    """A history file checked before any work: the output guard's checks (not an input
    of the command, not a directory, in a folder that exists and can be written;
    ``io.outputs``) and, if it exists, an SQLite database (one-line InputError)."""
    from planecal.io.outputs import check_output
    p = check_output(where, inputs, force=True, what="--history")
    if p.exists():
        try:
            with open(p, "rb") as f:
                head = f.read(len(SQLITE_MAGIC))
        except OSError as e:
            raise InputError(f"--history {p}: cannot read ({e.strerror})") from None
        if head and head != SQLITE_MAGIC:
            raise InputError(f"--history {p}: not an SQLite database (a history is one)")
    return p


class History:
    """An open history (module docstring). ``open`` checks the place and creates the schema
    if it is new; ``label`` is how messages name it."""

    def __init__(self, engine, label: str):
        md, self._meta, self._entries, self._inputs, self._params = _tables()
        self._md = md
        self.engine = engine
        self.label = label

    @classmethod
    def open(cls, where: str, inputs=(), create: bool = True) -> "History":
        """The history at ``where`` (a file path or a database URL). ``create`` False: a
        history that does not exist yet is an error (reading commands)."""
        from sqlalchemy import create_engine, event
        from sqlalchemy.exc import ArgumentError, SQLAlchemyError

        if is_url(where):
            url, label = where, _hide_password(where)
            sqlite = where.startswith("sqlite")
        else:
            p = check_file(where, inputs)
            if not create and not p.exists():
                raise InputError(f"--history {p}: no history here yet (commands that "
                                 "calibrate, validate, export, check or compare make one)")
            url, label, sqlite = f"sqlite:///{p.resolve()}", str(p), True
        try:
            engine = create_engine(url, **({"connect_args": {"timeout": BUSY_TIMEOUT_S}}
                                          if sqlite else {"pool_pre_ping": True}))
        except (ArgumentError, SQLAlchemyError, ImportError) as e:
            raise InputError(f"--history {label}: cannot open ({_first_line(e)})") from None
        if sqlite:
            _immediate_transactions(engine, event)
        h = cls(engine, label)
        h._schema(create)
        return h

    def _schema(self, create: bool) -> None:
        from sqlalchemy import inspect, select
        from sqlalchemy.exc import SQLAlchemyError
        try:
            with self.engine.begin() as conn:
                exists = inspect(conn).has_table("meta")
                if not exists:
                    if not create:
                        raise InputError(f"--history {self.label}: not a planecal history "
                                         "(no meta table)")
                    self._md.create_all(conn)
                    conn.execute(self._meta.insert(), [
                        {"key": "format", "value": FORMAT},
                        {"key": "schema_version", "value": str(SCHEMA_VERSION)}])
                rows = dict(conn.execute(select(self._meta.c.key, self._meta.c.value)).all())
        except SQLAlchemyError as e:
            raise InputError(f"--history {self.label}: cannot use the database "
                             f"({_first_line(e)})") from None
        if rows.get("format") != FORMAT:
            raise InputError(f"--history {self.label}: not a planecal history (meta format "
                             f"{rows.get('format')!r})")
        version = rows.get("schema_version", "?")
        if version != str(SCHEMA_VERSION):
            raise InputError(f"--history {self.label}: schema version {version}; this planecal "
                             f"reads version {SCHEMA_VERSION}")

    def close(self) -> None:
        self.engine.dispose()

    # ----- writing -----
    def add(self, e: Entry) -> int:
        """Write ``e`` with its inputs and parameters in one transaction; its number."""
        from sqlalchemy.exc import SQLAlchemyError
        if e.kind not in KINDS:
            raise ValueError(f"history entry kind {e.kind!r}: one of {', '.join(KINDS)}")
        row = {"kind": e.kind, "created_utc": e.created_utc, "cell": e.cell, "scene": e.scene,
               "robot": e.robot, "robot_sha256": e.robot_sha256, "world": to_json(e.world),
               "planecal_version": e.planecal_version, "note": e.note, "outcome": e.outcome,
               "exit_code": int(e.exit_code), "against_id": e.against,
               "result_sha256": e.result_sha256, "output": e.output,
               "summary": to_json(e.summary or {}), "document": to_json(e.document)}
        try:
            with self.engine.begin() as conn:
                n = int(conn.execute(self._entries.insert().values(**row)).inserted_primary_key[0])
                if e.inputs:
                    conn.execute(self._inputs.insert(), [
                        {"entry_id": n, "role": i.role, "path": i.path, "sha256": i.sha256,
                         "bytes": int(i.bytes)} for i in e.inputs])
                if e.parameters:
                    conn.execute(self._params.insert(), [
                        {"entry_id": n, "name": p.name, "value": float(p.value),
                         "std": None if p.std is None or not math.isfinite(p.std)
                         else float(p.std), "unit": p.unit, "status": p.status}
                        for p in e.parameters])
        except SQLAlchemyError as err:
            raise RunFailed(f"history {self.label}: the entry was not written "
                            f"({_first_line(err)})") from None
        e.id = n
        return n

    # ----- reading -----
    def entries(self, cell: str | None = None, kind: str | None = None) -> list[Entry]:
        """Every entry (without document, inputs and parameters), oldest first."""
        from sqlalchemy import select
        t = self._entries
        q = select(*[c for c in t.c if c.name != "document"]).order_by(t.c.id)
        if cell is not None:
            q = q.where(t.c.cell == cell)
        if kind is not None:
            q = q.where(t.c.kind == kind)
        with self.engine.connect() as conn:
            return [self._entry(r._mapping) for r in conn.execute(q)]

    def get(self, n: int) -> Entry:
        """Entry ``n`` with its document, inputs and parameters; InputError if none."""
        from sqlalchemy import select
        t = self._entries
        with self.engine.connect() as conn:
            r = conn.execute(select(t).where(t.c.id == int(n))).first()
            if r is None:
                raise InputError(f"history {self.label}: no entry {n}")
            e = self._entry(r._mapping)
            e.document = from_json(r._mapping["document"])
            ti, tp = self._inputs, self._params
            e.inputs = [InputRow(x.role, x.path, x.sha256, x.bytes) for x in conn.execute(
                select(ti).where(ti.c.entry_id == e.id))]
            e.parameters = [ParameterRow(x.name, x.value, x.std, x.unit, x.status)
                            for x in conn.execute(select(tp).where(tp.c.entry_id == e.id))]
        return e

    def find_result(self, sha256: str | None) -> int | None:
        """The newest calibrate entry that wrote a result file with this SHA-256."""
        from sqlalchemy import select
        if not sha256:
            return None
        t = self._entries
        q = (select(t.c.id).where(t.c.result_sha256 == sha256, t.c.kind == "calibrate")
             .order_by(t.c.id.desc()))
        with self.engine.connect() as conn:
            r = conn.execute(q).first()
        return None if r is None else int(r[0])

    @staticmethod
    def _entry(m) -> Entry:
        return Entry(kind=m["kind"], outcome=m["outcome"], exit_code=m["exit_code"],
                     created_utc=m["created_utc"], planecal_version=m["planecal_version"],
                     cell=m["cell"], scene=m["scene"], robot=m["robot"],
                     robot_sha256=m["robot_sha256"], world=from_json(m["world"]),
                     note=m["note"], against=m["against_id"],
                     result_sha256=m["result_sha256"], output=m["output"],
                     summary=from_json(m["summary"]) or {}, id=int(m["id"]))


def _immediate_transactions(engine, event) -> None:
    """SQLite: planecal, not the driver, begins transactions, and begins them IMMEDIATE
    (the write lock first, waiting up to the busy timeout)."""
    @event.listens_for(engine, "connect")
    def _connect(dbapi_connection, _record):
        dbapi_connection.isolation_level = None  # the driver emits no BEGIN of its own

    @event.listens_for(engine, "begin")
    def _begin(conn):
        conn.exec_driver_sql("BEGIN IMMEDIATE")


def _hide_password(url: str) -> str:
    from sqlalchemy.engine import make_url
    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # not a URL SQLAlchemy reads: opening it says why
        return url


def _first_line(e: Exception) -> str:
    text = str(getattr(e, "orig", None) or e)
    return (text.splitlines() or [type(e).__name__])[0]
