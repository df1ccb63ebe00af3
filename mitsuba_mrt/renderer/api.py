"""The Python API: MRT and reference renders of a Mitsuba scene.

Example::

    import mitsuba_mrt
    mitsuba_mrt.activate("auto")
    scene = mitsuba_mrt.load_scene("scenes_xml/paper_fig1.xml", res=400)
    result = mitsuba_mrt.render(scene, sample_fraction=0.1)
    reference, seconds = mitsuba_mrt.render_reference(scene)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import MRTError
from ..modes import OUTPUT_DENOISED_MODES, check_mode, reconstruct
from ..recon.sampling import SamplePattern, grid_pattern
from ..types import (MRTParams, SeedStream, Skips, SparseTrace, Timings, TracedCounts,
                     check_radiance)
from ..recon.compose import region_values
from ..recon.denoise import denoise_grid, denoise_image, textured_pixels
from . import auto
from .scene import resolve_sensor, unwrap
from .trace import diffuse_shapes, is_jit, trace_pixels


@dataclass
class MRTResult:
    """Everything an MRT render produced.

    Attributes
    ----------
    image : ndarray, shape (height, width, 3)
        The reconstructed linear RGB image.
    ids : ndarray of int64, shape (height, width)
        Region id of every pixel.
    traced_mask : ndarray of bool, shape (height, width)
    pattern : SamplePattern or None
        The traced grid; None when ``auto`` rendered in full without a pilot.
    trace : SparseTrace
        Radiance and AOVs of the grid's pixels.
    params : MRTParams
    spp : int
        Samples per traced pixel actually taken.
    mode : str
        The mode asked for (``auto`` or one of :data:`mitsuba_mrt.modes.MODES`).
    mode_used : str
        The mode that ran: ``mode`` itself, or what ``auto`` chose (``full``
        for a full render).
    timings : Timings
    skips : Skips
        Shortcuts the scene allowed.
    stats : dict
        Counts of the reconstruction (``regions``, ``edge_pixels``, ...).
    auto : AutoDecision or None
        What ``auto`` chose and why.
    traced : TracedCounts
        Pixels traced with the nested integrator, by why.
    alpha : ndarray, shape (height, width), or None
        Alpha as ``mi.render`` develops it: traced at traced pixels, the
        mean of its region's samples elsewhere (the background's is 0).
    """

    image: np.ndarray
    ids: np.ndarray
    traced_mask: np.ndarray
    pattern: SamplePattern | None
    trace: SparseTrace
    params: MRTParams
    spp: int
    mode: str
    mode_used: str
    timings: Timings = field(default_factory=Timings)
    skips: Skips = field(default_factory=Skips)
    stats: dict = field(default_factory=dict)
    auto: auto.AutoDecision | None = None
    traced: TracedCounts = field(default_factory=TracedCounts)
    alpha: np.ndarray | None = None


@dataclass
class GridTracer:
    """The :class:`~mitsuba_mrt.types.Tracer` of a render: pixels of ``scene``
    seen through ``sensor``, traced with ``integrator`` at ``spp``, each
    seed stream offset from ``seed``."""

    scene: mi.Scene
    sensor: mi.Sensor
    integrator: mi.Integrator
    spp: int
    seed: int

    def __call__(self, pixel_xy: np.ndarray, *, stream: SeedStream = SeedStream.EDGES,
                 aovs: bool = True, radiance: bool = True, replay: bool = False,
                 pad: bool = False) -> SparseTrace:
        return trace_pixels(self.scene, self.sensor, self.integrator, pixel_xy, self.spp,
                            self.seed + int(stream), aovs, radiance, replay, pad)


def _check_spp(spp: int | None) -> int | None:
    if spp is not None and int(spp) < 1:
        raise MRTError(f"spp must be >= 1, got {spp}")
    return None if spp is None else int(spp)


def render(scene: mi.Scene, integrator: mi.Integrator | None = None, *, sensor=0,
           spp: int | None = None, seed: int = 0, params: MRTParams | None = None,
           mode: str | None = None, **param_overrides) -> MRTResult:
    """Render ``scene`` with the MRT: trace the grid, reconstruct the rest.

    Parameters
    ----------
    scene : mi.Scene
    integrator : mi.SamplingIntegrator, optional
        The nested integrator; default: the scene's own (if that is an
        ``mrt`` integrator, the one it wraps, with its parameters and mode).
    sensor : int or mi.Sensor
    spp : int, optional
        Samples per traced pixel; default: the sensor's sampler.
    seed : int
    params : MRTParams, optional
        Default: those of the scene's ``mrt`` integrator, else the defaults.
    mode : str, optional
        ``auto``: ``refine`` or ``idpass``, whichever a measured pilot
        predicts cheaper, when it beats a full render, otherwise the full
        render itself (see ``mode_used``); or any key of
        :data:`mitsuba_mrt.modes.MODES` (``paper``, ``fast``, ...).
        Default: the scene's ``mrt`` integrator's mode, else ``auto``.
    **param_overrides
        Fields of :class:`MRTParams` (``sample_fraction=0.05`` ...).
    """
    start = time.perf_counter()
    wrapper = unwrap(scene, integrator)
    mode = check_mode(mode or wrapper.mode or "auto", ("auto",))
    params = (params or wrapper.params or MRTParams()).with_(**param_overrides)
    sensor = resolve_sensor(scene, sensor)
    spp = _check_spp(spp) or int(sensor.sampler().sample_count())
    width, height = (int(v) for v in sensor.film().crop_size())
    tracer = GridTracer(scene, sensor, wrapper.nested, spp, seed)
    if mode == "auto":
        decision = auto.decide_without_pilot(width, height, spp, is_jit())
        if decision is not None:  # decided before any grid work: a plain full render
            image, alpha, seconds = _full_render(scene, wrapper.nested, sensor, spp, seed)
            return _full_result(image, alpha, None, None, _empty_trace(spp), params, spp,
                                decision, Timings(full_render=seconds), start)
    pattern = grid_pattern(width, height, params.sample_fraction)
    timings = Timings()
    decision = pilot = None
    if mode == "auto":
        decision, pilot = auto.decide(pattern, tracer, params)
        if decision.mode_used == "full":
            return _rest_in_full(pattern, pilot, tracer, params, spp, decision, start)
        trace = auto.rest_of_grid(pattern, pilot, tracer)
        timings.trace_more, timings.check = pilot.band.seconds, decision.check_s
    else:
        trace = tracer(pattern.pixel_xy, stream=SeedStream.GRID, replay=True)
    used = decision.mode_used if decision else mode
    timings.trace = trace.seconds
    if params.denoise != "none":
        begin = time.perf_counter()
        trace = _denoised(scene, pattern, trace, params)
        timings.denoise = time.perf_counter() - begin

    recon = reconstruct(pattern, trace, params, used, tracer)
    traced = TracedCounts(grid=pattern.count, more=int(recon.traced_mask.sum()) - pattern.count)
    alpha = region_values(recon.ids, trace.ids(params.rule_for(used)), trace.alpha, "mean")
    pattern.put_traced(alpha, trace.alpha)
    if pilot is not None:  # auto's pilot traced these rows in full: keep them
        band = pilot.band.radiance.reshape(pilot.band_height, width, 3)
        check_radiance(band, "pilot pixels")
        before = int(recon.traced_mask.sum())
        recon.image[: len(band)] = band
        alpha[: len(band)] = pilot.band.alpha.reshape(pilot.band_height, width)
        recon.traced_mask[: len(band)] = True
        traced.band = int(recon.traced_mask.sum()) - before
    if params.denoise != "none" and used in OUTPUT_DENOISED_MODES:
        begin = time.perf_counter()
        recon.image = denoise_image(recon.image, quality=params.denoise_quality)
        timings.denoise += time.perf_counter() - begin
    timings.trace_more += recon.timings.trace_more
    timings.edges, timings.interpolate = recon.timings.edges, recon.timings.interpolate
    skips = recon.skips
    skips.shadow_rays = int(not trace.shadow_rays)
    return MRTResult(recon.image, recon.ids, recon.traced_mask, pattern, trace, params,
                     trace.spp, mode, used, timings.close(time.perf_counter() - start),
                     skips, dict(recon.stats), decision, traced, alpha)


def _denoised(scene: mi.Scene, pattern: SamplePattern, trace: SparseTrace,
              params: MRTParams) -> SparseTrace:
    """``trace`` with its radiance denoised as the grid image it forms, the
    shading alone on textured diffuse surfaces, and the pixels whose samples
    all agreed kept: the background's, and a surface's if not black (all of
    its samples may have missed the light); at 1 spp none can tell."""
    grid = pattern.grid_shape + (3,)
    normal = None if trace.normal is None else trace.normal.reshape(grid)
    textured = textured_pixels(trace.shape_index, trace.albedo, diffuse_shapes(scene))
    exact = None
    if trace.variance is not None and trace.spp > 1:
        exact = ((trace.variance == 0.0).all(axis=1)
                 & ((trace.radiance > 0.0).any(axis=1) | (trace.shape_index == 0)))
        exact = exact.reshape(pattern.grid_shape)
    radiance = denoise_grid(trace.radiance.reshape(grid), trace.albedo.reshape(grid), normal,
                            params.denoise, params.denoise_quality,
                            textured=textured.reshape(pattern.grid_shape), exact=exact)
    return replace(trace, radiance=np.asarray(radiance, dtype=np.float64).reshape(-1, 3))


def _empty_trace(spp: int) -> SparseTrace:
    return SparseTrace(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64),
                       np.zeros(0, np.uint32), 0, spp, 0.0)


def _full_result(image, alpha, ids, pattern, trace, params, spp, decision, timings,
                 start) -> MRTResult:
    height, width = image.shape[:2]
    ids = np.zeros((height, width), dtype=np.int64) if ids is None else ids
    return MRTResult(image, ids, np.ones((height, width), dtype=bool), pattern, trace, params,
                     spp, "auto", "full", timings.close(time.perf_counter() - start),
                     auto=decision, traced=TracedCounts(full=height * width), alpha=alpha)


def _rest_in_full(pattern: SamplePattern, pilot: auto.Pilot, tracer: GridTracer,
                  params: MRTParams, spp: int, decision: auto.AutoDecision,
                  start: float) -> MRTResult:
    """The full render that ``auto`` falls back to after a pilot.

    The pilot's band is kept and the remaining rows are traced the same way
    (each pixel's samples placed and weighted by the film's filter), so the
    pilot is not wasted.  Ids are not traced per pixel: the pilot's grid ids
    are nearest-filled.
    """
    width, height = pattern.width, pattern.height
    rest_xy = np.stack(np.meshgrid(np.arange(width), np.arange(pilot.band_height, height)),
                       -1).reshape(-1, 2)
    rest = tracer(rest_xy, stream=SeedStream.REST, aovs=False, replay=True)
    image = np.concatenate([pilot.band.radiance, rest.radiance]).reshape(height, width, 3)
    alpha = np.concatenate([pilot.band.alpha, rest.alpha]).reshape(height, width)
    check_radiance(image, "pixels")
    sub = SamplePattern(width, height, pattern.rows[pilot.rows], pattern.cols)
    ids = sub.nearest_image(pilot.grid.ids(params.rule_for("fast")))
    timings = Timings(trace=pilot.grid.seconds, check=decision.check_s,
                      full_render=pilot.band.seconds + rest.seconds)
    return _full_result(image, alpha, ids, pattern, pilot.grid, params, spp, decision, timings,
                        start)


def render_reference(scene: mi.Scene, integrator: mi.Integrator | None = None, *,
                     sensor=0, spp: int | None = None, seed: int = 0) -> tuple[np.ndarray, float]:
    """A plain full render with the nested integrator: (RGB image, seconds).

    ``seconds`` is the whole call, as a user pays it (and as ``render``'s
    ``total`` is timed), the check for NaN and Inf included.
    """
    image, _, seconds = _full_render(scene, unwrap(scene, integrator).nested,
                                     resolve_sensor(scene, sensor), _check_spp(spp), seed)
    return image, seconds


def _full_render(scene, integrator, sensor, spp, seed) -> tuple[np.ndarray, np.ndarray, float]:
    """``mi.render``: (RGB, alpha or None, seconds of the whole call)."""
    start = time.perf_counter()
    count = sensor.sampler().sample_count()
    try:
        image = mi.render(scene, integrator=integrator, sensor=sensor, seed=seed, spp=spp or 0)
        dr.eval(image)
    finally:  # mi.render(spp=...) leaves the sensor's sampler at that count
        sensor.sampler().set_sample_count(count)
    image = np.array(image, dtype=np.float64)
    check_radiance(image[..., :3], "pixels of the full render")
    alpha = image[..., 3] if sensor.film().base_channels_count() == 4 else None
    return image[..., :3], alpha, time.perf_counter() - start
