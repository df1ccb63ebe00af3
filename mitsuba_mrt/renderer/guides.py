"""What a denoiser of full renders needs from Mitsuba: guide images and the sampler's spp.

A user who denoises a full render with Intel Open Image Denoise gives it an
albedo and a normal image; :func:`render_guides` renders them with
Mitsuba's own ``aov`` integrator. :func:`sampler_spp` says how many samples
per pixel the scene's sampler really takes for a request (``stratified``
and ``multijitter`` round up to a square).
"""

from __future__ import annotations

import time

import drjit as dr
import mitsuba as mi
import numpy as np

from .scene import resolve_sensor
from .scene_query import set_sample_count

#: The ``aov`` integrator's channels: albedo (RGB), then the shading normal (XYZ).
GUIDE_AOVS = "albedo:albedo,nn:sh_normal"

_integrators: dict = {}  # variant -> the aov integrator


def render_guides(scene: mi.Scene, *, sensor=0, spp: int = 1,
                  seed: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """(albedo in [0, 1], world-space shading normal in [-1, 1], seconds of the whole call).

    Both are (height, width, 3), rendered with ``aov`` at ``spp`` through
    the film's own pixel filter; the clipping keeps a filter's overshoot
    within the ranges a denoiser expects.
    """
    start = time.perf_counter()
    integrator = _integrators.get(mi.variant())
    if integrator is None:
        integrator = _integrators[mi.variant()] = mi.load_dict(
            {"type": "aov", "aovs": GUIDE_AOVS})
    image = mi.render(scene, integrator=integrator, sensor=resolve_sensor(scene, sensor),
                      seed=seed, spp=spp)
    dr.eval(image)
    image = np.array(image, dtype=np.float64)
    albedo, normal = np.clip(image[..., 0:3], 0.0, 1.0), np.clip(image[..., 3:6], -1.0, 1.0)
    return albedo, normal, time.perf_counter() - start


def sampler_spp(scene: mi.Scene, spp: int, *, sensor=0) -> tuple[str, int]:
    """(the sensor's sampler, as its plugin is named, the spp it takes when asked for ``spp``)."""
    sampler = resolve_sensor(scene, sensor).sampler().clone()
    count = set_sample_count(sampler, spp)
    name = sampler.class_name()
    name = {"LowDiscrepancySampler": "ldsampler"}.get(name, name.removesuffix("Sampler").lower())
    return name, count
