"""The fast mode's near-edge fits as one Dr.Jit LLVM kernel.

:func:`mitsuba_mrt.recon.within_region.quadric_coefficients` fits a weighted quadric per
(grid cell, id) group as batched numpy solves; most of its time goes to small
matrix products and temporaries.  This module computes the same fits in a
single vectorised kernel on Dr.Jit's LLVM backend (all cores, no
temporaries): the 4 x 4 block's moments, the ridge and a 6 x 6 Cholesky
solve per group, then a second kernel evaluates the fits at the pixels.  It is used only where Dr.Jit's LLVM backend is safe to
start (:func:`mitsuba_mrt.recon.llvm_arrays.available`); elsewhere the numpy fit
runs, and the tests hold the two together.
"""

from __future__ import annotations

import numpy as np

from .llvm_arrays import aligned


#: Basis of the quadric, as powers (of x, of y) of the offsets from the cell's centre.
_POWERS = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))


def quadric_values_jit(rows: np.ndarray, cols: np.ndarray, grid_ids: np.ndarray,
                       grid_values: np.ndarray, gy0: np.ndarray, gx0: np.ndarray,
                       gid: np.ndarray, centre_y: np.ndarray, centre_x: np.ndarray,
                       spacing: float, ridge: np.ndarray, member: np.ndarray,
                       py: np.ndarray, px: np.ndarray) -> np.ndarray:
    """Weighted quadric of each (cell, id) group, evaluated at its pixels.

    The groups' parameters are those of
    :func:`mitsuba_mrt.recon.within_region.quadric_coefficients` (one kernel fits them all);
    pixel ``i`` at (``py[i]``, ``px[i]``) belongs to group ``member[i]``, and a
    second kernel evaluates its quadric there, reading the coefficients where
    the first left them, and clamps it to the range of the samples it was
    fitted to.  Returns float32 values (m, C); a group without any sample of
    its id gives 0.
    """
    return _quadric_values(rows, cols, grid_ids, grid_values, gy0, gx0, gid, centre_y,
                           centre_x, spacing, ridge, member, py, px)


def _quadric_values(rows, cols, grid_ids, grid_values, gy0, gx0, gid, centre_y, centre_x,
                    spacing, ridge, member, py, px) -> np.ndarray:
    """The kernels of :func:`quadric_values_jit` (same arguments)."""
    import drjit as dr
    from drjit.llvm import Float32, Float64, Int32, UInt64

    nr, nc = grid_ids.shape
    channels = grid_values.shape[2]
    ids = aligned(UInt64, grid_ids, np.uint64)
    values = aligned(Float64, grid_values, np.float64)
    row_pos = aligned(Float64, rows, np.float64)
    col_pos = aligned(Float64, cols, np.float64)
    own_id = aligned(UInt64, gid, np.uint64)
    cell_y, cell_x = aligned(Int32, gy0, np.int32), aligned(Int32, gx0, np.int32)
    scale = dr.opaque(Float64, 1.0 / spacing)
    last_row, last_col = dr.opaque(Int32, nr - 1), dr.opaque(Int32, nc - 1)
    width, depth = dr.opaque(Int32, nc), dr.opaque(Int32, channels)
    cy, cx = aligned(Float64, centre_y, np.float64), aligned(Float64, centre_x, np.float64)

    # moments[(i, j)] = sum_k w_k ox^i oy^j for i + j <= 4; rhs[b][c] = sum_k w_k basis_b v_kc
    moments = {(i, j): Float64(0.0) for i in range(5) for j in range(5 - i)}
    rhs = [[Float64(0.0) for _ in range(channels)] for _ in _POWERS]
    # range of the samples the fit uses, per channel: the fit is clamped to it
    lowest = [Float64(np.inf) for _ in range(channels)]
    highest = [Float64(-np.inf) for _ in range(channels)]
    oxs, inside_x = [], []
    for dx in range(-1, 3):
        gx = cell_x + dx
        inside_x.append((gx >= 0) & (gx <= last_col))
        oxs.append((dr.gather(Float64, col_pos, dr.clip(gx, 0, last_col)) - cx) * scale)
    for dy in range(-1, 3):
        gy = cell_y + dy
        inside_y = (gy >= 0) & (gy <= last_row)
        gy = dr.clip(gy, 0, last_row)
        oy = (dr.gather(Float64, row_pos, gy) - cy) * scale
        for dx in range(-1, 3):
            ox = oxs[dx + 1]
            index = gy * width + dr.clip(cell_x + dx, 0, last_col)
            use = inside_y & inside_x[dx + 1] & (dr.gather(UInt64, ids, index) == own_id)
            w = dr.select(use, dr.exp(-0.5 * (ox * ox + oy * oy)), 0.0)
            xs = [w, w * ox, w * ox * ox, w * ox * ox * ox, w * ox * ox * ox * ox]
            oyp = [Float64(1.0), oy, oy * oy, oy * oy * oy, oy * oy * oy * oy]
            for (i, j) in moments:
                moments[(i, j)] += xs[i] * oyp[j]
            for c in range(channels):
                v = dr.gather(Float64, values, index * depth + c)
                for b, (i, j) in enumerate(_POWERS):
                    rhs[b][c] += xs[i] * oyp[j] * v
                lowest[c] = dr.select(use, dr.minimum(lowest[c], v), lowest[c])
                highest[c] = dr.select(use, dr.maximum(highest[c], v), highest[c])

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
        out.extend(coeff)
    # an empty group keeps its unclamped zero (its pixels are filled elsewhere)
    lowest = [dr.select(empty, -np.inf, v) for v in lowest]
    highest = [dr.select(empty, np.inf, v) for v in highest]
    dr.eval(*out, *lowest, *highest)  # channel-major: coefficients of channel c are out[6c:6c + 6]
    group = aligned(Int32, member, np.int32)
    ox = (aligned(Float64, px, np.float64) - dr.gather(Float64, cx, group)) * scale
    oy = (aligned(Float64, py, np.float64) - dr.gather(Float64, cy, group)) * scale
    terms = [ox, oy, ox * ox, ox * oy, oy * oy]
    result = []
    for c in range(channels):
        coeff = out[6 * c:6 * c + 6]
        value = dr.gather(Float64, coeff[0], group)
        for b, term in enumerate(terms, start=1):
            value = dr.fma(term, dr.gather(Float64, coeff[b], group), value)
        value = dr.clip(value, dr.gather(Float64, lowest[c], group),
                        dr.gather(Float64, highest[c], group))
        result.append(Float32(value))
    dr.eval(*result)
    return np.stack([np.asarray(v) for v in result], axis=1)
