"""The one exception type that the command line turns into a one-line error."""


class MRTError(ValueError):
    """Bad input or a failed stage, with a message fit for one terminal line.

    It subclasses :class:`ValueError` so that callers who validate arguments
    the usual Python way catch it too.
    """
