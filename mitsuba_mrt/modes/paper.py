"""Mode ``paper``: the report's reconstruction (its Algorithms 2 and 3).

Quadtree fill and Gaussian smoothing of the grid's ids find the regions; a
linear RBF through each id's capstones and secondary samples interpolates
its irradiance (radiance / albedo), multiplied back by the region's albedo.
Beyond the report: fireflies are kept out of the RBF, and every pixel is
clamped to the range of its id's samples nearby (:mod:`mitsuba_mrt.recon.bounds`).
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np

from ..recon.bounds import clamp_to_samples, suppress_fireflies
from ..recon.compose import albedo_constant_per_id, compose, demodulate, region_albedo, safe_albedo
from ..recon.edges import id_boxes, quadtree_fill, smooth_ids
from ..recon.interpolate import interpolate_regions
from ..recon.sampling import SamplePattern
from ..types import MRTParams, Reconstruction, Skips, SparseTrace, Timings, Tracer


def paper_reconstruct(pattern: SamplePattern, trace: SparseTrace, params: MRTParams,
                      tracer: Tracer | None = None) -> Reconstruction:
    """The report's reconstruction (Algorithms 2 and 3), mode ``paper``.

    Parameters
    ----------
    pattern : SamplePattern
        The traced grid.
    trace : SparseTrace
        Radiance and AOVs of the traced pixels, rows outer, columns inner.
    params : MRTParams
    tracer : Tracer, optional
        Unused: this mode traces nothing beyond the grid.
    """
    sample_ids = trace.ids(params.rule_for("paper"))
    timings, skips, stats = Timings(), Skips(), Counter()
    start = time.perf_counter()
    if np.all(sample_ids == sample_ids[0]):
        ids = np.full((pattern.height, pattern.width), sample_ids[0], dtype=np.int64)
        skips.edge_finding += 1
    else:
        # the boxes of the filled map: an empty quadtree cell may take the id
        # of a sample far from it, beyond the box its samples would give
        filled = quadtree_fill(pattern, sample_ids.reshape(pattern.grid_shape))
        ids = smooth_ids(filled, params.filter_sigma, params.filter_cutoff,
                         boxes=id_boxes(filled))
    timings.edges = time.perf_counter() - start

    start = time.perf_counter()
    # one albedo per id: radiance interpolates as albedo x irradiance would
    modulated = not albedo_constant_per_id(sample_ids, safe_albedo(trace.albedo))
    values = demodulate(trace.radiance, trace.albedo) if modulated else trace.radiance
    # a firefly takes part in no other pixel's value; then every pixel is held
    # to the range of its id's samples nearby (the RBF overshoots between
    # samples and extrapolates without bound away from them)
    grid_ids = sample_ids.reshape(pattern.grid_shape)
    grid_values, stats["fireflies"] = suppress_fireflies(
        grid_ids, np.asarray(values, dtype=np.float64).reshape(pattern.grid_shape + (3,)))
    interp = interpolate_regions(
        ids, pattern.pixel_xy, sample_ids, grid_values.reshape(-1, 3),
        max_inpoints=params.max_inpoints, num_cappoints=params.num_cappoints,
        rbf_degree=params.rbf_degree)
    clamp_to_samples(pattern, grid_ids, grid_values, ids, interp.values)
    if modulated:
        albedo = region_albedo(ids, pattern.pixel_xy, sample_ids, trace.albedo,
                               nearest=pattern.nearest_image(np.arange(pattern.count)))
        image = compose(interp.values, albedo, pattern.mask, trace.radiance)
    else:
        skips.albedo_division += 1
        image = interp.values
        pattern.put_traced(image, trace.radiance)
    timings.interpolate = time.perf_counter() - start
    skips.constant_ids += interp.counts["constant"]
    skips.background += interp.counts["background"]
    stats.update(rbf=interp.counts["rbf"], no_samples=interp.counts["no_samples"])
    # every id of the map was interpolated, filled as constant, or had no samples
    stats["regions"] = sum(interp.counts[key] for key in ("rbf", "constant", "no_samples"))
    return Reconstruction(image, ids, pattern.mask, timings, skips, stats)
