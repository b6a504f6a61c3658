"""The documentation site's generated reference pages (an MkDocs hook: mkdocs.yml `hooks:`).

    reference/commands.md   every command's --help, from planecal.cli's own parser
    reference/schemas.md    every JSON file format, from docs/schemas/*.json

Nothing in them is written by hand: a command's options or a file's fields change in one
place (the command's ``add_arguments``, the format's pydantic model and
``scripts/export_schemas.py``) and the site follows. ``python scripts/docs_reference.py
DIR`` writes the two pages into DIR (to read them without building the site).
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCHEMAS = ROOT / "docs" / "schemas"
HELP_COLUMNS = "100"  # argparse wraps --help to the terminal: one width for the page


# ----- commands -----------------------------------------------------------------------

def commands_markdown() -> str:
    """One section per command: its one-line summary and its --help, as a user sees it."""
    from planecal.cli import COMMANDS, build_parser
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = HELP_COLUMNS
    try:
        parser = build_parser([], full=True)
        top = parser.format_help()
        helps = {name: parser.commands[name].format_help() for name in COMMANDS}
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old
    out = ["# Commands",
           "",
           "Generated from planecal's own argument parser (`planecal.cli`) when the site is "
           "built: what each command's `--help` prints. Conventions every command shares "
           "(`--config`, `-v`/`-q`, exit codes, what a command may write): "
           "[command-line conventions](conventions.md).",
           "",
           "| command | what it does |",
           "|---|---|"]
    out += [f"| [`{name}`](#{anchor(name)}) | {text} |" for name, text in COMMANDS.items()]
    out += ["", "## planecal", "", "```text", top.rstrip(), "```"]
    for name in COMMANDS:
        out += ["", f"## planecal {name}", "", COMMANDS[name][0].upper() + COMMANDS[name][1:]
                + ".", "", "```text", helps[name].rstrip(), "```"]
    return "\n".join(out) + "\n"


def anchor(name: str) -> str:
    """The anchor MkDocs gives the heading ``planecal NAME``."""
    return "planecal-" + name


# ----- file formats -------------------------------------------------------------------

def schemas_markdown(folder: Path = SCHEMAS) -> str:
    """One section per JSON Schema: its fields (type, bounds, default, description), then
    the nested objects it refers to."""
    out = ["# File formats (JSON Schemas)",
           "",
           "Generated from `docs/schemas/*.json` when the site is built (the schemas "
           "themselves are written by `scripts/export_schemas.py` from the pydantic models "
           "in `src/planecal/formats/`; a test keeps them current). Every JSON file "
           "planecal reads or writes carries a `format` field, `planecal-<kind>/<version>`. "
           "What the fields mean, and the tab-separated sample files: "
           "[FORMATS.md](../FORMATS.md).",
           ""]
    docs = [(p, json.loads(p.read_text())) for p in sorted(folder.glob("*.schema.json"))]
    for p, s in docs:
        out.append(f"- [`{format_name(s, p)}`](#{slug(p)}) ({s.get('title', '')})")
    for p, s in docs:
        out += ["", f"## {format_name(s, p)} {{#{slug(p)}}}", ""]
        if s.get("description"):
            out += [clean(s["description"]), ""]
        out += [f"Schema: [`{p.name}`](../schemas/{p.name}) (title `{s.get('title', '')}`)."
                + (" Other keys are allowed." if s.get("additionalProperties") is not False
                   else " No other keys."), ""]
        out += fields_table(s, slug(p))
        for name, d in sorted(s.get("$defs", {}).items()):
            out += ["", f"### {name} {{#{slug(p)}-{name.lower()}}}", ""]
            if d.get("description"):
                out += [clean(d["description"]), ""]
            if "properties" in d:
                out += fields_table(d, slug(p))
            else:
                out += [f"{type_of(d, slug(p))}."]
    return "\n".join(out) + "\n"


def format_name(s: dict, p: Path) -> str:
    fmt = s.get("properties", {}).get("format", {})
    values = fmt.get("enum") or ([fmt["const"]] if "const" in fmt else [])
    return values[0] if values else p.name.removesuffix(".schema.json")


def slug(p: Path) -> str:
    return p.name.removesuffix(".schema.json")


def fields_table(s: dict, page: str) -> list[str]:
    required = set(s.get("required", []))
    rows = ["| field | type | required | default | description |", "|---|---|---|---|---|"]
    for name, f in s.get("properties", {}).items():
        default = f"`{json.dumps(f['default'])}`" if "default" in f else ""
        rows.append(f"| `{name}` | {type_of(f, page)} | {'yes' if name in required else ''} "
                    f"| {default} | {cell(clean(f.get('description', '')))} |")
    return rows


def type_of(f: dict, page: str) -> str:
    """A field's type in words: references become links, bounds are shown."""
    if "$ref" in f:
        name = f["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#{page}-{name.lower()})"
    if "anyOf" in f:
        return " or ".join(type_of(x, page) for x in f["anyOf"])
    if "enum" in f:
        return "one of " + ", ".join(f"`{json.dumps(v)}`" for v in f["enum"])
    if "const" in f:
        return f"`{json.dumps(f['const'])}`"
    t = f.get("type", "any")
    if t == "array":
        n = ""
        if f.get("minItems") is not None and f.get("minItems") == f.get("maxItems"):
            n = f" of {f['minItems']}"
        elif f.get("maxItems") is not None:
            n = f" of {f.get('minItems', 0)}-{f['maxItems']}"
        item = type_of(f["items"], page) if "items" in f else "any"
        if "prefixItems" in f:
            item = ", ".join(type_of(x, page) for x in f["prefixItems"])
        return f"array{n} ({item})"
    if t == "object":
        extra = f.get("additionalProperties")
        return f"object ({type_of(extra, page)} values)" if isinstance(extra, dict) else "object"
    bounds = []
    for key, sign in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="),
                      ("exclusiveMaximum", "<")):
        if key in f:
            bounds.append(f"{sign} {f[key]}")
    return str(t) + (f" ({', '.join(bounds)})" if bounds else "")


def clean(text: str) -> str:
    """A docstring's reStructuredText literals as Markdown code."""
    return " ".join(text.replace("``", "`").split())


def cell(text: str) -> str:
    return text.replace("|", "\\|")


# ----- the MkDocs hook ----------------------------------------------------------------

PAGES = {"reference/commands.md": commands_markdown, "reference/schemas.md": schemas_markdown}


def on_files(files, config):
    """Add the generated pages to the site (MkDocs hook)."""
    from mkdocs.structure.files import File
    for path, make in PAGES.items():
        files.append(File.generated(config, path, content=make()))
    return files


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print(__doc__.strip().splitlines()[0], file=sys.stderr)
        print("usage: python scripts/docs_reference.py OUTDIR", file=sys.stderr)
        return 2
    out = Path(argv[0])
    for path, make in PAGES.items():
        (out / path).parent.mkdir(parents=True, exist_ok=True)
        (out / path).write_text(make())
        print(out / path)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
