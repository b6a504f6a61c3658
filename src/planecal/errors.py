"""The one error type for bad input: the CLI prints it as one line and exits 2."""


class InputError(Exception):
    """Bad user input (file, line, problem). Message is one line, ready to print."""


class RunFailed(Exception):
    """A run or a fit that could not do its job (not converged, not identifiable, gave up,
    link lost, cannot write): one line saying why; the CLI exits 1."""
