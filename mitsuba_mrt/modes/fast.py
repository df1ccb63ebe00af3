"""Mode ``fast``: nearest-sample ids, the report's smoothing, within-id cubic.

Every pixel takes the id of its nearest traced pixel (nearest row and
nearest column, chosen independently), then the report's Gaussian smoothing
(``filter_sigma``, ``filter_cutoff``) softens the boundaries, dilating the
ids in an order their samples decide (most samples first,
:func:`mitsuba_mrt.recon.edges.geometric_order`) rather than by number, so
that renumbering the shapes changes nothing; the traced pixels keep their
traced ids.  Values come from :mod:`mitsuba_mrt.recon.within_region`, of
the grid smoothed within its noise (:mod:`.smoothing`) on a worker thread
while the ids are found; a surface's
pixels within the pixel filter's reach of a light take theirs from the
samples there alone (:func:`~mitsuba_mrt.recon.ids.light_halo`).
Nothing is traced beyond the grid.
"""

from __future__ import annotations

import time
from collections import Counter
from functools import partial

import numpy as np

from ..recon.edges import geometric_order, region_boxes, smooth_ids
from ..recon.ids import light_halo, rank_ids
from ..recon.sampling import SamplePattern
from ..recon.within_region import TracedGridValues
from ..runtime.threads import beside
from ..types import MRTParams, Reconstruction, Skips, SparseTrace, Timings, Tracer
from .smoothing import smoothed_radiance, smooths


def skips_from(counts: Counter) -> Skips:
    """The shortcuts counted by :mod:`mitsuba_mrt.recon.within_region`, as Skips."""
    return Skips(albedo_division=counts["albedo_division"], background=counts["background"])


def _lights_apart(pattern: SamplePattern, trace: SparseTrace, values: TracedGridValues,
                  labels: np.ndarray, sample_ranks: np.ndarray, rank_map: np.ndarray,
                  background: int) -> tuple[np.ndarray, TracedGridValues]:
    """``rank_map`` with a surface's pixels within the pixel filter's reach of
    a light given ranks of their own (their rank plus the number of ids,
    :func:`~mitsuba_mrt.recon.ids.light_halo`), and ``values`` started anew
    where grid samples are among them; both as they were where the grid
    sees no light."""
    if not trace.sees_spread_light:
        return rank_map, values
    lit = np.zeros(len(labels), dtype=bool)
    lit[sample_ranks[trace.emitter]] = True
    halo = light_halo(lit[rank_map], rank_map, trace.filter_reach, background)
    if not halo.any():
        return rank_map, values
    rank_map = rank_map.astype(np.int16 if 2 * len(labels) < 1 << 15 else np.int32)
    np.add(rank_map, len(labels), out=rank_map, where=halo)
    apart = rank_map[np.ix_(pattern.rows, pattern.cols)].ravel()  # (traced: their own ranks)
    if (apart != sample_ranks).any():
        values.early.result()  # (its values are of the ranks before)
        values = TracedGridValues.start(pattern, trace.radiance, trace.albedo, apart,
                                        background, trace.albedo_per_shape,
                                        values.grid.result().radiance)
    return rank_map, values


def fast_reconstruct(pattern: SamplePattern, trace: SparseTrace, params: MRTParams,
                     tracer: Tracer | None = None) -> Reconstruction:
    """Nearest-sample ids, the report's smoothing, within-id cubic (mode ``fast``).

    Examples
    --------
    >>> import numpy as np
    >>> from mitsuba_mrt.recon.sampling import grid_pattern
    >>> p = grid_pattern(24, 24, 0.12)
    >>> x = p.pixel_xy[:, :1].astype(float) ** 2
    >>> t = SparseTrace(np.repeat(x, 3, 1), np.ones((p.count, 3)), np.ones(p.count, int),
    ...                 np.zeros(p.count, np.uint32), 0, 1, 0.0)
    >>> out = fast_reconstruct(p, t, MRTParams(id_rule="exact"))
    >>> bool(np.allclose(out.image[5, :, 0], np.arange(24.0) ** 2, rtol=1e-5))
    True
    """
    timings, skips, stats = Timings(), Skips(), Counter()
    start = time.perf_counter()
    # the ids' ranks (int16): the same order and regions, a quarter of the bytes
    labels, sample_ranks = rank_ids(trace.ids(params.rule_for("fast")))
    background = 0 if labels[0] == 0 else -1  # ids are >= 0, so id 0 is rank 0
    grid_ranks = sample_ranks.reshape(pattern.grid_shape)
    # the grid smoothed within its noise, and its values, beside the ids
    smoothing = (partial(smoothed_radiance, pattern, trace, params, "fast")
                 if smooths(trace, params, "fast") else None)
    values = TracedGridValues.start(pattern, trace.radiance, trace.albedo, sample_ranks,
                                    background, trace.albedo_per_shape, smoothing)
    rank_map = pattern.nearest_image(grid_ranks)
    boxes = region_boxes(pattern, grid_ranks)  # one per id
    stats["regions"] = len(boxes)
    if stats["regions"] == 1:
        skips.edge_finding += 1
    else:
        rank_map = smooth_ids(rank_map, params.filter_sigma, params.filter_cutoff,
                              background, boxes, order=geometric_order(sample_ranks))
        pattern.put_traced(rank_map, sample_ranks)  # a traced pixel's id is known
    shown = rank_map
    rank_map, values = _lights_apart(pattern, trace, values, labels, sample_ranks, rank_map,
                                     background)
    timings.edges = time.perf_counter() - start

    start = time.perf_counter()
    id_map = beside(labels.take, shown)  # back to ids, beside the fits
    image, counts = values.finish(rank_map)
    skips.add(skips_from(counts))
    stats["edge_pixels"] = counts["edge_pixels"]
    stats["fireflies"] = counts["fireflies"]
    id_map = id_map.result()
    timings.interpolate = time.perf_counter() - start
    return Reconstruction(image, id_map, pattern.mask, timings, skips, stats)
