"""The modes' first stage: the traced grid smoothed within its noise.

:func:`smoothed_radiance` is :func:`mitsuba_mrt.recon.smooth.smooth_grid`
on the grid's irradiance (radiance / albedo, so that textures are not
blurred), multiplied back by the albedo; :func:`smoothed_trace` is the
trace with that radiance, for the modes of :data:`SMOOTHED_MODES`.  Mode
``fast`` smooths its values itself, beside its id work
(:class:`~mitsuba_mrt.recon.within_region.TracedGridValues`), rather than
before it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..recon.bounds import suppress_fireflies
from ..recon.compose import safe_albedo
from ..recon.sampling import SamplePattern
from ..recon.smooth import smooth_grid
from ..types import MRTParams, SparseTrace

#: Modes whose grid is smoothed within the noise first (``params.noise_smoothing``);
#: ``paper`` stays the report's, the baselines plain.
SMOOTHED_MODES = ("fast", "refine", "idpass")
#: Of those, the modes that smooth their grid themselves, beside their id
#: work (which needs no values), rather than before it.
SMOOTHED_BESIDE = ("fast",)


def smooths(trace: SparseTrace, params: MRTParams, mode: str) -> bool:
    """Whether ``mode``'s grid is smoothed: a mode of :data:`SMOOTHED_MODES`,
    ``noise_smoothing`` above 0, a variance with some noise in it (not a
    deterministic trace) and no denoised grid."""
    return (mode in SMOOTHED_MODES and params.noise_smoothing > 0
            and trace.variance is not None and params.denoise == "none"
            and bool(trace.variance.any()))


def smoothed_trace(pattern: SamplePattern, trace: SparseTrace, params: MRTParams,
                   mode: str) -> SparseTrace:
    """``trace`` with its grid radiance smoothed within the noise
    (:func:`smoothed_radiance`), or ``trace`` itself where ``mode``'s is not
    (:func:`smooths`).  Fireflies are left to the modes."""
    if not smooths(trace, params, mode):
        return trace
    return replace(trace, radiance=smoothed_radiance(pattern, trace, params, mode))


def smoothed_radiance(pattern: SamplePattern, trace: SparseTrace, params: MRTParams,
                      mode: str) -> np.ndarray:
    """The grid's radiance (n, 3) smoothed within the noise: irradiance
    through :func:`~mitsuba_mrt.recon.smooth.smooth_grid` at
    ``params.noise_smoothing``, under ``mode``'s ids, fireflies neither
    changed nor used; a sample the smoothing left as it was keeps its
    traced radiance exactly.  ``trace`` must have a variance."""
    grid = pattern.grid_shape + (3,)
    albedo = safe_albedo(trace.albedo)
    values = (np.asarray(trace.radiance, dtype=np.float64) / albedo).reshape(grid)  # demodulated
    # (in place where the arrays are this function's own: a fresh array costs its pages)
    noise = np.multiply(albedo, trace.spp)
    noise *= albedo
    noise = np.divide(trace.variance, noise, out=noise).reshape(grid)
    ids = trace.ids(params.rule_for(mode)).reshape(pattern.grid_shape)
    suppressed, fireflies = suppress_fireflies(ids, values)
    fixed = (suppressed != values).any(axis=-1) if fireflies else None
    out = smooth_grid(ids, values, noise, params.noise_smoothing, fixed)
    kept = (out == values).reshape(-1, 3)
    radiance = np.multiply(out.reshape(-1, 3), albedo, out=albedo)
    np.copyto(radiance, trace.radiance, where=kept)
    return radiance
