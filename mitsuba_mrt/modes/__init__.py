"""The reconstruction modes, and :func:`reconstruct`, which runs one of them.

Each mode is a function ``(pattern, trace, params, tracer) -> Reconstruction``
in a module of its own; :data:`MODES` lists them.  A new mode is a module
here and a line in the table.
"""

from __future__ import annotations

import time

from ..errors import MRTError
from ..recon.sampling import SamplePattern
from ..types import MRTParams, Reconstruction, SparseTrace, Tracer, check_radiance
from .baselines import bicubic_reconstruct, nearest_reconstruct
from .fast import fast_reconstruct
from .idpass import idpass_reconstruct
from .paper import paper_reconstruct
from .refine import refine_reconstruct
from .smoothing import SMOOTHED_BESIDE, smoothed_trace

#: Reconstruction modes by name: ``fn(pattern, trace, params, tracer) -> Reconstruction``.
MODES = {
    "paper": paper_reconstruct,      # the report's quadtree + smoothing + per-id RBF
    "fast": fast_reconstruct,        # nearest-sample ids, within-id cubic
    "refine": refine_reconstruct,    # fast, after tracing the edges down to pixels
    "idpass": idpass_reconstruct,    # exact ids and albedo at every pixel
    "nearest": nearest_reconstruct,  # baseline: nearest traced pixel
    "bicubic": bicubic_reconstruct,  # baseline: bicubic spline through the grid
}

def render_modes() -> tuple[str, ...]:
    """What :func:`mitsuba_mrt.render` takes as ``mode``: ``auto`` (a measured
    plan, :mod:`mitsuba_mrt.renderer.auto`, which may run any of the others or
    a full render) and every reconstruction of :data:`MODES` (as it is now)."""
    return ("auto",) + tuple(MODES)

#: Modes that need a tracer (they trace pixels beyond the grid).
TRACING_MODES = ("refine", "idpass")

#: Modes whose image, with ``denoise``, is denoised once more as a whole after
#: the reconstruction: the pixels they trace beyond the grid (``refine``'s
#: edges and rough cells, a fifth to two fifths of an ordinary scene's pixels)
#: carry the noise of their spp, which the grid's denoising does not reach.
OUTPUT_DENOISED_MODES = ("refine",)

def check_mode(mode: str, choices: tuple[str, ...] | None = None) -> str:
    """``mode`` if it is one of ``choices`` (default: :data:`MODES`), else MRTError."""
    choices = tuple(MODES) if choices is None else choices
    if mode not in choices:
        raise MRTError(f"unknown mode {mode!r}; choose one of {', '.join(choices)}")
    return mode


def check_controls(mode: str, params: MRTParams) -> None:
    """MRTError where ``params`` set one of ``auto``'s controls
    (``time_limit``, ``noise_threshold``) for another ``mode``, which
    has no way to honour it."""
    for name in ("time_limit", "noise_threshold"):
        if mode != "auto" and getattr(params, name) is not None:
            raise MRTError(f"{name} applies to mode auto only, not to mode {mode!r}")


def reconstruct(pattern: SamplePattern, trace: SparseTrace, params: MRTParams = MRTParams(),
                mode: str = "paper", tracer: Tracer | None = None) -> Reconstruction:
    """Reconstruct the full image from the traced grid with one of :data:`MODES`.

    Parameters
    ----------
    pattern : SamplePattern
        The traced grid.
    trace : SparseTrace
        Radiance and AOVs of the traced pixels, rows outer, columns inner.
    params : MRTParams
    mode : str
        A key of :data:`MODES` (``paper``, ``fast``, ``bicubic``, ...).
    tracer : Tracer, optional
        Traces more pixels, for the modes that refine (``refine``, ``idpass``).

    Examples
    --------
    >>> import numpy as np
    >>> from mitsuba_mrt.recon.sampling import grid_pattern
    >>> p = grid_pattern(8, 8, 0.25)
    >>> t = SparseTrace(np.ones((p.count, 3)), np.full((p.count, 3), 0.5),
    ...                 np.ones(p.count, int), np.ones(p.count, np.uint32), 1, 1, 0.0)
    >>> out = reconstruct(p, t)
    >>> float(out.image.min()), float(out.image.max())
    (1.0, 1.0)
    """
    check_mode(mode)
    if mode in TRACING_MODES and tracer is None:
        raise MRTError(f"mode {mode!r} needs a tracer to trace pixels beyond the grid")
    n = pattern.count
    shapes = (trace.radiance.shape, trace.albedo.shape, trace.shape_index.shape,
              trace.visible_lights.shape)
    if shapes != ((n, 3), (n, 3), (n,), (n,)):
        raise MRTError(f"expected {n} traced samples with radiance, albedo and ids, got {shapes}")
    check_radiance(trace.radiance)
    start = time.perf_counter()
    smoothed = trace if mode in SMOOTHED_BESIDE else smoothed_trace(pattern, trace, params, mode)
    seconds = time.perf_counter() - start
    recon = MODES[mode](pattern, smoothed, params, tracer)
    if smoothed is not trace:  # traced pixels keep what was traced
        pattern.put_traced(recon.image, trace.radiance)
        recon.timings.interpolate += seconds
    return recon
