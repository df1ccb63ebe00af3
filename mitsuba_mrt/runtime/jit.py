"""Dr.Jit's backends and worker threads, as the package uses them.

The LLVM backend needs a system libLLVM 17 or newer: with 15 or 16 the JIT
aborts the whole process on its first kernel, which no ``try`` can catch,
so :func:`llvm_usable` asks Dr.Jit which libLLVM it loaded first.

Dr.Jit's own pool lets its workers poll for work for a while after every
kernel before they sleep, competing with numpy code that runs next.
:func:`jit_workers_parked` stops those workers while the reconstruction's
numpy code runs, and :func:`jit_workers` brings them back for a burst of
kernels.
"""

from __future__ import annotations

import contextlib

#: Oldest libLLVM major version the LLVM backend runs with.
MIN_LLVM = 17


def llvm_version() -> tuple[int, ...] | None:
    """Version of the libLLVM that Dr.Jit loaded, or None when there is none."""
    import drjit as dr

    try:
        version = dr.detail.llvm_version()
    except Exception:  # noqa: BLE001 - any failure means "no usable LLVM"
        return None
    return tuple(version) if version and version[0] > 0 else None


def llvm_usable() -> bool:
    """True when Dr.Jit's LLVM backend can run here without aborting."""
    version = llvm_version()
    return version is not None and version[0] >= MIN_LLVM


def cuda_usable() -> bool:
    """True when Dr.Jit finds a CUDA device."""
    import drjit as dr

    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # noqa: BLE001
        return False


#: Dr.Jit thread counts that the open :func:`jit_workers_parked` blocks
#: replaced with 1 (their own worker-less count), innermost last.
_parked_counts: list[int] = []

#: Images smaller than this are reconstructed without parking the workers:
#: their numpy stages are short, and every resize of Dr.Jit's pool risks a
#: lost wake-up in its thread pool (a hang, seen once in a thorough stress run).
PARK_MIN_PIXELS = 256 * 256


@contextlib.contextmanager
def jit_workers_parked(pixels: int | None = None):
    """Run the block with Dr.Jit's worker threads stopped, then restore them;
    for an image of fewer than :data:`PARK_MIN_PIXELS` ``pixels``, leave them.

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
    park = count > 1 and (pixels is None or pixels >= PARK_MIN_PIXELS)
    if park:
        dr.set_thread_count(1)
    _parked_counts.append(count if park else 1)  # unparked: jit_workers has nothing to do
    try:
        yield
    finally:
        _parked_counts.pop()
        if park:
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


@contextlib.contextmanager
def counting_kernels():
    """Yield a two-element list that holds, after the block, the kernels
    Dr.Jit compiled inside it and those it loaded from its on-disk cache
    (kernels found in memory count in neither).  Dr.Jit's launch counters
    are only read: nothing is switched on or cleared.

    Examples
    --------
    >>> with counting_kernels() as counts:
    ...     pass
    >>> counts
    [0, 0]
    """
    import drjit as dr

    stats = getattr(dr.detail, "launch_stats", None)  # (launches, soft misses, hard misses)
    before = stats() if stats else (0, 0, 0)
    counts = [0, 0]
    try:
        yield counts
    finally:
        after = stats() if stats else (0, 0, 0)
        counts[:] = [after[2] - before[2], after[1] - before[1]]


@contextlib.contextmanager
def compile_seconds():
    """Yield a one-element list that holds, after the block, the seconds Dr.Jit
    spent compiling kernels inside it (kernels found in its caches cost none).

    Examples
    --------
    >>> with compile_seconds() as spent:
    ...     pass
    >>> spent
    [0.0]
    """
    import drjit as dr

    spent = [0.0]
    before = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()  # (reading the history clears it)
    try:
        yield spent
    finally:
        spent[0] = sum(entry.get("codegen_time", 0.0) + entry.get("backend_time", 0.0)
                       for entry in dr.kernel_history() if not entry.get("cache_hit")) / 1e3
        dr.set_flag(dr.JitFlag.KernelHistory, before)
