"""The malformed-input corpus (tests/corpus/cases.py) through the CLI.

Each case runs in-process (``planecal.cli.main``), except a pipe (``| head -1``) and the
unbounded inputs (/dev/zero), which run in a subprocess so that the pipe is real and the
peak RSS is the command's own. Every case checks:
* the exit status (2 bad input or usage, 1 a failed fit, 0 valid);
* on failure, exactly one line on stderr, holding the case's fragment (the file or field
  and the problem), and no traceback;
* no input touched: every file in the case's directory and in tests/corpus/base has the
  same SHA-256 afterwards (a symbolic or hard link too: it still links to what it did),
  and a refused case leaves no new file behind;
* no JSON file a case writes holds NaN or Infinity.
"""
from __future__ import annotations

import contextlib
import hashlib
import io
import json
import logging
import random
import signal
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from corpus.cases import (CASES, Bytes, Case, Dir, Json, Link, Mut, Nest, Raw,  # noqa: E402
                          Rows, Text, Tmpl)

from planecal.cli import main  # noqa: E402

BASE = Path(__file__).parent / "corpus" / "base"
RSS_LIMIT_KB = 500 * 1024
CASE_TIMEOUT_S = 60  # a case that runs away fails instead of hanging the suite


def _set(doc, path, value):
    *head, last = path
    for k in head:
        doc = doc[k]
    doc[last] = value


def _drop(doc, path):
    *head, last = path
    for k in head:
        doc = doc[k]
    del doc[last]


def _mutated(m: Mut) -> str:
    doc = json.loads((BASE / m.base).read_text())
    for path, value in m.set:
        _set(doc, path, value)
    for path in m.drop:
        _drop(doc, path)
    marks = {}
    for i, (path, literal) in enumerate(m.raw):
        marks[f'"@@RAW{i}@@"'] = literal
        _set(doc, path, f"@@RAW{i}@@")
    text = json.dumps(doc, indent=1)
    for mark, literal in marks.items():
        text = text.replace(mark, literal)
    return text


def _rows(r: Rows) -> str:
    lines = (BASE / r.base).read_text().splitlines()
    header, rows = lines[0], [line.split("\t") for line in lines[1:]]
    for i, col, text in r.edit:
        if col == "header":
            rows.insert(i, header.split("\t"))
        elif text == "":
            del rows[i][col]
        else:
            rows[i][-1 if col is None and len(rows[i]) == 7 else (6 if col is None else col)] = text
    for i in r.drop_plate:
        rows[i] = rows[i][:7]
    if r.head:
        rows = rows[:r.head]
    if r.repeat:
        rows = [rows[0]] * r.repeat
    out = "\n".join([header] + ["\t".join(row) for row in rows]) + "\n"
    return out.replace(".", ",") if r.comma else out


def build(d: Path, files: dict) -> None:
    import os
    for name, spec in files.items():
        p = d / name
        if isinstance(spec, Tmpl):
            p.write_text(spec.text.replace("{d}", str(d)).replace("{base}", str(BASE)))
        elif isinstance(spec, Link) and spec.hard:
            os.link(spec.target.format(d=d, base=BASE), p)
        elif isinstance(spec, Link):
            p.symlink_to(spec.target.format(d=d, base=BASE))
        elif isinstance(spec, Raw):
            p.write_bytes(spec.data)
        elif isinstance(spec, Text):
            p.write_bytes(spec.text.encode("utf-8", "surrogateescape"))
        elif isinstance(spec, Json):
            p.write_text(json.dumps(spec.value))
        elif isinstance(spec, Mut):
            p.write_text(_mutated(spec))
        elif isinstance(spec, Nest):
            p.write_text("[" * spec.depth + "]" * spec.depth)
        elif isinstance(spec, Bytes):
            p.write_bytes(random.Random(spec.seed).randbytes(spec.n))
        elif isinstance(spec, Dir):
            p.mkdir()
        elif isinstance(spec, Rows):
            p.write_text(_rows(spec))
        else:
            raise TypeError(spec)


def hashes(*dirs: Path) -> dict[str, str]:
    """Each file's SHA-256; a symbolic link's also names its target."""
    import os
    out = {}
    for d in dirs:
        for p in sorted(d.rglob("*")):
            if p.is_file():
                link = f" -> {os.readlink(p)}" if p.is_symlink() else ""
                out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest() + link
    return out


def assert_standard_json(path: Path) -> None:
    """A JSON (or JSON-lines) file without NaN or Infinity: standard JSON throughout."""
    def bare(name):
        raise AssertionError(f"{path} holds {name}")
    text = path.read_text(encoding="utf-8")
    for doc in (text.splitlines() if path.suffix == ".jsonl" else [text]):
        json.loads(doc, parse_constant=bare)


def argv_of(c: Case, d: Path) -> list[str]:
    return [a.format(d=d, base=BASE) for a in c.argv]


def _alarm(signum, frame):
    raise TimeoutError(f"case ran longer than {CASE_TIMEOUT_S} s")


def run_inprocess(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    root = logging.getLogger()
    for h in list(root.handlers):  # basicConfig binds sys.stderr once: rebind per case
        root.removeHandler(h)
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(CASE_TIMEOUT_S)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as e:  # --help, --version
                code = e.code if isinstance(e.code, int) else 2
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        for h in list(root.handlers):
            root.removeHandler(h)
    return code, out.getvalue(), err.getvalue()


# the peak RSS of this process's own memory: /proc/self/status VmHWM. (getrusage's
# ru_maxrss is not: Linux keeps the high-water mark of the memory a process had before its
# exec, so a command started from a large pytest process reports pytest's peak.)
_RSS_WRAPPER = """
import sys
from planecal.cli import main
try:
    code = main(sys.argv[2:])
finally:
    with open("/proc/self/status") as st:
        hwm = next(line.split()[1] for line in st if line.startswith("VmHWM:"))
    with open(sys.argv[1], "w") as f:
        f.write(hwm)
sys.exit(code)
"""


def run_subprocess(c: Case, argv: list[str], d: Path) -> tuple[int, str, str, int | None]:
    rss_file = d.parent / f"{d.name}.rss"
    cmd = [sys.executable, "-c", _RSS_WRAPPER, str(rss_file), *argv]
    if c.pipe:
        import shlex
        shell = f"{shlex.join(cmd)} | {c.pipe}; exit ${{PIPESTATUS[0]}}"
        p = subprocess.run(["bash", "-c", shell], capture_output=True, text=True,
                           timeout=CASE_TIMEOUT_S)
    else:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=CASE_TIMEOUT_S)
    rss = int(rss_file.read_text()) if rss_file.exists() else None
    return p.returncode, p.stdout, p.stderr, rss


@pytest.fixture(scope="module")
def base_hashes():
    before = hashes(BASE)
    yield
    assert hashes(BASE) == before, "a corpus case modified a base file"


def test_corpus_is_large_and_names_unique():
    names = [c.name for c in CASES]
    assert len(names) == len(set(names))
    assert len(CASES) >= 150
    assert {c.code for c in CASES} == {0, 1, 2}


@pytest.mark.parametrize("c", CASES, ids=[c.name for c in CASES])
def test_case(c: Case, tmp_path: Path, base_hashes):
    d = tmp_path / "case"
    d.mkdir()
    build(d, c.files)
    argv = argv_of(c, d)
    before = hashes(d)
    if c.pipe or c.rss:
        code, out, err, rss = run_subprocess(c, argv, d)
        if c.rss:
            assert rss is not None and rss < RSS_LIMIT_KB, f"peak RSS {rss} kB"
    else:
        code, out, err = run_inprocess(argv)
    assert "Traceback" not in err, err
    assert code == c.code, f"exit {code}, expected {c.code}; stderr: {err!r}"
    after = hashes(d)
    for path, digest in before.items():
        assert after.get(path) == digest, f"input {path} was modified"
    for path in set(after) - set(before):
        if path.endswith((".json", ".jsonl")):
            assert_standard_json(Path(path))
    if c.code == 0:
        if c.pipe:
            assert err == "", err
        return
    lines = err.splitlines()
    assert len(lines) == 1, f"expected one line on stderr, got {len(lines)}: {err!r}"
    assert c.fragment.lower() in lines[0].lower(), f"{c.fragment!r} not in {lines[0]!r}"
    if c.code == 2:
        new = {p for p in after if p not in before}  # a lock file too (issue 25)
        assert not new, f"a refused command left files behind: {sorted(new)}"


# ----- every JSON file planecal writes says what it is ----------------------------------------

FORMAT_TAG = r"planecal-[a-z0-9-]+/[0-9]+"


def test_every_json_file_planecal_writes_has_a_format_and_version(tmp_path):
    """Each writer, run small, leaves JSON whose ``format`` is ``planecal-<kind>/<version>``
    (the sample file is TSV: its header says what it is, its sidecar carries the format).
    Schemas for the formats planecal also reads are published in docs/schemas."""
    import re

    from planecal.formats import MODELS, schema_file_name
    d, run = tmp_path, str(BASE / "run.tsv")
    commands = [
        ["calibrate", run, "--out", f"{d}/result.json"],
        ["export", f"{d}/result.json", "--out", f"{d}/fd11.json"],
        ["replay", str(BASE / "run3.tsv"), "--scene", "three_plates",
         "--params", f"{d}/truth3.json", "--out", f"{d}/replay.json"],
        ["rehearse", "--out", f"{d}/run.tsv", "--samples", "2", "--exact",
         "--truth-out", f"{d}/truth.json"],
        ["rehearse", "--out", f"{d}/run3.tsv", "--samples", "1", "--exact", "--scene",
         "three_plates", "--truth-out", f"{d}/truth3.json"],
        ["plan", "--out", f"{d}/poses.json", "--samples", "13", "--candidates", "60"],
        ["bootstrap", run, "--sizes", "60", "--repeats", "2", "--out", f"{d}/boot.json"],
        ["montecarlo", "--mode", "synthetic", "--runs", "2", "--samples", "40", "--jobs", "1",
         "--out", f"{d}/mc.json"],
    ]
    commands.insert(2, commands.pop(4))  # the three-plate truth before replay reads it
    for argv in commands:
        code, out, err = run_inprocess([*argv, "-q"])
        assert code == 0, (argv, err)
    written = sorted(p for p in d.glob("*.json"))
    assert len(written) == 10, [p.name for p in written]  # 6 outputs, 2 truths, 2 sidecars
    formats = {}
    for p in written:
        fmt = json.loads(p.read_text()).get("format")
        assert isinstance(fmt, str) and re.fullmatch(FORMAT_TAG, fmt), (p.name, fmt)
        formats[p.name] = fmt
    assert formats["result.json"] == "planecal-result/1"
    assert formats["run.tsv.json"] == "planecal-run/1"
    assert formats["truth.json"] == "planecal-params/1"
    docs = Path(__file__).parent.parent / "docs" / "schemas"
    for fmt in MODELS:
        assert (docs / schema_file_name(fmt)).exists(), fmt


def test_a_system_error_mid_run_is_one_line_and_exit_1(monkeypatch):
    """Disk full (or a file removed under a run) after the checks: the reason in one line,
    exit 1 (the run failed; the input was fine), no traceback."""
    import errno

    import planecal.commands.predict as predict

    def full(args):
        raise OSError(errno.ENOSPC, "No space left on device", "/data/result.json")

    monkeypatch.setattr(predict, "run", full)
    code, out, err = run_inprocess(["predict", str(BASE / "run.tsv"), "--params",
                                    str(BASE / "params.json")])
    assert code == 1
    assert err == "planecal predict: failed: /data/result.json: No space left on device\n"
