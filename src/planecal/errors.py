"""The one error type for bad input: the CLI prints it as one line and exits 2."""


class InputError(Exception):
    """Bad user input. The message is one line, ready to print: ``FILE: field.path:
    problem`` for JSON files (planecal.formats), ``FILE:LINE: problem`` for sample files
    and JSON syntax, or the option and the problem."""
