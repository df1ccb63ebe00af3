"""The Python API: MRT and reference renders of a Mitsuba scene.

Example::

    import mitsuba_mrt
    mitsuba_mrt.activate("auto")
    scene = mitsuba_mrt.load_scene("scenes_xml/paper_fig1.xml", res=400)
    result = mitsuba_mrt.render(scene, sample_fraction=0.1)
    reference, seconds = mitsuba_mrt.render_reference(scene)
"""

from __future__ import annotations

import os
import time
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from .errors import MRTError
from .pipeline import MRTParams, Reconstruction, reconstruct
from .sampling import SamplePattern, grid_pattern
from .trace import SparseTrace, trace_pixels


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
    pattern : SamplePattern
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
    pattern: SamplePattern
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


def _sensor(scene: mi.Scene, sensor) -> mi.Sensor:
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


def render(scene: mi.Scene, integrator: mi.Integrator | None = None, *, sensor=0,
           spp: int | None = None, seed: int = 0, params: MRTParams | None = None,
           mode: str = "paper", **param_overrides) -> MRTResult:
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
        Reconstruction mode, a key of :data:`mitsuba_mrt.pipeline.MODES`.
    **param_overrides
        Fields of :class:`MRTParams` (``sample_fraction=0.05`` ...).
    """
    start = time.perf_counter()
    nested, scene_params = nested_integrator(scene, integrator)
    params = (params or scene_params or MRTParams()).with_(**param_overrides)
    sensor = _sensor(scene, sensor)
    spp = int(spp or sensor.sampler().sample_count())
    width, height = (int(v) for v in sensor.film().crop_size())
    pattern = grid_pattern(width, height, params.sample_fraction)
    trace = trace_pixels(scene, sensor, nested, pattern.pixel_xy, spp, seed)

    def tracer(pixel_xy):
        return trace_pixels(scene, sensor, nested, pixel_xy, spp, seed + 1)

    recon: Reconstruction = reconstruct(pattern, trace, params, mode, tracer)
    timings = {"trace": trace.seconds, **recon.timings,
               "total": time.perf_counter() - start}
    return MRTResult(recon.image, recon.ids, recon.traced_mask, pattern, trace, params,
                     trace.spp, mode, timings, dict(recon.stats))


def render_reference(scene: mi.Scene, integrator: mi.Integrator | None = None, *,
                     sensor=0, spp: int | None = None, seed: int = 0) -> tuple[np.ndarray, float]:
    """A plain full render with the nested integrator: (RGB image, seconds)."""
    nested, _ = nested_integrator(scene, integrator)
    sensor = _sensor(scene, sensor)
    start = time.perf_counter()
    image = mi.render(scene, integrator=nested, sensor=sensor, seed=seed, spp=int(spp or 0))
    dr.eval(image)
    image = np.array(image, dtype=np.float64)[..., :3]
    seconds = time.perf_counter() - start
    bad = ~np.isfinite(image).all(axis=-1)
    if bad.any():
        raise MRTError(f"the reference render has NaN or Inf radiance at {int(bad.sum())} pixels")
    return image, seconds
