"""Fast evaluation of ``sum_j w_j |x - c_j|`` on integer pixel grids.

:class:`mitsuba_mrt.recon.rbf.LinearRBF` evaluates its interpolant densely, which
costs O(points x centres).  When both the centres and the evaluation points
are integer 2-D coordinates (pixels), :func:`grid_distance_sum` computes the
same sum in roughly O(points + centres + FFT of a coarse grid):

* far field: every centre is spread onto a coarse grid of spacing ``h`` with
  ``q``-point tensor-product Lagrange weights, the coarse charges are
  convolved with the exact kernel ``h |g - g'|`` by a zero-padded FFT, and the
  coarse potential is interpolated back to the pixels with the same Lagrange
  weights.  Away from a centre ``|x - c|`` is smooth and the two-sided
  interpolation is accurate (its error decays like ``(h / |x - c|)**q``);
* near field: within ``radius`` coarse cells of a centre the interpolation
  error is large, so it is removed exactly.  Because centres and pixels are
  integers, the error ``|x - c| - K_h(x, c)`` of the interpolated kernel only
  depends on the cell offset and on the residues of ``x`` and ``c`` modulo
  ``h``: it is tabulated once, and the correction for all (centre, cell)
  pairs is one sparse-times-dense product.

What remains is the interpolation error of the centres more than ``radius``
cells away: below ``4e-4`` pixels per unit weight for the defaults, and
decaying like ``|x - c|**(1 - q)``.  On the MRT's regions the result is
within about ``1e-5`` of the largest value (the MRT needs ``1e-4``).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.fft
import scipy.linalg
import scipy.sparse

from ..errors import MRTError

#: Spacing of the coarse grid in pixels.
CELL = 4
#: Points per axis of the Lagrange interpolation (even).
ORDER = 6
#: Coarse cells (Chebyshev distance) around a centre that are corrected exactly.
NEAR_CELLS = 5
#: Threads of the FFTs (scipy.fft ``workers``; -1: all CPUs).
WORKERS = -1
#: Largest |coordinate| handled; beyond it the dense path is used.
MAX_COORDINATE = 2 ** 31
#: Cost model, nanoseconds: dense evaluation per (point, centre) pair ...
DENSE_NS = 5.0
#: ... and for the fast one: per FFT grid point and transform, per near
#: (centre, cell) pair and channel, per point and channel, per coarse cell of
#: the points' bounding box, and fixed.
FFT_NS, NEAR_NS, POINT_NS, CELL_NS, FIXED_NS = 8.0, 12.0, 25.0, 10.0, 1.5e6
#: Singular values of the weights below this fraction of the largest are
#: dropped: such channels are linear combinations of the others.
RANK_RTOL = 1e-13


def _lagrange_weights(h: int, q: int) -> np.ndarray:
    """Weights ``(h, q)`` of nodes ``-q/2+1 .. q/2`` at fractions ``r / h``."""
    t = np.arange(h) / h
    nodes = np.arange(-q // 2 + 1, q // 2 + 1)
    weights = np.ones((h, q))
    for a, node in enumerate(nodes):
        for other in nodes:
            if other != node:
                weights[:, a] *= (t - other) / (node - other)
    return weights


@lru_cache(maxsize=8)
def _tensor_weights(h: int, q: int) -> np.ndarray:
    """``(q * q, h * h)`` weights of the nodes ``(a0, a1)`` at pixels ``(r0, r1)``."""
    lag = _lagrange_weights(h, q)
    weights = np.einsum("xa,yb->abxy", lag, lag).reshape(q * q, h * h)
    weights.setflags(write=False)
    return weights


@lru_cache(maxsize=8)
def _near_table(h: int, q: int, radius: int) -> np.ndarray:
    """Exact minus interpolated kernel for nearby (centre, cell) pairs.

    Returns an array ``((2R+1)**2 * h * h, h * h)``: rows ``(d0, d1, rc0,
    rc1)`` are the cell offset ``d = X - C`` (target cell minus centre cell)
    and the centre's residues ``rc`` modulo ``h``, columns ``(r0, r1)`` the
    pixel's residues.
    """
    lag = _lagrange_weights(h, q)
    span = 2 * q - 1
    # pair[r, rc, u]: weight of coarse offset u = ja - jb (+ q - 1)
    pair = np.zeros((h, h, span))
    for a in range(q):
        for b in range(q):
            pair[:, :, a - b + q - 1] += lag[:, None, a] * lag[None, :, b]
    reach = radius + q - 1
    u = np.arange(-reach, reach + 1)
    coarse = h * np.hypot(u[:, None], u[None, :])
    windows = np.lib.stride_tricks.sliding_window_view(coarse, (span, span))
    interp = np.einsum("ijuv,xau,ybv->ijabxy", windows, pair, pair, optimize=True)
    d = np.arange(-radius, radius + 1)
    res = np.arange(h)
    # offset x - c = h d + r - rc along each axis, indexed [d, rc, r]
    off = h * d[:, None, None] + res[None, None, :] - res[None, :, None]
    exact = np.hypot(off[:, None, :, None, :, None], off[None, :, None, :, None, :])
    table = exact - interp
    table.setflags(write=False)
    return table.reshape(-1, h * h)


def pays_off(centres: np.ndarray, k: int, lo, hi, m: int,
             h: int = CELL, q: int = ORDER, radius: int = NEAR_CELLS) -> bool:
    """Whether :func:`grid_distance_sum` should beat the dense evaluation.

    Parameters
    ----------
    centres : ndarray of int, shape (n, 2)
        Source positions.
    k : int
        Number of channels.
    lo, hi : array_like, shape (2,)
        Bounding box of the ``m`` evaluation points.
    m : int
        Number of evaluation points.
    h, q, radius : int
        As in :func:`grid_distance_sum`.

    Returns
    -------
    bool

    Examples
    --------
    >>> c = np.array([[0, 0], [9, 9]])
    >>> pays_off(c, 1, [0, 0], [9, 9], 100)
    False
    """
    return fast_cost(centres, k, lo, hi, m, h, q, radius) < DENSE_NS * m * len(centres)


def fast_cost(centres: np.ndarray, k: int, lo, hi, m: int,
              h: int = CELL, q: int = ORDER, radius: int = NEAR_CELLS) -> float:
    """Modelled nanoseconds of :func:`grid_distance_sum`; see :func:`pays_off`."""
    cells = (np.asarray(hi, dtype=np.float64) - lo) // h + 1
    span = (centres.max(axis=0) - centres.min(axis=0)) // h + 1
    fft_points = float(np.prod(cells + span + 2 * q - 2))
    return (FFT_NS * (1 + 2 * k) * fft_points + NEAR_NS * k * len(centres) * (2 * radius + 1) ** 2
            + POINT_NS * k * m + CELL_NS * float(np.prod(cells)) + FIXED_NS)


def grid_distance_sum(centres: np.ndarray, weights: np.ndarray, points: np.ndarray,
                      h: int = CELL, q: int = ORDER, radius: int = NEAR_CELLS) -> np.ndarray:
    """``sum_j weights[j] * |points[i] - centres[j]|`` for integer 2-D points.

    Parameters
    ----------
    centres : ndarray of int, shape (n, 2)
        Source positions (pixel coordinates).
    weights : ndarray of float, shape (n, k)
        Source weights, ``k`` channels.
    points : ndarray of int, shape (m, 2)
        Evaluation positions (pixel coordinates), at least one.
    h, q, radius : int
        Coarse grid spacing (a power of two), Lagrange order (even) and the
        near-field radius in cells; see the module docstring.

    Returns
    -------
    ndarray, shape (m, k)

    Examples
    --------
    >>> c = np.array([[0, 0], [40, 3]]); w = np.array([[1.0], [-2.0]])
    >>> x = np.array([[10, 10], [50, 60]])
    >>> exact = (np.hypot(*(x[:, None] - c[None]).transpose(2, 0, 1)) @ w)[:, 0]
    >>> bool(np.allclose(grid_distance_sum(c, w, x)[:, 0], exact))
    True
    """
    centres = np.asarray(centres, dtype=np.int64)
    points = np.asarray(points, dtype=np.int64)
    weights = np.asarray(weights, dtype=np.float64)
    if centres.ndim != 2 or centres.shape[1] != 2 or len(centres) == 0:
        raise MRTError(f"centres must be a non-empty (n, 2) array, got shape {centres.shape}")
    if points.ndim != 2 or points.shape[1] != 2 or len(points) == 0:
        raise MRTError(f"points must be a non-empty (m, 2) array, got shape {points.shape}")
    if weights.ndim != 2 or len(weights) != len(centres) or weights.shape[1] == 0:
        raise MRTError(f"weights must be an ({len(centres)}, k) array, got shape {weights.shape}")
    if h < 1 or h & (h - 1) or q < 2 or q % 2 or radius < 0:
        raise MRTError(f"need h a power of two, q even and radius >= 0, got {h}, {q}, {radius}")
    # Channels that are combinations of others (grey data) are summed once.
    basis, sing, mix = np.linalg.svd(weights, full_matrices=False)
    rank = max(1, int(np.count_nonzero(sing > RANK_RTOL * sing[0])))
    if rank < weights.shape[1]:
        reduced = _distance_sum(centres, basis[:, :rank] * sing[:rank], points, h, q, radius)
        return reduced @ mix[:rank]
    return _distance_sum(centres, weights, points, h, q, radius)


def _distance_sum(centres, weights, points, h, q, radius):
    """Body of :func:`grid_distance_sum` for validated arrays."""
    k = weights.shape[1]
    shift = h.bit_length() - 1
    # --- target cells: the h x h pixel blocks that hold points -------------
    # (column reductions: min(axis=0) of an (m, 2) array is ten times slower)
    origin = np.array([points[:, 0].min(), points[:, 1].min()])
    x0 = points[:, 0] - origin[0]
    x1 = points[:, 1] - origin[1]
    ncell = np.array([x0.max(), x1.max()]) // h + 1
    key = (x0 >> shift) * ncell[1] + (x1 >> shift)
    active = np.zeros(ncell[0] * ncell[1], dtype=bool)
    active[key] = True
    act_keys = np.flatnonzero(active)
    lookup = np.full(len(active), -1, dtype=np.int64)
    lookup[act_keys] = np.arange(len(act_keys))
    # index of every point in blocks of layout (cell, r0, r1)
    at = (lookup[key] << (2 * shift)) + ((x0 & (h - 1)) << shift) + (x1 & (h - 1))
    del x0, x1, key
    crel = centres - origin
    ccell, cres = crel >> shift, crel & (h - 1)

    blocks = _far_field(ccell, cres, weights, ncell, act_keys, h, q)
    blocks += _near_field(ccell, cres, weights, ncell, lookup, len(act_keys), h, q, radius)
    out = np.empty((len(points), k))
    for ch in range(k):
        out[:, ch] = blocks[ch].ravel()[at]
    return out


def _far_field(ccell, cres, weights, ncell, act_keys, h, q):
    """Interpolated coarse-grid potential, ``(k, cells, h * h)``.

    ``ccell`` and ``cres`` are the centres' cells and residues relative to the
    points' origin, ``ncell`` the points' cell grid and ``act_keys`` the flat
    indices of its active cells.
    """
    k = weights.shape[1]
    half = q // 2 - 1
    lag = _lagrange_weights(h, q)
    # spread the weights on the source nodes s_lo .. s_lo + s_size - 1
    s_lo = ccell.min(axis=0) - half
    s_size = ccell.max(axis=0) + q // 2 - s_lo + 1
    t_size = ncell + q - 1                     # target nodes -half .. ncell-1+q/2
    node = np.arange(q) - half
    flat = (((ccell[:, 0, None] + node - s_lo[0]) * s_size[1])[:, :, None]
            + (ccell[:, 1, None] + node - s_lo[1])[:, None, :]).ravel()
    spread = (lag[cres[:, 0]][:, :, None] * lag[cres[:, 1]][:, None, :]).reshape(len(ccell), -1)
    charges = np.empty((k, s_size[0], s_size[1]))
    for ch in range(k):
        charges[ch] = np.bincount(flat, (spread * weights[:, ch, None]).ravel(),
                                  minlength=s_size[0] * s_size[1]).reshape(s_size)
    # kernel h |t - s| on the offsets from (t_lo - s_hi) to (t_hi - s_lo)
    length = s_size + t_size - 1
    first = -half - (s_lo + s_size - 1)
    u0 = (np.arange(length[0]) + first[0]) * float(h)
    u1 = (np.arange(length[1]) + first[1]) * float(h)
    kernel = np.add.outer(u0 * u0, u1 * u1)
    np.sqrt(kernel, out=kernel)
    shape = [scipy.fft.next_fast_len(int(n), real=True) for n in length]
    # 2-D real FFTs axis by axis, skipping the rows that are only padding
    spec = scipy.fft.fft(scipy.fft.rfft(charges, n=shape[1], axis=2, workers=WORKERS),
                         n=shape[0], axis=1, workers=WORKERS)
    spec *= scipy.fft.rfft2(kernel, s=shape, workers=WORKERS)
    # target node t - t_lo sits at index t - t_lo + s_size - 1 of the product
    spec = scipy.fft.ifft(spec, axis=1, workers=WORKERS)[:, s_size[0] - 1:s_size[0] - 1 + t_size[0]]
    field = scipy.fft.irfft(spec, n=shape[1], axis=2, workers=WORKERS).reshape(k, -1)
    del spec
    # a q x q patch of coarse nodes per active cell, times the tensor weights
    node = np.arange(q)
    patch = (node[:, None] * shape[1] + node[None, :] + s_size[1] - 1).ravel()
    patch = (act_keys // ncell[1] * shape[1] + act_keys % ncell[1])[:, None] + patch
    tensor = _tensor_weights(h, q)
    # (patch @ tensor)' = tensor' @ patch': Fortran views, so scipy's BLAS copies
    # nothing; numpy's matmul would wake numpy's own BLAS threads, which then
    # compete for the cores with scipy's, still spinning after the RBF solves
    return np.stack([scipy.linalg.blas.dgemm(1.0, tensor.T, field[ch][patch].T).T
                     for ch in range(k)])


def _near_field(ccell, cres, weights, ncell, lookup, nact, h, q, radius):
    """Exact near-field correction, ``(k, cells, h * h)``.

    ``lookup`` maps the flat cells of the points' grid to the ``nact`` active
    ones (-1: inactive).  A sparse (cell, table row) matrix in CSC form per
    channel multiplies the table of :func:`_near_table`.  The (centre, cell) pairs are generated
    offset by offset over the centres sorted by residue class (then by cell,
    for locality), so the table row (offset, residue) never decreases and
    nothing needs sorting.
    """
    k = weights.shape[1]
    side = 2 * radius + 1
    near = np.flatnonzero(np.all((ccell >= -radius) & (ccell < ncell + radius), axis=1))
    rc_key = cres[near, 0] * h + cres[near, 1]
    order = near[np.lexsort((ccell[near, 1], ccell[near, 0], rc_key))]
    rc_key = cres[order, 0] * h + cres[order, 1]
    # cells padded by 2 radius on every side, so no bounds checks are needed
    pad = 2 * radius
    wide = ncell[1] + 2 * pad
    padded = np.full((ncell[0] + 2 * pad, wide), -1, dtype=np.int64)
    padded[pad:pad + ncell[0], pad:pad + ncell[1]] = lookup.reshape(ncell)
    base = (ccell[order, 0] + pad) * wide + ccell[order, 1] + pad
    offsets = (np.arange(-radius, radius + 1)[:, None] * wide
               + np.arange(-radius, radius + 1)[None, :]).ravel()
    target = padded.ravel()[offsets[:, None] + base[None, :]]      # (side^2, n)
    valid = target >= 0
    rows = target[valid]
    src = np.broadcast_to(order, target.shape)[valid]
    # nonzeros per (offset, residue class): classes are runs of the sorted rc_key
    cls, starts = np.unique(rc_key, return_index=True)
    counts = np.zeros((side * side, h * h), dtype=np.int64)
    if len(order):
        counts[:, cls] = np.add.reduceat(valid, starts, axis=1)
    indptr = np.zeros(side * side * h * h + 1, dtype=np.int64)
    np.cumsum(counts.ravel(), out=indptr[1:])
    table = _near_table(h, q, radius)
    out = np.empty((k, nact, h * h))
    for ch in range(k):
        mat = scipy.sparse.csc_array((weights[:, ch][src], rows, indptr), shape=(nact, len(table)))
        out[ch] = mat @ table
    return out
