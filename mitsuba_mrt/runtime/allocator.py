"""The process's memory: glibc's malloc keeps freed memory, NumPy asks for no huge pages;
how much memory a new allocation may take (:func:`available_memory`).

A reconstruction allocates and frees tens of large temporaries (about
100 MB at 1000 x 1000).  With glibc's default, adaptive thresholds much of
that memory goes back to the kernel when it is freed, and the next call
faults it in again, page by page.  :func:`keep_freed_memory` fixes the
thresholds instead (``mallopt``), so that up to :data:`TRIM_THRESHOLD` of
freed memory stays mapped for the next allocation, and grows the heap
:data:`TOP_PAD` beyond each allocation that needs more, so that a fresh
process's first reconstruction extends it a few times, not once per array.
:func:`mitsuba_mrt.runtime.configure` calls it; importing the package does not.

It does nothing when ``MITSUBA_MRT_MALLOC=system`` is set, when one of
glibc's own ``MALLOC_*_`` tuning variables is (the user tuned malloc), or
when the C library is not glibc.

NumPy advises the kernel to back arrays of 4 MB or more with transparent
huge pages.  Where the kernel grants them on advice
(``transparent_hugepage/enabled`` set to ``madvise``, a common default),
the first write to such an array waits while the kernel finds and clears a
huge page, for a time that depends on the machine's memory, not on the
work: a fresh process's large reconstructions (the id pass's
full-resolution arrays) took longer, and by varying amounts.  :func:`no_huge_pages` turns the advice off
(``MITSUBA_MRT_MALLOC=system`` or NumPy's own ``NUMPY_MADVISE_HUGEPAGE``
keep it).
"""

from __future__ import annotations

import ctypes
import os

#: Blocks of at least this size get their own mapping (and are unmapped when freed).
MMAP_THRESHOLD = 64 << 20
#: Freed memory at the top of the heap beyond this size goes back to the kernel.
TRIM_THRESHOLD = 256 << 20
#: The heap grows by this much more than an allocation needs.
TOP_PAD = 64 << 20

_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3  # mallopt's parameter numbers (malloc.h)
_USER_TUNING = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_",
                "MALLOC_MMAP_MAX_")


def _user_chose(variables: tuple) -> bool:
    """Whether the user keeps the process's memory as it is:
    ``MITSUBA_MRT_MALLOC=system``, or one of ``variables`` (the tuning's own) set."""
    return (os.environ.get("MITSUBA_MRT_MALLOC") == "system"
            or any(name in os.environ for name in variables))


def keep_freed_memory() -> bool:
    """Set glibc's mmap and trim thresholds and its top pad (see the module);
    True if they were set.

    Examples
    --------
    >>> import os
    >>> os.environ["MITSUBA_MRT_MALLOC"] = "system"
    >>> keep_freed_memory()
    False
    >>> del os.environ["MITSUBA_MRT_MALLOC"]
    """
    if _user_chose(_USER_TUNING):
        return False
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION").startswith("glibc"):
            return False
        mallopt = ctypes.CDLL(None).mallopt
    except (AttributeError, OSError, ValueError):  # not glibc, or no confstr name here
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return all(mallopt(parameter, value) for parameter, value in (
        (_M_MMAP_THRESHOLD, MMAP_THRESHOLD), (_M_TRIM_THRESHOLD, TRIM_THRESHOLD),
        (_M_TOP_PAD, TOP_PAD)))


def no_huge_pages() -> bool:
    """Stop NumPy advising huge pages for its large arrays (see the module);
    True if it did so before.

    Examples
    --------
    >>> import os
    >>> os.environ["NUMPY_MADVISE_HUGEPAGE"] = "1"
    >>> no_huge_pages()
    False
    >>> del os.environ["NUMPY_MADVISE_HUGEPAGE"]
    """
    if _user_chose(("NUMPY_MADVISE_HUGEPAGE",)):
        return False
    try:
        from numpy._core import multiarray
    except ImportError:  # NumPy 1
        from numpy.core import multiarray
    advise = getattr(multiarray, "_set_madvise_hugepage", None)
    return bool(advise(False)) if advise is not None else False


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (``MemAvailable``), else
    the physical memory, else None."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None
