"""Stage 3: the report's edge finder (quadtree id fill + Gaussian smoothing).

Both functions work on plain numpy arrays.  The traced pixels form the
tensor grid of a :class:`~mitsuba_mrt.recon.sampling.SamplePattern`, so the known
pixels inside any rectangle are a sub-block of the grid, found by two
``searchsorted`` calls, and the known pixel nearest to a point is found one
axis at a time (Euclidean distance on a tensor grid is separable), from the
pattern's ``nearest_rows`` and ``nearest_cols``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..errors import MRTError
from .sampling import SamplePattern
from ..runtime.threads import for_row_blocks_of


def quadtree_fill(pattern: SamplePattern, grid_ids: np.ndarray) -> np.ndarray:
    """Assign an id to every pixel from the traced grid (report Algorithm 2, 1-7).

    The image is split into four rectangles (two when one side is a single
    pixel).  A rectangle whose known ids are all equal is filled with that
    id; one with differing ids is split again, down to single pixels.  A
    rectangle with no known pixel takes the id of the known pixel of its
    parent that lies nearest to its outer corner (the corner it shares with
    the parent).

    A rectangle of ``[r0, r1) x [c0, c1)`` is split at row
    ``(r0 + r1) // 2`` (not at all if ``r1 - r0 == 1``) and likewise at a
    column.  As the split of an interval depends only on the interval, the
    rectangles at depth ``k`` of the recursion are all cells of one tensor
    grid (the depth-``k`` row intervals x the depth-``k`` column intervals),
    so the recursion runs one depth at a time over all its live rectangles
    at once, with numpy.

    Parameters
    ----------
    pattern : SamplePattern
        The traced grid.
    grid_ids : ndarray, shape pattern.grid_shape
        Integer id of each traced pixel.

    Returns
    -------
    ndarray of int64, shape (height, width)

    Examples
    --------
    >>> from mitsuba_mrt.recon.sampling import SamplePattern
    >>> p = SamplePattern(4, 4, np.array([0, 3]), np.array([0, 3]))
    >>> int(quadtree_fill(p, np.array([[1, 1], [1, 1]]))[2, 1])
    1
    """
    grid_ids = np.asarray(grid_ids, dtype=np.int64)
    if grid_ids.shape != pattern.grid_shape:
        raise MRTError(f"grid_ids has shape {grid_ids.shape}, "
                       f"expected {pattern.grid_shape}")
    if grid_ids.size == 0:
        raise MRTError("the pattern has no traced pixel")
    # depths until every rectangle is a single pixel: an interval of size
    # s > 1 splits into sizes floor(s / 2) and ceil(s / 2)
    depth = max(pattern.height - 1, pattern.width - 1).bit_length() + 1
    row_levels = _interval_levels(pattern.height, pattern.rows, pattern.nearest_rows, depth)
    col_levels = _interval_levels(pattern.width, pattern.cols, pattern.nearest_cols, depth)

    # summed-area tables of "differs from the grid pixel to the right" and
    # "differs from the grid pixel below", with a leading row and column of
    # zeros: a block is uniform iff both counts inside it are zero
    right = np.zeros((grid_ids.shape[0] + 1, grid_ids.shape[1]), dtype=np.int64)
    np.cumsum(grid_ids[:, 1:] != grid_ids[:, :-1], axis=0, out=right[1:, 1:])
    np.cumsum(right[1:, 1:], axis=1, out=right[1:, 1:])
    below = np.zeros((grid_ids.shape[0], grid_ids.shape[1] + 1), dtype=np.int64)
    np.cumsum(grid_ids[1:] != grid_ids[:-1], axis=0, out=below[1:, 1:])
    np.cumsum(below[1:, 1:], axis=1, out=below[1:, 1:])

    # values[a, b]: id of the cell (row interval a, column interval b) of the
    # current depth, valid where the cell or one of its ancestors is finished
    values = np.zeros((1, 1), dtype=np.int64)
    live_a = live_b = np.zeros(1, dtype=np.intp)  # cells still to be tested
    empty_a = empty_b = np.zeros(0, dtype=np.intp)  # cells without a grid pixel
    for k in range(depth):
        rl, cl = row_levels[k], col_levels[k]
        if k > 0:
            # a finished parent's id covers its children; then paint the
            # children of split parents that hold no grid pixel
            values = values.take(cl.parent, axis=1).take(rl.parent, axis=0)
            values[empty_a, empty_b] = grid_ids[rl.fill_index[empty_a], cl.fill_index[empty_b]]
        # test the live cells: all ids in their grid block equal?
        i0, i1 = rl.grid_start[live_a], rl.grid_start[live_a + 1]
        j0, j1 = cl.grid_start[live_b], cl.grid_start[live_b + 1]
        n_differ = (right[i1, j1 - 1] - right[i0, j1 - 1] - right[i1, j0] + right[i0, j0]
                    + below[i1 - 1, j1] - below[i0, j1] - below[i1 - 1, j0] + below[i0, j0])
        uniform = n_differ == 0
        values[live_a[uniform], live_b[uniform]] = grid_ids[i0[uniform], j0[uniform]]
        split_a, split_b = live_a[~uniform], live_b[~uniform]
        if len(split_a) == 0:
            break
        # the (up to) four children of each split cell, at depth k + 1
        rl_next, cl_next = row_levels[k + 1], col_levels[k + 1]
        child_a, child_b = [], []
        for da in (0, 1):
            for db in (0, 1):
                exists = (da < rl.n_children[split_a]) & (db < cl.n_children[split_b])
                child_a.append(rl.first_child[split_a[exists]] + da)
                child_b.append(cl.first_child[split_b[exists]] + db)
        child_a, child_b = np.concatenate(child_a), np.concatenate(child_b)
        has_grid = rl_next.has_lines[child_a] & cl_next.has_lines[child_b]
        live_a, live_b = child_a[has_grid], child_b[has_grid]
        empty_a, empty_b = child_a[~has_grid], child_b[~has_grid]
    # expand the cells of the last depth reached to pixels
    if values.shape != (pattern.height, pattern.width):
        row_cell = np.repeat(np.arange(len(rl.has_lines)), np.diff(rl.bounds))
        col_cell = np.repeat(np.arange(len(cl.has_lines)), np.diff(cl.bounds))
        values = values.take(col_cell, axis=1).take(row_cell, axis=0)
    return values


@dataclass(frozen=True)
class _IntervalLevel:
    """One depth of the 1-D subdivision of an image axis (see quadtree_fill).

    Attributes
    ----------
    bounds : ndarray of int64, shape (n + 1,)
        The n intervals are ``[bounds[a], bounds[a + 1])``.
    grid_start : ndarray of intp, shape (n + 1,)
        Interval a holds the grid lines ``grid_start[a] : grid_start[a + 1]``.
    has_lines : ndarray of bool, shape (n,)
        Whether the interval holds a grid line.
    parent : ndarray of intp, shape (n,)
        Index of the interval's parent at the previous depth (0 at depth 0).
    fill_index : ndarray of intp, shape (n,)
        Grid line nearest to the interval's outer corner (its parent's first
        pixel for a first child, else the parent's last pixel), clipped into
        the parent's grid lines; meaningless at depth 0 and where the parent
        holds no grid line.
    n_children : ndarray of intp, shape (n,)
        2 where the interval is split at the next depth, else 1.
    first_child : ndarray of intp, shape (n,)
        Index of the interval's first child at the next depth.
    """

    bounds: np.ndarray
    grid_start: np.ndarray
    has_lines: np.ndarray
    parent: np.ndarray
    fill_index: np.ndarray
    n_children: np.ndarray
    first_child: np.ndarray


def _interval_levels(length: int, lines: np.ndarray, nearest: np.ndarray,
                     depth: int) -> list[_IntervalLevel]:
    """Subdivide ``[0, length)`` by halving, as quadtree_fill does.

    Parameters
    ----------
    length : int
        Image size along the axis.
    lines : ndarray of int, sorted
        Grid lines (``pattern.rows`` or ``pattern.cols``).
    nearest : ndarray of int, shape (length,)
        Index into ``lines`` of the line nearest to each pixel.
    depth : int
        Number of levels to return; levels past the one where every interval
        is a single pixel repeat it (each interval is its own only child).

    Returns
    -------
    list of _IntervalLevel
        Depth 0 (the whole axis) to ``depth - 1``.
    """
    levels = []
    bounds = np.array([0, length], dtype=np.int64)
    parent = fill_index = np.zeros(1, dtype=np.intp)
    for _ in range(depth):
        grid_start = np.searchsorted(lines, bounds)
        is_split = np.diff(bounds) > 1
        n_children = np.where(is_split, 2, 1).astype(np.intp)
        first_child = np.cumsum(n_children) - n_children
        levels.append(_IntervalLevel(bounds, grid_start, grid_start[1:] > grid_start[:-1],
                                     parent, fill_index, n_children, first_child))
        # children: a split interval [r0, r1) gives [r0, rm) and [rm, r1),
        # rm = (r0 + r1) // 2; the second child's outer corner is r1 - 1
        split = np.flatnonzero(is_split)
        parent = np.repeat(np.arange(len(is_split)), n_children)
        is_first = np.ones(len(parent), dtype=bool)
        is_first[first_child[split] + 1] = False
        corner = np.where(is_first, bounds[parent], bounds[parent + 1] - 1)
        fill_index = np.minimum(np.maximum(nearest[corner], grid_start[parent]),
                                grid_start[parent + 1] - 1)
        bounds = np.insert(bounds, split + 1, (bounds[split] + bounds[split + 1]) // 2)
    return levels


def region_boxes(pattern: SamplePattern, grid_ids: np.ndarray) -> dict:
    """Pixel bounding box (r0, r1, c0, c1) of each id, for :func:`smooth_ids`.

    Holds for the nearest-sample fill (:meth:`SamplePattern.nearest_image`):
    it gives a pixel an id only from a traced pixel of that id on a grid
    line next to it, so an id's pixels lie between the grid lines on either
    side of its outermost samples, and the box reaches one grid line beyond
    them.  Not for :func:`quadtree_fill`, which fills an empty rectangle
    from the sample nearest to its parent's corner, however far that is:
    use :func:`id_boxes` there.
    """
    nr, nc = grid_ids.shape
    flat = grid_ids.ravel()
    order = np.argsort(flat, kind="stable")
    values, starts = np.unique(flat[order], return_index=True)
    gy, gx = np.divmod(order, nc)
    lo_y = np.minimum.reduceat(gy, starts)
    hi_y = np.maximum.reduceat(gy, starts)
    lo_x = np.minimum.reduceat(gx, starts)
    hi_x = np.maximum.reduceat(gx, starts)
    rows, cols = pattern.rows, pattern.cols
    r0 = np.where(lo_y > 0, rows[np.maximum(lo_y - 1, 0)], 0)
    r1 = np.where(hi_y < nr - 1, rows[np.minimum(hi_y + 1, nr - 1)] + 1, pattern.height)
    c0 = np.where(lo_x > 0, cols[np.maximum(lo_x - 1, 0)], 0)
    c1 = np.where(hi_x < nc - 1, cols[np.minimum(hi_x + 1, nc - 1)] + 1, pattern.width)
    return {int(v): (int(a), int(b), int(c), int(d)) for v, a, b, c, d in zip(values, r0, r1, c0, c1)}


def id_boxes(ids: np.ndarray) -> dict:
    """Pixel bounding box (r0, r1, c0, c1) of each id of an id map, for :func:`smooth_ids`.

    Found from the runs of equal ids along the rows (one comparison per
    pixel, then work per run), so it holds for any map.

    Examples
    --------
    >>> id_boxes(np.array([[1, 1, 2], [3, 1, 1]]))
    {1: (0, 2, 0, 3), 2: (0, 1, 2, 3), 3: (1, 2, 0, 1)}
    """
    ids = np.asarray(ids)
    height, width = ids.shape
    starts = np.ones(ids.shape, dtype=bool)
    np.not_equal(ids[:, 1:], ids[:, :-1], out=starts[:, 1:])
    flat = np.flatnonzero(starts)  # run starts, row-major
    ends = np.append(flat[1:], ids.size) - 1  # the next run's start - 1 ...
    row = flat // width
    ends = np.minimum(ends, (row + 1) * width - 1)  # ... within the row
    values = ids.ravel()[flat]
    order = np.argsort(values, kind="stable")
    labels, first = np.unique(values[order], return_index=True)
    r0 = np.minimum.reduceat(row[order], first)
    r1 = np.maximum.reduceat(row[order], first) + 1
    c0 = np.minimum.reduceat((flat - row * width)[order], first)
    c1 = np.maximum.reduceat((ends - row * width)[order], first) + 1
    return {int(v): (int(a), int(b), int(c), int(d))
            for v, a, b, c, d in zip(labels, r0, r1, c0, c1)}


#: The widest id smoothing, pixels: the report's is 1, and its taps (8 sigma
#: + 1) are blurred over every pixel of an id's box, per id.  Beyond this the
#: blur takes minutes, and far beyond it the taps alone exhaust the memory.
FILTER_SIGMA_MAX = 100.0


def smooth_ids(ids: np.ndarray, filter_sigma: float = 1.0,
               filter_cutoff: float = 0.05, background: int = 0,
               boxes: dict | None = None, order=None) -> np.ndarray:
    """Soften the quadtree's jagged edges (report Algorithm 2, 8-13).

    For every id except ``background``, in increasing order, the 0/1 mask of
    the pixels that currently carry it is blurred with a Gaussian of
    ``filter_sigma`` pixels, divided by its maximum, and every pixel above
    ``filter_cutoff`` is given that id.  The blur runs only on the id's
    bounding box grown by the filter's reach (4 sigma), which gives the
    same result as blurring the whole image.

    A later id grows over an earlier one, so the result depends on the
    order: ``order`` (the ids, in the order to dilate them) replaces the
    report's increasing order, e.g. by one that the geometry decides
    (:func:`geometric_order`), so that renumbering the ids changes nothing.

    Parameters
    ----------
    ids : ndarray of int, shape (height, width)
    filter_sigma : float
        Gaussian standard deviation in pixels, in [0, :data:`FILTER_SIGMA_MAX`]
        (0 leaves ids as they are).
    filter_cutoff : float
        Normalised threshold in [0, 1].
    boxes : dict, optional
        ``id -> (r0, r1, c0, c1)``, a box known to hold all pixels of the id
        in ``ids`` (a caller that built ``ids`` may know them); by default
        each id's box is found by scanning the image.

    Returns
    -------
    ndarray, a new array of the dtype of ``ids`` (int64 if not an integer type).

    Examples
    --------
    >>> ids = np.zeros((5, 5), dtype=int); ids[2, 2] = 1
    >>> int(smooth_ids(ids, 1.0, 0.05).sum())  # pixels with dx^2 + dy^2 <= 5
    21
    """
    filter_sigma = float(filter_sigma)
    filter_cutoff = float(filter_cutoff)
    check_filter_sigma(filter_sigma)
    if not 0.0 <= filter_cutoff <= 1.0:
        raise MRTError(f"filter_cutoff must be in [0, 1], got {filter_cutoff}")
    out = np.array(ids, copy=True)
    if out.dtype.kind not in "iu":
        out = out.astype(np.int64)
    if filter_sigma == 0.0:
        return out
    reach = int(4.0 * filter_sigma + 0.5)  # scipy's default truncation
    weights = gaussian_weights(filter_sigma, reach)
    height, width = out.shape
    if order is not None:
        values = [int(v) for v in order]
    else:
        values = sorted(boxes) if boxes is not None else np.unique(out).tolist()
    for value in values:
        if value == background:
            continue
        # The mask on the id's box grown by the reach, which holds the blur's rectangle.
        b0, b1, d0, d1 = boxes[value] if boxes is not None else (0, height, 0, width)
        g0, g1 = max(b0 - reach, 0), min(b1 + reach, height)
        h0, h1 = max(d0 - reach, 0), min(d1 + reach, width)
        mask = out[g0:g1, h0:h1] == value
        rr = np.flatnonzero(mask.any(axis=1))
        if len(rr) == 0:  # all its pixels were taken by an earlier id
            continue
        cc = np.flatnonzero(mask.any(axis=0))
        r0, r1 = max(g0 + rr[0] - reach, 0), min(g0 + rr[-1] + reach + 1, height)
        c0, c1 = max(h0 + cc[0] - reach, 0), min(h0 + cc[-1] + reach + 1, width)
        blurred = _blurred_mask(mask[r0 - g0:r1 - g0, c0 - h0:c1 - h0], weights)
        peak = blurred.max()
        if peak > 0.0:  # blurred / peak > cutoff, without the division
            np.copyto(out[r0:r1, c0:c1], value,
                      where=blurred >= least_above(filter_cutoff, peak))
    return out


def check_filter_sigma(value: float) -> None:
    """MRTError unless ``value`` is a number in [0, :data:`FILTER_SIGMA_MAX`].

    Examples
    --------
    >>> check_filter_sigma(1.5)
    >>> check_filter_sigma(1e9)
    Traceback (most recent call last):
    ...
    mitsuba_mrt.errors.MRTError: filter_sigma must be in [0, 100], got 1000000000.0
    """
    if not 0.0 <= value <= FILTER_SIGMA_MAX:  # (NaN too)
        raise MRTError(f"filter_sigma must be in [0, {FILTER_SIGMA_MAX:g}], got {value}")


def geometric_order(sample_ids: np.ndarray) -> np.ndarray:
    """The distinct ids, most samples first, ties by their first sample.

    An order for :func:`smooth_ids` that the samples' layout decides, not
    the ids' numbers: the largest regions are dilated first, so the small
    ones, dilated last, are not swallowed by their neighbours.

    Examples
    --------
    >>> geometric_order(np.array([7, 3, 3, 9, 9, 9, 5, 7])).tolist()
    [9, 7, 3, 5]
    """
    sample_ids = np.asarray(sample_ids).ravel()
    if sample_ids.dtype.kind in "iu" and sample_ids.min() >= 0 and sample_ids.max() < 1 << 20:
        # small non-negative ids (ranks): counts and first samples without a sort
        counts = np.bincount(sample_ids)
        first = np.full(len(counts), len(sample_ids))
        first[sample_ids[::-1]] = np.arange(len(sample_ids) - 1, -1, -1)  # the last write wins
        labels = np.flatnonzero(counts)
        counts, first = counts[labels], first[labels]
    else:
        labels, first, counts = np.unique(sample_ids, return_index=True, return_counts=True)
    return labels[np.lexsort((first, -counts))]


def least_above(cutoff: float, peak: np.float32) -> np.float32:
    """The least float32 ``b`` with ``b / peak > cutoff`` in float32 arithmetic.

    The quotient does not decrease as ``b`` grows, so ``blurred >= t`` selects
    exactly the pixels that ``blurred / peak > cutoff`` selects (for float32
    ``blurred``, and ``cutoff`` rounded to float32 as numpy compares a
    float32 array with a Python float), without dividing the whole array.

    Examples
    --------
    >>> t = least_above(0.05, np.float32(0.7))
    >>> bool(t / np.float32(0.7) > np.float32(0.05)), bool(np.nextafter(t, 0) / np.float32(0.7) > np.float32(0.05))
    (True, False)
    """
    cutoff, peak = np.float32(cutoff), np.float32(peak)
    below, up = np.float32(0.0), np.float32(np.inf)
    guess = np.float32(cutoff * peak)
    while guess / peak > cutoff:  # step down to the last value not above
        guess = np.nextafter(guess, below)
    while not guess / peak > cutoff:  # then up to the first value above
        guess = np.nextafter(guess, up)
    return guess


def gaussian_weights(sigma: float, reach: int) -> np.ndarray:
    """The 1-D Gaussian taps ``scipy.ndimage.gaussian_filter`` uses (``2 reach + 1``, sum 1)."""
    x = np.arange(-reach, reach + 1)
    taps = np.exp(-0.5 / (sigma * sigma) * x ** 2)
    return taps / taps.sum()


#: Rectangles of at least this many pixels are blurred in row blocks on all
#: cores (scipy's filters release the GIL); smaller ones are not worth the threads.
PARALLEL_AREA = 1 << 18


def _blurred_mask(mask: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Gaussian blur (float32) of a boolean ``mask``, as ``gaussian_filter`` does it.

    Two ``correlate1d`` passes (rows, then columns, reflecting at the edges)
    with the taps of :func:`gaussian_weights`: bit for bit what
    ``ndimage.gaussian_filter(mask.astype(np.float32), sigma)`` returns,
    without its per-call set-up.  A large mask is blurred in row blocks,
    each with ``reach`` rows of margin: the filter is separable and
    truncated at ``reach``, so every block's rows come out exactly as in
    the blur of the whole mask.
    """
    reach = len(weights) // 2
    out = np.empty(mask.shape, dtype=np.float32)
    source = mask.view(np.uint8)
    if out.size < PARALLEL_AREA:  # in place, on this thread
        ndimage.correlate1d(source, weights, 0, out)
        return ndimage.correlate1d(out, weights, 1, out)

    def blur(lo, hi):
        block = ndimage.correlate1d(source[lo:hi], weights, 0, np.float32)
        return ndimage.correlate1d(block, weights, 1, block)
    for_row_blocks_of(blur, out, halo=reach, min_rows=8 * reach)
    return out
