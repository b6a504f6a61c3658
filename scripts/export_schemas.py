#!/usr/bin/env python
"""Write docs/schemas/<format>.schema.json (JSON Schema, draft 2020-12) for every file
format in planecal.formats.MODELS, generated from the pydantic models the readers use.

usage: python scripts/export_schemas.py [--check]
--check exits 1 (writing nothing) when a committed schema differs from the models, or a
schema file has no model any more.

A JSON Schema holds the types, lengths and ranges; the checks that relate fields (a
non-singular coupling matrix, plates within reach, the sampling distances inside the
laser window) are in the models only, and docs/FORMATS.md describes them.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from planecal.formats import schema_documents

SCHEMAS = Path(__file__).resolve().parents[1] / "docs" / "schemas"  # in this checkout


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare, do not write")
    args = ap.parse_args(argv)
    out = SCHEMAS
    docs = schema_documents()
    status = 0
    if args.check:
        for name, text in docs.items():
            path = out / name
            same = path.exists() and path.read_text() == text
            print(f"{path}: {'up to date' if same else 'differs from the models'}")
            status |= 0 if same else 1
        for stale in sorted(set(p.name for p in out.glob("*.schema.json")) - set(docs)):
            print(f"{out / stale}: no model has this format any more")
            status = 1
        return status
    out.mkdir(parents=True, exist_ok=True)
    for name, text in docs.items():
        (out / name).write_text(text)
        print(f"wrote {out / name}")
    return status


if __name__ == "__main__":
    sys.exit(main())
