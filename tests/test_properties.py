"""Property tests (hypothesis) of what a careless user can hand planecal (issue 16 item 5).

* Random command lines to every command's option parser (``planecal.cli.parse``: parse
  only, nothing runs): each gives a namespace, a one-line InputError (a usage error names
  the command and ``--help``) or SystemExit(0) for ``--help``/``--version``; never
  another exception.
* Random and near-valid sample files (tab-separated rows of a valid run with one field
  replaced by junk, both decimal marks): ``read_samples`` gives samples with finite
  values in range or a one-line InputError naming the file.
* Decimal comma: whatever ``write_samples`` writes with either mark (with or without the
  plate column and the direction group), ``read_samples`` reads back exactly (to the 6
  written decimals).

The JSON readers (robot, scene, parameters, result, poses, sidecar, error profile) get
random bytes, random JSON and near-valid documents in tests/test_schemas_property.py.

Determinism: ``derandomize=True`` and no example database (CI cannot flake);
``deadline=None`` (the machine is shared). Budget: 60 command lines per command (19
commands), 150 sample files, 60 round trips; the file runs in a few seconds.
"""
from __future__ import annotations

import argparse
import atexit
import contextlib
import io
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from planecal.cli import COMMANDS, Parser, _common, _module, parse
from planecal.base.errors import InputError
from planecal.io.samples import COUNT_LIMIT, MAX_DM_MM, read_samples, write_samples

SETTINGS = dict(derandomize=True, database=None, deadline=None,
                suppress_health_check=[HealthCheck.too_slow,
                                       HealthCheck.function_scoped_fixture])
BASE = Path(__file__).parent / "corpus" / "base"
DIR = Path(tempfile.mkdtemp(prefix="planecal-argv-"))  # in VALUES at collection: a fixture is late
atexit.register(shutil.rmtree, DIR, ignore_errors=True)


def options_of(command: str) -> list[str]:
    """The option strings of a command, read from its own help text (public argparse)."""
    p = Parser(prog=f"planecal {command}", formatter_class=argparse.RawDescriptionHelpFormatter)
    _module(command).add_arguments(p)
    _common(p)
    return sorted(set(re.findall(r"(?<![\w-])(--?[A-Za-z][A-Za-z0-9-]*)", p.format_help())))


OPTIONS = {c: options_of(c) for c in COMMANDS}
VALUES = ["nan", "inf", "-inf", "-1", "0", "1", "1e400", "9" * 40, "1,2,3", "a,b", "",
          "thesis_final", "three_plates", "/dev/null", "/dev/zero", str(DIR),
          str(DIR / "none.json"), str(BASE / "run.tsv"), str(BASE / "params.json"),
          "delta1,delta9", "gn", "lm", "bash", "-", "--", "\x00", "é"]


def token(command: str):
    return st.one_of(st.sampled_from(OPTIONS[command]), st.sampled_from(VALUES),
                     st.integers(-10**30, 10**30).map(str),
                     st.floats(allow_nan=True, allow_infinity=True).map(repr),
                     st.text(max_size=6))


def _one_line(text: str) -> None:
    assert text and "\n" not in text.strip() and "Traceback" not in text, repr(text)


@pytest.mark.parametrize("command", list(COMMANDS))
def test_random_command_lines_parse_or_one_line_error(command):
    @settings(max_examples=60, **SETTINGS)
    @given(st.lists(token(command), max_size=6))
    def check(tokens):
        argv = [command, *tokens]
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            try:
                args = parse(argv)
            except InputError as e:
                _one_line(str(e))
                return
            except SystemExit as e:  # --help, --version
                assert e.code in (0, None), e.code
                return
        assert args.command == command

    check()


def test_every_command_has_options():
    assert all(OPTIONS[c] for c in COMMANDS)
    assert "--out" in OPTIONS["calibrate"] and "--decimal-comma" in OPTIONS["rehearse"]


# ----- sample files ---------------------------------------------------------------------------

ROWS = [line.split("\t") for line in (BASE / "run.tsv").read_text().splitlines()[1:]]
JUNK = ["", "nan", "inf", "-inf", "-1", "1e400", "9" * 30, "8388608.5", "0x10", "92,52",
        "92.52.1", "1_000", "\x00", "é", " ", "+5", "16777216", "65", "95", "500", "0"]


@st.composite
def near_valid_sample_file(draw) -> str:
    rows = [list(r) for r in ROWS[:draw(st.integers(0, 12))]]
    for _ in range(draw(st.integers(0, 3))):
        if not rows:
            break
        r = draw(st.integers(0, len(rows) - 1))
        c = draw(st.integers(0, 7))
        value = draw(st.one_of(st.sampled_from(JUNK), st.text(max_size=8)))
        if c < len(rows[r]):
            rows[r][c] = value
        else:
            rows[r].append(value)
    comma = draw(st.booleans())
    text = "q1\tq2\tq3\tq4\tq5\tq6\tDm\n" * draw(st.integers(0, 1))
    text += "".join("\t".join(r) + draw(st.sampled_from(["\n", "\r\n"])) for r in rows)
    return text.replace(".", ",") if comma else text


def _check_samples_or_error(path: Path) -> None:
    try:
        s = read_samples(path)
    except InputError as e:
        _one_line(str(e))
        assert str(path) in str(e)
        return
    assert len(s) >= 1
    assert np.all((s.qe >= 0) & (s.qe < COUNT_LIMIT))
    assert np.all(np.isfinite(s.d_mm)) and np.all((s.d_mm > 0) & (s.d_mm <= MAX_DM_MM))
    assert np.all(s.plate >= 0)


@settings(max_examples=150, **SETTINGS)
@given(near_valid_sample_file())
def test_near_valid_sample_files(text):
    path = DIR / "near.tsv"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    _check_samples_or_error(path)


@settings(max_examples=60, **SETTINGS)
@given(st.binary(max_size=2000))
def test_random_bytes_as_sample_file(data):
    path = DIR / "bytes.tsv"
    path.write_bytes(data)
    _check_samples_or_error(path)


# ----- decimal comma round trip ------------------------------------------------------------------

@settings(max_examples=60, **SETTINGS)
@given(st.lists(st.tuples(st.lists(st.integers(0, COUNT_LIMIT - 1), min_size=6, max_size=6),
                          st.floats(0.001, 9999.0), st.integers(0, 2),
                          st.lists(st.integers(-1, 1), min_size=6, max_size=6)),
                min_size=2, max_size=20, unique_by=lambda r: tuple(r[0])),
       st.booleans(), st.booleans(), st.booleans())
def test_decimal_comma_round_trip(rows, comma, plates, dirs):
    path = DIR / "rt.tsv"
    qe = np.array([r[0] for r in rows])
    d = np.array([r[1] for r in rows])
    plate = np.array([r[2] for r in rows]) if plates else None
    direction = np.array([r[3] for r in rows]) if dirs else None
    write_samples(path, qe, d, plate, decimal_comma=comma, direction=direction)
    text = path.read_text()
    data = text.splitlines()[1:]
    assert all(("," in line.split("\t")[6]) == comma for line in data)
    assert all("." not in line.split("\t")[6] for line in data) or not comma
    s = read_samples(path)
    np.testing.assert_array_equal(s.qe, qe)
    np.testing.assert_array_equal(s.d_mm, [float(f"{x:.6f}") for x in d])
    if plates:
        np.testing.assert_array_equal(s.plate, plate)
    if dirs:
        np.testing.assert_array_equal(s.direction, direction)
    else:
        assert s.direction is None


def test_appended_file_keeps_its_decimal_mark(tmp_path):
    """A resumed run continues its file in the mark it was started with, whatever the
    new writer was asked for: one file, one style."""
    from planecal.io.samples import SampleWriter
    path = tmp_path / "run.tsv"
    with SampleWriter(path, decimal_comma=True) as w:
        w.write([1, 2, 3, 4, 5, 6], 80.25)
    with SampleWriter(path, append=True, decimal_comma=False) as w:
        w.write([2, 2, 3, 4, 5, 6], 81.5)
    assert path.read_text().splitlines()[1:] == ["1\t2\t3\t4\t5\t6\t80,250000",
                                                 "2\t2\t3\t4\t5\t6\t81,500000"]
    with SampleWriter(tmp_path / "dot.tsv") as w:
        w.write([1, 2, 3, 4, 5, 6], 80.25)
    with SampleWriter(tmp_path / "dot.tsv", append=True, decimal_comma=True) as w:
        w.write([2, 2, 3, 4, 5, 6], 81.5)
    assert (tmp_path / "dot.tsv").read_text().count(",") == 0


def test_rehearse_decimal_comma_end_to_end(tmp_path):
    """rehearse --decimal-comma writes the seed's style, records it in the sidecar, and
    calibrate/predict read the file as they read a dot file."""
    import json

    from planecal.cli import main
    out = tmp_path / "run.tsv"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["rehearse", "--out", str(out), "--samples", "3", "--decimal-comma",
                     "--exact", "-q"]) == 0
    lines = out.read_text().splitlines()
    assert lines[0].split("\t")[:7] == ["q1", "q2", "q3", "q4", "q5", "q6", "Dm"]
    assert len(lines) == 4
    assert all(re.fullmatch(r"[0-9]+,[0-9]{6}", line.split("\t")[6]) for line in lines[1:])
    side = json.loads((tmp_path / "run.tsv.json").read_text())
    assert side["settings"]["decimal_comma"] is True
    s = read_samples(out)
    assert len(s) == 3 and np.all((s.d_mm >= 65) & (s.d_mm <= 95))
