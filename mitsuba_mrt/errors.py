"""The one exception type that the command line turns into a one-line error,
and the one warning type it prints as a line."""


class MRTError(ValueError):
    """Bad input or a failed stage, with a message fit for one terminal line.

    It subclasses :class:`ValueError` so that callers who validate arguments
    the usual Python way catch it too.
    """


def one_line(exc: BaseException) -> str:
    """``exc`` as one terminal line: an MRTError's message, else ``Type: first line``.

    Examples
    --------
    >>> one_line(MRTError("scene file not found: a.xml"))
    'scene file not found: a.xml'
    >>> one_line(RuntimeError("boom\\nmore detail"))
    'RuntimeError: boom'
    """
    first = first_line(exc)
    return first if isinstance(exc, MRTError) else f"{type(exc).__name__}: {first}"


def first_line(exc: BaseException) -> str:
    """The first line of ``exc``'s message ("" for none).

    Examples
    --------
    >>> first_line(RuntimeError("  boom\\nmore detail"))
    'boom'
    """
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else ""


class MRTWarning(UserWarning):
    """Something in the input that is allowed but seldom meant (a negative
    light); the command line prints it as one ``warning:`` line."""
