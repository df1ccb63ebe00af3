"""Full-resolution id pass: mode ``idpass``, and textures.

For expensive nested integrators (``path`` at many spp) one primary ray per
pixel, plus one shadow ray per point, spot or directional light, is cheap next to the
integrator itself, and it gives every pixel its exact id and its albedo.
The expensive integrator then runs only at the grid pixels, and at the
pixels whose id no grid sample nearby carries (thin slivers).  Irradiance
(radiance / albedo) is interpolated within ids and multiplied by the
full-resolution albedo, so textures stay as sharp as in a full render, as
the report's Section 4 proposes; an id whose light does not follow its
albedo (the background, a mirror, glass that shows the sky) is interpolated
as radiance (:func:`~mitsuba_mrt.recon.compose.radiance_channels`).  An
edge pixel whose albedo is a mix of its region's colour and a neighbour's
shows both surfaces: it is given both regions' light in that mix (:mod:`mitsuba_mrt.recon.mixed`).  A
surface's pixels within the pixel filter's reach of a light seen in the
image are an id of their own (:func:`~mitsuba_mrt.recon.ids.light_halo`):
the filter mixes the light into them, not into the pixels beyond.
"""

from __future__ import annotations

import time
from collections import Counter
from concurrent.futures import Future
from typing import NamedTuple

import numpy as np

from ..recon.compose import division_albedo, pixel_modulation, radiance_channels
from ..recon.ids import HALO_BIT, light_halo
from ..recon.mixed import unmix_edges
from ..recon.sampling import SamplePattern, cell_coordinates, every_pixel
from ..recon.within_region import (GridValues, black_background, early_values,
                                   interpolate_within_ids)
from ..runtime.threads import beside
from ..types import (MRTParams, Reconstruction, SeedStream, Skips, SparseTrace, Timings, Tracer,
                     check_radiance)


def unsupported_pixels(pattern: SamplePattern, grid_ids: np.ndarray,
                       id_map: np.ndarray) -> np.ndarray:
    """(height, width) bool: pixels whose id no sample of their 4 x 4 grid block carries.

    Examples
    --------
    >>> from mitsuba_mrt.recon.sampling import grid_pattern
    >>> p = grid_pattern(20, 20, 0.2)
    >>> ids = np.zeros((20, 20), dtype=int); ids[9, 9] = 5   # a one-pixel sliver
    >>> int(unsupported_pixels(p, np.zeros(p.grid_shape, int), ids).sum())
    1
    """
    nr, nc = grid_ids.shape
    cy, _ = cell_coordinates(pattern.rows, pattern.height)
    cx, _ = cell_coordinates(pattern.cols, pattern.width)
    # the block's own corner sample first, over the image: it carries most pixels' ids
    missing = grid_ids[cy[:, None], cx[None, :]] != id_map
    y, x = np.nonzero(missing)
    ids, found = id_map[y, x], np.zeros(len(y), dtype=bool)
    for dy in (-1, 0, 1, 2):  # the other 15, for the pixels left
        gy = np.clip(cy[y] + dy, 0, nr - 1)
        for dx in (-1, 0, 1, 2):
            if dy or dx:
                found |= grid_ids[gy, np.clip(cx[x] + dx, 0, nc - 1)] == ids
    missing[y, x] = ~found
    return missing


class _Grid(NamedTuple):
    """The grid's values as :func:`idpass_reconstruct` interpolates them:
    which ids are interpolated as radiance (``ids``, ``plain``:
    :func:`~mitsuba_mrt.recon.compose.radiance_channels`), the values and
    the cubic (a future, computed beside)."""

    ids: np.ndarray
    plain: np.ndarray
    values: GridValues
    early: Future


def _grid(pattern: SamplePattern, trace: SparseTrace, grid_ids: np.ndarray) -> _Grid:
    """The :class:`_Grid` of ``trace`` under ``grid_ids``: irradiance (or
    radiance) over a power of two per channel, so float32 work cannot overflow."""
    ids, inverse, plain = radiance_channels(grid_ids, trace.albedo, trace.radiance)
    grid = GridValues.from_samples(pattern, grid_ids,
                                   trace.radiance / division_albedo(trace.albedo, plain[inverse]))
    return _Grid(ids, plain, grid, beside(early_values, pattern, grid_ids, grid.values))


def idpass_reconstruct(pattern: SamplePattern, trace: SparseTrace, params: MRTParams,
                       tracer: Tracer | None = None) -> Reconstruction:
    """Exact ids and albedo at every pixel, radiance on the grid (mode ``idpass``).

    A surface's pixels within the pixel filter's reach of a light are set
    apart from the rest of the surface (:func:`~mitsuba_mrt.recon.ids.light_halo`):
    where the grid sees a light, its values wait for the id pass, which says
    where those pixels are.
    """
    rule = params.rule_for("idpass")
    stats = Counter()
    height, width = pattern.height, pattern.width
    start = time.perf_counter()
    grid_ids = trace.ids(rule).reshape(pattern.grid_shape)
    # the grid's values beside the id pass, unless a light's halo may change its ids
    grid = None if trace.sees_spread_light else _grid(pattern, trace, grid_ids)
    grid_s = time.perf_counter() - start
    start = time.perf_counter()
    every = every_pixel(width, height)
    called = time.perf_counter()
    aov = tracer(every, stream=SeedStream.ID_PASS, radiance=False, replay=True)
    called = time.perf_counter() - called  # (less than its seconds where ``auto`` traced it)
    id_map = shown_ids = aov.ids(rule).reshape(height, width)
    albedo = np.asarray(aov.albedo, dtype=np.float64).reshape(height, width, 3)
    if aov.emitter is not None:
        halo = light_halo(aov.emitter.reshape(height, width), id_map, trace.filter_reach)
        if halo.any():
            id_map = np.where(halo, id_map | HALO_BIT, id_map)
            apart = np.where(halo[np.ix_(pattern.rows, pattern.cols)], grid_ids | HALO_BIT,
                             grid_ids)
            if grid is not None and (apart != grid_ids).any():
                grid.early.result()  # (its values are of the ids before)
                grid = None
            grid_ids = apart
    if grid is None:
        begin = time.perf_counter()
        grid = _grid(pattern, trace, grid_ids)
        grid_s += time.perf_counter() - begin
    missing = unsupported_pixels(pattern, grid_ids, id_map)
    missing[np.ix_(pattern.rows, pattern.cols)] = False
    extra_xy = np.argwhere(missing)[:, ::-1]
    extra = (tracer(extra_xy, stream=SeedStream.SLIVERS, aovs=False, pad=True)
             if len(extra_xy) else None)
    id_pass_s = aov.seconds
    edges_s = time.perf_counter() - start - called - (extra.seconds if extra else 0.0)

    start = time.perf_counter()
    constant = black_background(grid_ids.ravel(), trace.radiance, stats)
    skips = Skips(background=stats.pop("background", 0))
    interp, edge_pixels = interpolate_within_ids(pattern, grid_ids, grid.values.values, id_map,
                                                 constant, grid.early.result())
    traced_mask = pattern.mask.copy()
    traced_mask[extra_xy[:, 1], extra_xy[:, 0]] = True
    # float64: traced pixels go in exactly
    image, unmixed = unmix_edges(grid.values.unscaled(interp), albedo, id_map, traced_mask,
                                 pixel_modulation(id_map, albedo, grid.ids, grid.plain))
    if extra is not None:
        check_radiance(extra.radiance, "pixels traced for thin regions")
        image[extra_xy[:, 1], extra_xy[:, 0]] = extra.radiance
    image[np.ix_(pattern.rows, pattern.cols)] = trace.radiance.reshape(pattern.grid_shape + (3,))
    stats["regions"] = int(len(np.unique(shown_ids)))
    stats["edge_pixels"] = int(edge_pixels)
    stats["sliver_pixels"] = int(len(extra_xy))
    stats["unmixed_pixels"] = int(unmixed.sum())
    stats["fireflies"] = grid.values.fireflies
    timings = Timings(trace_more=id_pass_s + (extra.seconds if extra else 0.0), edges=edges_s,
                      interpolate=grid_s + time.perf_counter() - start)
    return Reconstruction(image, shown_ids, traced_mask, timings, skips, stats, unmixed)
