"""The results file of a map (``studies.distributed.Engine.map(..., out=...)``): JSON
lines, one result appended the moment it arrives (one ``os.write`` of a whole line: a killed
map -- Ctrl-C, SIGKILL -- leaves whole lines), read back to resume::

    {"format": "planecal-results/1", "header": {...the study's settings...}}
    {"key": 0, "result": {...}, "arrays": {"/err": ["float64", [17]], ...}}

Numpy arrays are written as (nested) lists; ``arrays`` names them by JSON pointer (RFC 6901)
with dtype and shape, so a result read back is the same arrays, bit for bit (floats are
written with Python's shortest round-trip repr). A number that is not defined (NaN, an
infinity) is written as null, its pointer and value in ``nonfinite`` (``{"/err/0":
"nan"}``, "+inf", "-inf"): the file is standard JSON, and it reads back as written. A line holding a bare
``NaN`` or ``Infinity`` (not planecal's) is refused, naming the line. Every result the engine returns with a file -- read back or just computed --
is the decoded line (``ResultsFile.append``), so a resumed map returns exactly what an
uninterrupted one does. Tuples come back as lists; dict keys must be strings. Resuming
refuses a file written with another ``header`` (one line naming the first field that
differs). ``read_results`` reads a finished file.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError

RESULTS_FORMAT = "planecal-results/1"


def _ptr(parent: str, k) -> str:
    return parent + "/" + str(k).replace("~", "~0").replace("/", "~1")


_NONFINITE = {"nan": float("nan"), "+inf": float("inf"), "-inf": float("-inf")}


def _nonfinite_name(v: float) -> str:
    return "nan" if v != v else ("+inf" if v > 0 else "-inf")


def encode(obj, arrays: dict | None = None, at: str = "", nonfinite: dict | None = None):
    """``obj`` as JSON values (arrays as nested lists, numpy scalars as Python numbers, a
    NaN or infinity as null); ``arrays`` collects ``{pointer: [dtype, shape]}`` of every
    array, ``nonfinite`` ``{pointer: "nan" | "+inf" | "-inf"}`` of every number
    written as null."""
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in "biuf":
            raise TypeError(f"result {at or '/'}: cannot write an array of dtype {obj.dtype}")
        if arrays is not None:
            arrays[at] = [obj.dtype.str, list(obj.shape)]
        out = obj.tolist()
        if obj.dtype.kind == "f":
            for idx in np.argwhere(~np.isfinite(obj)):
                ptr = at + "".join(f"/{i}" for i in idx)
                if nonfinite is not None:
                    nonfinite[ptr] = _nonfinite_name(float(obj[tuple(idx)]))
                if len(idx):
                    parent = _get(out, [str(i) for i in idx[:-1]])
                    parent[int(idx[-1])] = None
                else:
                    out = None
        return out
    if isinstance(obj, np.generic):
        return encode(obj.item(), arrays, at, nonfinite)
    if isinstance(obj, dict):
        bad = [k for k in obj if not isinstance(k, str)]
        if bad:
            raise TypeError(f"result {at or '/'}: dict key {bad[0]!r} is not a string")
        return {k: encode(v, arrays, _ptr(at, k), nonfinite) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [encode(v, arrays, _ptr(at, i), nonfinite) for i, v in enumerate(obj)]
    if isinstance(obj, float) and not np.isfinite(obj):
        if nonfinite is not None:
            nonfinite[at] = _nonfinite_name(obj)
        return None
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    raise TypeError(f"result {at or '/'}: cannot write a {type(obj).__name__}")


def _parts(ptr: str) -> list[str]:
    return [p.replace("~1", "/").replace("~0", "~") for p in ptr.split("/")[1:]]


def decode(value, arrays: dict, nonfinite: dict | None = None):
    """The inverse of ``encode``: the numbers ``nonfinite`` names restored, the arrays
    named in ``arrays`` made numpy arrays again."""
    for ptr, name in (nonfinite or {}).items():
        parts = _parts(ptr)
        if not parts:
            value = _NONFINITE[name]
            continue
        parent = _get(value, parts[:-1])
        parent[int(parts[-1]) if isinstance(parent, list) else parts[-1]] = _NONFINITE[name]
    for ptr, (dtype, shape) in sorted(arrays.items(), key=lambda kv: -kv[0].count("/")):
        parts = _parts(ptr)
        arr = np.array(_get(value, parts), dtype=np.dtype(dtype)).reshape(shape)
        if not parts:
            value = arr
        else:
            parent = _get(value, parts[:-1])
            parent[int(parts[-1]) if isinstance(parent, list) else parts[-1]] = arr
    return value


def _get(value, parts):
    for p in parts:
        value = value[int(p)] if isinstance(value, list) else value[p]
    return value


def canonical_key(key) -> str:
    """One text per key, whatever the order of its dict fields (keys are compared so)."""
    return json.dumps(key, sort_keys=True)


def _line(obj) -> bytes:
    return (json.dumps(obj, separators=(",", ":"), allow_nan=False) + "\n").encode()


class _Bare(ValueError):
    pass


def _refuse_constant(name: str):
    raise _Bare(name)


def _loads(text):
    """A results line: standard JSON only (a bare NaN or Infinity is not planecal's)."""
    return json.loads(text, parse_constant=_refuse_constant)


def _check_head(path: Path, first: bytes, header) -> None:
    """InputError unless ``first`` is a results file's first line with this ``header``."""
    try:
        head = json.loads(first) if first else None
    except ValueError:
        head = None
    if not isinstance(head, dict) or head.get("format") != RESULTS_FORMAT:
        raise InputError(f"{path}: not a planecal results file "
                         f"(first line is not {{\"format\": \"{RESULTS_FORMAT}\", ...}})")
    if head.get("header") != json.loads(json.dumps(header)):
        field = _first_difference(head.get("header"), header)
        raise InputError(f"{path}: written for other settings ({field}); use another "
                         "file or start afresh")


def check_header(path, header: dict | None) -> None:
    """A results file a map is about to resume, checked before any work (a sweep plans for
    minutes first): written by planecal for the same ``header``; InputError (one line)
    naming the first setting that differs. Nothing to check where it is new or empty."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            first = f.readline(1 << 20)
    except FileNotFoundError:
        return
    except OSError as e:
        raise InputError(f"{p}: cannot read ({e.strerror})") from None
    if first:
        _check_head(p, first.rstrip(b"\n"), encode(header or {}))


class ResultsFile:
    """The JSON-lines results of one map (module docstring), open for appending."""

    def __init__(self, path, header: dict | None, resume: bool):
        from planecal.sampling.runfiles import RunLock
        self.path = Path(path)
        self.header = encode(header or {})
        self.done: dict[str, tuple] = {}  # canonical key -> (key, result)
        self._lock = RunLock(self.path)
        try:
            exists = self.path.exists() and self.path.stat().st_size > 0
            if exists and not resume:
                raise InputError(f"{self.path}: exists (resume to continue it, or remove it)")
            if exists:
                self._read()
            flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT
            self._fd = os.open(self.path, flags, 0o644)
            if not exists:
                self._write({"format": RESULTS_FORMAT, "header": self.header})
        except BaseException:
            self._lock.close()
            raise

    def _read(self) -> None:
        data = self.path.read_bytes()
        end = data.rfind(b"\n") + 1  # a torn last line (power loss) is dropped
        lines = data[:end].split(b"\n")[:-1]
        _check_head(self.path, lines[0] if lines else b"", self.header)
        for n, ln in enumerate(lines[1:], start=2):
            try:
                rec = _loads(ln)
                key, res = rec["key"], decode(rec["result"], rec.get("arrays", {}),
                                              rec.get("nonfinite"))
            except _Bare as e:
                raise InputError(f"{self.path}, line {n}: {e} is not a value planecal "
                                 "writes (a number that is not defined is null); the line "
                                 "was not written by planecal: remove it or start afresh") \
                    from None
            except (ValueError, KeyError, TypeError, IndexError, AttributeError):
                raise InputError(f"{self.path}, line {n}: not a result line") from None
            self.done.setdefault(canonical_key(key), (key, res))
        if end < len(data):
            os.truncate(self.path, end)

    def _write(self, obj) -> None:
        b = _line(obj)
        while b:  # one write of the whole line; loop only on a short write
            b = b[os.write(self._fd, b):]

    def append(self, key, result):
        """Write one result; returns it as read back (``decode(encode(result))``)."""
        arrays: dict = {}
        nonfinite: dict = {}
        rec = {"key": encode(key), "result": encode(result, arrays, nonfinite=nonfinite),
               "arrays": arrays}
        if nonfinite:
            rec["nonfinite"] = nonfinite
        self._write(rec)
        return decode(json.loads(json.dumps(rec["result"])), arrays, nonfinite)

    def close(self) -> None:
        if getattr(self, "_fd", None) is not None:
            os.close(self._fd)
            self._fd = None
        self._lock.close()


def _first_difference(old, new, at: str = "header") -> str:
    if isinstance(old, dict) and isinstance(new, dict):
        for k in sorted(set(old) | set(new)):
            if old.get(k) != new.get(k):
                return _first_difference(old.get(k), new.get(k), f"{at}.{k}")
    return f"{at}: {json.dumps(old)} in the file, {json.dumps(new)} now"


def read_results(path) -> tuple[dict, list[tuple]]:
    """(header, [(key, result), ...] in file order) of a results file."""
    p = Path(path)
    lines = p.read_bytes().split(b"\n")
    try:
        head = _loads(lines[0])
        out = []
        for ln in lines[1:]:
            if ln.strip():
                rec = _loads(ln)
                out.append((rec["key"], decode(rec["result"], rec.get("arrays", {}),
                                               rec.get("nonfinite"))))
    except (ValueError, KeyError, IndexError, TypeError, AttributeError):
        raise InputError(f"{p}: not a planecal results file") from None
    if not isinstance(head, dict) or head.get("format") != RESULTS_FORMAT:
        raise InputError(f"{p}: not a planecal results file")
    return head.get("header", {}), out
