"""The Python API: MRT and reference renders of a Mitsuba scene.

Example::

    import mitsuba_mrt
    mitsuba_mrt.activate("auto")
    scene = mitsuba_mrt.load_scene("scenes_xml/paper_fig1.xml", res=400)
    result = mitsuba_mrt.render(scene, sample_fraction=0.1)
    reference, seconds = mitsuba_mrt.render_reference(scene)
"""

from __future__ import annotations

import functools
import os
import time
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field, replace

import drjit as dr
import mitsuba as mi
import numpy as np

from .errors import MRTError
from .pipeline import MRTParams, Reconstruction, SparseTrace, check_radiance, reconstruct
from .sampling import SamplePattern, grid_pattern
from .trace import is_jit, trace_pixels


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
        Radiance and AOVs of the traced pixels.
    params : MRTParams
    spp : int
        Samples per traced pixel actually taken.
    mode : str
        The reconstruction mode used.
    timings : dict
        Seconds: ``trace``, ``edges``, ``interpolate``, ``total``.
    stats : dict
        Region counts of the reconstruction.
    """

    image: np.ndarray
    ids: np.ndarray
    traced_mask: np.ndarray
    pattern: SamplePattern | None
    trace: SparseTrace
    params: MRTParams
    spp: int
    mode: str
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)


def load_scene(path: str | os.PathLike, **defines) -> mi.Scene:
    """Load a Mitsuba XML scene, with ``<default>`` parameters overridden.

    Raises MRTError with a one-line message for a missing or malformed file.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise MRTError(f"scene file not found: {path}")
    try:
        ElementTree.parse(path)
    except ElementTree.ParseError as exc:
        raise MRTError(f"malformed XML in {path}: {exc}") from None
    try:
        return mi.load_file(path, **{k: str(v) for k, v in defines.items()})
    except Exception as exc:  # noqa: BLE001 - Mitsuba raises plain Exceptions
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise MRTError(f"cannot load {path}: {first}") from None


def resolve_sensor(scene: mi.Scene, sensor) -> mi.Sensor:
    """``sensor`` itself, or the scene's sensor of that index (checked)."""
    if isinstance(sensor, mi.Sensor):
        return sensor
    sensors = scene.sensors()
    if not 0 <= int(sensor) < len(sensors):
        raise MRTError(f"sensor index {sensor} out of range: the scene has {len(sensors)}")
    return sensors[int(sensor)]


def nested_integrator(scene: mi.Scene, integrator=None):
    """The integrator to trace with, and MRT parameters found on an ``mrt`` wrapper."""
    from .plugins import MRTIntegrator

    integrator = integrator if integrator is not None else scene.integrator()
    if isinstance(integrator, MRTIntegrator):
        return integrator.nested, integrator.params
    return integrator, None


#: ``auto`` runs the MRT only when its predicted time is below this share of
#: the predicted full render: a wide margin, since the pilot is small.
AUTO_MARGIN = 0.6
#: ``auto``'s pilot traces the top 1/AUTO_BAND of the image's rows.
AUTO_BAND = 16
#: Below this many samples (pixels x spp) ``auto`` renders in full without a
#: pilot: such a render takes well under a second here (0.18 s for matte at
#: 1200 x 1200), and the pilot's own launches (~10-20 % of it, measured with
#: ``bench pixels --methods auto``) would cost more than the MRT could save.
AUTO_MIN_SAMPLES = 1 << 21
#: Share of the pixels that ``refine`` is expected to trace beyond the grid
#: (measured 2-10 % on the bundled scenes at f = 0.1).
AUTO_REFINE_SHARE = 0.06


def render(scene: mi.Scene, integrator: mi.Integrator | None = None, *, sensor=0,
           spp: int | None = None, seed: int = 0, params: MRTParams | None = None,
           mode: str = "auto", **param_overrides) -> MRTResult:
    """Render ``scene`` with the MRT: trace the grid, reconstruct the rest.

    Parameters
    ----------
    scene : mi.Scene
    integrator : mi.SamplingIntegrator, optional
        The nested integrator; default: the scene's own (if that is an
        ``mrt`` integrator, the one it wraps, with its parameters).
    sensor : int or mi.Sensor
    spp : int, optional
        Samples per traced pixel; default: the sensor's sampler.
    seed : int
    params : MRTParams, optional
    mode : str
        ``auto`` (default): ``refine`` or ``idpass``, whichever a measured
        pilot predicts cheaper, when it beats a full render, otherwise the
        full render itself (see ``stats["mode_used"]``); or any key of
        :data:`mitsuba_mrt.pipeline.MODES` (``paper``, ``fast``, ...).
    **param_overrides
        Fields of :class:`MRTParams` (``sample_fraction=0.05`` ...).
    """
    from .pipeline import MODES

    start = time.perf_counter()
    if mode != "auto" and mode not in MODES:
        raise MRTError(f"unknown mode {mode!r}; choose one of auto, {', '.join(MODES)}")
    nested, scene_params = nested_integrator(scene, integrator)
    params = (params or scene_params or MRTParams()).with_(**param_overrides)
    sensor = resolve_sensor(scene, sensor)
    spp = int(spp or sensor.sampler().sample_count())
    width, height = (int(v) for v in sensor.film().crop_size())
    if mode == "auto":
        reason = _auto_without_pilot(width, height, spp)
        if reason is not None:  # decided before any grid work: this path is the full render
            return _full_fallback(scene, nested, sensor, width, height, None, None, spp, seed,
                                  params, reason, start)
    pattern = grid_pattern(width, height, params.sample_fraction)

    def tracer(pixel_xy, seed_offset=1, aovs=True, radiance=True):
        return trace_pixels(scene, sensor, nested, pixel_xy, spp, seed + seed_offset, aovs,
                            radiance)

    if mode == "auto":
        decision = _auto_decide(pattern, tracer, spp)
        if decision["mode_used"] == "full":
            return _full_fallback(scene, nested, sensor, width, height, pattern, tracer, spp,
                                  seed, params, decision, start)
        trace, used = decision.pop("trace"), decision["mode_used"]
    else:
        trace, decision, used = tracer(pattern.pixel_xy, 0), {}, mode

    recon: Reconstruction = reconstruct(pattern, trace, params, used, tracer)
    band = decision.pop("band", None)
    if band is not None:  # auto's pilot traced these rows in full: keep them
        check_radiance(band, "pilot pixels")
        recon.image[: len(band)] = band
        recon.traced_mask[: len(band)] = True
    timings = {"trace": trace.seconds, **recon.timings,
               "total": time.perf_counter() - start}
    stats = {**decision, **dict(recon.stats), "mode_used": used}
    if not trace.shadow_rays:
        stats["skipped_shadow_rays"] = 1
    return MRTResult(recon.image, recon.ids, recon.traced_mask, pattern, trace, params,
                     trace.spp, mode, timings, stats)


def _auto_decide(pattern: SamplePattern, tracer, spp: int) -> dict:
    """Decide between refine, idpass and a full render from a measured pilot.

    Called when :func:`_auto_without_pilot` found a pilot worthwhile: the pilot traces the top
    ``1 / AUTO_BAND`` of the image: every pixel with the nested integrator
    alone (what a full render pays; kept as part of the image if the full
    render wins) and the grid rows in it with the id AOVs (what the MRT pays
    per traced pixel; the difference is the id AOVs' cost).  Scaled to the
    whole image, with the reconstruction's cost per pixel calibrated once
    per process: ``refine`` adds ``AUTO_REFINE_SHARE`` of the pixels traced
    in full, ``idpass`` the id AOVs of every pixel.  The cheaper runs only
    if it is predicted below ``AUTO_MARGIN`` of the full render.
    """
    nr, nc = pattern.grid_shape
    width, height = pattern.width, pattern.height
    pixels = width * height
    band_height = height // AUTO_BAND
    band_xy = np.stack(np.meshgrid(np.arange(width), np.arange(band_height)), -1).reshape(-1, 2)
    band = tracer(band_xy, 0, False)
    xy = pattern.pixel_xy.reshape(nr, nc, 2)
    pilot_rows = np.flatnonzero(pattern.rows < band_height)
    pilot = tracer(xy[pilot_rows].reshape(-1, 2), 2)
    scale = height / band_height
    predicted_full = band.seconds * scale
    radiance_per_pixel = band.seconds / len(band_xy)
    aov_per_pixel = max(pilot.seconds / max(len(pilot.radiance), 1) - radiance_per_pixel,
                        0.1 * radiance_per_pixel)
    grid_and_reconstruction = (pilot.seconds * nr / max(len(pilot_rows), 1)
                               + _reconstruction_seconds_per_pixel() * pixels)
    predicted = {"refine": grid_and_reconstruction
                 + AUTO_REFINE_SHARE * pixels * (radiance_per_pixel + aov_per_pixel),
                 "idpass": grid_and_reconstruction + pixels * aov_per_pixel}
    best = min(predicted, key=predicted.get)
    wins = predicted[best] < AUTO_MARGIN * predicted_full
    decision = {"mode_used": best if wins else "full", "auto_reason": "pilot",
                "predicted_mrt_s": predicted[best], "predicted_full_s": predicted_full,
                "predicted_refine_s": predicted["refine"],
                "predicted_idpass_s": predicted["idpass"],
                "pilot_pixels": int(len(band_xy) + pilot.radiance.shape[0]),
                "band": band}
    if wins:
        rest_rows = np.setdiff1d(np.arange(nr), pilot_rows)
        rest = tracer(xy[rest_rows].reshape(-1, 2), 0)
        merged = _merge_rows(pattern, pilot_rows, pilot, rest_rows, rest)
        decision["trace"] = replace(merged, seconds=band.seconds + pilot.seconds + rest.seconds)
        decision["band"] = band.radiance.reshape(band_height, width, 3)
    else:
        decision["pilot"] = (pilot_rows, pilot)
    return decision


def _auto_without_pilot(width: int, height: int, spp: int) -> dict | None:
    """``auto``'s decision when no pilot is worth running, else None.

    The scalar variant traces pixel by pixel in Python while ``mi.render``
    runs Mitsuba's multithreaded C++ loop, so the MRT cannot win there;
    below ``AUTO_MIN_SAMPLES`` samples the pilot would cost more than the
    MRT could save.
    """
    if not is_jit():
        return {"mode_used": "full", "auto_reason": "scalar", "pilot_pixels": 0}
    if width * height * spp < AUTO_MIN_SAMPLES or height < 2 * AUTO_BAND:
        return {"mode_used": "full", "auto_reason": "small", "pilot_pixels": 0}
    return None


def _full_fallback(scene, nested, sensor, width, height, pattern, tracer, spp, seed, params,
                   decision, start):
    """The full render that ``auto`` falls back to, as an MRTResult.

    Without a pilot it is a plain ``mi.render``.  After a pilot, the pilot's
    band is kept and the remaining rows are traced the same way (every
    sample of a pixel averaged, as the box pixel filter of the bundled
    scenes does), so the pilot is not wasted.  Ids are not traced per pixel:
    the pilot's grid ids (or none) are nearest-filled.
    """
    band = decision.pop("band", None)
    pilot_rows, pilot = decision.pop("pilot", (None, None))
    if band is None:
        image, seconds = render_reference(scene, nested, sensor=sensor, spp=spp, seed=seed)
        ids = np.zeros((height, width), dtype=np.int64)
        trace_s = 0.0
    else:
        band_height = len(band.radiance) // width
        rest_xy = np.stack(np.meshgrid(np.arange(width), np.arange(band_height, height)),
                           -1).reshape(-1, 2)
        rest = tracer(rest_xy, 1, False)
        image = np.concatenate([band.radiance, rest.radiance]).reshape(height, width, 3)
        seconds = band.seconds + rest.seconds
        check_radiance(image, "pixels")
        sub = SamplePattern(width, height, pattern.rows[pilot_rows], pattern.cols)
        ids = sub.nearest_image(pilot.ids(params.rule_for("fast")))
        trace_s = pilot.seconds
    timings = {"trace": trace_s, "edges": 0.0, "interpolate": 0.0, "full_render": seconds,
               "total": time.perf_counter() - start}
    empty = SparseTrace(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64),
                        np.zeros(0, np.uint32), 0, spp, 0.0)
    return MRTResult(image, ids, np.ones((height, width), dtype=bool), pattern,
                     pilot if pilot is not None else empty, params, spp, "auto", timings,
                     decision)


def _merge_rows(pattern, rows_a, trace_a, rows_b, trace_b) -> SparseTrace:
    """Two traces of disjoint grid rows, as one trace in grid order."""
    nr, nc = pattern.grid_shape
    order = np.empty(nr, dtype=np.int64)
    order[np.concatenate([rows_a, rows_b])] = np.arange(nr)

    def merge(a, b):
        both = np.concatenate([a.reshape(len(rows_a), nc, -1), b.reshape(len(rows_b), nc, -1)])
        return both[order].reshape((nr * nc,) + a.shape[1:])
    optional = {name: None if getattr(trace_a, name) is None
                else merge(getattr(trace_a, name), getattr(trace_b, name))
                for name in ("path_id", "curved_mirror")}
    return replace(trace_a, radiance=merge(trace_a.radiance, trace_b.radiance),
                   albedo=merge(trace_a.albedo, trace_b.albedo),
                   shape_index=merge(trace_a.shape_index, trace_b.shape_index),
                   visible_lights=merge(trace_a.visible_lights, trace_b.visible_lights),
                   seconds=0.0, **optional)


@functools.cache
def _reconstruction_seconds_per_pixel() -> float:
    """Seconds per pixel of the fast reconstruction, measured once per process.

    A synthetic 256 x 256 scene of two regions stands in for a real one;
    the result is doubled, since real scenes have more edges.
    """
    p = grid_pattern(256, 256, 0.1)
    x, y = p.pixel_xy[:, 0], p.pixel_xy[:, 1]
    shape = 1 + ((x - 128) ** 2 + (y - 128) ** 2 < 60 ** 2)
    rad = np.repeat((0.5 + 0.001 * x)[:, None], 3, axis=1)
    trace = SparseTrace(rad, np.ones((p.count, 3)), shape, np.zeros(p.count, np.uint32),
                        0, 1, 0.0)
    reconstruct(p, trace, MRTParams(id_rule="exact"), "fast")  # warm caches
    begin = time.perf_counter()
    reconstruct(p, trace, MRTParams(id_rule="exact"), "fast")
    return 2.0 * (time.perf_counter() - begin) / (256 * 256)


def render_reference(scene: mi.Scene, integrator: mi.Integrator | None = None, *,
                     sensor=0, spp: int | None = None, seed: int = 0) -> tuple[np.ndarray, float]:
    """A plain full render with the nested integrator: (RGB image, seconds).

    ``seconds`` is the whole call, as a user pays it (and as ``render``'s
    ``total`` is timed), the check for NaN and Inf included.
    """
    start = time.perf_counter()
    nested, _ = nested_integrator(scene, integrator)
    sensor = resolve_sensor(scene, sensor)
    image = mi.render(scene, integrator=nested, sensor=sensor, seed=seed, spp=int(spp or 0))
    dr.eval(image)
    image = np.array(image, dtype=np.float64)[..., :3]
    check_radiance(image, "pixels of the full render")
    return image, time.perf_counter() - start
