"""numpy arrays handed to Dr.Jit's LLVM backend, for the reconstruction's kernels.

:mod:`.quadric_jit` and :mod:`.smooth_jit` run stages of the reconstruction
as single vectorised Dr.Jit kernels where the LLVM backend is safe to
start (:func:`available`); this module holds what both need to do so.
"""

from __future__ import annotations

import functools

import numpy as np


def aligned(array_type, values: np.ndarray, dtype):
    """``array_type`` over a 64-byte aligned copy of ``values``, flattened.

    Dr.Jit wraps numpy memory without copying and writes its alignment into
    the kernel, so unaligned inputs would give a new kernel (and an LLVM
    compilation of about a second) on every call.
    """
    values = np.ravel(values)
    itemsize = np.dtype(dtype).itemsize
    buffer = np.empty(len(values) + 64 // itemsize, dtype=dtype)
    start = (-buffer.ctypes.data % 64) // itemsize
    view = buffer[start:start + len(values)]
    view[:] = values
    return array_type(view)


@functools.cache
def available() -> bool:
    """True when the LLVM backend can run here (libLLVM >= 17 loaded)."""
    from ..runtime.jit import llvm_usable

    return llvm_usable()
