"""An MRT image from a traced grid: denoise, reconstruct, finish.

The stages after the trace, as :func:`mitsuba_mrt.render` runs them and as
``auto``'s pilot runs them on its strips: :func:`denoise_stage` (the grid
through OIDN, with ``denoise``), :func:`mitsuba_mrt.modes.reconstruct` (the
mode) and :func:`finish_stage` (``refine``'s whole image through OIDN once
more, with ``denoise``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import mitsuba as mi
import numpy as np

from ..modes import OUTPUT_DENOISED_MODES, reconstruct
from ..recon.denoise import denoise_grid, denoise_image, grid_preset, preset, textured_pixels
from ..recon.sampling import SamplePattern
from ..types import MRTParams, Reconstruction, SparseTrace, Tracer
from .scene_query import textured_diffuse_shapes


@dataclass
class MRTImage:
    """What the stages after the trace made.

    ``trace`` is the grid's trace as the reconstruction saw it (denoised
    with ``denoise``); ``denoise_s`` the seconds of both OIDN stages.
    """

    recon: Reconstruction
    trace: SparseTrace
    denoise_s: float


def mrt_image(scene: mi.Scene, pattern: SamplePattern, trace: SparseTrace, params: MRTParams,
              mode: str, tracer: Tracer | None) -> MRTImage:
    """Denoise the grid (with ``params.denoise``), reconstruct with ``mode``, finish."""
    if params.denoise == "none":
        return MRTImage(reconstruct(pattern, trace, params, mode, tracer), trace, 0.0)
    begin = time.perf_counter()
    trace = denoise_stage(scene, pattern, trace, params)
    denoise_s = time.perf_counter() - begin
    recon = reconstruct(pattern, trace, params, mode, tracer)
    begin = time.perf_counter()
    recon = finish_stage(recon, params, mode)
    return MRTImage(recon, trace, denoise_s + time.perf_counter() - begin)


def denoise_stage(scene: mi.Scene, pattern: SamplePattern, trace: SparseTrace,
                  params: MRTParams) -> SparseTrace:
    """``trace`` with its radiance denoised as the grid image it forms, at
    :func:`~mitsuba_mrt.recon.denoise.grid_preset`'s preset (or ``trace``
    itself without ``params.denoise``).

    On textured diffuse surfaces the shading alone is denoised; the pixels
    whose samples all agreed keep their values: the background's, and a
    surface's if not black (all of its samples may have missed the light);
    at 1 spp none can tell.
    """
    if params.denoise == "none":
        return trace
    grid = pattern.grid_shape + (3,)
    normal = None if trace.normal is None else trace.normal.reshape(grid)
    textured = textured_pixels(trace.shape_index, trace.albedo, textured_diffuse_shapes(scene))
    exact = None
    if trace.variance is not None and trace.spp > 1:
        exact = ((trace.variance == 0.0).all(axis=1)
                 & ((trace.radiance > 0.0).any(axis=1) | (trace.shape_index == 0)))
        exact = exact.reshape(pattern.grid_shape)
    radiance = denoise_grid(trace.radiance.reshape(grid), trace.albedo.reshape(grid), normal,
                            params.denoise, grid_preset(params.denoise_quality),
                            textured=textured.reshape(pattern.grid_shape), exact=exact)
    return replace(trace, radiance=np.asarray(radiance, dtype=np.float64).reshape(-1, 3))


def finish_stage(recon: Reconstruction, params: MRTParams, mode: str) -> Reconstruction:
    """``recon`` with its whole image denoised once more where ``mode`` asks
    for it (:data:`mitsuba_mrt.modes.OUTPUT_DENOISED_MODES`, with ``denoise``)."""
    if params.denoise != "none" and mode in OUTPUT_DENOISED_MODES:
        recon.image = denoise_image(recon.image, quality=preset(params.denoise_quality))
    return recon
