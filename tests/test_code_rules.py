"""The code's own rules (issue 21, the brief's layout): no module over 500 lines and no
function over 80, argparse only in the commands, no command importing another, and
``fit.solve`` called by the one calibrate entry only. Each rule reads the source as it is,
so a change that breaks one fails here (planning.py grew to 588 lines unnoticed)."""
import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "planecal"
FILES = sorted(SRC.rglob("*.py"))


def _tree(p: Path) -> ast.Module:
    return ast.parse(p.read_text(), str(p))


def _imports(tree: ast.Module) -> list[str]:
    out = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Import):
            out += [a.name for a in n.names]
        elif isinstance(n, ast.ImportFrom) and n.module:
            out.append(n.module)
            out += [f"{n.module}.{a.name}" for a in n.names]
    return out


def test_no_module_over_500_lines_and_no_function_over_80():
    assert len(FILES) > 100
    long_modules = {str(p.relative_to(SRC)): n for p in FILES
                    if (n := len(p.read_text().splitlines())) > 500}
    assert not long_modules
    long_functions = []
    for p in FILES:
        for n in ast.walk(_tree(p)):
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if n.end_lineno - n.lineno + 1 > 80:
                    long_functions.append(f"{p.relative_to(SRC)}:{n.name}")
    assert not long_functions


def test_argparse_stays_in_the_commands_and_no_command_imports_another():
    commands = {p.stem for p in (SRC / "commands").glob("*.py")}
    shared = {c for c in commands if c.endswith("_options") or c == "__init__"}
    for p in FILES:
        rel = p.relative_to(SRC)
        mods = _imports(_tree(p))
        if rel.parts[0] != "commands" and rel.name != "cli.py":
            assert "argparse" not in mods, rel
        if rel.parts[0] == "commands":
            others = {m.split(".")[2] for m in mods if m.startswith("planecal.commands.")
                      and len(m.split(".")) > 2} - shared - {p.stem}
            assert not others, f"{rel} imports the command(s) {sorted(others)}"


def test_only_calibrate_calls_the_solver():
    callers = []
    for p in FILES:
        tree = _tree(p)
        names = {a.asname or a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                 and n.module == "planecal.estimation.fit" for a in n.names}
        if "solve" in names:
            callers.append(str(p.relative_to(SRC)))
    assert callers == ["estimation/calibrate.py"]
