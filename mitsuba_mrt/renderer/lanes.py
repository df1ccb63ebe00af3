"""A trace's values as the active variant makes them: Dr.Jit arrays or Python scalars.

In a JIT variant (LLVM, CUDA) every ray of a trace is one lane of a Dr.Jit
array; in the scalar variant a value is a Python scalar or bool.  The
trace's modules ask here which variant is active, negate masks of either
kind, and turn either kind of value into numpy.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

def is_jit() -> bool:
    """True in a JIT variant (LLVM, CUDA), False in a scalar one."""
    return dr.is_jit_v(mi.Float)


def logical_not(mask):
    """``~mask`` for Dr.Jit masks, ``not mask`` for the scalar variant's bools."""
    return ~mask if is_jit() else not mask


def _to_numpy(value, width: int) -> np.ndarray:
    """A Dr.Jit Color3f/Float as (width, 3)/(width,) numpy, literals broadcast.

    A 3-vector is read a component at a time: numpy's own conversion of it
    launches a kernel that bakes ``width`` in, one kernel per pixel count.
    """
    if is_jit() and dr.depth_v(value) > 1:
        dr.eval(value)
        out = np.empty((width, len(value)))
        for j, c in enumerate(value):  # each component straight into its column
            out[:, j] = np.asarray(c)
        return out
    arr = np.asarray(value)
    if arr.ndim == 2:
        return np.broadcast_to(arr.T, (width, arr.shape[0])).astype(np.float64)
    return np.broadcast_to(arr, (width,)).copy()
