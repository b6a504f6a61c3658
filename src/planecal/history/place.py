"""Where a history is: an SQLite file, or a PostgreSQL database by URL (docs/HISTORY.md).

``place_of(where)`` reads ``--history`` (or ``$PLANECAL_HISTORY``): a path is an SQLite
file; ``postgresql://`` (or ``postgresql+psycopg://``, ``postgres://``) a PostgreSQL
database through psycopg 3; ``sqlite:///PATH`` the file at PATH. Any other database is
refused: the history's guarantees (a schema created race-free, entry numbers never
reused, limits identical on both) are built and tested on these two.

A password never leaves this module in any form: the place's ``label`` (what every message
prints) shows ``***`` for it, whether it was given as ``user:pw@``, as ``?password=``
(or any ``...password=`` option) or in a URL that does not parse; ``scrub`` takes it out
of any text (a driver's message). A URL without one lets libpq find it as usual
(``PGPASSWORD``, ``~/.pgpass``, a service file).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import parse_qsl, urlsplit

from planecal.base.errors import InputError

DEFAULT_FILE = "planecal.db"
ENV = "PLANECAL_HISTORY"
WAIT_ENV = "PLANECAL_HISTORY_WAIT_S"
DEFAULT_WAIT_S = 60.0
_SCHEME = re.compile(r"^(postgres(ql)?|sqlite)([+][A-Za-z0-9_]*)?:", re.IGNORECASE)
_PG_DRIVERS = ("postgresql", "postgres", "postgresql+psycopg")
_SQLITE_DRIVERS = ("sqlite", "sqlite+pysqlite")
SHAPE = "postgresql://USER@HOST[:PORT]/DATABASE"


@dataclass(frozen=True)
class Place:
    """A history's place: ``path`` for an SQLite file, else ``url`` (a SQLAlchemy URL of
    PostgreSQL through psycopg); ``label`` is how messages name it (no password);
    ``secrets`` what ``scrub`` removes from any text."""
    label: str
    path: Path | None = None
    url: object | None = None
    secrets: tuple = ()

    @property
    def sqlite(self) -> bool:
        return self.path is not None

    def scrub(self, text: str) -> str:
        """``text`` with every form of the password replaced by ***."""
        for s in sorted(self.secrets, key=len, reverse=True):
            text = text.replace(s, "***")
        return text

    def error(self, what: str) -> str:
        """A one-line message about this history."""
        line = self.scrub(" ".join(str(what).split()))
        return f"--history {self.label}: {line}"


def location(arg: str | None) -> str:
    """The history a command uses: ``--history``, else ``$PLANECAL_HISTORY``, else
    ``planecal.db`` in the working folder."""
    if arg:
        return str(arg)
    return os.environ.get(ENV) or DEFAULT_FILE


def wait_s() -> float:
    """How long a command waits for a history another process holds (a write lock, a
    busy server): ``$PLANECAL_HISTORY_WAIT_S``, default 60 s."""
    text = os.environ.get(WAIT_ENV)
    if not text:
        return DEFAULT_WAIT_S
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not 0.1 <= v <= 3600:
        raise InputError(f"${WAIT_ENV}: expected seconds in [0.1, 3600], got {text[:40]!r}")
    return v


def is_url(where: str) -> bool:
    return "://" in where or bool(_SCHEME.match(where))


def place_of(where: str) -> Place:
    """The place ``where`` names (module docstring); one-line InputError (its label with
    no password) for a URL that is not one of a database planecal keeps a history in."""
    if not is_url(where):
        return Place(str(where), path=Path(where))
    secrets = _raw_secrets(where)
    label = f"{where.split(':', 1)[0][:40]}:..."  # a URL that does not parse: its scheme
    try:
        from sqlalchemy.engine import make_url
        url = make_url(where)
        url.port  # noqa: B018  (a port that is not a number raises here)
    except Exception as e:  # noqa: BLE001  (ArgumentError, ValueError: not a URL)
        why = "its port is not a number" if "int()" in str(e) else "it does not parse"
        raise InputError(Place(label, secrets=secrets).error(
            f"not a database URL ({why}; expected {SHAPE}, or an SQLite file's path)")) \
            from None
    secrets += tuple(s for s in [url.password] + [v for k, v in url.query.items()
                                                  if "password" in k.lower()]
                     if isinstance(s, str) and s)
    if url.drivername in _SQLITE_DRIVERS:
        if not url.database or url.database == ":memory:" or url.query:
            raise InputError(Place(label, secrets=secrets).error(
                "an SQLite history is a file: give sqlite:///PATH (no options), or the path"))
        return Place(url.database, path=Path(url.database))
    if url.drivername not in _PG_DRIVERS:
        raise InputError(Place(label, secrets=secrets).error(
            f"{url.drivername}: a history is an SQLite file or a PostgreSQL database "
            f"({SHAPE})"))
    url = url.set(drivername="postgresql+psycopg")
    label = _redacted(url.render_as_string(hide_password=False), secrets)
    return Place(label, url=url, secrets=secrets)


def _raw_secrets(where: str) -> tuple:
    """The password as written in ``where`` (percent-encoded or not), from the userinfo and
    from any ``...password=`` option, however malformed the rest."""
    out = []
    m = re.search(r"^[^:]*:(?://)?([^@/?#]*)@", where)
    if m and ":" in m.group(1):
        out.append(m.group(1).split(":", 1)[1])
    query = where.split("?", 1)[1] if "?" in where else ""
    for part in re.split(r"[&;]", query):
        k, _, v = part.partition("=")
        if "password" in k.lower() and v:
            out.append(v)
    try:
        parts = urlsplit(where)
        if parts.password:
            out.append(parts.password)
        out += [v for k, v in parse_qsl(parts.query) if "password" in k.lower() and v]
    except ValueError:
        pass
    return tuple(s for s in dict.fromkeys(out) if s)


def _redacted(where: str, secrets: tuple = ()) -> str:
    """``where`` with the userinfo's password and every ``...password=`` value as ***."""
    text = re.sub(r"^([^:]*:(?://)?[^:@/?#]*):[^@/?#]*@", r"\1:***@", where)
    text = re.sub(r"((?:^|[?&;])[^=&;?]*password=)[^&;#]*", r"\1***", text, flags=re.I)
    for s in sorted(secrets, key=len, reverse=True):
        text = text.replace(s, "***")
    return text
