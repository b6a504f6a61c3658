"""What every planecal file format shares: bounded JSON reading, the one-line error
``FILE: field.path: problem``, and the small annotated number types the models are
built from (finite, strict, with plausible magnitudes).

Reading is bounded before anything is parsed: at most ``MAX_JSON_BYTES``, no NUL bytes
(binary data), UTF-8, at most ``MAX_DEPTH`` levels of nesting and no integer beyond the
float range. Validation is pydantic's (strict types: ``"65"`` is not a number, ``true``
is not 1); physical checks raise ``problem(...)`` so that the message names the field.
"""
from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path
from typing import Annotated, Any, TypeVar

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, Strict, ValidationError
from pydantic_core import PydanticCustomError

from planecal.base.errors import InputError

MAX_JSON_BYTES = 16 * 2**20  # planecal writes kB: a 14-pose plan is 5.6 kB, ~0.4 kB a pose
MAX_DEPTH = 64  # planecal's formats nest at most 6 levels
_CHUNK = 1 << 16

M = TypeVar("M", bound=BaseModel)


# ----- reading ------------------------------------------------------------------------------

def open_input(path: Path, what: str):
    """``path`` opened for binary reading, or a one-line InputError naming the file, the
    ``what`` it should be and why it cannot be opened (every reader's opening)."""
    try:
        return open(path, "rb")
    except FileNotFoundError:
        raise InputError(f"{path}: file not found ({what})") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, not a {what}") from None
    except PermissionError:
        raise InputError(f"{path}: cannot read the {what} (permission denied)") from None
    except (OSError, ValueError) as e:  # ValueError: a NUL character in the path
        raise InputError(f"{path}: cannot open the {what} ({_reason(e)})") from None


def read_bounded(path: Path, what: str, limit: int) -> bytes:
    """The bytes of ``path`` (at most ``limit``), refusing directories, devices that never
    end (/dev/zero), binary data and oversized files with a one-line InputError."""
    f = open_input(path, what)
    chunks, size = [], 0
    with f:
        while True:
            try:
                chunk = f.read(_CHUNK)
            except OSError as e:
                raise InputError(f"{path}: cannot read the {what} ({_reason(e)})") from None
            if not chunk:
                break
            if b"\0" in chunk:
                raise InputError(f"{path}: binary data (NUL bytes at byte {size + chunk.index(0)}), "
                                 f"not a {what}")
            size += len(chunk)
            if size > limit:
                raise InputError(f"{path}: larger than {limit // 2**20} MiB, not a {what}")
            chunks.append(chunk)
    return b"".join(chunks)


def read_toml(path: str | Path, what: str, limit: int) -> dict:
    """A TOML file within ``limit`` bytes, UTF-8 (``read_bounded``); one-line InputError
    naming the file otherwise."""
    import tomllib
    path = Path(path)
    data = read_bounded(path, what, limit)
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: not UTF-8 text (byte {e.start}), not a {what}") from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: invalid TOML: {str(e).splitlines()[0]}") from None


def _reason(e: Exception) -> str:
    return getattr(e, "strerror", None) or (str(e).splitlines() or [type(e).__name__])[0]


def read_json(path: str | Path, what: str) -> Any:
    """Parse a JSON file within the bounds above; one-line InputError otherwise."""
    path = Path(path)
    data = read_bounded(path, what, MAX_JSON_BYTES)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: not UTF-8 text (byte {e.start}), not a {what}") from None
    try:
        value = json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"{path}:{e.lineno}: invalid JSON: {e.msg}") from None
    except RecursionError:
        raise InputError(f"{path}: JSON nested more than {MAX_DEPTH} levels deep, "
                         f"not a {what}") from None
    except ValueError as e:  # an integer literal beyond Python's digit limit
        raise InputError(f"{path}: invalid JSON: {str(e).split(':')[0]}") from None
    _check_shape(value, path, what)
    return value


def _check_shape(value: Any, path: Path, what: str) -> None:
    """Nesting depth and integer size, walked without recursion."""
    stack = [(value, 1, ())]
    while stack:
        v, depth, loc = stack.pop()
        if isinstance(v, (dict, list)):
            if depth > MAX_DEPTH:
                raise InputError(f"{path}: JSON nested more than {MAX_DEPTH} levels deep, "
                                 f"not a {what}")
            items = v.items() if isinstance(v, dict) else enumerate(v)
            stack.extend((x, depth + 1, loc + (k,)) for k, x in items)
        elif isinstance(v, int) and not isinstance(v, bool) and abs(v) > sys.float_info.max:
            raise InputError(f"{path}: {loc_text(loc)}: an integer of {len(str(abs(v)))} "
                             f"digits, too large for any quantity")


# ----- validation and its one-line message -----------------------------------------------------

_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")


def loc_text(loc) -> str:
    """('plates', 0, 'n_tilde', 2) -> 'plates[0].n_tilde[2]'; a key that is not a plain
    name is quoted (repr, shortened): no control character reaches the message."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif _KEY.fullmatch(str(part)):
            out += f".{part}" if out else str(part)
        else:
            out += f"[{short(str(part))}]"
    return out or "(top level)"


def short(v: Any) -> str:
    """repr, at most 40 characters: user text quoted, never multi-line."""
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def error_line(path, e: ValidationError) -> str:
    """The first problem of a ValidationError as ``FILE: field.path: problem``."""
    errs = e.errors(include_url=False)
    err = errs[0]
    loc = tuple(err["loc"]) + tuple((err.get("ctx") or {}).get("at", ()))
    msg = err["msg"]
    if err["type"] == "missing":
        msg = "missing (required)"
    elif err["type"] == "extra_forbidden":
        msg = "unknown key (misspelt? the format is in docs/FORMATS.md)"
    elif err["type"] != "planecal" and "input" in err:
        msg += f", got {short(err['input'])}"
    more = f" (and {len(errs) - 1} more problem{'s' if len(errs) > 2 else ''})" if len(errs) > 1 else ""
    return f"{path}: {loc_text(loc)}: {msg}{more}"


def validate(model: type[M], data: Any, path, what: str, context: dict | None = None) -> M:
    """``model`` validated from parsed JSON, or a one-line InputError."""
    if not isinstance(data, dict):
        raise InputError(f"{path}: a {what} is a JSON object {{...}}, not {_json_type(data)}")
    try:
        return model.model_validate(data, context=context)
    except ValidationError as e:
        raise InputError(error_line(path, e)) from None


def _json_type(v: Any) -> str:
    return {list: "an array", str: "a string", bool: "true/false", type(None): "null",
            int: "a number", float: "a number"}.get(type(v), type(v).__name__)


def problem(message: str, *at) -> PydanticCustomError:
    """A physical check's failure. ``at``: the field path below the validator's own
    location (a model validator names the field it found wrong)."""
    return PydanticCustomError("planecal", "{message}", {"message": message, "at": at})


class Model(BaseModel):
    """Hand-written files: unknown keys are refused (a misspelt optional key would
    otherwise silently fall back to its default)."""
    model_config = ConfigDict(extra="forbid", frozen=True)


class Record(BaseModel):
    """Files planecal writes: keys added by later versions are kept, not refused."""
    model_config = ConfigDict(extra="allow", frozen=True)


# ----- number types ---------------------------------------------------------------------------

Num = Annotated[float, Strict(), Field(allow_inf_nan=False)]
Int = Annotated[int, Strict()]
Bool = Annotated[bool, Strict()]
def _printable(v: str) -> str:
    if _CONTROL.search(v):
        raise problem(f"{short(v)} holds a control character (newline, tab, NUL, ...): not "
                      f"allowed in a name or a path")
    return v


_CONTROL = re.compile(r"[\x00-\x1f\x7f]")
Str = Annotated[str, Strict(), Field(max_length=4096), AfterValidator(_printable)]


def _fixed_length(n: int, what: str = "values"):
    def check(v):
        if len(v) != n:
            raise problem(f"must hold {n} {what}, got {len(v)}")
        return v
    return check


def Vector(item, n: int, what: str = "numbers"):
    """A JSON array of exactly ``n`` items (schema: minItems = maxItems = n)."""
    return Annotated[list[item], AfterValidator(_fixed_length(n, what)),
                     Field(json_schema_extra={"minItems": n, "maxItems": n})]


class Hint:
    """A likely unit mistake, named when the value divided back lands in range."""

    def __init__(self, text: str, scale: float):
        self.text, self.scale = text, scale

    def __call__(self, v: float, lo: float | None, hi: float | None) -> str:
        w = v * self.scale
        fits = (lo is None or w >= lo) and (hi is None or w <= hi)
        return f": {self.text}?" if fits else ""


MM_AS_M = Hint("a value in mm written as m", 1e-3)
DEG_AS_RAD = Hint("degrees written as rad", math.pi / 180)
M_AS_MM = Hint("a value in m written as mm", 1e3)


def _num(v) -> str:
    return str(v) if isinstance(v, int) else f"{v:g}"


def _span(lo, hi, unit: str) -> str:
    u = f" {unit}" if unit else ""
    if lo is not None and hi is not None:
        return f"in [{_num(lo)}, {_num(hi)}]{u}"
    return f">= {_num(lo)}{u}" if lo is not None else f"<= {_num(hi)}{u}"


def _bounded(lo: float | None, hi: float | None, unit: str, what: str, hint: Hint | None):
    def check(v):
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            u = f" {unit}" if unit else ""
            raise problem(f"{_num(v)}{u} is not a plausible {what} ({_span(lo, hi, unit)})"
                          + (hint(v, lo, hi) if hint else ""))
        return v
    return check


def Ranged(lo: float | None, hi: float | None, unit: str, what: str, hint: Hint | None = None,
           *, base=Num):
    """A number within [lo, hi]; the message names the quantity, its unit and, when it
    explains the value, a likely unit mistake."""
    extra = {k: v for k, v in (("minimum", lo), ("maximum", hi)) if v is not None}
    return Annotated[base, AfterValidator(_bounded(lo, hi, unit, what, hint)),
                     Field(description=f"{what}, {unit}" if unit else what,
                           json_schema_extra=extra)]


def _positive(unit: str, what: str):
    def check(v):
        if not v > 0:
            raise problem(f"{v:g} {unit}: a {what} must be > 0")
        return v
    return check


def Positive(unit: str, what: str, hi: float, hint: Hint | None = None):
    """A number in (0, hi]."""
    return Annotated[Num, AfterValidator(_positive(unit, what)),
                     AfterValidator(_bounded(None, hi, unit, what, hint)),
                     Field(description=f"{what}, {unit}",
                           json_schema_extra={"exclusiveMinimum": 0, "maximum": hi})]


Angle = Ranged(-2 * math.pi, 2 * math.pi, "rad", "angle", DEG_AS_RAD)


def _norm_at_most(limit_m: float, what: str):
    def check(v):
        r = math.hypot(*v)
        if r > limit_m:
            hint = MM_AS_M(r, None, limit_m)
            raise problem(f"|{what}| = {r:g} m is not plausible (at most {limit_m:g} m){hint}")
        return v
    return check


def Point(limit_m: float, what: str):
    """Three finite numbers in metres whose norm is at most ``limit_m``."""
    return Annotated[Vector(Num, 3), AfterValidator(_norm_at_most(limit_m, what))]


def _ordered(unit: str, what: str, lo: float, hi: float, hint: Hint | None):
    def check(v):
        a, b = v
        if not lo <= a < b <= hi:
            raise problem(f"[{a:g}, {b:g}] {unit} is not a plausible {what} (increasing, "
                          f"within [{lo:g}, {hi:g}] {unit})"
                          + (hint(a, lo, hi) if hint and hint(b, lo, hi) else ""))
        return v
    return check


def Interval(unit: str, what: str, lo: float, hi: float, hint: Hint | None = None):
    """[low, high] with lo <= low < high <= hi."""
    return Annotated[Vector(Num, 2), AfterValidator(_ordered(unit, what, lo, hi, hint))]


def _format_is(accepted: tuple[str, ...], what: str):
    def check(v):
        if v is not None and v not in accepted:
            raise problem(f"{short(v)} is not a {what} ({' or '.join(accepted)})")
        return v
    return check


def FormatTag(*accepted: str, what: str):
    """The ``format`` field: ``name/version``; files from before it existed omit it."""
    return Annotated[Str | None, AfterValidator(_format_is(accepted, what)),
                     Field(json_schema_extra={"enum": [*accepted, None]})]


def json_values(v: Any) -> Any:
    """``v`` as the JSON values planecal writes: numpy arrays and scalars as lists and
    numbers, tuples as lists, and a number that is not defined (NaN, an infinity) as null:
    no file planecal writes holds NaN or Infinity (``json.dumps(..., allow_nan=False)``
    after this)."""
    if isinstance(v, dict):
        return {k: json_values(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_values(x) for x in v]
    if hasattr(v, "tolist") and hasattr(v, "dtype"):  # numpy arrays and scalars
        return json_values(v.tolist())
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def dumps(doc: Any) -> str:
    """JSON as planecal writes the files people read: indented, a list of scalars on one
    line, an object of scalars on one line where it fits in 120 characters. Numbers that
    are not defined are null (``json_values``)."""
    return _dump(json_values(doc), 0) + "\n"


def _dump(v: Any, level: int) -> str:
    pad, inner = "  " * level, "  " * (level + 1)
    scalar = (lambda x: not isinstance(x, (dict, list)))
    if isinstance(v, list):
        if all(scalar(x) for x in v):
            return "[" + ", ".join(json.dumps(x, allow_nan=False) for x in v) + "]"
        return "[\n" + ",\n".join(inner + _dump(x, level + 1) for x in v) + "\n" + pad + "]"
    if isinstance(v, dict):
        if not v:
            return "{}"
        flat = all(scalar(x) or (isinstance(x, list) and all(scalar(y) for y in x))
                   for x in v.values())
        one = "{" + ", ".join(f"{json.dumps(k)}: {_dump(x, 0)}" for k, x in v.items()) + "}"
        if flat and len(one) + len(pad) <= 120:
            return one
        return ("{\n" + ",\n".join(f"{inner}{json.dumps(k)}: {_dump(x, level + 1)}"
                                    for k, x in v.items()) + "\n" + pad + "}")
    return json.dumps(v, allow_nan=False)
