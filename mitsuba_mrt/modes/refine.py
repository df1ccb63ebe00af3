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
Values then come from :func:`mitsuba_mrt.recon.within_region.interpolate_traced_grid` with
the refined ids (demodulated by albedo where it varies, as in ``fast``), and
every traced pixel keeps its traced radiance.
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np
from scipy.spatial import cKDTree

from ..recon.sampling import SamplePattern
from ..recon.within_region import interpolate_traced_grid
from ..types import (MRTParams, Reconstruction, SeedStream, Skips, SparseTrace, Timings, Tracer,
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
    r0 = np.repeat(pattern.rows[:-1], len(pattern.cols) - 1)
    r1 = np.repeat(pattern.rows[1:], len(pattern.cols) - 1)
    c0 = np.tile(pattern.cols[:-1], len(pattern.rows) - 1)
    c1 = np.tile(pattern.cols[1:], len(pattern.rows) - 1)
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
        points = np.unique(points, axis=0)
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


def refine_reconstruct(pattern: SamplePattern, trace: SparseTrace, params: MRTParams,
                       tracer: Tracer | None = None) -> Reconstruction:
    """Grid trace + adaptive edge refinement + within-id interpolation (mode ``refine``)."""
    rule = params.rule_for("refine")
    stats = Counter()
    start = time.perf_counter()
    grid_ids = trace.ids(rule).reshape(pattern.grid_shape)
    extra = []

    curved = trace.curved_mirror
    if curved is not None:
        stats["curved_mirror_samples"] = int(curved.sum())

    def trace_ids(points):
        more = tracer(points, stream=SeedStream.EDGES)
        extra.append((points, more))
        if curved is None:
            return more.ids(rule)
        return more.ids(rule), more.curved_mirror

    refined, _ = refine_edges(pattern, grid_ids, trace_ids,
                              None if curved is None else curved.reshape(pattern.grid_shape))
    trace_s = sum(more.seconds for _, more in extra)
    id_map = np.where(refined >= 0, refined, pattern.nearest_image(grid_ids))
    edges_s = time.perf_counter() - start - trace_s

    start = time.perf_counter()
    image, counts = interpolate_traced_grid(pattern, trace.radiance, trace.albedo,
                                            grid_ids.ravel(), id_map)
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

