"""The tutorial (docs/tutorial.md) and the README's first calibration run as written.

Every ```console block of a page is a list of `$ command` lines (a trailing backslash
continues one), each followed by what it prints. The test runs the commands in order in
one bash, in a new folder, with this environment's planecal first on PATH, and checks that
each exits 0 and that every output line the page shows appears in what it printed
(stdout, then stderr), in order:

- numbers may differ by 5 % or two units of their last digit (another machine's rounding),
- `<port>`, `<n>` and the like stand for anything (a port, a device, a date),
- a line `...` stands for any lines, and a line ending in ` ...` for any rest of a line.

So the page cannot drift from the commands: an option renamed, an output reworded or a
figure moved fails here, naming the command and the line. Blocks fenced ```bash are
examples not run (a real controller's address). Cost: about a minute of CPU for the
tutorial (40 planned poses; the emulator's runs at --rt-tick-s 0), 10 s for the README.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NUMBER = r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?"
TOKEN = re.compile(rf"(?P<hole><[a-z][a-z _-]*>)|(?<![\w.]){NUMBER}(?![\w])")
REL_TOL = 0.05


@dataclass
class Step:
    command: str
    expected: list[str] = field(default_factory=list)


def console_steps(text: str) -> list[Step]:
    """The commands of the page's ```console blocks with the lines shown under each."""
    steps: list[Step] = []
    for block in re.findall(r"^```console\n(.*?)^```", text, re.S | re.M):
        lines = block.splitlines()
        i = 0
        while i < len(lines):
            line = lines[i]
            if line.startswith("$ "):
                cmd = line[2:]
                while cmd.endswith("\\") and i + 1 < len(lines):
                    i += 1
                    cmd = cmd[:-1].rstrip() + " " + lines[i].strip()
                steps.append(Step(cmd))
            elif steps:
                steps[-1].expected.append(line)
            i += 1
    return steps


def line_pattern(expected: str) -> tuple[re.Pattern, list[str]]:
    """A regular expression for one shown line: its words as they are, its numbers and
    holes as groups; and the shown numbers, in order."""
    text = expected.strip()
    prefix = text.endswith(" ...")
    if prefix:
        text = text[:-4].rstrip()
    parts, numbers, pos = [], [], 0
    for m in TOKEN.finditer(text):
        parts.append(_words(text[pos:m.start()]))
        if m.group("hole"):
            parts.append(r"(?:.*?)")
        else:
            parts.append(rf"({NUMBER})")
            numbers.append(m.group(0))
        pos = m.end()
    parts.append(_words(text[pos:]))
    return re.compile("".join(parts) + (r".*" if prefix else "")), numbers


def _words(s: str) -> str:
    return r"\s+".join(re.escape(w) for w in re.split(r"\s+", s)) if s.strip() else (
        r"\s*" if s else "")


def close(shown: str, got: str) -> bool:
    a, b = float(shown), float(got)
    digits = len(shown.split(".")[1].split("e")[0].split("E")[0]) if "." in shown else 0
    unit = 10.0 ** -digits
    if "e" in shown.lower():
        unit *= 10.0 ** int(re.split("[eE]", shown)[1])
    return abs(a - b) <= max(REL_TOL * abs(a), 2 * unit)


def matches(expected: str, actual: str) -> bool:
    pattern, numbers = line_pattern(expected)
    m = pattern.fullmatch(actual.strip())
    return bool(m) and all(close(s, g) for s, g in zip(numbers, m.groups()))


def missing_line(expected: list[str], output: str) -> str | None:
    """The first shown line not found, in order, in the output (None: all found)."""
    lines = output.splitlines()
    at = 0
    for want in expected:
        if want.strip() in ("...", ""):
            continue
        for k in range(at, len(lines)):
            if matches(want, lines[k]):
                at = k + 1
                break
        else:
            return want
    return None


def run_page(page: Path, tmp_path: Path) -> list[tuple[Step, int, str]]:
    """Run the page's commands in one bash in tmp_path; (step, exit code, output) each,
    up to the first that fails."""
    steps = console_steps(page.read_text())
    assert steps, f"{page}: no ```console block"
    out = tmp_path / ".steps"
    out.mkdir(parents=True)
    script = ["cd " + _q(tmp_path)]
    for k, st in enumerate(steps):
        script.append(f"{{ {st.command}\n}} > {_q(out / f'{k}.out')} 2> {_q(out / f'{k}.err')}"
                      f"; echo $? > {_q(out / f'{k}.rc')}; "
                      f"[ \"$(cat {_q(out / f'{k}.rc')})\" = 0 ] || exit 1")
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env["COLUMNS"] = "100"
    env["PLANECAL_STATE_DIR"] = str(tmp_path / ".state")
    for k in ("PLANECAL_HISTORY", "PLANECAL_HOME"):
        env.pop(k, None)
    proc = subprocess.Popen(["bash", "-c", "\n".join(script)], env=env,
                            start_new_session=True, stdin=subprocess.DEVNULL)
    try:
        proc.wait(timeout=900)
    finally:
        try:  # whatever the page left running (an emulator in the background)
            os.killpg(proc.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
        proc.wait()
    done = []
    for k, st in enumerate(steps):
        rc_file = out / f"{k}.rc"
        if not rc_file.exists():
            break
        text = (out / f"{k}.out").read_text() + (out / f"{k}.err").read_text()
        done.append((st, int(rc_file.read_text()), text))
    return done


def _q(p) -> str:
    return "'" + str(p).replace("'", "'\\''") + "'"


def check_page(page: Path, tmp_path: Path) -> None:
    steps = console_steps(page.read_text())
    done = run_page(page, tmp_path)
    wrong = []  # every step's, so one run shows all a change broke
    for st, rc, text in done:
        if rc != 0:
            wrong.append(f"{page.name}: `{st.command}` exited {rc}:\n{text[-3000:]}")
            continue
        gone = missing_line(st.expected, text)
        if gone is not None:
            wrong.append(f"{page.name}: `{st.command}` did not print\n  {gone}\n"
                         f"(in order after the lines before it); it printed:\n{text[-4000:]}")
    assert not wrong, "\n\n".join(wrong)
    assert len(done) == len(steps), f"{page.name}: stopped after {len(done)} of {len(steps)}"


@pytest.mark.slow
def test_the_tutorial_runs_as_written(tmp_path):
    check_page(ROOT / "docs" / "tutorial.md", tmp_path)


def test_the_readme_first_calibration_runs_as_written(tmp_path):
    check_page(ROOT / "README.md", tmp_path)


# ----- the checker itself -------------------------------------------------------------

PAGE = """
text
```console
$ echo a 1.50 mm \\
    b
a 1.52 mm b
$ printf 'x\\ny 7 of 9\\nport 127.0.0.1:4242\\n'
...
y 7 of 9
port 127.0.0.1:<port>
```
```bash
not run
```
"""


def test_steps_are_read_with_their_lines():
    steps = console_steps(PAGE)
    assert [s.command for s in steps] == ["echo a 1.50 mm b", "printf 'x\\ny 7 of 9\\nport "
                                          "127.0.0.1:4242\\n'"]
    assert steps[0].expected == ["a 1.52 mm b"]
    assert steps[1].expected == ["...", "y 7 of 9", "port 127.0.0.1:<port>"]


def test_lines_match_words_exactly_and_numbers_within_tolerance():
    assert matches("model error RMS 0.0524 mm", "model error RMS 0.0525 mm")
    assert matches("model error RMS 0.0524 mm", "model error  RMS   0.0540 mm")  # 3 %
    assert not matches("model error RMS 0.0524 mm", "model error RMS 0.0600 mm")
    assert not matches("model error RMS 0.0524 mm", "model error (rms) 0.0524 mm")
    assert matches("samples used 34 of 34", "samples used 35 of 34")  # two units
    assert not matches("samples used 34 of 34", "samples used 40 of 34")
    assert matches("J3 (delta3) +0.4980 +- 0.0231 mrad", "J3 (delta3) +0.4990 +- 0.0230 mrad")
    assert not matches("J3 (delta3) +0.4980 mrad", "J2 (delta2) +0.4980 mrad")
    assert matches("std 8.306e-04 rad", "std 8.31e-04 rad")
    assert matches("UDP 127.0.0.1:<port> (replies)", "UDP 127.0.0.1:50501 (replies)")
    assert matches("AP before 8.6540 mm, after ...", "AP before 8.6540 mm, after 0.49 mm")
    assert not matches("AP before 8.6540 mm", "AP before 8.6540 mm, after 0.49 mm")


def test_a_changed_output_or_a_failing_command_fails(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("```console\n$ echo one 1.0\none 1.0\n$ echo two\nthree\n```\n")
    with pytest.raises(AssertionError, match="did not print\n *three"):
        check_page(page, tmp_path / "a")
    page.write_text("```console\n$ false\n$ echo never\n```\n")
    with pytest.raises(AssertionError, match="`false` exited 1"):
        check_page(page, tmp_path / "b")
