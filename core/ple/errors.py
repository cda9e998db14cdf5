"""Errors raised for user mistakes (bad input) as opposed to bugs."""


class PleError(ValueError):
    """A user-facing error: the message names the bad input. The CLI prints it and exits 2."""
