"""The `planecal` command. Each subcommand lives in planecal/commands/<name>.py with
``add_arguments(parser)`` and ``run(args) -> int``; they are imported lazily."""
from __future__ import annotations

import argparse
import importlib
import sys

from planecal.errors import InputError

COMMANDS = {
    "demo": "rehearse on the default twin scene, calibrate, and compare with the twin's truth",
    "calibrate": "identify joint offsets, sensor pose and plane(s) from sample files",
    "predict": "print measured and predicted distance per sample",
    "rehearse": "run a whole sampling run on the MuJoCo twin",
    "sample": "run the sampling loop on the real cell (FD11 RT link, ZS-LD80)",
    "emulate": "serve the twin behind the real wire formats (FD11 UDP, laser pty)",
    "view": "open a Rerun recording",
    "bootstrap": "spread of identified parameters over random subsets of a sample pool",
    "montecarlo": "repeated twin rehearsals: bias, spread and Cramer-Rao bound",
    "plan": "choose sample poses for identifiability (D-optimal)",
    "validate": "ISO 9283 pose accuracy and gauge-block test on the twin",
    "replay": "replay a recorded file's encoder positions in the twin",
    "report": "write an HTML report with figures of a result file (calibration or study)",
    "urdf": "export the nominal or calibrated robot as URDF (base, flange, laser)",
}


def _module(name: str):
    return importlib.import_module(f"planecal.commands.{name}")


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="planecal", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    wanted = next((a for a in argv if not a.startswith("-")), None)
    for name, help_text in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if name == wanted:  # only import the command actually run
            try:
                _module(name).add_arguments(p)
            except ModuleNotFoundError as e:
                if e.name != f"planecal.commands.{name}":
                    raise
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if not args.command:
        parser.print_help()
        return 2
    try:
        module = _module(args.command)
    except ModuleNotFoundError as e:
        if e.name != f"planecal.commands.{args.command}":
            raise
        print(f"planecal {args.command}: not available in this version", file=sys.stderr)
        return 2
    try:
        return int(module.run(args) or 0)
    except InputError as e:
        print(f"planecal {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"planecal {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
