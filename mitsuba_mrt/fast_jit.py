"""The fast mode's near-edge fits as one Dr.Jit LLVM kernel.

:func:`mitsuba_mrt.fast.local_poly_fit` fits a weighted quadric per (grid
cell, id) in numpy; most of its time goes to small batched matrix products
and temporaries.  This module computes the same fit per pixel in a single
vectorised kernel on Dr.Jit's LLVM backend (all cores, no temporaries):
the 4 x 4 stencil's moments, the ridge, a 6 x 6 Cholesky solve and the
evaluation at the pixel.  It is used only where Dr.Jit's LLVM backend is
safe to start (:func:`mitsuba_mrt.variants.llvm_usable`); elsewhere the
numpy fit runs, and the tests hold the two together.
"""

from __future__ import annotations

import functools

import numpy as np

#: Basis of the quadric, as powers (of x, of y) of the offsets from the cell's centre.
_POWERS = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))


def _aligned(array_type, values: np.ndarray, dtype):
    """``array_type`` over a 64-byte aligned copy of ``values``.

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
    from .variants import llvm_usable

    return llvm_usable()


def local_poly_fit_jit(rows: np.ndarray, cols: np.ndarray, grid_ids: np.ndarray,
                       grid_values: np.ndarray, py: np.ndarray, px: np.ndarray,
                       own: np.ndarray, cell_y: np.ndarray, cell_x: np.ndarray,
                       centre_y: np.ndarray, centre_x: np.ndarray, spacing: float,
                       ridge: np.ndarray, nearest: np.ndarray) -> np.ndarray:
    """Per-pixel weighted quadric through same-id samples of the 4 x 4 block.

    Parameters
    ----------
    rows, cols : ndarray of int
        Traced grid lines (``pattern.rows``, ``pattern.cols``).
    grid_ids : ndarray of int64, shape (nr, nc)
    grid_values : ndarray, shape (nr, nc, C)
    py, px : ndarray of int, shape (m,)
        The pixels to fit.
    own : ndarray of int64, shape (m,)
        Each pixel's id.
    cell_y, cell_x : ndarray of int, shape (m,)
        Grid cell of each pixel (its block is cell - 1 .. cell + 2).
    centre_y, centre_x : ndarray of float, shape (m,)
        Centre of each pixel's cell, the origin of the quadric.
    spacing : float
        Grid spacing in pixels, the unit of the offsets.
    ridge : ndarray, shape (6,)
        Ridge per basis term, relative to the total weight.
    nearest : ndarray, shape (m, C)
        Value taken where no sample of the block carries the pixel's id.

    Returns
    -------
    ndarray of float32, shape (m, C)
    """
    import drjit as dr
    from drjit.llvm import Float64, Int32, UInt64

    nr, nc = grid_ids.shape
    channels = grid_values.shape[2]
    ids = _aligned(UInt64, grid_ids, np.uint64)
    values = _aligned(Float64, grid_values, np.float64)
    row_pos = _aligned(Float64, rows, np.float64)
    col_pos = _aligned(Float64, cols, np.float64)
    own_id = _aligned(UInt64, own, np.uint64)
    gy0, gx0 = _aligned(Int32, cell_y, np.int32), _aligned(Int32, cell_x, np.int32)
    scale = dr.opaque(Float64, 1.0 / spacing)
    last_row, last_col = dr.opaque(Int32, nr - 1), dr.opaque(Int32, nc - 1)
    width, depth = dr.opaque(Int32, nc), dr.opaque(Int32, channels)
    cy, cx = _aligned(Float64, centre_y, np.float64), _aligned(Float64, centre_x, np.float64)

    # moments[(i, j)] = sum_k w_k ox^i oy^j for i + j <= 4; rhs[b][c] = sum_k w_k basis_b v_kc
    moments = {(i, j): Float64(0.0) for i in range(5) for j in range(5 - i)}
    rhs = [[Float64(0.0) for _ in range(channels)] for _ in _POWERS]
    for dy in range(-1, 3):
        gy = gy0 + dy
        inside_y = (gy >= 0) & (gy <= last_row)
        gy = dr.clip(gy, 0, last_row)
        oy = (dr.gather(Float64, row_pos, gy) - cy) * scale
        for dx in range(-1, 3):
            gx = gx0 + dx
            inside = inside_y & (gx >= 0) & (gx <= last_col)
            gx = dr.clip(gx, 0, last_col)
            ox = (dr.gather(Float64, col_pos, gx) - cx) * scale
            index = gy * width + gx
            use = inside & (dr.gather(UInt64, ids, index) == own_id)
            w = dr.select(use, dr.exp(-0.5 * (ox * ox + oy * oy)), 0.0)
            xs = [w, w * ox, w * ox * ox, w * ox * ox * ox, w * ox * ox * ox * ox]
            oyp = [Float64(1.0), oy, oy * oy, oy * oy * oy, oy * oy * oy * oy]
            for (i, j) in moments:
                moments[(i, j)] += xs[i] * oyp[j]
            for c in range(channels):
                v = dr.gather(Float64, values, index * depth + c)
                for b, (i, j) in enumerate(_POWERS):
                    rhs[b][c] += xs[i] * oyp[j] * v

    total = moments[(0, 0)]
    empty = total <= 0.0
    normal = [[moments[(pi + qi, pj + qj)] for (qi, qj) in _POWERS] for (pi, pj) in _POWERS]
    for b in range(6):
        normal[b][b] = normal[b][b] + float(ridge[b]) * (total + 1e-300)
        normal[b][b] = dr.select(empty, 1.0, normal[b][b])

    # Cholesky: normal = L L^T, then forward and back substitution per channel
    lower = [[None] * 6 for _ in range(6)]
    for a in range(6):
        for b in range(a + 1):
            s = normal[a][b]
            for k in range(b):
                s = s - lower[a][k] * lower[b][k]
            lower[a][b] = dr.sqrt(dr.maximum(s, 1e-300)) if a == b else s / lower[b][b]
    ox = (_aligned(Float64, px, np.float64) - cx) * scale
    oy = (_aligned(Float64, py, np.float64) - cy) * scale
    at_pixel = [dr.power(ox, i) * dr.power(oy, j) if i + j else Float64(1.0) for i, j in _POWERS]
    fallback = [_aligned(Float64, nearest[:, c], np.float64) for c in range(channels)]
    out = []
    for c in range(channels):
        z = []
        for a in range(6):
            s = dr.select(empty, 0.0, rhs[a][c])
            for k in range(a):
                s = s - lower[a][k] * z[k]
            z.append(s / lower[a][a])
        coeff = [None] * 6
        for a in reversed(range(6)):
            s = z[a]
            for k in range(a + 1, 6):
                s = s - lower[k][a] * coeff[k]
            coeff[a] = s / lower[a][a]
        value = sum(coeff[b] * at_pixel[b] for b in range(1, 6)) + coeff[0]
        out.append(dr.select(empty, fallback[c], value))
    dr.eval(*out)
    return np.stack([np.asarray(v, dtype=np.float32) for v in out], axis=1)
