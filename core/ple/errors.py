"""Errors raised for user mistakes (bad input) as opposed to bugs."""


class PleError(ValueError):
    """A user-facing error: the message names the bad input. The CLI prints it and exits 2."""


ECHO_LIMIT = 80  # characters of a user's key or value quoted in a message


def cut(text: str, limit: int = ECHO_LIMIT) -> str:
    """``text`` (a key, a value, a name the user gave) as a message quotes it: at most ``limit``
    characters, the rest replaced by "…", so a 1 MB key makes a one-line error, not a 1 MB one."""
    text = str(text)
    return text if len(text) <= limit else text[:limit - 1] + "…"


def echo(value, limit: int = ECHO_LIMIT) -> str:
    """``repr(value)`` cut to ``limit`` characters (``cut``): how errors quote the user's input."""
    return cut(repr(value), limit)
