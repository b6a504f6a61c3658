"""Calibrate an industrial robot on plates with a flange-mounted laser distance sensor,
and rehearse every run first on a MuJoCo digital twin of the cell.

Each subcommand lives in planecal/commands/<name>.py with ``add_arguments(parser)`` and
``run(args) -> int``; only the command that runs is imported.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys

from planecal import __version__
from planecal.base.errors import InputError, RunFailed

COMMANDS = {
    "demo": "rehearse on the default twin scene, calibrate, and compare with the twin's truth",
    "calibrate": "identify joint offsets, sensor pose and plane(s) from sample files",
    "predict": "print measured and predicted distance per sample",
    "export": "encoder offsets (integer counts) to enter into the FD11 after a calibration",
    "rehearse": "run a whole sampling run on the MuJoCo twin",
    "sample": "run the sampling loop on the real cell (FD11 RT link, ZS-LD80)",
    "emulate": "serve the twin behind the real wire formats (FD11 UDP, laser pty)",
    "view": "open a Rerun recording",
    "bootstrap": "spread of identified parameters over random subsets of a sample pool",
    "montecarlo": "repeated twin rehearsals: bias, spread and Cramer-Rao bound",
    "plan": "choose sample poses for identifiability (D-optimal)",
    "validate": "ISO 9283 pose accuracy and gauge-block test on the twin",
    "replay": "replay a recorded file's encoder positions in the twin",
    "scenes": "list the scenes (cells) planecal knows, with their plates",
    "completion": "print a shell completion script (bash, zsh, tcsh)",
    "report": "write an HTML report with figures of a result file (calibration or study)",
    "urdf": "export the nominal or calibrated robot as URDF (base, flange, laser)",
    "mjcf": "write a scene's MuJoCo model (robot, tool, cell) for a viewer",
    "sweep": "accuracy against robot time over a grid of worlds, pose designs and sizes",
    "compensate": "correct a program's targets with a calibration (counts the controller plays)",
    "layouts": "identifiable parameters and predicted std for 1, 2 and 3 of a scene's plates",
    "worker-env": "the environment of a Dask worker for the studies: export $(planecal worker-env)",
    "robot": "import a robot from a URDF (robot import), or show a robot description",
    "scene": "write a default cell for any robot (scene new)",
    "check": "has the cell drifted since a calibration? a short run tested against it",
    "compare": "twin against real: two runs of the same poses, agree or differ",
    "history": "the cell's history: list, show, diff and roll back calibrations",
}

EPILOG = """exit codes: 0 success; 1 the run or fit failed (not converged, not identifiable,
gave up, link lost), the reason in one line; 2 bad input or usage; 3 done, its files
written, but the cell's history could not record it (one line says why); 130 interrupted
(SIGINT, SIGHUP); 143 terminated (SIGTERM).
Every command takes --config FILE.toml (a table per command, keys = long option names,
e.g. [rehearse] samples = 20; flags given on the command line win), -v and -q."""


MAX_CONFIG_BYTES = 2**20  # a run configuration is a few lines


class UsageError(InputError):
    """A command line argparse refuses; the message names the command and --help."""


class Parser(argparse.ArgumentParser):
    """One line for a usage error, with a pointer to --help (exit 2). No abbreviations: an
    option is taken only by its whole name, so an input flag (``--truth``) can never
    resolve to an output flag (``--truth-out``). Remembers its long options without the
    dashes (``long_options``: what a ``--config`` table may name), those of its argument
    groups included."""

    def __init__(self, *args, **kwargs):
        kwargs["allow_abbrev"] = False
        self.long_options: set[str] = set()  # before argparse adds --help
        self.option_actions: dict[str, argparse.Action] = {}  # long option -> its action
        self.commands: dict[str, Parser] = {}  # the top-level parser's commands
        super().__init__(*args, **kwargs)

    def error(self, message):
        raise UsageError(f"{self.prog}: error: {message} (see {self.prog} --help)")

    def _recording(self, add):
        def add_argument(*args, **kwargs):
            action = add(*args, **kwargs)
            names = [s[2:] for s in action.option_strings if s.startswith("--")]
            self.long_options.update(names)
            self.option_actions.update((n, action) for n in names)
            return action
        return add_argument

    def add_argument(self, *args, **kwargs):
        return self._recording(super().add_argument)(*args, **kwargs)

    def add_argument_group(self, *args, **kwargs):
        group = super().add_argument_group(*args, **kwargs)
        group.add_argument = self._recording(group.add_argument)
        return group

    def add_mutually_exclusive_group(self, **kwargs):
        group = super().add_mutually_exclusive_group(**kwargs)
        group.add_argument = self._recording(group.add_argument)
        return group


class DefaultsFormatter(argparse.RawDescriptionHelpFormatter):
    """Help that shows each option's default, unless its text already says it."""

    def _get_help_string(self, action):
        text = action.help or ""
        if ("%(default)" in text or "default" in text.lower() or action.default in
                (None, False, argparse.SUPPRESS) or not action.option_strings):
            return text
        return text + " (default: %(default)s)"


def _module(name: str):
    return importlib.import_module(f"planecal.commands.{name.replace('-', '_')}")


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE.toml",
                   help="take options from the [<command>] table of this TOML file; flags "
                        "given on the command line win")
    g = p.add_mutually_exclusive_group()
    g.add_argument("-v", "--verbose", action="count", default=0,
                   help="more messages on stderr (-vv: debug)")
    g.add_argument("-q", "--quiet", action="store_true",
                   help="no progress and notes on stderr; errors only")


def build_parser(argv: list[str], full: bool = False) -> Parser:
    """The parser; only the command in ``argv`` gets its arguments (all with ``full``).
    ``parser.commands`` holds each command's own parser."""
    parser = Parser(prog="planecal", description=__doc__.split("\n\n")[0].replace("\n", " "),
                    epilog=EPILOG, formatter_class=DefaultsFormatter)
    parser.add_argument("--version", action="version", version=f"planecal {__version__}")
    # the common options' values exist with no command too (``_common`` adds the flags)
    parser.set_defaults(command=None, config=None, verbose=0, quiet=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    wanted = next((a for a in argv if not a.startswith("-")), None)
    for name, help_text in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text, epilog=EPILOG,
                           formatter_class=DefaultsFormatter)
        parser.commands[name] = p
        if name == "completion":  # the one command that reads every command's parser
            p.set_defaults(full_parser=full_parser)
        if full or name == wanted:
            _module(name).add_arguments(p)
            _common(p)
    return parser


def _config_argv(path: str, command: str, options: dict) -> list:
    """The options of the ``[command]`` table of a TOML file, as command-line tokens (so
    argparse checks them as if typed), each typed by its option: a flag takes true or
    false (``--flag`` or nothing), an option of one value a string or a number
    (``--key=value``: the value can never be read as another option or a file), one of
    several values (``nargs``, repeatable) a list or one value. ``options``: the
    command's long options and their actions. A table that names no command, a key
    outside a table, a key that is not one of the command's long options (misspelt,
    abbreviated) and a value of the wrong type are refused. One-line errors name the file
    and the key."""
    from planecal.formats.base import read_toml
    doc = read_toml(path, "TOML file", MAX_CONFIG_BYTES)  # /dev/zero, a directory, binary
    for name, value in doc.items():
        if name in COMMANDS and not isinstance(value, dict):
            raise InputError(f"{path}: [{name}] must be a table of options")
        if not isinstance(value, dict):
            raise InputError(f"{path}: {name}: an option outside a [command] table (each "
                             "command reads its own table, e.g. [rehearse])")
        if name not in COMMANDS:
            raise InputError(f"{path}: [{name}]: no such command (the tables are "
                             f"commands: {', '.join(sorted(COMMANDS))})")
    table = doc.get(command, {})
    out = []
    for key, value in table.items():
        flag = "--" + key.replace("_", "-")
        if key in ("config", "help"):
            raise InputError(f"{path}: [{command}].{key}: not allowed in a config file")
        if flag[2:] not in options:
            raise InputError(f"{path}: [{command}].{key}: planecal {command} has no option "
                             f"{flag} (the keys are its long option names, in full; see "
                             f"planecal {command} --help)")
        out += _config_tokens(f"{path}: [{command}].{key}", flag, options[flag[2:]], value)
    return out


def _config_tokens(where: str, flag: str, action: argparse.Action, value) -> list:
    """The tokens of one config key (``_config_argv``), its value typed by ``action``; an
    option of any number of values (``nargs`` + or \\*) as (action, values): its default."""
    if action.nargs == 0:  # a flag
        if not isinstance(value, bool):
            raise InputError(f"{where}: {flag} is a flag: true or false, not {value!r}"[:300])
        return [flag] if value else []
    many = action.nargs not in (None, "?") or isinstance(action, argparse._AppendAction)
    values = value if isinstance(value, list) and many else [value]
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (str, int, float)):
            what = ("a list" if isinstance(v, list) else "a table" if isinstance(v, dict)
                    else "true/false" if isinstance(v, bool) else type(v).__name__)
            raise InputError(f"{where}: {flag} takes "
                             + ("a value or a list of values" if many else "one value")
                             + f" (a string or a number), not {what}")
    if isinstance(action.nargs, int) and len(values) != action.nargs:
        raise InputError(f"{where}: {flag} takes {action.nargs} values, got {len(values)}")
    if not many:
        return [f"{flag}={values[0]}"]
    if isinstance(action, argparse._AppendAction):
        return [f"{flag}={v}" for v in values]
    if any(str(v).startswith("-") and not _number(v) for v in values):
        raise InputError(f"{where}: {flag}: a value may not start with '-'")
    if not isinstance(action.nargs, int):  # + or *: its values would take the next tokens
        return [(action, [str(v) for v in values])]
    return [flag, *(str(v) for v in values)]


def _number(v) -> bool:
    try:
        float(v)
        return True
    except ValueError:
        return False


def _usage(command: str | None, e: UsageError, where: str = "") -> UsageError:
    """The error as the command's own (the top-level parser reports unknown options)."""
    if command not in COMMANDS:
        return e
    why = str(e).split(": error: ", 1)[-1].rsplit(" (see ", 1)[0]
    return UsageError(f"planecal {command}: error: {where}{why} (see planecal {command} --help)")


def _config_path(argv: list[str]) -> str | None:
    """The --config FILE of a command line (its last), before it is parsed: its options
    can be what the command requires (``[plan] out = ...``)."""
    path = None
    for i, a in enumerate(argv):
        if a == "--config" and i + 1 < len(argv):
            path = argv[i + 1]
        elif a.startswith("--config="):
            path = a.split("=", 1)[1]
    return path


def parse(argv: list[str]) -> argparse.Namespace:
    parser = build_parser(argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    cfg = _config_path(argv) if command in COMMANDS else None
    if not cfg:
        try:
            return parser.parse_args(argv)
        except UsageError as e:
            raise _usage(command, e) from None
    # the file's options first, the command line's after: the last value wins
    pos = argv.index(command)
    sub = parser.commands[command]
    extra = _config_argv(cfg, command, sub.option_actions)
    try:
        for action, values in [t for t in extra if isinstance(t, tuple)]:
            sub.set_defaults(**{action.dest: sub._get_values(action, values)})
        tokens = [t for t in extra if not isinstance(t, tuple)]
        return parser.parse_args(argv[:pos + 1] + tokens + argv[pos + 1:])
    except argparse.ArgumentError as e:
        raise _usage(command, UsageError(f"x: error: {e}"), f"{cfg} [{command}]: ") from None
    except UsageError as e:
        try:  # the command line's own mistake is said as the command line's
            parser.parse_args(argv)
        except UsageError as own:
            if "are required" not in str(own):
                raise _usage(command, own) from None
        raise _usage(command, e, f"{cfg} [{command}]: ") from None


def _logging(args) -> None:
    from planecal.base.progress import set_quiet
    quiet = args.quiet
    level = (logging.ERROR if quiet else
             {0: logging.WARNING, 1: logging.INFO}.get(args.verbose, logging.DEBUG))
    logging.basicConfig(level=level, format="planecal: %(message)s", stream=sys.stderr)
    set_quiet(quiet)


def _check_files(module, args) -> None:
    """The command's inputs and outputs (``--config`` included, and the history of a
    command that records: no output replaces it), before it runs: its ``files(args)``
    declaration (``planecal.commands.io_options``) through the output guard
    (``planecal.io.outputs.check_files``): an input the command line names must exist (a
    history is made where there is none), an output may not overwrite an input. The
    declarations and the guard import nothing heavy, so these are said before the command
    loads its libraries."""
    declare = getattr(module, "files", None)
    if declare is None:
        return
    from planecal.commands.history_options import history_files
    from planecal.io.outputs import check_files
    files = declare(args)
    files.read(args.config, role="--config")
    history = history_files(args)
    files.read(*history, role="the history")
    named = _named(args) - {str(p) for p in history}
    check_files(files, bool(getattr(args, "force", False)), named)


def _named(args) -> set[str]:
    """Every value the command line (or its --config file) gave, as text: the files it
    names among them."""
    out = set()
    for v in vars(args).values():
        for x in v if isinstance(v, (list, tuple)) else (v,):
            if isinstance(x, (str, os.PathLike)):
                out.add(str(x))
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:
        args = parse(argv)
    except UsageError as e:
        print(e, file=sys.stderr)
        return 2
    except InputError as e:
        print(f"planecal: error: {e}", file=sys.stderr)
        return 2
    if not args.command:  # a usage error: one line and the pointer to --help
        print("planecal: error: a COMMAND is required (see planecal --help)", file=sys.stderr)
        return 2
    from planecal.base.progress import quiet, set_quiet
    was_quiet = quiet()
    _logging(args)
    try:
        return _command(args)
    finally:  # -q is this command's: a caller of main in the same process keeps its own
        set_quiet(was_quiet)


def _command(args) -> int:
    """The parsed command run, its errors said in one line (``main``)."""
    module = _module(args.command)
    from planecal.base.interrupts import exit_code, interrupt_on_signals, signal_name
    try:
        _check_files(module, args)
        with interrupt_on_signals():  # SIGTERM, SIGHUP end a command as Ctrl-C does
            return int(module.run(args) or 0)
    except InputError as e:
        print(f"planecal {args.command}: error: {e}", file=sys.stderr)
        return 2
    except RunFailed as e:
        print(f"planecal {args.command}: failed: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:
        print(f"planecal {args.command}: interrupted ({signal_name(e)})", file=sys.stderr)
        return exit_code(e)
    except BrokenPipeError:  # stdout closed early (| head): end quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except OSError as e:  # the system refused mid-run (disk full, a file vanished): one line
        where = f"{e.filename}: " if e.filename else ""
        print(f"planecal {args.command}: failed: {where}{e.strerror or e}", file=sys.stderr)
        return 1


def full_parser() -> argparse.ArgumentParser:
    """Every command with its arguments (shell completion)."""
    return build_parser([], full=True)


if __name__ == "__main__":
    sys.exit(main())


