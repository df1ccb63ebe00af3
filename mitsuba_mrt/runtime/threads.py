"""Row blocks on all cores, for numpy and scipy calls that release the GIL.

``cdist``, numpy's ufuncs and scipy's filters drop the GIL while they work,
so plain threads run them side by side.  One pool serves the package.

Dr.Jit's own pool (nanothread) lets its workers poll for work 500,000 times
after every kernel before they sleep: about 20 ms of a busy core, here, that
numpy code running next competes with.  :func:`jit_workers_parked` stops
those workers while the reconstruction's numpy code runs, and
:func:`jit_workers` brings them back for a burst of kernels.
"""

from __future__ import annotations

import contextlib
import functools
import os
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np


@functools.cache
def _pool() -> tuple[ThreadPoolExecutor | None, int]:
    """The package's thread pool and its size (None: a single core)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    workers = min(cores, 8)
    return (ThreadPoolExecutor(workers, thread_name_prefix="mitsuba-mrt") if workers > 1
            else None), workers


def for_row_blocks(function, rows: int, min_rows: int = 512,
                   upper_triangle: bool = False) -> None:
    """Call ``function(start, stop)`` on contiguous blocks covering ``range(rows)``.

    One block per core, on threads, when ``rows >= min_rows`` and there is
    more than one core; else one call on the calling thread.  ``function``
    must only write rows ``start:stop`` of its output.  The blocks hold equal
    numbers of rows, or, with ``upper_triangle``, equal areas of the upper
    triangle of a square matrix (row ``i`` costing ``rows - i``).

    Examples
    --------
    >>> out = np.zeros(1000)
    >>> def fill(a, b): out[a:b] = np.arange(a, b)
    >>> for_row_blocks(fill, 1000, min_rows=10)
    >>> bool(np.array_equal(out, np.arange(1000)))
    True
    """
    pool, workers = _pool()
    if pool is None or rows < min_rows:
        function(0, rows)
        return
    share = np.linspace(0.0, 1.0, workers + 1)
    cuts = (rows * (1.0 - np.sqrt(1.0 - share)) if upper_triangle else rows * share)
    cuts = np.round(cuts).astype(int).tolist()
    futures = [pool.submit(function, a, b) for a, b in zip(cuts[:-2], cuts[1:-1])]
    function(cuts[-2], cuts[-1])  # the last block on the calling thread
    for future in futures:
        future.result()


def beside(function, *args) -> Future:
    """Start ``function(*args)`` on the pool while the caller goes on.

    Returns its future; on a single core the call runs at once and the
    future is already done.  Exceptions come out of ``result()``.

    Examples
    --------
    >>> beside(sum, [1, 2, 3]).result()
    6
    """
    pool, _ = _pool()
    if pool is not None:
        return pool.submit(function, *args)
    future = Future()
    try:
        future.set_result(function(*args))
    except Exception as error:  # delivered by result(), as from the pool
        future.set_exception(error)
    return future


#: Dr.Jit thread counts that the open :func:`jit_workers_parked` blocks
#: replaced with 1 (their own worker-less count), innermost last.
_parked_counts: list[int] = []


@contextlib.contextmanager
def jit_workers_parked():
    """Run the block with Dr.Jit's worker threads stopped, then restore them.

    Inside, a Dr.Jit kernel runs on the calling thread alone, unless it is
    wrapped in :func:`jit_workers`; nobody busy-waits beside numpy.  The
    thread count the caller had (``drjit.thread_count()``) is restored on
    exit, also after an exception.

    Examples
    --------
    >>> import drjit as dr
    >>> before = dr.thread_count()
    >>> with jit_workers_parked():
    ...     dr.thread_count()
    1
    >>> dr.thread_count() == before
    True
    """
    import drjit as dr

    count = dr.thread_count()
    if count > 1:
        dr.set_thread_count(1)
    _parked_counts.append(count)
    try:
        yield
    finally:
        _parked_counts.pop()
        if count > 1:
            dr.set_thread_count(count)


@contextlib.contextmanager
def jit_workers():
    """Inside :func:`jit_workers_parked`: Dr.Jit's workers for one burst of
    kernels (a trace, a fit), stopped again after it; elsewhere a no-op."""
    count = _parked_counts[-1] if _parked_counts else 1
    if count <= 1:
        yield
        return
    import drjit as dr

    dr.set_thread_count(count)
    try:
        yield
    finally:
        dr.set_thread_count(1)
