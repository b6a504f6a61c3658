"""The history tests' databases: every test that takes the ``db`` fixture runs once on an
SQLite file and once on a PostgreSQL database (a fresh one per test), with the same
assertions: the two backends must give the same outputs.

PostgreSQL runs where ``PLANECAL_TEST_POSTGRES`` names a server (a URL without password;
its password in ``PLANECAL_TEST_POSTGRES_PASSWORD``): ``.ci/postgres`` starts one and sets
both, and .ci/run runs these tests there (``-k postgresql``). Elsewhere the PostgreSQL
cases skip, saying so.
"""
from __future__ import annotations

import os
import uuid
from dataclasses import dataclass
from pathlib import Path

import pytest

PG_ENV = "PLANECAL_TEST_POSTGRES"
PG_PASSWORD_ENV = "PLANECAL_TEST_POSTGRES_PASSWORD"


@dataclass
class Db:
    """One test's history place: ``where`` is what ``--history`` takes."""
    backend: str
    where: str
    path: Path | None = None  # the SQLite file
    admin_url: str | None = None  # PostgreSQL: the server's maintenance database

    def execute(self, *statements: str) -> list:
        """Raw SQL on the history, as a hand (or another tool) would edit it; the last
        statement's rows."""
        import sqlalchemy as sa
        url = f"sqlite:///{self.path}" if self.path else self.where
        engine = sa.create_engine(url, poolclass=sa.pool.NullPool)
        rows: list = []
        try:
            with engine.begin() as conn:
                for s in statements:
                    r = conn.exec_driver_sql(s)
                    rows = r.all() if r.returns_rows else []
        finally:
            engine.dispose()
        return rows

    def url_with_password(self, form: str) -> str:
        """The URL with the password written in: ``userinfo`` (user:pw@) or ``query``
        (?password=)."""
        pw = os.environ[PG_PASSWORD_ENV]
        if form == "userinfo":
            return self.where.replace("planecal@", f"planecal:{pw}@", 1)
        return self.where + f"?password={pw}"


def postgres_or_skip() -> str:
    url = os.environ.get(PG_ENV)
    if not url:
        pytest.skip(f"no PostgreSQL server configured (${PG_ENV}; .ci/postgres starts one "
                    "and .ci/run runs these tests on it)")
    return url


def new_postgres_database(monkeypatch) -> tuple[str, str, str]:
    """A fresh database on the test server: (its URL, the maintenance URL, its name)."""
    import sqlalchemy as sa
    admin = postgres_or_skip()
    monkeypatch.setenv("PGPASSWORD", os.environ.get(PG_PASSWORD_ENV, ""))
    name = f"h_{uuid.uuid4().hex[:16]}"
    engine = sa.create_engine(admin, isolation_level="AUTOCOMMIT", poolclass=sa.pool.NullPool)
    with engine.connect() as conn:
        conn.exec_driver_sql(f'CREATE DATABASE "{name}"')
    engine.dispose()
    return admin.rsplit("/", 1)[0] + f"/{name}", admin, name


def drop_postgres_database(admin: str, name: str) -> None:
    import sqlalchemy as sa
    engine = sa.create_engine(admin, isolation_level="AUTOCOMMIT", poolclass=sa.pool.NullPool)
    with engine.connect() as conn:
        conn.exec_driver_sql(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')
    engine.dispose()


@pytest.fixture(params=["sqlite", "postgresql"])
def db(request, tmp_path, monkeypatch):
    """A place for a new history, on each backend (module docstring)."""
    if request.param == "sqlite":
        yield Db("sqlite", str(tmp_path / "h.db"), path=tmp_path / "h.db")
        return
    url, admin, name = new_postgres_database(monkeypatch)
    yield Db("postgresql", url, admin_url=admin)
    drop_postgres_database(admin, name)
