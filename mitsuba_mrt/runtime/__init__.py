"""Process-wide tuning and threads: nothing here runs on import.

The library leaves the host process as it found it.  Programs that own
their process (the command line, the benchmark) call :func:`configure`
first; a Python user may too.
"""

from __future__ import annotations

import os

from .allocator import keep_freed_memory, no_huge_pages

#: OpenBLAS's idle-thread timeout set by :func:`configure` (2**16 cycles,
#: about 20 us): short enough that idle BLAS threads sleep before the next
#: stage wants the cores, long enough to bridge pauses within one
#: factorisation.  OpenBLAS's default spins for about 2**28 cycles.
OPENBLAS_THREAD_TIMEOUT = "16"


def configure() -> dict[str, bool]:
    """Tune this process for repeated reconstructions; returns what was set.

    * ``OPENBLAS_THREAD_TIMEOUT`` (unless already set): OpenBLAS reads it
      when it is loaded, so this reaches only BLAS libraries loaded later.
    * glibc's malloc keeps up to 256 MB of freed memory mapped for reuse
      and grows its heap in 64 MB steps
      (:func:`mitsuba_mrt.runtime.allocator.keep_freed_memory`); skipped
      with ``MITSUBA_MRT_MALLOC=system`` or glibc's own ``MALLOC_*_``
      variables.
    * NumPy advises no transparent huge pages for its large arrays
      (:func:`mitsuba_mrt.runtime.allocator.no_huge_pages`: a first write
      to one could wait on the kernel finding a huge page); skipped with
      ``MITSUBA_MRT_MALLOC=system`` or ``NUMPY_MADVISE_HUGEPAGE``.

    Examples
    --------
    >>> sorted(configure())
    ['huge_pages_off', 'malloc', 'openblas_timeout']
    """
    timeout = "OPENBLAS_THREAD_TIMEOUT" not in os.environ
    if timeout:
        os.environ["OPENBLAS_THREAD_TIMEOUT"] = OPENBLAS_THREAD_TIMEOUT
    return {"openblas_timeout": timeout, "malloc": keep_freed_memory(),
            "huge_pages_off": no_huge_pages()}
