"""The history's values checked on the way in and on the way out.

In: JSON columns hold standard JSON only (NaN and infinities as null, numpy types as
Python's: ``to_json``); a number column holds a finite number or null; text holds no NUL
character (PostgreSQL refuses one, SQLite would keep it: the limits are planecal's, the
same on both); the user's ``--cell`` and ``--note`` are checked before the command's work
(``check_label``).

Out: what a database gives back is not trusted (a file edited by hand, a foreign tool):
``Reader`` takes each value through a check of its kind and keeps, for the entry, what was
wrong (``problems``: "summary: not JSON", "parameters[delta3].value: 'abc' is not a
number"). A value that fails is None, never a guess: a NaN, an infinity or a number too
large for a double (``1e999``) is never read as a number, text is never read as one.
"""
from __future__ import annotations

import json
import math

MAX_CELL = 200  # characters of --cell (a cell's name)
MAX_NOTE = 2000  # characters of --note
MAX_INT = 2**63 - 1


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


def number_in(v) -> float | None:
    """A number column's value: a finite float, else None."""
    if v is None or isinstance(v, bool):
        return None
    f = float(v)
    return f if math.isfinite(f) else None


def text_in(v, what: str) -> str | None:
    """A text column's value; ValueError for one that no backend takes alike."""
    if v is None:
        return None
    s = str(v)
    if "\0" in s:
        raise ValueError(f"{what}: holds a NUL character")
    return s


def check_label(text: str | None, flag: str, limit: int) -> None:
    """``--cell`` / ``--note``: one line of at most ``limit`` characters, no control
    characters (a line of ``history list`` each); ValueError saying so."""
    if text is None:
        return
    bad = next((c for c in text if ord(c) < 32 or 0x7f <= ord(c) < 0xa0), None)
    if bad is not None:
        raise ValueError(f"{flag}: one line of text without control characters (found "
                         f"{bad!r}); at most {limit} characters")
    if len(text) > limit:
        raise ValueError(f"{flag}: at most {limit} characters, got {len(text)}")
    if flag == "--cell" and not text.strip():
        raise ValueError("--cell: an empty name")


class _Bad(ValueError):
    pass


def _refuse(name: str):
    raise _Bad(f"{name} is not a number planecal writes")


def _finite(text: str) -> float:
    f = float(text)
    if not math.isfinite(f):
        raise _Bad(f"{text[:20]} is not a finite number")
    return f


def _bounded_int(text: str) -> int:
    if len(text.lstrip("-")) > 19 or abs(int(text)) > MAX_INT:
        raise _Bad(f"{text[:20]}... is too large a number")
    return int(text)


def shown(v, limit: int = 40) -> str:
    """A stored value as a message shows it: repr, cut."""
    r = repr(v)
    return r if len(r) <= limit else r[:limit - 3] + "..."


class Reader:
    """Values of one entry read back, each checked (module docstring); ``problems`` lists
    what was not what planecal writes."""

    def __init__(self):
        self.problems: list[str] = []

    def bad(self, where: str, why: str) -> None:
        self.problems.append(f"{where}: {why}")

    def json(self, text, where: str, kind=None):
        """A JSON column: None for null; the value, or None with a problem."""
        if text is None:
            return None
        if not isinstance(text, str):
            self.bad(where, f"{shown(text)} is not JSON text")
            return None
        try:
            v = json.loads(text, parse_constant=_refuse, parse_float=_finite,
                           parse_int=_bounded_int)
        except _Bad as e:
            self.bad(where, str(e))
            return None
        except (ValueError, RecursionError):
            self.bad(where, "not JSON")
            return None
        if kind is not None and not isinstance(v, kind):
            self.bad(where, f"not a JSON {'object' if kind is dict else 'value'}")
            return None
        return v

    def number(self, v, where: str) -> float | None:
        """A number column: a finite float (an int is one), None for null or a problem."""
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.bad(where, f"{shown(v)} is not a number")
            return None
        f = float(v)
        if not math.isfinite(f):
            self.bad(where, f"{shown(v)} is not a finite number")
            return None
        return f

    def integer(self, v, where: str, required: bool = False) -> int | None:
        if v is None:
            if required:
                self.bad(where, "missing")
            return None
        if isinstance(v, bool) or not isinstance(v, int) or abs(v) > MAX_INT:
            self.bad(where, f"{shown(v)} is not a whole number")
            return None
        return int(v)

    def text(self, v, where: str, required: bool = False, choices=None) -> str | None:
        if v is None:
            if required:
                self.bad(where, "missing")
            return None
        if not isinstance(v, str):
            self.bad(where, f"{shown(v)} is not text")
            return None
        if choices is not None and v not in choices:
            self.bad(where, f"{shown(v)} is not one of {', '.join(choices)}")
        return v
