"""The one exception type that the command line turns into a one-line error,
and the one warning type it prints as a line."""


class MRTError(ValueError):
    """Bad input or a failed stage, with a message fit for one terminal line.

    It subclasses :class:`ValueError` so that callers who validate arguments
    the usual Python way catch it too.
    """


class MRTWarning(UserWarning):
    """Something in the input that is allowed but seldom meant (a negative
    light); the command line prints it as one ``warning:`` line."""
