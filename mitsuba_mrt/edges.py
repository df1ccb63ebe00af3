"""Stage 3: the report's edge finder (quadtree id fill + Gaussian smoothing).

Both functions work on plain numpy arrays.  The traced pixels form the
tensor grid of a :class:`~mitsuba_mrt.sampling.SamplePattern`, so the known
pixels inside any rectangle are a sub-block of the grid, found by two
``searchsorted`` calls, and the known pixel nearest to a point is found one
axis at a time (Euclidean distance on a tensor grid is separable), from the
pattern's ``nearest_rows`` and ``nearest_cols``.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .errors import MRTError
from .sampling import SamplePattern


def quadtree_fill(pattern: SamplePattern, grid_ids: np.ndarray) -> np.ndarray:
    """Assign an id to every pixel from the traced grid (report Algorithm 2, 1-7).

    The image is split into four rectangles (two when one side is a single
    pixel).  A rectangle whose known ids are all equal is filled with that
    id; one with differing ids is split again, down to single pixels.  A
    rectangle with no known pixel takes the id of the known pixel of its
    parent that lies nearest to its outer corner (the corner it shares with
    the parent).

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
    >>> from mitsuba_mrt.sampling import SamplePattern
    >>> p = SamplePattern(4, 4, np.array([0, 3]), np.array([0, 3]))
    >>> int(quadtree_fill(p, np.array([[1, 1], [1, 1]]))[2, 1])
    1
    """
    grid_ids = np.asarray(grid_ids, dtype=np.int64)
    if grid_ids.shape != pattern.grid_shape:
        raise MRTError(f"grid_ids has shape {grid_ids.shape}, "
                       f"expected {pattern.grid_shape}")
    rows, cols = pattern.rows, pattern.cols
    nearest_rows, nearest_cols = pattern.nearest_rows, pattern.nearest_cols
    out = np.zeros((pattern.height, pattern.width), dtype=np.int64)
    stack = [(0, pattern.height, 0, pattern.width)]
    while stack:
        r0, r1, c0, c1 = stack.pop()
        i0, i1 = np.searchsorted(rows, (r0, r1))
        j0, j1 = np.searchsorted(cols, (c0, c1))
        block = grid_ids[i0:i1, j0:j1]
        first = block.flat[0]
        if (block == first).all():
            out[r0:r1, c0:c1] = first
            continue
        rm = (r0 + r1) // 2 if r1 - r0 > 1 else r1
        cm = (c0 + c1) // 2 if c1 - c0 > 1 else c1
        for qr0, qr1, qc0, qc1, corner_r, corner_c in (
                (r0, rm, c0, cm, r0, c0), (r0, rm, cm, c1, r0, c1 - 1),
                (rm, r1, c0, cm, r1 - 1, c0), (rm, r1, cm, c1, r1 - 1, c1 - 1)):
            if qr0 >= qr1 or qc0 >= qc1:
                continue
            has_rows = np.searchsorted(rows, qr1) > np.searchsorted(rows, qr0)
            has_cols = np.searchsorted(cols, qc1) > np.searchsorted(cols, qc0)
            if has_rows and has_cols:
                stack.append((qr0, qr1, qc0, qc1))
            else:
                # nearest known pixel within the parent: on a sorted axis, the
                # image-wide nearest grid line clipped into the parent's lines
                i = min(max(nearest_rows[corner_r], i0), i1 - 1)
                j = min(max(nearest_cols[corner_c], j0), j1 - 1)
                out[qr0:qr1, qc0:qc1] = grid_ids[i, j]
    return out


def smooth_ids(ids: np.ndarray, filter_sigma: float = 1.0,
               filter_cutoff: float = 0.05, background: int = 0,
               boxes: dict | None = None) -> np.ndarray:
    """Soften the quadtree's jagged edges (report Algorithm 2, 8-13).

    For every id except ``background``, in increasing order, the 0/1 mask of
    the pixels that currently carry it is blurred with a Gaussian of
    ``filter_sigma`` pixels, divided by its maximum, and every pixel above
    ``filter_cutoff`` is given that id.  The blur runs only on the id's
    bounding box grown by the filter's reach (4 sigma), which gives the
    same result as blurring the whole image.

    Parameters
    ----------
    ids : ndarray of int, shape (height, width)
    filter_sigma : float
        Gaussian standard deviation in pixels, >= 0 (0 leaves ids as they are).
    filter_cutoff : float
        Normalised threshold in [0, 1].
    boxes : dict, optional
        ``id -> (r0, r1, c0, c1)``, a box known to hold all pixels of the id
        in ``ids`` (a caller that built ``ids`` may know them); by default
        each id's box is found by scanning the image.

    Returns
    -------
    ndarray of int64, a new array.

    Examples
    --------
    >>> ids = np.zeros((5, 5), dtype=int); ids[2, 2] = 1
    >>> int(smooth_ids(ids, 1.0, 0.05).sum())  # pixels with dx^2 + dy^2 <= 5
    21
    """
    filter_sigma = float(filter_sigma)
    filter_cutoff = float(filter_cutoff)
    if not filter_sigma >= 0.0 or not np.isfinite(filter_sigma):
        raise MRTError(f"filter_sigma must be a finite number >= 0, got {filter_sigma}")
    if not 0.0 <= filter_cutoff <= 1.0:
        raise MRTError(f"filter_cutoff must be in [0, 1], got {filter_cutoff}")
    out = np.array(ids, dtype=np.int64, copy=True)
    if filter_sigma == 0.0:
        return out
    reach = int(4.0 * filter_sigma + 0.5)  # scipy's default truncation
    height, width = out.shape
    values = sorted(boxes) if boxes is not None else np.unique(out).tolist()
    for value in values:
        if value == background:
            continue
        b0, b1, d0, d1 = boxes[value] if boxes is not None else (0, height, 0, width)
        mask = out[b0:b1, d0:d1] == value
        rr = np.flatnonzero(mask.any(axis=1))
        if len(rr) == 0:  # all its pixels were taken by an earlier id
            continue
        cc = np.flatnonzero(mask.any(axis=0))
        r0, r1 = max(b0 + rr[0] - reach, 0), min(b0 + rr[-1] + reach + 1, height)
        c0, c1 = max(d0 + cc[0] - reach, 0), min(d0 + cc[-1] + reach + 1, width)
        mask = out[r0:r1, c0:c1] == value
        blurred = ndimage.gaussian_filter(mask.astype(np.float32), filter_sigma)
        peak = blurred.max()
        if peak > 0.0:
            out[r0:r1, c0:c1][blurred / peak > filter_cutoff] = value
    return out
