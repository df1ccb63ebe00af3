"""Within-region interpolation on the traced grid, shared by ``fast``,
``refine`` and ``idpass``.

The traced pixels form a tensor grid, so interpolation is gathers and
sparse products:

* Where a pixel's 4 x 4 stencil of traced pixels all carry the pixel's id,
  a separable cubic (4-point Lagrange along each axis, exact for cubics on
  the non-uniform grid) gives its value: two sparse products for the whole
  image.
* Near edges, a weighted quadric is fitted per grid cell and id through the
  samples *of that id* in the cell's 4 x 4 block, so interpolation never
  crosses an edge.

Radiance is interpolated directly when the albedo is constant within every
id (then demodulating by albedo changes nothing); otherwise irradiance
(radiance / albedo) and albedo are interpolated with the same weights.

The values are divided by a power of two per channel before the float32
work (:class:`GridValues`), fireflies are kept out of it, and every pixel
is clamped to the range of its id's samples in its 4 x 4 grid block
(:mod:`mitsuba_mrt.recon.bounds`); the image comes back in float64, with
the traced radiance exactly.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from ..runtime.threads import beside, for_row_blocks
from . import quadric_jit
from .bounds import (block_ranges, cell_row_runs, neighbourhood_ranges, power_of_two_scale,
                     suppress_fireflies)
from .compose import albedo_constant_per_id, division_albedo, radiance_channels
from .llvm_arrays import available
from .sampling import SamplePattern, cell_coordinates


def cubic_weights(positions: np.ndarray, length: int) -> tuple[np.ndarray, np.ndarray]:
    """4-point Lagrange weights along one axis of the grid, for every pixel.

    Returns ``first`` (length,), the index of the first of four consecutive
    grid positions around each pixel (shifted inwards at the grid's ends),
    and ``weights`` (length, 4); the interpolant is exact for cubics.

    Examples
    --------
    >>> first, w = cubic_weights(np.array([0, 3, 6, 9, 12]), 13)
    >>> x = np.array([0, 3, 6, 9, 12.0])
    >>> bool(np.allclose((w * x[first[:, None] + np.arange(4)] ** 3).sum(1), np.arange(13.0) ** 3))
    True
    """
    n = len(positions)
    if n < 4:
        raise ValueError("cubic weights need at least 4 grid positions")
    x = np.arange(length, dtype=np.float64)
    cell = np.clip(np.searchsorted(positions, x, side="right") - 1, 0, n - 2)
    first = np.clip(cell - 1, 0, n - 4)
    nodes = positions[first[:, None] + np.arange(4)].astype(np.float64)
    weights = np.ones((length, 4))
    for k in range(4):
        for j in range(4):
            if j != k:
                weights[:, k] *= (x - nodes[:, j]) / (nodes[:, k] - nodes[:, j])
    return first, weights


def _axis_matrix(positions: np.ndarray, length: int, dtype) -> sparse.csr_matrix:
    """(length, len(positions)) sparse matrix of 4-point Lagrange weights."""
    first, weights = cubic_weights(positions, length)
    columns = (first[:, None] + np.arange(4)).ravel()
    rows = np.repeat(np.arange(length), 4)
    return sparse.csr_matrix((weights.ravel().astype(dtype), (rows, columns)),
                             shape=(length, len(positions)))


def separable_cubic(pattern: SamplePattern, grid_values: np.ndarray) -> np.ndarray:
    """Cubic interpolation of ``grid_values`` (nr, nc, C) at every pixel.

    Two sparse products with four non-zeros a row: along the columns of
    every grid row, then along the rows (:func:`_cubic_rows`).
    """
    first, weights = cubic_weights(pattern.rows, pattern.height)
    return _cubic_rows(_axis_matrix(pattern.cols, pattern.width, grid_values.dtype),
                       grid_values.transpose(1, 0, 2), first,
                       weights.astype(grid_values.dtype))


def _uniform_blocks(grid_ids: np.ndarray, size: int) -> np.ndarray:
    """(nr - size + 1, nc - size + 1) bool: every size x size block of equal ids."""
    nr, nc = grid_ids.shape
    first = grid_ids[: nr - size + 1, : nc - size + 1]
    same = np.ones(first.shape, dtype=bool)
    for dy in range(size):
        for dx in range(size):
            if dy or dx:
                same &= grid_ids[dy: nr - size + 1 + dy, dx: nc - size + 1 + dx] == first
    return same


#: Ridge added to the quadric's normal equations, per term (1, x, y, xx, xy, yy),
#: relative to the total weight: a small pull of the slope and a stronger pull
#: of the curvature towards zero, so that sparse samples give a plane or a mean.
_RIDGE = np.array([1e-9, 1e-3, 1e-3, 3e-2, 3e-2, 3e-2])


def local_poly_fit(pattern: SamplePattern, grid_ids: np.ndarray, grid_values: np.ndarray,
                   py: np.ndarray, px: np.ndarray, own: np.ndarray,
                   use_jit: bool | None = None) -> np.ndarray:
    """Values at pixels (py, px) from a weighted quadric through same-id samples.

    One fit per (grid cell, id): the samples are the 4 x 4 grid block around
    the cell, weighted by a Gaussian of one grid spacing around the cell's
    centre, and only samples with the id count.  A quadric, not a weighted
    mean, so that gradients and curvature continue up to an edge instead of
    flattening; its values are clamped, per channel, to the range of those
    samples (a quadric overshoots where they are few).  Pixels whose block
    has no sample of their id take the value of the nearest sample of
    their id on the grid (:func:`nearest_of_same_id`).

    The pixels are grouped by (cell, id) first, so each quadric is fitted
    once (a cell holds about ``1 / sample_fraction`` pixels) and evaluated at
    its pixels.  With ``use_jit`` (default: when Dr.Jit's LLVM backend is
    usable) the fits run in one Dr.Jit kernel (:mod:`mitsuba_mrt.recon.quadric_jit`),
    otherwise as batched numpy solves; the tests hold the two together.
    """
    nr, nc = grid_ids.shape
    rows, cols = pattern.rows, pattern.cols
    spacing = max(pattern.height / max(nr - 1, 1), pattern.width / max(nc - 1, 1))
    cy, _ = cell_coordinates(rows, pattern.height)
    cx, _ = cell_coordinates(cols, pattern.width)
    cell_y, cell_x = cy[py], cx[px]
    slot = _matching_slot(grid_ids, cell_y, cell_x, own)
    # a (cell, slot) pair names a (cell, id) group; the slot search is canonical
    # (corners first, then the rest in a fixed order), so each group has one name
    groups, member = group_keys((cell_y * nc + cell_x) * 17 + (slot + 1), nr * nc * 17)
    group_cell, group_slot = np.divmod(groups, 17)
    gy0, gx0 = np.divmod(group_cell, nc)
    found = group_slot > 0
    gid = grid_ids[np.clip(gy0 + (group_slot - 1) // 4 - 1, 0, nr - 1),
                   np.clip(gx0 + (group_slot - 1) % 4 - 1, 0, nc - 1)]
    centre_y = 0.5 * (rows[gy0] + rows[np.minimum(gy0 + 1, nr - 1)])
    centre_x = 0.5 * (cols[gx0] + cols[np.minimum(gx0 + 1, nc - 1)])
    if use_jit is None:
        use_jit = available()
    if use_jit:  # clamped in the kernel
        values = quadric_jit.quadric_values_jit(
            rows, cols, grid_ids, grid_values, gy0, gx0, gid, centre_y, centre_x, spacing,
            _RIDGE, member, py, px)
    else:
        coeffs = quadric_coefficients(rows, cols, grid_ids, grid_values, gy0, gx0, gid,
                                      centre_y, centre_x, spacing, _RIDGE)
        ox = (px - centre_x[member]) / spacing
        oy = (py - centre_y[member]) / spacing
        values = coeffs[member, 0]
        for b, term in enumerate((ox, oy, ox * ox, ox * oy, oy * oy), start=1):
            values += term[:, None] * coeffs[member, b]
        lo, hi, _ = neighbourhood_ranges(grid_ids, grid_values, gy0, gx0, gid)
        lo[~found], hi[~found] = -np.inf, np.inf
        np.clip(values, lo[member], hi[member], out=values)
    lost = ~found[member]
    if lost.any():
        values[lost] = nearest_of_same_id(pattern, grid_ids, grid_values, py[lost], px[lost],
                                          own[lost])
    return values


def nearest_of_same_id(pattern: SamplePattern, grid_ids: np.ndarray, grid_values: np.ndarray,
                       py: np.ndarray, px: np.ndarray, own: np.ndarray) -> np.ndarray:
    """Values (m, C) of the grid sample of id ``own`` nearest to each pixel (py, px).

    One k-d tree over the samples of the wanted ids, in (column, row,
    rank x (height + width)): a sample of another id is always farther
    than any of the pixel's own, so the nearest is of the pixel's id.  A
    pixel of an id that no grid sample carries (an id found beyond the grid,
    such as a thin sliver traced by ``refine``) takes its nearest sample of
    any id, as its mode then decides (``refine`` replaces them, ``idpass``
    traces them).

    Examples
    --------
    >>> from mitsuba_mrt.recon.sampling import grid_pattern
    >>> p = grid_pattern(7, 1, 1.0)
    >>> ids = np.array([[1, 2, 2, 2, 2, 2, 1]]); values = np.arange(7.0).reshape(1, 7, 1)
    >>> nearest_of_same_id(p, ids, values, np.array([0, 0]), np.array([2, 5]),
    ...                    np.array([1, 1]))[:, 0].tolist()
    [0.0, 6.0]
    """
    nc = grid_ids.shape[1]
    flat_ids = grid_ids.ravel()
    wanted = np.unique(own)
    samples = np.flatnonzero(np.isin(flat_ids, wanted))
    labels = np.unique(flat_ids[samples])
    at = np.searchsorted(labels, own)
    has = at < len(labels)
    has[has] = labels[at[has]] == own[has]
    out = grid_values[pattern.nearest_rows[py], pattern.nearest_cols[px]]  # any id
    if has.any():
        gy, gx = np.divmod(samples, nc)
        step = float(pattern.height + pattern.width)
        rank = np.searchsorted(labels, flat_ids[samples])
        tree = cKDTree(np.column_stack([pattern.cols[gx], pattern.rows[gy], rank * step]))
        _, k = tree.query(np.column_stack([px[has], py[has], at[has] * step]))
        out[has] = grid_values[gy[k], gx[k]]
    return out


def group_keys(keys: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(keys, return_inverse=True)`` for integer keys in [0, size).

    With a table of ``size`` flags when that is not much larger than the
    keys (no sort), else with ``np.unique``.

    Examples
    --------
    >>> groups, member = group_keys(np.array([7, 2, 7, 5]), 10)
    >>> groups.tolist(), member.tolist()
    ([2, 5, 7], [2, 0, 2, 1])
    """
    keys = np.asarray(keys)
    if size > 16 * len(keys) + (1 << 20):
        groups, member = np.unique(keys, return_inverse=True)
        return groups, member.ravel()
    used = np.zeros(size, dtype=bool)
    used[keys] = True
    groups = np.flatnonzero(used)
    index = np.empty(size, dtype=np.intp)
    index[groups] = np.arange(len(groups))
    return groups, index[keys]


#: Order in which the 4 x 4 block (row-major slots 0..15) is searched for a
#: pixel's id: the cell's four corners first (slots 5, 6, 9, 10), as the
#: pixel's id is nearly always one of theirs.
_SLOT_ORDER = (5, 6, 9, 10, 0, 1, 2, 3, 4, 7, 8, 11, 12, 13, 14, 15)


def _matching_slot(grid_ids: np.ndarray, cell_y: np.ndarray, cell_x: np.ndarray,
                   own: np.ndarray) -> np.ndarray:
    """First slot (in ``_SLOT_ORDER``) of each cell's 4 x 4 block whose sample
    carries ``own``; -1 where none does.

    The grid is padded (one row and column before it, two after) with an id
    no pixel has, so every slot is one 1-D gather at a fixed offset.
    """
    nr, nc = grid_ids.shape
    missing = min(int(grid_ids.min()), int(own.min()) if len(own) else 0) - 1
    padded = np.full((nr + 3, nc + 3), missing, dtype=grid_ids.dtype)
    padded[1:nr + 1, 1:nc + 1] = grid_ids
    padded = padded.ravel()
    block = cell_y * (nc + 3) + cell_x  # padded index of each pixel's slot 0
    slot = np.full(len(own), -1, dtype=np.int64)
    todo = np.arange(len(own))
    for s in _SLOT_ORDER:
        if len(todo) == 0:
            break
        hit = padded.take(block[todo] + (s // 4) * (nc + 3) + s % 4) == own[todo]
        slot[todo[hit]] = s
        todo = todo[~hit]
    return slot


def quadric_coefficients(rows: np.ndarray, cols: np.ndarray, grid_ids: np.ndarray,
                         grid_values: np.ndarray, gy0: np.ndarray, gx0: np.ndarray,
                         gid: np.ndarray, centre_y: np.ndarray, centre_x: np.ndarray,
                         spacing: float, ridge: np.ndarray) -> np.ndarray:
    """Weighted quadric of each (cell, id) group, as batched numpy solves.

    Parameters
    ----------
    rows, cols : ndarray of int
        Traced grid lines (``pattern.rows``, ``pattern.cols``).
    grid_ids : ndarray of int64, shape (nr, nc)
    grid_values : ndarray, shape (nr, nc, C)
    gy0, gx0 : ndarray of int, shape (g,)
        Grid cell of each group (its block is cell - 1 .. cell + 2).
    gid : ndarray of int64, shape (g,)
        The group's id: only the block's samples with it count.
    centre_y, centre_x : ndarray of float, shape (g,)
        Centre of the group's cell, the origin of the quadric.
    spacing : float
        Grid spacing in pixels, the unit of the offsets.
    ridge : ndarray, shape (6,)
        Ridge per basis term, relative to the total weight.

    Returns
    -------
    ndarray of float64, shape (g, 6, C)
        Coefficients of 1, x, y, xx, xy, yy (offsets in grid spacings from
        the centre); zero for a group without any sample of its id.
    """
    nr, nc = grid_ids.shape
    g = len(gy0)
    offsets = np.arange(-1, 3)
    gy = (gy0[:, None] + offsets[None, :])[:, :, None]          # (g, 4, 1)
    gx = (gx0[:, None] + offsets[None, :])[:, None, :]          # (g, 1, 4)
    inside = (gy >= 0) & (gy < nr) & (gx >= 0) & (gx < nc)
    gy, gx = np.clip(gy, 0, nr - 1), np.clip(gx, 0, nc - 1)
    ox = ((cols[gx] - centre_x[:, None, None]) / spacing) * np.ones_like(gy)
    oy = ((rows[gy] - centre_y[:, None, None]) / spacing) * np.ones_like(gx)
    use = inside & (grid_ids[gy, gx] == gid[:, None, None])
    w = np.where(use, np.exp(-0.5 * (ox * ox + oy * oy)), 0.0).reshape(g, 16)
    ox, oy = ox.reshape(g, 16), oy.reshape(g, 16)
    basis = np.stack([np.ones_like(ox), ox, oy, ox * ox, ox * oy, oy * oy], axis=2)
    weighted = (basis * w[:, :, None]).transpose(0, 2, 1)        # (g, 6, 16)
    normal = weighted @ basis                                     # (g, 6, 6)
    rhs = weighted @ grid_values[gy, gx].reshape(g, 16, -1)       # (g, 6, C)
    total = normal[:, 0, 0].copy()  # a copy: the ridge below changes normal
    normal += (ridge[None, :] * (total[:, None] + 1e-300))[:, :, None] * np.eye(6)[None]
    empty = total <= 0.0
    normal[empty] = np.eye(6)
    rhs[empty] = 0.0
    return np.linalg.solve(normal, rhs)


@dataclass
class EarlyValues:
    """What :func:`interpolate_within_ids` can compute before the final pixel ids."""

    image: np.ndarray        # (height, width, C): the separable cubic
    stencil_ids: np.ndarray  # (height, width): the id all 16 cubic samples carry, else -1


def early_values(pattern: SamplePattern, grid_ids: np.ndarray,
                 grid_values: np.ndarray) -> EarlyValues:
    """The id-independent half of :func:`interpolate_within_ids`.

    The separable cubic at every pixel and, per pixel, the id all 16
    samples of its cubic stencil carry (-1 where they differ, and everywhere
    on a grid under 4 x 4, where there is no cubic).  The cubic is clamped,
    per channel, to the range of the 4 x 4 block of the pixel's cell
    (:func:`mitsuba_mrt.recon.bounds.block_ranges`): the Lagrange weights
    have negative lobes, and a pixel must stay within its samples.  Where
    the stencil carries one id the block (inside the stencil) does too;
    elsewhere the cubic is not used.
    """
    nr, nc = pattern.grid_shape
    if nr < 4 or nc < 4:
        image = np.zeros((pattern.height, pattern.width) + grid_values.shape[2:],
                         grid_values.dtype)
    else:  # (one block: the whole image)
        (_, _, image), = _clamped_cubic(pattern, grid_ids, grid_values, pattern.height)
    return EarlyValues(image, stencil_ids_of(pattern, grid_ids))


#: Image rows :func:`early_radiance` makes at a time: a block of them stays
#: in cache from the cubic's product to the radiance.
FUSED_ROWS = 64


def early_radiance(pattern: SamplePattern, grid_ids: np.ndarray,
                   grid: "GridValues") -> np.ndarray:
    """The radiance (:meth:`GridValues.radiance`) of :func:`early_values`'
    image, the same numbers, made :data:`FUSED_ROWS` rows at a time
    (:func:`_clamped_cubic`): no image-sized array but the radiance (a fresh
    process pays for every page it touches, and a block stays in cache from
    the products to the radiance)."""
    nr, nc = pattern.grid_shape
    if nr < 4 or nc < 4:  # no cubic: zeros
        return np.zeros((pattern.height, pattern.width, 3))
    out = np.empty((pattern.height, pattern.width, 3))
    tiled = grid.tiled_scale(pattern.width)
    for start, stop, block in _clamped_cubic(pattern, grid_ids, grid.values, FUSED_ROWS):
        grid.radiance_into(block, out[start:stop], tiled)
    return out


def _clamped_cubic(pattern: SamplePattern, grid_ids: np.ndarray, values: np.ndarray,
                   rows: int):
    """(start, stop, block): :func:`separable_cubic`'s image rows
    ``start:stop`` (n, width, C), at least ``rows`` of them at a time (whole
    grid cells), each made from the grid rows its stencils take and clamped,
    per channel, to the range of the 4 x 4 block of its cell
    (:func:`mitsuba_mrt.recon.bounds.block_ranges`); a grid of at least 4 x 4."""
    wx = _axis_matrix(pattern.cols, pattern.width, values.dtype)
    first, weights = cubic_weights(pattern.rows, pattern.height)
    weights = weights.astype(values.dtype)
    _, _, lo, hi = block_ranges(grid_ids, values)
    cy, _ = cell_coordinates(pattern.rows, pattern.height)
    cx, _ = cell_coordinates(pattern.cols, pattern.width)
    by_grid_column = values.transpose(1, 0, 2)  # (nc, nr, C), a view
    for start, stop, runs in _run_blocks(cy, rows):
        r0, r1 = first[start], first[stop - 1] + 4  # the grid rows the block's stencils take
        block = _cubic_rows(wx, by_grid_column[:, r0:r1], first[start:stop] - r0,
                            weights[start:stop])
        c0, c1 = runs[0][2], runs[-1][2] + 1  # the cells of the block's rows
        block_lo, block_hi = lo[c0:c1].take(cx, axis=1), hi[c0:c1].take(cx, axis=1)
        for begin, end, i in runs:  # the rows of one grid cell share a range
            _clamp(block[begin - start:end - start], block_lo[i - c0], block_hi[i - c0])
        yield start, stop, block


def _cubic_rows(wx: sparse.csr_matrix, columns: np.ndarray, first: np.ndarray,
                weights: np.ndarray) -> np.ndarray:
    """Rows of :func:`separable_cubic`'s image, (n, width, C), from the grid
    rows their stencils take, ``columns`` (nc, k, C): every value is the
    whole image's, the same products summed in the same order.  ``wx``: the
    columns' weights (:func:`_axis_matrix`); ``first`` (n,) and ``weights``
    (n, 4): each row's first grid row (of the k) and its weights."""
    nc, k, channels = columns.shape
    by_column = wx @ columns.reshape(nc, k * channels)
    by_row = np.ascontiguousarray(by_column.reshape(-1, k, channels).transpose(1, 0, 2))
    n = len(first)
    wy = sparse.csr_matrix((weights.ravel(), (first[:, None] + np.arange(4)).ravel(),
                            np.arange(0, 4 * n + 1, 4)), shape=(n, k))
    return (wy @ by_row.reshape(k, -1)).reshape(n, -1, channels)


def stencil_ids_of(pattern: SamplePattern, grid_ids: np.ndarray) -> np.ndarray:
    """(height, width): the id all 16 samples of a pixel's cubic stencil
    carry, else -1 (everywhere on a grid under 4 x 4, which has no cubic)."""
    nr, nc = pattern.grid_shape
    if nr < 4 or nc < 4:
        return np.full((pattern.height, pattern.width), -1, dtype=np.int64)
    fy, _ = cubic_weights(pattern.rows, pattern.height)
    fx, _ = cubic_weights(pattern.cols, pattern.width)
    stencil_id = np.where(_uniform_blocks(grid_ids, 4), grid_ids[: nr - 3, : nc - 3], -1)
    return stencil_id.take(fy, axis=0).take(fx, axis=1)  # two 1-D gathers


def _clamp(rows: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """``rows`` (k, width, C) clamped in place to ``lo`` and ``hi`` (width, C)
    (minimum and maximum: np.clip is several times slower)."""
    np.minimum(rows, hi, out=rows)
    np.maximum(rows, lo, out=rows)


def _run_blocks(cell: np.ndarray, rows: int):
    """The runs of :func:`~mitsuba_mrt.recon.bounds.cell_row_runs` in groups
    of at least ``rows`` image rows (the last may have fewer): (start, stop,
    the group's runs)."""
    group = []
    for run in cell_row_runs(cell):
        group.append(run)
        if run[1] - group[0][0] >= rows:
            yield group[0][0], run[1], group
            group = []
    if group:
        yield group[0][0], group[-1][1], group


def interpolate_within_ids(pattern: SamplePattern, grid_ids: np.ndarray,
                           grid_values: np.ndarray, id_map: np.ndarray,
                           constant: dict | None = None,
                           early: EarlyValues | None = None) -> tuple[np.ndarray, int]:
    """Interpolate grid values at every pixel from samples of the pixel's own id.

    Parameters
    ----------
    pattern : SamplePattern
    grid_ids : ndarray of int, shape pattern.grid_shape
    grid_values : ndarray, shape pattern.grid_shape + (C,)
    id_map : ndarray of int, shape (height, width)
    constant : dict, optional
        ``id -> value`` for ids known to be constant (e.g. a black
        background): their pixels near edges are filled, not fitted.
    early : EarlyValues, optional
        What :func:`early_values` returns for these grid ids and values, if
        the caller computed it already (it is written to).

    Returns
    -------
    values : ndarray, shape (height, width, C)
    edge_pixels : int
        Number of pixels fitted near edges (the rest used the cubic).
    """
    if early is None:
        early = early_values(pattern, grid_ids, grid_values)
    out = np.ascontiguousarray(early.image)  # (it is already: no copy)
    index, values, fitted = near_edge_values(pattern, grid_ids, grid_values, id_map,
                                             constant, early.stencil_ids)
    out.reshape(-1, out.shape[2])[index] = values  # a view, written through
    return out, fitted


def near_edge_values(pattern: SamplePattern, grid_ids: np.ndarray, grid_values: np.ndarray,
                     id_map: np.ndarray, constant: dict | None,
                     stencil_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The pixels whose cubic stencil is not all of their id (``stencil_ids``,
    :class:`EarlyValues`'): flat indices, values (m, C) and how many were
    fitted (the others are of a constant id)."""
    index = np.flatnonzero(stencil_ids != id_map)  # flat: cheaper than 2-D
    own = id_map.ravel()[index]
    values = np.empty((len(index), grid_values.shape[2]), dtype=grid_values.dtype)
    fit = np.ones(len(index), dtype=bool)
    for value, fill in (constant or {}).items():
        filled = own == value
        values[filled] = fill
        fit &= ~filled
    fit = np.flatnonzero(fit)
    if len(fit):
        py, px = np.divmod(index[fit], pattern.width)
        values[fit] = local_poly_fit(pattern, grid_ids, grid_values, py, px, own[fit])
    return index, values, len(fit)


#: Images of at least this many pixels are scaled back in row blocks on all cores.
PARALLEL_PIXELS = 1 << 18


@dataclass
class GridValues:
    """Values ready for the grid interpolators.

    ``values`` (grid shape + (C,), float32) are the samples' values divided
    by ``scale`` (C,), a power of two per channel above their largest
    magnitude (exact, and no float32 overflow whatever the data), with
    fireflies suppressed (:func:`mitsuba_mrt.recon.bounds.suppress_fireflies`);
    ``fireflies`` counts the samples that were.
    """

    values: np.ndarray
    scale: np.ndarray
    fireflies: int = 0

    @classmethod
    def from_samples(cls, pattern: SamplePattern, grid_ids: np.ndarray,
                     values: np.ndarray) -> "GridValues":
        """From per-sample values (count, C), any finite magnitude."""
        values = np.asarray(values, dtype=np.float64)
        scale = power_of_two_scale(values)
        grid = np.empty(values.shape, dtype=np.float32)
        for c in range(values.shape[1]):  # exact: 1 / scale is a power of two too
            np.multiply(values[:, c], 1.0 / scale[c], out=grid[:, c], casting="same_kind")
        grid = grid.reshape(pattern.grid_shape + (-1,))
        grid, fireflies = suppress_fireflies(grid_ids, grid)
        return cls(grid, scale, fireflies)

    def unscaled(self, interpolated: np.ndarray) -> np.ndarray:
        """float64 values (..., C) of interpolated scaled values."""
        return interpolated * self.scale  # float32 times float64: float64

    def radiance_of(self, values: np.ndarray) -> np.ndarray:
        """float64 radiance (m, 3) of scaled values (m, C), as :meth:`radiance`."""
        values = self.unscaled(values)
        return values if values.shape[-1] == 3 else values[:, :3] * values[:, 3:]

    def radiance(self, interpolated: np.ndarray) -> np.ndarray:
        """float64 radiance (height, width, 3) of interpolated scaled radiance
        (C = 3), or irradiance and albedo (C = 6); in row blocks on all cores
        (on one, called from a task of the pool itself)."""
        height, width, _ = interpolated.shape
        out = np.empty((height, width, 3))
        tiled = self.tiled_scale(width)

        def rows(start, stop):
            self.radiance_into(interpolated[start:stop], out[start:stop], tiled)

        for_row_blocks(rows, height, min_rows=max(1, PARALLEL_PIXELS // max(width, 1)))
        return out

    def tiled_scale(self, width: int) -> np.ndarray:
        """The radiance's scale (3,) tiled along a row of ``width`` pixels
        (numpy broadcasts a (3,) operand slowly)."""
        scale = self.scale if len(self.scale) == 3 else self.scale[:3] * self.scale[3:]
        return np.tile(scale, width)

    @staticmethod
    def radiance_into(block: np.ndarray, out: np.ndarray, tiled: np.ndarray) -> None:
        """:meth:`radiance` of the rows ``block`` (k, width, C) into ``out``
        (k, width, 3), float64; ``tiled``: :meth:`tiled_scale`."""
        flat = out.reshape(len(out), -1)
        if block.shape[2] == 3:
            np.multiply(block.reshape(len(block), -1), tiled, out=flat)
        else:  # irradiance times albedo, multiplied in float64
            np.multiply(block[..., :3], block[..., 3:], out=out, dtype=np.float64)
            flat *= tiled


@dataclass
class TracedGridValues:
    """Within-id interpolation of the traced grid, in two halves.

    :meth:`start` launches, on a worker thread, all that needs no final
    pixel ids: the radiance to interpolate, where it is to be made first
    (a mode's smoothing of the grid), the values to interpolate
    (:class:`EarlyGrid`, handed over as soon as they are chosen), then
    :func:`early_radiance` on them, the cubic's float64 radiance; a caller
    finds the ids meanwhile, and :meth:`finish` takes them and fits the
    pixels near edges while the cubic goes on.
    Radiance is interpolated directly when albedo is constant within every
    id; otherwise irradiance (radiance / albedo) and albedo are, with the
    same weights, and multiplied back.  A black background is filled, and
    traced pixels keep their traced radiance (the image is float64).
    """

    pattern: SamplePattern
    radiance: np.ndarray  # (n, 3) traced radiance, grid order
    grid_ids: np.ndarray  # sample ids (or their ranks), shape pattern.grid_shape
    grid: Future          # of the EarlyGrid, set before the cubic starts
    early: Future         # of _values_and_early(...): the cubic's radiance

    @classmethod
    def start(cls, pattern: SamplePattern, radiance: np.ndarray, albedo: np.ndarray,
              sample_ids: np.ndarray, background: int = 0,
              albedo_constant: bool = False,
              interpolated: np.ndarray | Callable[[], np.ndarray] | None = None
              ) -> "TracedGridValues":
        """Launch the id-independent half; ``background`` is the id (or rank)
        of the background in ``sample_ids``, -1 if none; ``albedo_constant``
        says every id's albedo is one colour whatever the samples say (those
        straddling two surfaces mix theirs); ``interpolated``: the radiance
        (n, 3) to interpolate where it is not ``radiance`` (the traced
        pixels keep ``radiance``), or a function that makes it, called
        first on the worker."""
        grid = Future()
        return cls(pattern, radiance, sample_ids.reshape(pattern.grid_shape), grid,
                   beside(_values_and_early, pattern,
                          radiance if interpolated is None else interpolated, albedo,
                          sample_ids, background, albedo_constant, grid))

    def finish(self, id_map: np.ndarray) -> tuple[np.ndarray, Counter]:
        """Radiance (height, width, 3), float64, with every pixel's values from
        its own id, and counts: ``albedo_division`` and ``background``
        (shortcuts taken), ``edge_pixels`` (pixels fitted near edges),
        ``fireflies`` (samples kept out of the interpolation)."""
        early = self.grid.result()
        # the pixels near edges, fitted while the cubic's radiance is made
        index, values, edge_pixels = near_edge_values(
            self.pattern, self.grid_ids, early.grid.values, id_map, early.constant,
            early.stencil_ids)
        values = early.grid.radiance_of(values)
        image = self.early.result()
        image.reshape(-1, 3)[index] = values
        self.pattern.put_traced(image, self.radiance)
        counts = early.counts
        counts["edge_pixels"] = int(edge_pixels)
        return image, counts


class EarlyGrid(NamedTuple):
    """What :class:`TracedGridValues` hands over before its cubic: the grid
    values to interpolate, the ids known constant (:func:`black_background`),
    the shortcut counts, the stencil ids (:func:`stencil_ids_of`) and the
    radiance interpolated (n, 3)."""

    grid: GridValues
    constant: dict
    counts: Counter
    stencil_ids: np.ndarray
    radiance: np.ndarray


def _values_and_early(pattern: SamplePattern,
                      radiance: np.ndarray | Callable[[], np.ndarray], albedo: np.ndarray,
                      sample_ids: np.ndarray, background: int, albedo_constant: bool,
                      handed: Future) -> np.ndarray:
    """Set ``handed`` to the :class:`EarlyGrid` (the values to interpolate:
    :class:`GridValues` of ``radiance``, made first where it is a function,
    or of irradiance and albedo where the albedo varies within an id), then
    return :func:`early_radiance` of them."""
    try:
        radiance = radiance() if callable(radiance) else radiance
        counts = Counter()
        constant = black_background(sample_ids, radiance, counts, background)
        if not albedo_constant:
            _, inverse, plain = radiance_channels(sample_ids, albedo, radiance)
            albedo = division_albedo(albedo, plain[inverse])
            albedo_constant = albedo_constant_per_id(sample_ids, albedo)
        if albedo_constant:
            counts["albedo_division"] += 1
            values = radiance
        else:
            values = np.concatenate([radiance / albedo, albedo], axis=1)
        grid_ids = sample_ids.reshape(pattern.grid_shape)
        grid = GridValues.from_samples(pattern, grid_ids, values)
        counts["fireflies"] = grid.fireflies
        handed.set_result(EarlyGrid(grid, constant, counts, stencil_ids_of(pattern, grid_ids),
                                    radiance))
    except BaseException as error:  # (the caller waits on it first)
        handed.set_exception(error)
        raise
    return early_radiance(pattern, grid_ids, grid)


def black_background(sample_ids: np.ndarray, radiance: np.ndarray, counts: Counter,
                     background: int = 0) -> dict:
    """``{background: 0.0}`` when every sample of the ``background`` id is
    black (it is then filled, never interpolated; ``counts["background"]``
    counts it), else ``{}``."""
    seen = sample_ids == background
    if seen.any() and not radiance[seen].any():
        counts["background"] += 1
        return {background: 0.0}
    return {}

