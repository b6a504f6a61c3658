"""The error types the CLI turns into one line: bad input (exit 2) and a run or fit that
failed (exit 1)."""


class InputError(Exception):
    """Bad user input. The message is one line, ready to print: ``FILE: field.path:
    problem`` for JSON files (planecal.formats), ``FILE:LINE: problem`` for sample files
    and JSON syntax, or the option and the problem."""


class RunFailed(Exception):
    """A run or a fit that could not do its job (not converged, not identifiable, gave up,
    link lost, cannot write): one line saying why; the CLI exits 1."""
