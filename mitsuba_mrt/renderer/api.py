"""The Python API: MRT and reference renders of a Mitsuba scene.

Example::

    import mitsuba_mrt
    mitsuba_mrt.activate("auto")
    scene = mitsuba_mrt.load_scene("scenes_xml/paper_fig1.xml", res=400)
    result = mitsuba_mrt.render(scene, sample_fraction=0.1)
    reference, seconds = mitsuba_mrt.render_reference(scene)
    denoised, seconds = mitsuba_mrt.render_denoised(scene, spp=4)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import MRTError
from ..modes import check_controls, check_mode, render_modes
from ..modes.plan import Plan
from ..recon.compose import region_values
from ..recon.denoise import denoise_image, oidn_available
from ..recon.sampling import SamplePattern, every_pixel, grid_pattern
from ..runtime.jit import counting_kernels, recording_flags
from ..types import (KernelCounts, MRTParams, SeedStream, Skips, SparseTrace, Timings,
                     TracedCounts, check_radiance, check_seed, check_spp)
from . import auto, auto_limit, auto_plans, kept_plans
from .held_out import check_image
from .lanes import is_jit
from .pilot import effective_area
from .pipeline import mrt_image
from .replay import (Recorded, recorded_during, recorded_so_far, recording_seconds,
                     recordings)
from .scene import as_rgb, check_traceable, resolve_sensor, unwrap, warn_nested_aovs
from .trace import pass_recorded, scene_warm, trace_pixels

# Intel Open Image Denoise's module, where installed, loads with the renderer:
# its import (tens of milliseconds, mostly reading package metadata) is then
# no part of a render's time, which a time limit counts.
oidn_available()


@dataclass
class MRTResult:
    """Everything an MRT render produced.

    Attributes
    ----------
    image : ndarray, shape (height, width, 3)
        The reconstructed linear RGB image.
    ids : ndarray of int64, shape (height, width)
        Region id of every pixel (a full render's: a read-only view of 0).
    traced_mask : ndarray of bool, shape (height, width)
        The pixels traced with the nested integrator (a full render's: a
        read-only view of True).
    pattern : SamplePattern or None
        The traced grid; None when ``auto`` rendered in full.
    trace : SparseTrace
        Radiance and AOVs of the grid's pixels.
    params : MRTParams
    spp : int
        Samples per traced pixel actually taken.
    mode : str
        The mode asked for (``auto`` or one of :data:`mitsuba_mrt.modes.MODES`).
    mode_used : str
        The mode that ran: ``mode`` itself, or what ``auto`` chose (``full``
        for ``mi.render``'s image, ``full+oidn`` for a denoised full render).
    timings : Timings
    skips : Skips
        Shortcuts the scene allowed.
    stats : dict
        Counts of the reconstruction (``regions``, ``edge_pixels``, ...).
    auto : Plan or None
        What ``auto`` chose, among which candidates, and why.
    traced : TracedCounts
        Pixels traced with the nested integrator, by why.
    alpha : ndarray, shape (height, width), or None
        For an RGBA film, alpha as ``mi.render`` develops it: traced at
        traced pixels, the mean of its region's samples elsewhere (the
        background's is 0); None for an RGB film.
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
    auto: Plan | None = None
    traced: TracedCounts = field(default_factory=TracedCounts)
    alpha: np.ndarray | None = None


@dataclass
class GridTracer:
    """The :class:`~mitsuba_mrt.types.Tracer` of a render: pixels of ``scene``
    seen through ``sensor``, traced with ``integrator`` at ``spp``, each
    seed stream offset from ``seed``.  ``id_pass``: the image's id pass
    (every pixel, :data:`~mitsuba_mrt.types.SeedStream.ID_PASS`, AOVs
    alone), where ``auto`` has traced it already: the call that asks for
    it again gets it."""

    scene: mi.Scene
    sensor: mi.Sensor
    integrator: mi.Integrator
    spp: int
    seed: int
    id_pass: SparseTrace | None = None

    def __call__(self, pixel_xy: np.ndarray, *, stream: SeedStream = SeedStream.EDGES,
                 aovs: bool = True, radiance: bool = True, replay: bool = False,
                 pad: bool = False, box: bool = False, ids: bool = True,
                 albedo: bool = True, halves: bool = False,
                 variance: bool = True) -> SparseTrace:
        known = self.id_pass
        if (known is not None and stream == SeedStream.ID_PASS and aovs and not radiance
                and ids and albedo and not box and len(pixel_xy) == len(known.shape_index)):
            return known
        return trace_pixels(self.scene, self.sensor, self.integrator, pixel_xy, self.spp,
                            self.seed + int(stream), aovs, radiance, replay, pad, box, ids,
                            albedo, halves, variance)

    def pass_recorded(self, spp: int, guides: bool = True, halves: bool = False) -> bool:
        """Whether a trace of every pixel at ``spp``, as the passes launch
        it (with the ``guides``, the odd samples apart where ``halves``),
        would replay a recording: :func:`~.trace.pass_recorded`."""
        return pass_recorded(self.scene, self.sensor, self.integrator, spp, guides, halves)

    def warm(self) -> bool:
        """Whether a trace finds the scene's first uses in this process paid:
        :func:`~.trace.scene_warm`."""
        return scene_warm(self.scene, self.sensor, self.integrator)


def _spp_of(spp: int | None, sensor) -> int:
    """``spp`` where given, else the sensor's sampler's ``sample_count`` (each >= 1)."""
    if spp is not None:
        return check_spp(spp)
    count = int(sensor.sampler().sample_count())
    if count < 1:  # (a kernel would divide by it: the process would die of SIGFPE)
        raise MRTError(f"the scene's sampler takes sample_count >= 1, got {count}")
    return count


def render(scene: mi.Scene, integrator: mi.Integrator | None = None, *, sensor=0,
           spp: int | None = None, seed: int = 0, params: MRTParams | None = None,
           mode: str | None = None, progress=None, **param_overrides) -> MRTResult:
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
        ``auto``: the plan a measured pilot picks (:mod:`.auto`): a full
        render (``mi.render``'s own image), the same with a box filter
        through OIDN, or an MRT mode, under ``time_limit`` and
        ``noise_threshold`` (see ``mode_used`` and ``auto``); or any key of
        :data:`mitsuba_mrt.modes.MODES` (``paper``, ``fast``, ...).
        Default: the scene's ``mrt`` integrator's mode, else ``auto``.
    progress : callable, optional
        Called as ``progress(stage, done)`` when a stage of the render ends
        (``done`` in [0, 1], the share of the render's work done so far).
    **param_overrides
        Fields of :class:`MRTParams` (``sample_fraction=0.05``,
        ``time_limit=2.0`` ...).
    """
    with counting_kernels() as counts, recording_flags():
        result = _render(scene, integrator, sensor, spp, seed, params, mode, progress,
                         param_overrides)
    result.timings.compile = KernelCounts(*counts)
    _note_overrun(result)
    return result


#: A render under a time limit that takes more than this many times the limit
#: says so in its plan's notes.
OVERRUN = 1.1


def _note_overrun(result: MRTResult) -> None:
    """Add to ``result``'s plan a note of a time limit it overran (by more
    than :data:`OVERRUN`): a limit below what the image can cost here, or
    kernels compiled for it (a scene's first render at an image size on a
    machine: Mitsuba's camera bakes the film's size into them)."""
    plan = result.auto
    if plan is None or plan.time_limit is None:
        return
    took, limit = result.timings.total, plan.time_limit
    if took > OVERRUN * limit:
        compiled = result.timings.compile.compiled
        if compiled:
            why = (f": it compiled {compiled} kernel{'s' if compiled != 1 else ''}, which "
                   f"Dr.Jit keeps on disk for later renders")
        elif plan.choice in (auto_limit.PREVIEW, auto_limit.UNDENOISED, auto_limit.UPSAMPLED):
            why = ": the preview is the least this image costs here"
        else:
            why = ""
        plan.notes.append(f"took {took:.3f} s, {took / limit:.1f}x the time limit of "
                          f"{limit:.3g} s{why}")


#: The parameters of a render that sets none (frozen: shared).
_DEFAULTS = MRTParams()


def _render(scene, integrator, sensor, spp, seed, params, mode, progress,
            param_overrides) -> MRTResult:
    """:func:`render`'s work, its arguments as given: checked, then mode
    ``auto``'s plan and the image it names (:func:`_auto`), or the MRT's
    pipeline in the mode asked for (:func:`_mrt`)."""
    start = time.perf_counter()
    wrapper = unwrap(scene, integrator)
    mode = check_mode(mode or wrapper.mode or "auto", render_modes())
    params = (params or wrapper.params or _DEFAULTS).with_(**param_overrides)
    check_controls(mode, params)
    check_traceable(wrapper.nested, mode)
    warn_nested_aovs(wrapper.nested)
    if progress is not None and not callable(progress):
        raise MRTError(f"progress must be callable as progress(stage, done), got {progress!r}")
    sensor = resolve_sensor(scene, sensor)
    tracer = GridTracer(scene, sensor, wrapper.nested, _spp_of(spp, sensor), check_seed(seed))
    if mode == "auto":
        return _auto(tracer, params, start, progress)
    width, height = (int(v) for v in sensor.film().crop_size())
    return _mrt(grid_pattern(width, height, params.sample_fraction), tracer, params, mode,
                None, start, progress or _quiet)


def _auto(tracer: GridTracer, params: MRTParams, start: float, progress) -> MRTResult:
    """Mode ``auto``: its plan (:mod:`.auto`), then the image the plan names:
    the passes' own, a full render (``mi.render``'s), or the MRT's in the
    plan's mode (checked, :func:`_checked`, where chosen without a pilot);
    what it took kept for the next such plan, with the kernel recordings it
    made (counted from before its first trace)."""
    scene, sensor = tracer.scene, tracer.sensor
    width, height = (int(v) for v in sensor.film().crop_size())
    plan = auto.plan_without_pilot(width, height, tracer.spp, is_jit(), params,
                                   tracer.integrator)
    pattern = recorded = None
    if plan is None:
        recorded = recorded_so_far()
        pattern = grid_pattern(width, height, params.sample_fraction)
        outcome = auto.run_auto(scene, pattern, tracer, params, start, on_round=progress)
        if outcome.image is not None:
            return _passes_result(outcome, tracer, params, start)
    else:
        outcome = auto_plans.AutoOutcome(plan)
    plan, choice = outcome.plan, outcome.plan.choice
    if choice.kind == "full":
        return _full_result(tracer, params, plan, start)
    if choice.fraction is not None:  # (the plan chose its grid)
        pattern = grid_pattern(width, height, choice.fraction)
    planned = replace(tracer, spp=choice.spp, id_pass=outcome.id_pass)
    run = params.with_(denoise="oidn" if choice.denoise else "none")
    if outcome.preview_key is not None:  # (at the preset its time was planned at)
        run = auto_limit.preview_params(run)
    begin = time.perf_counter()
    with recorded_during() as made:  # (what its grid's recording takes: its kept share's)
        grid = outcome.grid if outcome.grid is not None else _grid_trace(planned, pattern)
    grid_recording_s = made.seconds
    result = _mrt(pattern, planned, run, choice.mode, plan, start, progress or _quiet, grid)
    if outcome.check:  # an MRT image chosen without a pilot: kept if its check says so
        return _checked(result, scene, pattern, tracer, params, start, recorded, progress,
                        grid_recording_s)
    if outcome.preview_key is not None and choice.mode == "fast":
        # (its grid was traced: the rest of a preview, for the next one)
        auto_limit.note_preview_after(outcome.preview_key, time.perf_counter() - begin,
                                      result.timings.denoise, width * height, tracer,
                                      run.denoise_quality, pattern.count)
    if outcome.kept_key is not None:  # (a kept plan at this spp: what it took, for the next)
        kept_plans.note_render(outcome.kept_key, planned.spp, result.timings.total,
                               recordings() == recorded.count)
    return result


def _checked(result: MRTResult, scene: mi.Scene, pattern: SamplePattern, tracer: GridTracer,
             params: MRTParams, start: float, recorded: Recorded, progress,
             grid_recording_s: float = 0.0) -> MRTResult:
    """``result``, an MRT image ``auto`` chose without a pilot, if its held-out
    check keeps it (:func:`.auto_plans.keeps`; then :mod:`.kept_plans` keeps what
    it took, less what recording its traces took since ``recorded``, of which
    ``grid_recording_s`` its grid's trace); else
    ``auto``'s denoised passes (without OIDN, the full render, kept for the
    scene's next renders), the MRT's seconds and the check's counted as
    ``check``."""
    recording_s = recording_seconds() - recorded.seconds  # (the check's own left out)
    held = check_image(result.image, result.traced_mask, tracer,
                       effective_area(tracer.sensor.film().rfilter()))
    plan = result.auto
    plan.choice = replace(plan.choice, error=held.error)
    plan.target_error, plan.pilot_pixels = held.full_error, 2 * held.pixels
    plan.pilot_s += held.seconds
    key = auto.scene_key(scene, tracer, pattern.width * pattern.height)
    key += auto.plan_key(tracer, params)
    if auto_plans.keeps(held):
        result.timings.check += held.seconds
        result.timings.close(time.perf_counter() - start)
        kept_plans.note_checked(key, plan.choice, plan.reason,
                                result.timings.total - held.seconds, result.timings,
                                recording_s, auto_limit.plan_memory_key(key, tracer),
                                grid_recording_s)
        return result
    outcome = auto.run_auto(scene, pattern, tracer, params, start, escape=False,
                            on_round=progress)
    outcome.plan.reason = (f"{plan.choice.name} missed its check ({held.error:.4f} against "
                           f"a full render's {held.full_error:.4f}): {outcome.plan.reason}")
    outcome.plan.candidates = [plan.choice]
    outcome.plan.pilot_s += result.timings.total + held.seconds
    if outcome.image is None:  # (no denoiser: the full render, for the next renders too)
        kept_plans.note_plan(key, outcome.plan.choice, outcome.plan.reason,
                             auto_limit.plan_memory_key(key, tracer))
        return _full_result(tracer, params, outcome.plan, start)
    passes = _passes_result(outcome, tracer, params, start)
    passes.timings.check += result.timings.total + held.seconds
    passes.timings.close(passes.timings.total)
    return passes


def _full_result(tracer: GridTracer, params: MRTParams, plan: Plan, start: float) -> MRTResult:
    """The full render ``plan`` chose (``mi.render``'s own image), what
    ``auto`` spent before it counted as ``check``."""
    spp = plan.choice.spp
    image, alpha, seconds = _full_render(tracer.scene, tracer.integrator, tracer.sensor, spp,
                                         tracer.seed)
    return _whole_image_result(image, alpha, params, spp, plan,
                               Timings(check=plan.pilot_s, full_render=seconds), start)


def _quiet(stage: str, done: float) -> None:
    """A ``progress`` that says nothing."""


def _mrt(pattern: SamplePattern, tracer: GridTracer, params: MRTParams, mode: str,
         plan: Plan | None, start: float, progress, grid: SparseTrace | None = None
         ) -> MRTResult:
    """The MRT's pipeline: trace the grid (unless ``grid`` is its trace
    already), denoise, reconstruct, finish."""
    trace = grid if grid is not None else _grid_trace(tracer, pattern)
    progress("trace", 0.5)
    made = mrt_image(tracer.scene, pattern, trace, params, mode, tracer)
    progress("reconstruct", 1.0)
    recon = made.recon
    alpha = None  # an RGB film has none: a full-resolution pass saved
    if tracer.sensor.film().base_channels_count() == 4:
        alpha = region_values(recon.ids, trace.ids(params.rule_for(mode)), trace.alpha, "mean")
        pattern.put_traced(alpha, trace.alpha)
    timings = Timings(trace=trace.seconds, trace_more=recon.timings.trace_more,
                      check=plan.pilot_s if plan else 0.0, denoise=made.denoise_s,
                      edges=recon.timings.edges, interpolate=recon.timings.interpolate)
    skips = recon.skips
    skips.shadow_rays = int(not trace.shadow_rays)
    traced = TracedCounts(grid=pattern.count, more=int(recon.traced_mask.sum()) - pattern.count)
    return MRTResult(recon.image, recon.ids, recon.traced_mask, pattern, made.trace, params,
                     trace.spp, "auto" if plan else mode, mode,
                     timings.close(time.perf_counter() - start), skips, dict(recon.stats),
                     plan, traced, alpha)


def _grid_trace(tracer: GridTracer, pattern: SamplePattern) -> SparseTrace:
    """The grid's trace: ``pattern``'s pixels, replayed on the image's next renders."""
    return tracer(pattern.pixel_xy, stream=SeedStream.GRID, replay=True)


def render_denoised(scene: mi.Scene, integrator: mi.Integrator | None = None, *,
                    sensor=0, spp: int | None = None, seed: int = 0,
                    quality: str = "fast") -> tuple[np.ndarray, float]:
    """A full render done as Intel Open Image Denoise asks: (RGB image, seconds).

    Every pixel at ``spp`` with a box pixel filter (no sample shared between
    pixels), the albedo and normals of the same samples as the guides,
    through OIDN's ``RT`` filter at ``quality``: the usual alternative to
    the MRT (``bench rival``).  ``seconds`` is the whole call.
    """
    start = time.perf_counter()
    sensor = resolve_sensor(scene, sensor)
    spp = _spp_of(spp, sensor)
    tracer = GridTracer(scene, sensor, unwrap(scene, integrator).nested, spp, check_seed(seed))
    width, height = (int(v) for v in sensor.film().crop_size())
    xy = every_pixel(width, height)
    with recording_flags():  # (as a render's passes: theirs replay its recording)
        trace = tracer(xy, stream=SeedStream.GRID, aovs=True, ids=False, replay=True,
                       box=True, variance=False)
    check_radiance(trace.radiance, "pixels")
    image = denoise_image(*(v.reshape(height, width, 3)
                            for v in (trace.radiance, trace.albedo, trace.normal)),
                          quality=quality)
    return image, time.perf_counter() - start


def _passes_result(outcome: auto_plans.AutoOutcome, tracer: GridTracer, params: MRTParams,
                   start: float) -> MRTResult:
    """The image ``auto``'s denoised passes made (:mod:`.progressive`)."""
    image, progress, plan = outcome.image, outcome.progress, outcome.plan
    check_radiance(image, "pixels")
    height, width = image.shape[:2]
    rgba = tracer.sensor.film().base_channels_count() == 4
    timings = Timings(trace=progress.trace_s, check=progress.estimate_s,
                      denoise=progress.denoise_s,
                      trace_more=0.0 if outcome.id_pass is None else outcome.id_pass.seconds)
    return _whole_image_result(image, outcome.alpha if rgba else None, params, progress.spp,
                               plan, timings, start)


def _whole_image_result(image, alpha, params: MRTParams, spp: int, plan: Plan,
                        timings: Timings, start: float) -> MRTResult:
    """The result of an ``auto`` plan that traced every pixel (``plan.choice.name``)."""
    shape = image.shape[:2]
    return MRTResult(image, _constant_view(_ZERO_ID, shape), _constant_view(_TRACED, shape),
                     None, _empty_trace(spp),
                     params, spp, "auto", plan.choice.name,
                     timings.close(time.perf_counter() - start), auto=plan,
                     traced=TracedCounts(full=shape[0] * shape[1]), alpha=alpha)


#: The one id and the traced flag of a full render's pixels (read-only).
_ZERO_ID, _TRACED = np.zeros(1, np.int64), np.ones(1, bool)
_ZERO_ID.flags.writeable = _TRACED.flags.writeable = False


def _constant_view(one: np.ndarray, shape: tuple) -> np.ndarray:
    """A read-only array of ``shape`` whose every element is ``one``'s only
    one: no memory allocated or written after the render (where the array
    functions that would, cold in the cache, take a full render's per cent)."""
    view = np.ndarray(shape, one.dtype, one, strides=(0,) * len(shape))
    view.flags.writeable = False
    return view


def _empty_trace(spp: int) -> SparseTrace:
    return SparseTrace(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64),
                       np.zeros(0, np.uint32), 0, spp, 0.0)


def render_reference(scene: mi.Scene, integrator: mi.Integrator | None = None, *,
                     sensor=0, spp: int | None = None, seed: int = 0) -> tuple[np.ndarray, float]:
    """A plain full render with the nested integrator: (RGB image, seconds).

    ``seconds`` is the whole call, as a user pays it (and as ``render``'s
    ``total`` is timed), the check for NaN and Inf included.
    """
    start = time.perf_counter()
    sensor = resolve_sensor(scene, sensor)
    count = _spp_of(spp, sensor)  # (checked; None stays: mi.render takes the sampler's own)
    image, _, _ = _full_render(scene, unwrap(scene, integrator).nested, sensor,
                               None if spp is None else count, check_seed(seed))
    return image, time.perf_counter() - start


def _full_render(scene, integrator, sensor, spp, seed) -> tuple[np.ndarray, np.ndarray, float]:
    """``mi.render``: (RGB, alpha or None, seconds of the whole call)."""
    start = time.perf_counter()
    count = sensor.sampler().sample_count()
    try:
        # (as a plain mi.render call runs: without the kernel history that
        # render() keeps on for its own traces, which adds to every launch)
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, False):
            image = mi.render(scene, integrator=integrator, sensor=sensor, seed=seed,
                              spp=spp or 0)
            dr.eval(image)
    finally:  # mi.render(spp=...) leaves the sensor's sampler at that count
        sensor.sampler().set_sample_count(count)
    rgb, alpha = as_rgb(np.array(image, dtype=np.float64), sensor.film())
    check_radiance(rgb, "pixels of the full render")
    return rgb, alpha, time.perf_counter() - start
