"""The last few times a repeated call took, and what the next is expected to take.

``auto`` plans a time limit from what its stages took in earlier renders
(OIDN's calls per image size, a preview's stages after its grid, a
checked MRT plan).  Each
keeps the seconds of its last few calls in a list and expects their
median: one slow call (the machine's noise) does not set it alone; the
tables of them keep their last few keys (:func:`keep`).
"""

from __future__ import annotations


def note(calls: list, seconds: float, kept: int) -> None:
    """Add ``seconds`` to ``calls``, which keeps its last ``kept``.

    Examples
    --------
    >>> calls = [0.1, 0.2, 0.3]
    >>> note(calls, 0.4, 3)
    >>> calls
    [0.2, 0.3, 0.4]
    """
    calls.append(seconds)
    del calls[:-kept]


def typical(calls: list) -> float:
    """The median of ``calls``' seconds, the lower of two.

    Examples
    --------
    >>> typical([0.3, 5.0, 0.2]), typical([0.3, 5.0])
    (0.3, 0.3)
    """
    return sorted(calls)[(len(calls) - 1) // 2]


def keep(table: dict, key, value, kept: int):
    """``value`` kept for ``key`` in ``table`` as its most recently used
    entry, of the last ``kept`` keys; returned.

    Examples
    --------
    >>> table = {"a": 1, "b": 2}
    >>> keep(table, "a", 3, 2), table
    (3, {'b': 2, 'a': 3})
    >>> keep(table, "c", 4, 2), table
    (4, {'a': 3, 'c': 4})
    """
    table.pop(key, None)
    table[key] = value
    for old in list(table)[:-kept]:
        del table[old]
    return value
