"""Row blocks on all cores, for numpy and scipy calls that release the GIL.

``cdist``, numpy's ufuncs and scipy's filters drop the GIL while they work,
so plain threads run them side by side.  One pool serves the package; it is
created on first use, one thread per core unless :func:`use_threads` says
fewer.
"""

from __future__ import annotations

import functools
import os
import threading
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np


#: The names of the pool's threads begin with this.
THREAD_PREFIX = "mitsuba-mrt"
#: Threads the pool is limited to (:func:`use_threads`); None: one per core.
_limit: list[int | None] = [None]


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@functools.cache
def _pool() -> tuple[ThreadPoolExecutor | None, int]:
    """The package's thread pool and its size (None: a single thread)."""
    workers = min(_limit[0] or cores(), 8)
    return (ThreadPoolExecutor(workers, thread_name_prefix=THREAD_PREFIX) if workers > 1
            else None), workers


def use_threads(count: int | None) -> None:
    """Limit the pool to ``count`` threads (None: one per core), from the next call on.

    A process that shares the machine with others of its kind (a Dask
    worker beside other workers) takes its share of the cores.

    Examples
    --------
    >>> use_threads(1); _pool()[1]
    1
    >>> use_threads(None)
    """
    if _limit[0] == count:
        return
    _limit[0] = count
    if _pool.cache_info().currsize:
        pool, _ = _pool()
        _pool.cache_clear()
        if pool is not None:
            pool.shutdown(wait=False)


def for_row_blocks(function, rows: int, min_rows: int = 512,
                   upper_triangle: bool = False) -> None:
    """Call ``function(start, stop)`` on contiguous blocks covering ``range(rows)``.

    One block per core, on threads, when ``rows >= min_rows`` and there is
    more than one core; else, and on one of the pool's own threads (work
    started :func:`beside` the caller, which would otherwise wait on blocks
    queued behind it), one call on the calling thread.  ``function``
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
    if pool is None or rows < min_rows or _on_pool_thread():
        function(0, rows)
        return
    share = np.linspace(0.0, 1.0, workers + 1)
    cuts = (rows * (1.0 - np.sqrt(1.0 - share)) if upper_triangle else rows * share)
    cuts = np.round(cuts).astype(int).tolist()
    futures = [pool.submit(function, a, b) for a, b in zip(cuts[:-2], cuts[1:-1])]
    function(cuts[-2], cuts[-1])  # the last block on the calling thread
    for future in futures:
        future.result()


def _on_pool_thread() -> bool:
    """Whether the calling thread is one of the pool's."""
    return threading.current_thread().name.startswith(THREAD_PREFIX)


#: Fewest rows :func:`for_row_blocks_of` splits by default: a smaller grid's
#: 3 x 3 stencil (the grid's smoothing, its neighbourhood maxima) takes less
#: than handing it to the pool.
STENCIL_ROWS = 128


def for_row_blocks_of(function, out: np.ndarray, halo: int = 1,
                      min_rows: int = STENCIL_ROWS) -> None:
    """Fill ``out`` by row blocks on all cores: ``function(lo, hi)`` returns
    the rows ``lo:hi`` of a result whose rows depend on their ``halo`` rows
    on either side, of which the block's own rows are kept.

    For an elementwise stencil the result is the whole call's, bit for bit.

    Examples
    --------
    >>> a = np.arange(1000.0) ** 2
    >>> def second_difference(lo, hi):
    ...     d = np.zeros(hi - lo)
    ...     d[1:-1] = a[lo:hi - 2] - 2 * a[lo + 1:hi - 1] + a[lo + 2:hi]
    ...     return d
    >>> out = np.empty(1000)
    >>> for_row_blocks_of(second_difference, out, halo=1, min_rows=10)
    >>> bool(np.array_equal(out, second_difference(0, 1000)))
    True
    """
    rows = len(out)

    def block(start: int, stop: int) -> None:
        lo, hi = max(start - halo, 0), min(stop + halo, rows)
        out[start:stop] = function(lo, hi)[start - lo: stop - lo]
    for_row_blocks(block, rows, min_rows=min_rows)


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
