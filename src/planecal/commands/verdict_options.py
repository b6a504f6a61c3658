"""The options of a command that gives a verdict a CI job acts on (``planecal check``,
``planecal compare``): the false-alarm rate, the suspect parameters, the JSON verdict on
stdout or in a file (checked before any work), and its printing."""
from __future__ import annotations

import json

from planecal.base.errors import InputError


def add_verdict_arguments(p, alpha_help: str, suspects_help: str) -> None:
    p.add_argument("--alpha", type=float, default=0.01,
                   help=alpha_help + " (default %(default)s)")
    p.add_argument("--suspects", default=None, metavar="NAMES", help=suspects_help)
    p.add_argument("--out", metavar="VERDICT.json", help="write the JSON verdict here")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not a verdict planecal wrote")
    p.add_argument("--json", action="store_true", help="print the JSON verdict, not the text")


def verdict_out(args, inputs, fmt: str):
    """--alpha checked, and --out (the output guard checked it before the run: the
    command's ``files``), None without it."""
    if not 0 < args.alpha < 1:
        raise InputError(f"--alpha must be in (0, 1), got {args.alpha}")
    return args.out or None


def emit_verdict(args, doc: dict, text, out) -> None:
    """The verdict on stdout (JSON with --json, else ``text(doc)``) and in ``out``."""
    print(json.dumps(doc, indent=2) if args.json else text(doc))
    if out:
        from planecal.io.params import save_json
        save_json(out, doc)
