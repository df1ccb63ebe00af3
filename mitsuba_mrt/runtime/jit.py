"""Dr.Jit's backends and worker threads, as the package uses them.

The LLVM backend needs a system libLLVM 17 or newer: with 15 or 16 the JIT
aborts the whole process on its first kernel, which no ``try`` can catch,
so :func:`llvm_usable` asks Dr.Jit which libLLVM it loaded first.

Dr.Jit's thread pool is left as the host set it: its idle workers do not
slow the reconstruction's numpy code measurably (docs/BENCHMARKS.md), and
resizing the pool around every reconstruction once hung a process.
:func:`counting_kernels` and :func:`kernel_seconds` watch what Dr.Jit compiles
and runs; a render traces under :func:`recording_flags`.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

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


#: A kernel of at most this many operations moves data (a copy, a gather,
#: a sum per pixel of a trace's lanes) rather than tracing: not one of
#: :attr:`KernelSeconds.widest`'s.
DATA_OPS = 100


@dataclass
class KernelSeconds:
    """Seconds Dr.Jit spent on the kernels of a block: compiling those not
    found in its caches, and executing all of them; ``widest``: executing
    those over the most lanes, of more than :data:`DATA_OPS` operations each
    (a trace's own kernels, which grow with its samples, where the others,
    reading back per pixel, do not)."""

    compile: float = 0.0
    execute: float = 0.0
    widest: float = 0.0


@contextlib.contextmanager
def kernel_seconds():
    """Yield a :class:`KernelSeconds` that holds, after the block, what
    Dr.Jit spent on the block's kernels (from its kernel history, which is
    switched on inside the block, cleared at its start and read, so cleared,
    at its end: blocks do not nest).

    Examples
    --------
    >>> with kernel_seconds() as spent:
    ...     pass
    >>> spent
    KernelSeconds(compile=0.0, execute=0.0, widest=0.0)
    """
    import drjit as dr

    spent = KernelSeconds()
    before = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history_clear()
    try:
        yield spent
    finally:
        history = dr.kernel_history()
        spent.compile = sum(entry.get("codegen_time", 0.0) + entry.get("backend_time", 0.0)
                            for entry in history if not entry.get("cache_hit")) / 1e3
        spent.execute = sum(entry.get("execution_time", 0.0) for entry in history) / 1e3
        spent.widest = _widest_seconds(history)
        dr.set_flag(dr.JitFlag.KernelHistory, before)


def _widest_seconds(history: list) -> float:
    """:attr:`KernelSeconds.widest` of the entries of a kernel history."""
    import drjit as dr

    traced = [entry for entry in history if entry.get("type") == dr.KernelType.JIT
              and entry.get("operation_count", 0) > DATA_OPS]
    if not traced:
        return 0.0
    lanes = max(entry.get("size", 0) for entry in traced)
    return sum(entry.get("execution_time", 0.0) for entry in traced
               if entry.get("size", 0) == lanes) / 1e3


@contextlib.contextmanager
def recording_flags():
    """Dr.Jit's kernel history on within the block, as :func:`kernel_seconds`
    switches it on (what the block gathered is dropped after, and the flag
    set back): a frozen function's recording holds for the JIT flags it was
    made under, and a call under others records it again (a fresh process's
    first trace of a scene: about 0.1 s), so every trace of a render is
    recorded under the one set of flags, timed or not.

    Examples
    --------
    >>> import drjit as dr
    >>> with recording_flags():
    ...     dr.flag(dr.JitFlag.KernelHistory)
    True
    """
    import drjit as dr

    before = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        yield
    finally:
        if not before:  # (cleared, not read: an entry holds its kernel's IR)
            dr.kernel_history_clear()
            dr.set_flag(dr.JitFlag.KernelHistory, False)
