"""A cell's history (SQLAlchemy Core): an SQLite file by default, a PostgreSQL database by
URL for a shop with many cells (``place``); the tables and their versions in ``schema``,
how each backend is opened in ``backend`` and ``opening``. docs/HISTORY.md describes it.

An entry is one command's record (``Entry``): calibrate, validate, export, check, compare,
rollback. Its number (``id``) is the database's, unique in the history and never reused
(also after the last entry is deleted). ``add`` writes an entry with its inputs and
parameters in one transaction: a reader sees all of it or none, a writer killed in it
leaves nothing of it. Any number of processes add entries at once; readers never wait
for them.

Values are checked on the way in and out (``values``): an entry read back carries the
``problems`` of what was stored in it that planecal does not write (text where a number
belongs, NaN, an infinity, JSON that is not JSON), with those values None. Every failure
of the database is a ``HistoryError`` (an ``InputError``: one line naming the history,
no password, and the cause).
"""
from __future__ import annotations

import sqlite3
from contextlib import contextmanager
from dataclasses import dataclass, field

from planecal.base.errors import InputError
from planecal.history import backend, opening, schema
from planecal.history.backend import HistoryError
from planecal.history.place import DEFAULT_FILE, ENV, location, place_of  # noqa: F401
from planecal.history.values import Reader, clean, number_in, text_in, to_json  # noqa: F401

KINDS = ("calibrate", "validate", "export", "check", "compare", "rollback")
OUTCOMES = ("ok", "failed", "in_control", "drifted", "agree", "differ")


@dataclass(frozen=True)
class ParameterRow:
    """One parameter of a calibration entry, by name, in SI units (``value`` or ``std``
    None: not a number, fixed or not identifiable)."""
    name: str
    value: float | None
    std: float | None
    unit: str | None
    status: str | None


@dataclass(frozen=True)
class InputRow:
    role: str
    path: str | None
    sha256: str | None
    bytes: int | None


@dataclass
class Entry:
    """One command's record. ``outcome``: ok, failed, in_control, drifted, agree, differ;
    ``against``: the entry it refers to (the calibration a check, an export or a rollback
    read); ``result_sha256``: the result file it wrote (calibrate) or read (the others);
    ``world``: where the data was made (a twin's world, the real cell); ``summary``: a few
    figures; ``document``: the whole result (calibrate: the result file's JSON).
    ``problems``: read back, what was stored that planecal does not write."""
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
    problems: list[str] = field(default_factory=list)


class History:
    """An open history (module docstring). ``open`` checks the place and the schema;
    ``label`` is how messages name it (never a password)."""

    def __init__(self, engine, place, version: int):
        _, self._meta, self._entries, self._inputs, self._params = schema.tables()
        self.engine = engine
        self.place = place
        self.label = place.label
        self.version = version
        self.unread: HistoryError | None = None  # a lookup that failed (commands' ``consult``)

    @classmethod
    def open(cls, where: str, inputs=(), create: bool = True, new: bool = True) -> "History":
        """The history at ``where`` (a file path or a database URL). ``create`` True: a
        command that records (the history is made if new, upgraded if older, and must be
        writable; with ``new`` False it must exist: a rollback); False: one that only reads
        (it must exist; nothing is written)."""
        from sqlalchemy.exc import SQLAlchemyError
        place = place_of(where)
        if place.sqlite:
            backend.check_file(place, inputs, create, new)
        try:
            engine, version = cls._engine(place, create, new)
        except HistoryError:
            raise
        except (SQLAlchemyError, sqlite3.Error, OSError) as e:  # sqlite3: its backup API
            raise backend.failure(place, e, "cannot open it") from None
        return cls(engine, place, version)

    @staticmethod
    def _engine(place, write: bool, new: bool):
        from sqlalchemy.exc import SQLAlchemyError
        if not place.sqlite:
            engine = backend.postgres_engine(place)
            return engine, opening.prepare(engine, place, write, new)
        if write and not place.path.exists():
            backend.create_file(place)
        engine = backend.sqlite_engine(place.path, write)
        try:
            return engine, opening.prepare(engine, place, write, new)
        except SQLAlchemyError as e:
            wal = place.path.with_name(place.path.name + "-wal")
            why = str(e).lower()
            if write or wal.exists() or not ("readonly" in why or "unable to open" in why):
                raise
        engine.dispose()  # read-only where no -wal waits: the file is the whole history
        engine = backend.sqlite_engine(place.path, False, immutable=True)
        return engine, opening.prepare(engine, place, False)

    def close(self) -> None:
        self.engine.dispose()

    @contextmanager
    def _transaction(self, doing: str, write: bool = False):
        from sqlalchemy.exc import SQLAlchemyError
        try:
            with self.engine.connect().execution_options(planecal_write=write) as conn, \
                    conn.begin():
                yield conn
        except HistoryError:
            raise
        except (SQLAlchemyError, sqlite3.Error, OSError) as e:
            raise backend.failure(self.place, e, doing) from None

    # ----- writing -----
    def add(self, e: Entry) -> int:
        """Write ``e`` with its inputs and parameters in one transaction; its number.
        ``HistoryError`` where the entry was not written."""
        if e.kind not in KINDS:
            raise ValueError(f"history entry kind {e.kind!r}: one of {', '.join(KINDS)}")
        try:
            row, inputs, params = _rows(e)
        except (ValueError, TypeError) as err:
            raise HistoryError(self.place.error(f"the entry was not written ({err})")) from None
        with self._transaction("the entry was not written", write=True) as conn:
            n = int(conn.execute(self._entries.insert().values(**row)).inserted_primary_key[0])
            if inputs:
                conn.execute(self._inputs.insert(), [{"entry_id": n, **i} for i in inputs])
            if params:
                conn.execute(self._params.insert(), [{"entry_id": n, **p} for p in params])
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
        with self._transaction("cannot read it") as conn:
            return [_entry(r._mapping) for r in conn.execute(q)]

    def get(self, n: int) -> Entry:
        """Entry ``n`` with its document, inputs and parameters; InputError if none."""
        from sqlalchemy import select
        t, ti, tp = self._entries, self._inputs, self._params
        with self._transaction("cannot read it") as conn:
            r = conn.execute(select(t).where(t.c.id == int(n))).first()
            if r is None:
                raise InputError(f"history {self.label}: no entry {n}")
            e = _entry(r._mapping)
            rd = Reader()
            e.document = rd.json(r._mapping["document"], "document", dict)
            e.inputs = [_input(x._mapping, k, rd) for k, x in enumerate(conn.execute(
                self._rows_of(ti, e.id)))]
            e.parameters = [_parameter(x._mapping, k, rd) for k, x in enumerate(conn.execute(
                self._rows_of(tp, e.id)))]
            e.problems += rd.problems
        return e

    def _rows_of(self, table, entry_id: int):
        """A child table's rows of one entry, in the order written (version 1 kept none:
        SQLite's row order)."""
        from sqlalchemy import select
        cols = [table.c[c] for c in schema.COLUMNS[self.version][table.name]]
        q = select(*cols).where(table.c.entry_id == entry_id)
        return q.order_by(table.c.id) if "id" in schema.COLUMNS[self.version][table.name] else q

    def find_result(self, sha256: str | None) -> int | None:
        """The newest calibrate entry that wrote a result file with this SHA-256."""
        from sqlalchemy import select
        if not sha256:
            return None
        t = self._entries
        q = (select(t.c.id).where(t.c.result_sha256 == sha256, t.c.kind == "calibrate")
             .order_by(t.c.id.desc()))
        with self._transaction("cannot read it") as conn:
            r = conn.execute(q).first()
        return None if r is None or isinstance(r[0], bool) or not isinstance(r[0], int) \
            else int(r[0])


def _rows(e: Entry) -> tuple[dict, list, list]:
    """The entry's rows as the tables take them, every value checked (``values``)."""
    t = text_in
    row = {"kind": e.kind, "created_utc": t(e.created_utc, "created_utc"),
           "cell": t(e.cell, "cell"), "scene": t(e.scene, "scene"), "robot": t(e.robot, "robot"),
           "robot_sha256": t(e.robot_sha256, "robot_sha256"), "world": to_json(e.world),
           "planecal_version": t(e.planecal_version, "planecal_version"),
           "note": t(e.note, "note"), "outcome": t(e.outcome, "outcome"),
           "exit_code": int(e.exit_code), "against_id": None if e.against is None
           else int(e.against), "result_sha256": t(e.result_sha256, "result_sha256"),
           "output": t(e.output, "output"), "summary": to_json(e.summary or {}),
           "document": to_json(e.document)}
    inputs = [{"role": t(i.role, "inputs.role"), "path": t(i.path, "inputs.path"),
               "sha256": t(i.sha256, "inputs.sha256"),
               "bytes": None if i.bytes is None else int(i.bytes)} for i in e.inputs]
    params = [{"name": t(p.name, "parameters.name"), "value": number_in(p.value),
               "std": number_in(p.std), "unit": t(p.unit, "parameters.unit"),
               "status": t(p.status, "parameters.status")} for p in e.parameters]
    return row, inputs, params


def _entry(m) -> Entry:
    """An entries row read back, every value checked."""
    rd = Reader()
    e = Entry(kind=rd.text(m["kind"], "kind", True, KINDS) or "?",
              outcome=rd.text(m["outcome"], "outcome", True, OUTCOMES) or "?",
              exit_code=rd.integer(m["exit_code"], "exit_code", True),
              created_utc=rd.text(m["created_utc"], "created_utc", True) or "?",
              planecal_version=rd.text(m["planecal_version"], "planecal_version"),
              cell=rd.text(m["cell"], "cell"), scene=rd.text(m["scene"], "scene"),
              robot=rd.text(m["robot"], "robot"),
              robot_sha256=rd.text(m["robot_sha256"], "robot_sha256"),
              world=rd.json(m["world"], "world"), note=rd.text(m["note"], "note"),
              against=rd.integer(m["against_id"], "against_id"),
              result_sha256=rd.text(m["result_sha256"], "result_sha256"),
              output=rd.text(m["output"], "output"),
              summary=rd.json(m["summary"], "summary", dict) or {},
              id=rd.integer(m["id"], "id", True))
    e.problems = rd.problems
    return e


def _input(m, k: int, rd: Reader) -> InputRow:
    where = f"inputs[{k}]"
    n = rd.integer(m["bytes"], f"{where}.bytes")
    return InputRow(rd.text(m["role"], f"{where}.role", True) or "?",
                    rd.text(m["path"], f"{where}.path"), rd.text(m["sha256"], f"{where}.sha256"),
                    None if n is None or n < 0 else n)


def _parameter(m, k: int, rd: Reader) -> ParameterRow:
    name = rd.text(m["name"], f"parameters[{k}].name", True) or f"?{k}"
    where = f"parameters[{name}]"
    return ParameterRow(name, rd.number(m["value"], f"{where}.value"),
                        rd.number(m["std"], f"{where}.std"), rd.text(m["unit"], f"{where}.unit"),
                        rd.text(m["status"], f"{where}.status"))


def consult(hist, read, default):
    """``read(hist)``, a lookup in the history during a command's work (None: no history);
    where the history fails, ``default`` (the work goes on without it), the failure kept
    for the one line ``commands.history_options.record`` prints."""
    if hist is None:
        return default
    try:
        return read(hist)
    except HistoryError as e:
        if hist.unread is None:
            hist.unread = e
        return default
