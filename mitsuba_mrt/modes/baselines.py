"""Modes ``nearest`` and ``bicubic``: scene-agnostic upsampling, what the MRT must beat.

Both see the same traced colours as the MRT and nothing else (no ids, no
albedo); the upsampling is :mod:`mitsuba_mrt.recon.upsample`.
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np

from ..recon.sampling import SamplePattern
from ..recon.upsample import upsample_nearest, upsample_spline
from ..types import MRTParams, Reconstruction, SparseTrace, Timings, Tracer


def _baseline(upsample):
    """A mode that upsamples the traced radiance with ``upsample(pattern, values)``."""

    def mode(pattern: SamplePattern, trace: SparseTrace, params: MRTParams,
             tracer: Tracer | None = None) -> Reconstruction:
        start = time.perf_counter()
        image = upsample(pattern, trace.radiance)
        image[pattern.mask] = trace.radiance
        seconds = time.perf_counter() - start
        sample_ids = trace.ids(params.rule_for("nearest"))
        ids = pattern.nearest_image(sample_ids)
        return Reconstruction(image, ids, pattern.mask, Timings(interpolate=seconds),
                              stats=Counter(regions=int(len(np.unique(ids)))))
    return mode


nearest_reconstruct = _baseline(upsample_nearest)
bicubic_reconstruct = _baseline(upsample_spline)
