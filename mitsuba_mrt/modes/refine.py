"""Adaptive edge refinement: mode ``refine``.

After the grid trace, every grid cell whose four corner ids differ is split
at its midlines: the centre and the midpoints of sides whose ends differ
are traced with the nested integrator (a side whose ends agree gives its
midpoint their id), and the sub-cells whose corners still differ are split
again, down to single pixels.  Sub-cells whose corners agree take that id.  The cost grows with
the length of the edges, not with the area, and every pixel near an edge
ends up with its traced id (up to features thinner than the sub-cells).
Cells with a corner on a curved mirror are split down to pixels whatever
their ids: such a mirror minifies what it reflects, so its reflected
regions are often thinner than the cells and invisible to their corners.
Values then come from :class:`mitsuba_mrt.recon.within_region.TracedGridValues` with
the refined ids (demodulated by albedo where it varies, as in ``fast``), and
every traced pixel keeps its traced radiance; the half of that interpolation
that needs no ids runs beside the edges' tracing.
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np
from scipy.spatial import cKDTree

from ..recon.sampling import SamplePattern
from ..recon.within_region import TracedGridValues
from ..types import (MRTParams, Reconstruction, SeedStream, SparseTrace, Timings, Tracer,
                     check_radiance)
from .fast import skips_from


def refine_edges(pattern: SamplePattern, grid_ids: np.ndarray, trace_ids,
                 grid_split: np.ndarray | None = None):
    """Trace midpoints of mixed cells, level by level, until edges are resolved.

    Parameters
    ----------
    pattern : SamplePattern
    grid_ids : ndarray of int, shape pattern.grid_shape
    trace_ids : callable
        ``trace_ids(pixel_xy) -> ids`` traces (column, row) pixels and
        returns their ids; called once per level with all of its new points.
        With ``grid_split`` it returns ``(ids, split)``.
    grid_split : ndarray of bool, shape pattern.grid_shape, optional
        Samples whose cells are split even where the corner ids agree,
        down to pixels (e.g. those on a curved mirror, whose minified
        reflections may lie between the corners); ``split`` flags the
        traced points the same way.

    Returns
    -------
    ids : ndarray of int64, shape (height, width)
        Traced ids where known, the corners' id inside agreeing sub-cells,
        -1 elsewhere (pixels of cells that were never mixed).
    traced : list of (pixel_xy, ids) per level
    """
    ids = np.full((pattern.height, pattern.width), -1, dtype=np.int64)
    ids[np.ix_(pattern.rows, pattern.cols)] = grid_ids
    split = None
    if grid_split is not None and grid_split.any():
        split = np.zeros((pattern.height, pattern.width), dtype=bool)
        split[np.ix_(pattern.rows, pattern.cols)] = grid_split
    # cells between consecutive grid lines; a grid of one row (column) has cells
    # of no height (width) along it
    rows, cols = pattern.rows, pattern.cols
    lo_r, hi_r = (rows[:-1], rows[1:]) if len(rows) > 1 else (rows, rows)
    lo_c, hi_c = (cols[:-1], cols[1:]) if len(cols) > 1 else (cols, cols)
    r0, r1 = np.repeat(lo_r, len(lo_c)), np.repeat(hi_r, len(lo_c))
    c0, c1 = np.tile(lo_c, len(lo_r)), np.tile(hi_c, len(lo_r))
    traced = []
    level = 0
    while len(r0):
        corners = np.stack([ids[r0, c0], ids[r0, c1], ids[r1, c0], ids[r1, c1]], axis=1)
        mixed = (corners != corners[:, :1]).any(axis=1)
        if split is not None:
            mixed |= split[r0, c0] | split[r0, c1] | split[r1, c0] | split[r1, c1]
        if level > 0:  # agreeing grid cells are left to the nearest-sample fill
            _fill_agreeing(ids, r0[~mixed], r1[~mixed], c0[~mixed], c1[~mixed],
                           corners[~mixed, 0])
        level += 1
        r0, r1, c0, c1 = r0[mixed], r1[mixed], c0[mixed], c1[mixed]
        splittable = (r1 - r0 > 1) | (c1 - c0 > 1)
        r0, r1, c0, c1 = r0[splittable], r1[splittable], c0[splittable], c1[splittable]
        if not len(r0):
            break
        rm, cm = (r0 + r1) // 2, (c0 + c1) // 2
        # A side's midpoint takes the id its two ends agree on (unless an end
        # is flagged for splitting); the centre and the other midpoints are traced.
        for (ya, xa), (yb, xb), (ym, xm) in (((r0, c0), (r0, c1), (r0, cm)),
                                             ((r1, c0), (r1, c1), (r1, cm)),
                                             ((r0, c0), (r1, c0), (rm, c0)),
                                             ((r0, c1), (r1, c1), (rm, c1))):
            agree = (ids[ya, xa] == ids[yb, xb]) & (ids[ym, xm] < 0)
            if split is not None:
                agree &= ~(split[ya, xa] | split[yb, xb])
            ids[ym[agree], xm[agree]] = ids[ya[agree], xa[agree]]
        points = np.concatenate([np.stack([cm, r0], 1), np.stack([c0, rm], 1),
                                 np.stack([cm, rm], 1), np.stack([c1, rm], 1),
                                 np.stack([cm, r1], 1)])
        # unique (column, row) pairs in their lexicographic order, by one integer key each
        # (np.unique(axis=0) sorts rows as opaque records, several times slower)
        key = np.unique(points[:, 0] * pattern.height + points[:, 1])
        points = np.stack([key // pattern.height, key % pattern.height], 1)
        points = points[ids[points[:, 1], points[:, 0]] < 0]
        if len(points):
            new_ids = trace_ids(points)
            if grid_split is not None:
                new_ids, new_split = new_ids
                if split is not None:
                    split[points[:, 1], points[:, 0]] = new_split
            ids[points[:, 1], points[:, 0]] = new_ids
            traced.append((points, new_ids))
        r0, r1, c0, c1 = (np.concatenate(v) for v in (
            (r0, r0, rm, rm), (rm, rm, r1, r1), (c0, cm, c0, cm), (cm, c1, cm, c1)))
        keep = (r1 > r0) | (c1 > c0)
        r0, r1, c0, c1 = r0[keep], r1[keep], c0[keep], c1[keep]
    return ids, traced


def _fill_agreeing(ids, r0, r1, c0, c1, value):
    """Give the unknown pixels of each cell the id its corners agree on.

    Vectorised over the cells, looping over the few offsets inside one.
    """
    if not len(r0):
        return
    for dy in range(int((r1 - r0).max()) + 1):
        for dx in range(int((c1 - c0).max()) + 1):
            inside = (dy <= r1 - r0) & (dx <= c1 - c0)
            rr, cc = r0[inside] + dy, c0[inside] + dx
            unknown = ids[rr, cc] < 0
            ids[rr[unknown], cc[unknown]] = value[inside][unknown]


#: Most pixels traced for shading the grid cannot follow, as a share of all pixels.
ROUGH_BUDGET = 0.3
#: A second difference is rough beyond this many standard deviations of its noise...
ROUGH_NOISE = 4.0
#: ... and beyond this share of the magnitude of the samples it is taken over.
ROUGH_RELATIVE = 0.1


def rough_cells(grid_ids: np.ndarray, values: np.ndarray, variance: np.ndarray | None,
                spp: int) -> tuple[np.ndarray, np.ndarray]:
    """Grid cells whose shading the grid cannot follow, roughest first.

    Along the grid's rows and columns, the second difference
    ``v[i-1] - 2 v[i] + v[i+1]`` of three samples of one id is zero on a
    linear ramp and small on smooth shading; it is large on a highlight, a
    texture edge, a caustic or a penumbra narrower than the grid.  A triple
    is rough when the difference (summed over the channels) exceeds both
    ``ROUGH_NOISE`` standard deviations of its noise (from the per-sample
    ``variance`` and ``spp``) and ``ROUGH_RELATIVE`` of the samples'
    magnitude; the four cells around its middle sample are then rough.

    Parameters
    ----------
    grid_ids : ndarray of int, shape (nr, nc)
    values : ndarray, shape (nr, nc, C)
    variance : ndarray, shape (nr, nc, C), or None (noise-free samples)
    spp : int

    Returns
    -------
    rows, cols : ndarray of int
        Top-left grid line of each rough cell, in decreasing roughness.

    Examples
    --------
    >>> ids = np.ones((1, 5), dtype=int)
    >>> ramp = np.arange(5.0).reshape(1, 5, 1)
    >>> len(rough_cells(ids, ramp, None, 1)[0])
    0
    >>> spike = np.array([0, 0, 5.0, 0, 0]).reshape(1, 5, 1)
    >>> rough_cells(ids, spike, None, 1)[1].tolist()
    [0, 1, 2, 3]
    """
    nr, nc = grid_ids.shape
    score = np.zeros((max(nr - 1, 1), max(nc - 1, 1)))
    noise = np.zeros_like(values) if variance is None else variance / max(spp, 1)
    for axis in (0, 1):
        if values.shape[axis] < 3:
            continue
        lo, mid, hi = (np.take(values, np.arange(k, values.shape[axis] - 2 + k), axis=axis)
                       for k in range(3))
        ilo, imid, ihi = (np.take(grid_ids, np.arange(k, grid_ids.shape[axis] - 2 + k),
                                  axis=axis) for k in range(3))
        nlo, nmid, nhi = (np.take(noise, np.arange(k, noise.shape[axis] - 2 + k), axis=axis)
                          for k in range(3))
        second = np.abs(lo - 2.0 * mid + hi).sum(axis=-1)
        sigma = np.sqrt((nlo + 4.0 * nmid + nhi).sum(axis=-1))
        scale = (np.abs(lo) + 2.0 * np.abs(mid) + np.abs(hi)).sum(axis=-1) / 4.0
        limit = np.maximum(ROUGH_NOISE * sigma, ROUGH_RELATIVE * scale)
        rough = (ilo == imid) & (imid == ihi) & (second > limit) & (second > 0.0)
        ratio = np.where(rough, second / np.where(limit > 0, limit, 1.0), 0.0)
        r, c = np.nonzero(ratio)
        found = ratio[r, c]
        if axis == 0:  # the middle sample: one line further along this axis
            r = r + 1
        else:
            c = c + 1
        for dy, dx in ((-1, -1), (-1, 0), (0, -1), (0, 0)):  # its four cells
            rr, cc = r + dy, c + dx
            ok = (rr >= 0) & (rr < score.shape[0]) & (cc >= 0) & (cc < score.shape[1])
            np.maximum.at(score, (rr[ok], cc[ok]), found[ok])
    order = np.argsort(-score, axis=None, kind="stable")
    order = order[score.ravel()[order] > 0]
    return np.divmod(order, score.shape[1])


def _cell_pixels(pattern: SamplePattern, rows: np.ndarray, cols: np.ndarray,
                 budget: int) -> np.ndarray:
    """(column, row) of the pixels of the given grid cells (in order, at most
    ``budget``), grid pixels left out."""
    chosen, total = [], 0
    for r, c in zip(rows.tolist(), cols.tolist()):
        y0, y1 = pattern.rows[r], pattern.rows[min(r + 1, len(pattern.rows) - 1)]
        x0, x1 = pattern.cols[c], pattern.cols[min(c + 1, len(pattern.cols) - 1)]
        cell = (y1 - y0 + 1) * (x1 - x0 + 1)
        if total + cell > budget:
            break
        total += cell
        chosen.append((y0, y1, x0, x1))
    if not chosen:
        return np.zeros((0, 2), dtype=np.int64)
    mask = np.zeros((pattern.height, pattern.width), dtype=bool)
    for y0, y1, x0, x1 in chosen:
        mask[y0:y1 + 1, x0:x1 + 1] = True
    mask[pattern.mask] = False
    return np.argwhere(mask)[:, ::-1]


def refine_reconstruct(pattern: SamplePattern, trace: SparseTrace, params: MRTParams,
                       tracer: Tracer | None = None) -> Reconstruction:
    """Grid trace + adaptive refinement + within-id interpolation (mode ``refine``).

    Cells are traced finer where ids differ (edges, down to pixels) and,
    within the budget ``ROUGH_BUDGET``, every pixel of the cells whose
    shading the grid cannot follow (:func:`rough_cells`).
    """
    rule = params.rule_for("refine")
    stats = Counter()
    start = time.perf_counter()
    grid_ids = trace.ids(rule).reshape(pattern.grid_shape)
    # the interpolation's half that needs no final ids, beside the edges' tracing
    values = TracedGridValues.start(pattern, trace.radiance, trace.albedo, grid_ids.ravel(),
                                    albedo_constant=trace.albedo_per_shape)
    extra = []

    curved = trace.curved_mirror
    if curved is not None:
        stats["curved_mirror_samples"] = int(curved.sum())

    def trace_ids(points):
        more = tracer(points, stream=SeedStream.EDGES, pad=True, albedo=False)
        extra.append((points, more))
        if curved is None:
            return more.ids(rule)
        return more.ids(rule), more.curved_mirror

    refined, _ = refine_edges(pattern, grid_ids, trace_ids,
                              None if curved is None else curved.reshape(pattern.grid_shape))
    grid_shape = pattern.grid_shape + (3,)
    rows, cols = rough_cells(grid_ids, trace.radiance.reshape(grid_shape),
                             None if trace.variance is None else trace.variance.reshape(grid_shape),
                             trace.spp)
    rough = _cell_pixels(pattern, rows, cols, int(ROUGH_BUDGET * pattern.width * pattern.height))
    if len(rough):
        traced_before = np.zeros((pattern.height, pattern.width), dtype=bool)
        for points, _ in extra:
            traced_before[points[:, 1], points[:, 0]] = True
        rough = rough[~traced_before[rough[:, 1], rough[:, 0]]]
    stats["rough_cells"] = int(len(rows))
    if len(rough):
        more = tracer(rough, stream=SeedStream.ROUGH, pad=True, albedo=False)
        extra.append((rough, more))
        refined[rough[:, 1], rough[:, 0]] = more.ids(rule)
    trace_s = sum(more.seconds for _, more in extra)
    id_map = np.where(refined >= 0, refined, pattern.nearest_image(grid_ids))
    edges_s = time.perf_counter() - start - trace_s

    start = time.perf_counter()
    image, counts = values.finish(id_map)
    stats["edge_pixels"] = counts["edge_pixels"]
    traced_mask = pattern.mask.copy()
    if extra:
        xy = np.concatenate([p for p, _ in extra])
        radiance = np.concatenate([m.radiance for _, m in extra])
        check_radiance(radiance, "refined pixels")
        image[xy[:, 1], xy[:, 0]] = radiance
        traced_mask[xy[:, 1], xy[:, 0]] = True
        _fix_orphans(image, id_map, traced_mask, grid_ids, pattern, xy,
                     np.concatenate([m.ids(rule) for _, m in extra]), radiance)
    stats["regions"] = int(len(np.unique(id_map)))
    stats["refined_pixels"] = int(traced_mask.sum() - pattern.count)
    stats["refined_fraction"] = float(stats["refined_pixels"] / id_map.size)
    timings = Timings(trace_more=trace_s, edges=edges_s,
                      interpolate=time.perf_counter() - start)
    return Reconstruction(image, id_map, traced_mask, timings, skips_from(counts), stats)


def _fix_orphans(image, id_map, traced_mask, grid_ids, pattern, xy, ids, radiance):
    """Pixels of an id that no grid sample nearby carries (a thin sliver found
    by refinement) take the value of the nearest traced pixel of that id."""
    grid_present = set(np.unique(grid_ids).tolist())
    for value in np.unique(ids).tolist():
        if value in grid_present:
            continue
        members = ids == value
        pixels = np.argwhere((id_map == value) & ~traced_mask)
        if len(pixels):
            _, k = cKDTree(xy[members][:, ::-1]).query(pixels)
            image[pixels[:, 0], pixels[:, 1]] = radiance[members][k]

