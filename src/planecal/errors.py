"""The one error type for bad input: the CLI prints it as one line and exits 2."""


class InputError(Exception):
    """Bad user input (file, line, problem). Message is one line, ready to print."""
