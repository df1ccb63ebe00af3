"""Keeping reconstructed pixels within the samples of their region.

Every mode interpolates within ids and then holds each reconstructed pixel
to the values its region's samples took nearby:

* :func:`power_of_two_scale`: per channel, a power of two above the largest
  magnitude.  Values divided by it are exact and lie in (-1, 1), so float32
  work on them cannot overflow, and gives the same numbers at any scale and
  whatever other regions hold.
* :func:`suppress_fireflies`: a sample far above the other samples of its
  id around it on the grid (a firefly of the nested integrator) is
  replaced, for interpolation only, by the largest of them; the traced
  pixel itself keeps its value, so a firefly stays one pixel.
* :func:`block_ranges`, :func:`neighbourhood_ranges`, :func:`region_ranges`
  and :func:`clamp_to_samples`: per channel, the least and the largest
  sample of a pixel's id in its 4 x 4 grid block (the grid lines from one
  before its cell to one after it), or in its whole region where the block
  holds none, and every pixel clamped to them.

Everything works on the traced grid (``grid_shape``) and per channel.
"""

from __future__ import annotations

import numpy as np

from ..runtime.threads import for_row_blocks_of
from .ids import run_starts
from .sampling import SamplePattern, cell_coordinates

#: A sample is a firefly when it is more than this many times the largest
#: other sample of its id in its 3 x 3 grid neighbourhood ...
FIREFLY_RATIO = 4.0
#: ... and above it by more than this fraction of the largest sample of its id.
FIREFLY_MARGIN = 1e-3


def power_of_two_scale(values: np.ndarray) -> np.ndarray:
    """(C,) per channel of ``values`` (..., C): the least power of two above the
    largest magnitude (1 for a channel of zeros).

    Examples
    --------
    >>> power_of_two_scale(np.array([[3.0e38, 0.5, 0.0], [1.0, -3.0, 0.0]])).tolist()
    [3.402823669209385e+38, 4.0, 1.0]
    """
    values = np.asarray(values)
    # column by column: a reduction along axis 0 of an (n, 3) array is many times slower
    top = np.array([np.abs(column).max(initial=0.0)
                    for column in values.reshape(-1, values.shape[-1]).T], dtype=np.float64)
    _, exponent = np.frexp(top)
    return np.where(top > 0, np.ldexp(1.0, np.minimum(exponent, 1023)), 1.0)  # finite


def region_ranges(ids: np.ndarray, values: np.ndarray,
                  wanted: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sorted ids and, per id and channel, the least and the largest of its samples.

    Parameters
    ----------
    ids : ndarray of int, shape (n,)
    values : ndarray, shape (n, C)
    wanted : ndarray of int, optional
        Only these ids (the others' samples are not sorted).

    Examples
    --------
    >>> labels, lo, hi = region_ranges(np.array([5, 2, 5]), np.array([[1.0], [4.0], [3.0]]))
    >>> labels.tolist(), lo[:, 0].tolist(), hi[:, 0].tolist()
    ([2, 5], [4.0, 1.0], [4.0, 3.0])
    """
    ids = np.asarray(ids).ravel()
    values = np.asarray(values).reshape(len(ids), -1)
    if wanted is not None:
        keep = np.isin(ids, wanted)
        ids, values = ids[keep], values[keep]
    order = np.argsort(ids, kind="stable")
    ordered = ids[order]
    starts = run_starts(ordered)
    if len(starts) == 0:
        empty = np.zeros((0, values.shape[1]), values.dtype)
        return ordered[:0], empty, empty
    ordered_values = values[order]
    return (ordered[starts], np.minimum.reduceat(ordered_values, starts, axis=0),
            np.maximum.reduceat(ordered_values, starts, axis=0))


def _neighbour_max(grid_ids: np.ndarray, grid_values: np.ndarray) -> np.ndarray:
    """(nr, nc, C): the largest value of the other samples of each sample's id in
    its 3 x 3 grid neighbourhood; -inf where there is none.

    Inside a region (3 x 3 ids all equal, off the grid's border) it is the
    largest of the 8 neighbours, a few separable maxima over the whole grid;
    the other samples (near edges, on the border) are gathered one by one.
    Blocks of rows run on all cores.
    """
    out = np.empty(grid_values.shape, dtype=grid_values.dtype)
    for_row_blocks_of(lambda lo, hi: _block_neighbour_max(grid_ids[lo:hi], grid_values[lo:hi]),
                      out, halo=1)
    return out


def _block_neighbour_max(grid_ids: np.ndarray, grid_values: np.ndarray) -> np.ndarray:
    """:func:`_neighbour_max` of a block of whole rows (its first and last
    rows lack the neighbours beyond it)."""
    nr, nc = grid_ids.shape
    out = np.full(grid_values.shape, -np.inf, dtype=grid_values.dtype)
    inner = np.zeros((nr, nc), dtype=bool)
    if nr >= 3 and nc >= 3:
        ids = grid_ids
        lo = np.minimum(np.minimum(ids[:, :-2], ids[:, 1:-1]), ids[:, 2:])
        hi = np.maximum(np.maximum(ids[:, :-2], ids[:, 1:-1]), ids[:, 2:])
        lo = np.minimum(np.minimum(lo[:-2], lo[1:-1]), lo[2:])
        hi = np.maximum(np.maximum(hi[:-2], hi[1:-1]), hi[2:])
        inner[1:-1, 1:-1] = lo == hi
        v = grid_values
        across = np.maximum(v[:, :-2], v[:, 1:-1])  # along the rows, 3 wide
        np.maximum(across, v[:, 2:], out=across)
        inner_out = out[1:-1, 1:-1]  # (in place: fresh temporaries cost page faults)
        np.maximum(across[:-2], across[2:], out=inner_out)
        np.maximum(inner_out, v[1:-1, :-2], out=inner_out)
        np.maximum(inner_out, v[1:-1, 2:], out=inner_out)
    rest = np.flatnonzero(~inner)
    if len(rest) == 0:
        return out
    channels = grid_values.shape[-1]
    flat_ids = grid_ids.ravel()
    # channel-major: the gathers and selects below are 1-D and contiguous
    by_channel = np.ascontiguousarray(grid_values.reshape(-1, channels).T)
    ry, rx = np.divmod(rest, nc)
    own = flat_ids[rest]
    found = np.full((channels, len(rest)), -np.inf, dtype=grid_values.dtype)
    for dy in (-1, 0, 1):
        y = ry + dy
        y_ok = (y >= 0) & (y < nr)
        row = np.clip(y, 0, nr - 1) * nc
        for dx in (-1, 0, 1):
            if not (dy or dx):
                continue
            x = rx + dx
            index = row + np.clip(x, 0, nc - 1)
            same = y_ok & (x >= 0) & (x < nc) & (flat_ids.take(index) == own)
            if same.any():
                for c in range(channels):
                    np.maximum(found[c], np.where(same, by_channel[c].take(index), -np.inf),
                               out=found[c])
    out.reshape(-1, channels)[rest] = found.T
    return out


def suppress_fireflies(grid_ids: np.ndarray, grid_values: np.ndarray,
                       ratio: float = FIREFLY_RATIO,
                       margin: float = FIREFLY_MARGIN) -> tuple[np.ndarray, int]:
    """Grid values with fireflies replaced by the largest of their neighbours.

    A sample's channel is a firefly when it exceeds ``ratio`` times the
    largest other sample of its id in its 3 x 3 grid neighbourhood, and that
    by more than ``margin`` times the largest sample of its id (so that
    noise on black is not one).  Only samples of the same id are compared:
    a region's fireflies depend on its samples alone, at any scale.

    Parameters
    ----------
    grid_ids : ndarray of int, shape (nr, nc)
    grid_values : ndarray, shape (nr, nc, C)

    Returns
    -------
    values : ndarray, shape (nr, nc, C)
        ``grid_values`` itself when there is no firefly, else a copy.
    count : int
        Samples with a firefly in some channel.

    Examples
    --------
    >>> ids = np.zeros((3, 3), dtype=int)
    >>> values = np.ones((3, 3, 1)); values[1, 1] = 100.0
    >>> out, count = suppress_fireflies(ids, values)
    >>> count, float(out[1, 1, 0])
    (1, 1.0)
    """
    nmax = _neighbour_max(grid_ids, grid_values)
    with np.errstate(over="ignore", invalid="ignore"):
        bound = nmax * ratio
    np.maximum(bound, nmax, out=bound)
    bound[nmax == -np.inf] = np.inf  # no neighbour of its id: no firefly
    candidate = grid_values > bound
    channels = grid_values.shape[-1]
    flat = candidate.reshape(-1, channels)
    any_channel = flat[:, 0].copy()
    for c in range(1, channels):  # (any(axis=1) of an (n, 3) array is slow)
        any_channel |= flat[:, c]
    rows = np.flatnonzero(any_channel)
    if len(rows) == 0:
        return grid_values, 0
    ids = grid_ids.ravel()
    values = grid_values.reshape(-1, channels)
    labels, _, top = region_ranges(ids, values, np.unique(ids[rows]))
    at = np.searchsorted(labels, ids[rows])
    near = nmax.reshape(-1, channels)[rows]
    fire = flat[rows] & (values[rows] - near > margin * top[at])
    if not fire.any():
        return grid_values, 0
    out = values.copy()
    out[rows] = np.where(fire, near, values[rows])
    return out.reshape(grid_values.shape), int(fire.any(axis=1).sum())


def _window4(a: np.ndarray, op) -> np.ndarray:
    """``op`` over 4 consecutive entries along axis 0 (length n + 3 -> n)."""
    pairs = op(a[:-1], a[1:])
    return op(pairs[:-2], pairs[2:])


def block_ranges(grid_ids: np.ndarray, grid_values: np.ndarray):
    """Per grid cell, its 4 x 4 block: uniform id, least and largest value.

    The block of cell (i, j) is grid rows i - 1 .. i + 2 and columns
    j - 1 .. j + 2, clipped to the grid (the block of
    :func:`mitsuba_mrt.recon.within_region.local_poly_fit`).

    Returns
    -------
    uniform : ndarray of bool, shape (nr, nc)
        Whether the block's samples all carry one id, ...
    block_id : ndarray, shape (nr, nc)
        ... then that id (else the least id of the block),
    lo, hi : ndarray, shape (nr, nc, C)
        and the least and largest values of the block per channel.
    """
    pad = ((1, 2), (1, 2))
    ids = np.pad(grid_ids, pad, mode="edge")  # edge copies: the clipping
    values = np.pad(grid_values, pad + ((0, 0),), mode="edge")

    def both_axes(a, op):
        return _window4(_window4(a, op).swapaxes(0, 1), op).swapaxes(0, 1)

    id_lo, id_hi = both_axes(ids, np.minimum), both_axes(ids, np.maximum)
    return (id_lo == id_hi, id_lo, both_axes(values, np.minimum),
            both_axes(values, np.maximum))


def neighbourhood_ranges(grid_ids: np.ndarray, grid_values: np.ndarray, cell_y: np.ndarray,
                         cell_x: np.ndarray, own: np.ndarray):
    """Per pixel, the range of the samples of ``own`` id in its cell's 4 x 4 block.

    Parameters
    ----------
    grid_ids : ndarray of int, shape (nr, nc)
    grid_values : ndarray, shape (nr, nc, C)
    cell_y, cell_x : ndarray of int, shape (m,)
        The pixels' grid cells.
    own : ndarray of int, shape (m,)
        The pixels' ids.

    Returns
    -------
    lo, hi : ndarray, shape (m, C)
        +inf and -inf where the block holds no sample of the id.
    found : ndarray of bool, shape (m,)
    """
    nr, nc = grid_ids.shape
    channels = grid_values.shape[-1]
    flat_ids = grid_ids.ravel()
    # channel-major copies: every gather and select below is then 1-D and contiguous
    by_channel = np.ascontiguousarray(grid_values.reshape(-1, channels).T)
    lo = np.full((channels, len(own)), np.inf, dtype=grid_values.dtype)
    hi = np.full((channels, len(own)), -np.inf, dtype=grid_values.dtype)
    found = np.zeros(len(own), dtype=bool)
    cols = [np.clip(cell_x + dx, 0, nc - 1) for dx in range(-1, 3)]
    for dy in range(-1, 3):
        row = np.clip(cell_y + dy, 0, nr - 1) * nc
        for col in cols:
            index = row + col
            hit = flat_ids.take(index) == own
            if not hit.any():
                continue
            found |= hit
            for c in range(channels):
                v = by_channel[c].take(index)
                np.minimum(lo[c], np.where(hit, v, np.inf), out=lo[c])
                np.maximum(hi[c], np.where(hit, v, -np.inf), out=hi[c])
    return lo.T, hi.T, found


def clamp_to_samples(pattern: SamplePattern, grid_ids: np.ndarray, grid_values: np.ndarray,
                     id_map: np.ndarray, image: np.ndarray) -> None:
    """Clamp every pixel of ``image`` to the samples of its id nearby, in place.

    Per channel, to the least and largest sample of the pixel's id in its
    4 x 4 grid block; where the block holds none, in its whole region;
    pixels of an id that no sample carries are left as they are.  Pixels
    whose block is all of their id (most) take the block's range from
    :func:`block_ranges`, gathered a run of image rows at a time; the
    others are searched slot by slot (:func:`neighbourhood_ranges`).

    Parameters
    ----------
    pattern : SamplePattern
    grid_ids : ndarray of int, shape pattern.grid_shape
    grid_values : ndarray, shape pattern.grid_shape + (C,)
        The values the image was interpolated from (fireflies suppressed).
    id_map : ndarray of int, shape (height, width)
    image : ndarray, shape (height, width, C)
    """
    cy, _ = cell_coordinates(pattern.rows, pattern.height)
    cx, _ = cell_coordinates(pattern.cols, pattern.width)
    uniform, block_id, lo, hi = block_ranges(grid_ids, grid_values)
    runs = list(cell_row_runs(cy))
    slow = np.empty(id_map.shape, dtype=bool)
    for start, stop, i in runs:
        slow[start:stop] = ~(uniform[i].take(cx) & (block_id[i].take(cx) == id_map[start:stop]))
    py, px = np.nonzero(slow)
    values = image[py, px]  # before the block ranges, which are not theirs
    lo, hi = lo.take(cx, axis=1), hi.take(cx, axis=1)
    for start, stop, i in runs:  # (minimum and maximum: np.clip is several times slower)
        rows = image[start:stop]
        np.minimum(rows, hi[i], out=rows)
        np.maximum(rows, lo[i], out=rows)
    if len(py) == 0:
        return
    own = id_map[py, px]
    pixel_lo, pixel_hi, found = neighbourhood_ranges(grid_ids, grid_values, cy[py], cx[px], own)
    far = np.flatnonzero(~found)
    if len(far):
        labels, region_lo, region_hi = region_ranges(grid_ids, grid_values, np.unique(own[far]))
        at = np.searchsorted(labels, own[far])
        known = at < len(labels)
        known[known] = labels[at[known]] == own[far][known]
        pixel_lo[far], pixel_hi[far] = -np.inf, np.inf  # ids without samples: as they are
        pixel_lo[far[known]], pixel_hi[far[known]] = region_lo[at[known]], region_hi[at[known]]
    image[py, px] = np.minimum(np.maximum(values, pixel_lo), pixel_hi)


def cell_row_runs(cell: np.ndarray):
    """(start, stop, cell) of each run of image rows in one grid cell."""
    bounds = np.flatnonzero(np.diff(cell)) + 1
    starts = np.concatenate(([0], bounds))
    stops = np.concatenate((bounds, [len(cell)]))
    return zip(starts.tolist(), stops.tolist(), cell[starts].tolist())
