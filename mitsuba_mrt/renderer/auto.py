"""Mode ``auto``: choose ``refine``, ``idpass`` or a full render from a measured pilot."""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, fields, replace

import numpy as np

from ..modes import reconstruct
from ..recon.sampling import SamplePattern, grid_pattern
from ..runtime.jit import compile_seconds
from ..types import MRTParams, SeedStream, SparseTrace, Tracer

#: ``auto`` runs the MRT only when its predicted time is below this share of
#: the predicted full render: a wide margin, since the pilot is small.
AUTO_MARGIN = 0.6
#: ``auto``'s pilot traces the top 1/AUTO_BAND of the image's rows.
AUTO_BAND = 16
#: Below this many samples (pixels x spp) ``auto`` renders in full without a
#: pilot: the pilot's own launches would cost more than the MRT could save.
AUTO_MIN_SAMPLES = 1 << 21
#: Share of the pixels that ``refine`` is expected to trace beyond the grid.
AUTO_REFINE_SHARE = 0.1
#: On the pilot's band, mean squared errors closer than this share of the
#: band's own noise (per-pixel variance of a full render) count as equal.
BAND_TIE = 0.05


@dataclass
class AutoDecision:
    """What ``auto`` chose, and why.

    Attributes
    ----------
    mode_used : str
        ``refine``, ``idpass`` or ``full``.
    reason : str
        ``pilot`` (measured), ``inaccurate`` (measured fast enough, but less
        accurate on the pilot's band than a full render or bicubic),
        ``small`` (too few samples for a pilot to pay) or ``scalar`` (the
        scalar variant, where the MRT cannot win).
    pilot_pixels : int
        Pixels the pilot traced (its band and its grid rows).
    predicted_full_s, predicted_refine_s, predicted_idpass_s, predicted_mrt_s : float or None
        The pilot's predictions for the whole image (``predicted_mrt_s`` the
        cheaper MRT mode's), without the pilot's kernel compilation.
    compile_s : float
        Seconds of the pilot spent compiling kernels (a first run's cost,
        left out of the predictions).
    band_mse_mrt, band_mse_bicubic, band_noise : float or None
        On the pilot's band, reconstructed from its grid rows: the mean
        squared difference to the band's own render at untraced pixels of
        the chosen mode and of bicubic, and the band's noise (variance of a
        pixel's mean).
    check_s : float
        Seconds of that accuracy check (its id pass and reconstructions).
    """

    mode_used: str
    reason: str
    pilot_pixels: int = 0
    predicted_full_s: float | None = None
    predicted_refine_s: float | None = None
    predicted_idpass_s: float | None = None
    predicted_mrt_s: float | None = None
    compile_s: float = 0.0
    band_mse_mrt: float | None = None
    band_mse_bicubic: float | None = None
    band_noise: float | None = None
    check_s: float = 0.0


@dataclass
class Pilot:
    """What the pilot traced: every pixel of the top rows, and the grid rows in them."""

    band: SparseTrace      # radiance of every pixel of the band, row by row
    band_height: int
    rows: np.ndarray       # indices of the grid rows inside the band
    grid: SparseTrace      # those grid rows' samples, with the id AOVs
    ids: SparseTrace       # the band's id pass: every pixel's ids and albedo, no radiance


def decide_without_pilot(width: int, height: int, spp: int, jit: bool) -> AutoDecision | None:
    """``auto``'s decision when no pilot is worth running, else None.

    The scalar variant traces pixel by pixel in Python while ``mi.render``
    runs Mitsuba's multithreaded C++ loop, so the MRT cannot win there;
    below ``AUTO_MIN_SAMPLES`` samples the pilot would cost more than the
    MRT could save.
    """
    if not jit:
        return AutoDecision("full", "scalar")
    if width * height * spp < AUTO_MIN_SAMPLES or height < 2 * AUTO_BAND:
        return AutoDecision("full", "small")
    return None


def decide(pattern: SamplePattern, tracer: Tracer,
           params: MRTParams) -> tuple[AutoDecision, Pilot]:
    """Decide between refine, idpass and a full render from a measured pilot.

    The pilot traces the top ``1 / AUTO_BAND`` of the image: every pixel with
    the nested integrator alone (what a full render pays; kept as part of the
    image whatever wins) and the grid rows in it with the id AOVs (what the
    MRT pays per traced pixel; the difference is the id AOVs' cost), and the
    band's id pass (what ``idpass`` pays for every pixel).  Kernel
    compilation (a one-time cost) is left out.  Scaled to the whole image,
    with the reconstruction's cost per pixel calibrated once per process:
    ``refine`` adds ``AUTO_REFINE_SHARE`` of the pixels traced in full,
    ``idpass`` the id pass.  The cheaper runs only if it is
    predicted below ``AUTO_MARGIN`` of the full render and if, on the band
    reconstructed from its grid rows, it is as accurate as a full render and
    more accurate than bicubic (:func:`band_accuracy`).
    """
    nr, _ = pattern.grid_shape
    width, height = pattern.width, pattern.height
    pixels = width * height
    band_height = height // AUTO_BAND
    band_xy = np.stack(np.meshgrid(np.arange(width), np.arange(band_height)), -1).reshape(-1, 2)
    xy = pattern.pixel_xy.reshape(nr, -1, 2)
    rows = np.flatnonzero(pattern.rows < band_height)
    with compile_seconds() as band_compile:
        band = tracer(band_xy, stream=SeedStream.BAND, aovs=False, replay=True)
    with compile_seconds() as grid_compile:
        grid = tracer(xy[rows].reshape(-1, 2), stream=SeedStream.PILOT, replay=True)
    with compile_seconds() as ids_compile:
        ids = tracer(band_xy, stream=SeedStream.ID_PASS, radiance=False, replay=True)
    band_s = max(band.seconds - band_compile[0], 0.1 * band.seconds)
    grid_s = max(grid.seconds - grid_compile[0], 0.1 * grid.seconds)
    ids_s = max(ids.seconds - ids_compile[0], 0.1 * ids.seconds)
    scale = height / band_height
    predicted_full = band_s * scale
    radiance_per_pixel = band_s / len(band_xy)
    aov_per_pixel = max(grid_s / max(len(grid.radiance), 1) - radiance_per_pixel,
                        0.1 * radiance_per_pixel)
    grid_and_reconstruction = (grid_s * nr / max(len(rows), 1)
                               + reconstruction_seconds_per_pixel() * pixels)
    predicted = {"refine": grid_and_reconstruction
                 + AUTO_REFINE_SHARE * pixels * (radiance_per_pixel + aov_per_pixel),
                 "idpass": grid_and_reconstruction + ids_s * scale}
    best = min(predicted, key=predicted.get)
    wins = predicted[best] < AUTO_MARGIN * predicted_full
    decision = AutoDecision(best if wins else "full", "pilot",
                            pilot_pixels=int(len(band_xy) + grid.radiance.shape[0]),
                            predicted_full_s=predicted_full,
                            predicted_refine_s=predicted["refine"],
                            predicted_idpass_s=predicted["idpass"],
                            predicted_mrt_s=predicted[best],
                            compile_s=band_compile[0] + grid_compile[0] + ids_compile[0])
    pilot = Pilot(band, band_height, rows, grid, ids)
    if wins and len(rows) >= 2:
        begin = time.perf_counter()
        accurate = band_accuracy(pattern, pilot, params, best, decision)
        decision.check_s = time.perf_counter() - begin
        if not accurate:
            decision.mode_used, decision.reason = "full", "inaccurate"
    return decision, pilot


def band_accuracy(pattern: SamplePattern, pilot: Pilot, params: MRTParams, mode: str,
                  decision: AutoDecision) -> bool:
    """Whether ``mode`` reconstructs the pilot's band as well as it must.

    The band's grid rows (traced with their own seed) are reconstructed
    with ``mode`` and with ``bicubic``; pixels that ``mode`` traces come from
    the band's render, and its ids from the pilot's id pass over the band.  At the
    pixels neither traced, the mean squared difference to the band's render
    is the reconstruction's error plus the band's own noise ``s2``; the MRT's
    image is as accurate as a full render where that difference is at most
    ``2 s2``, and it must also be at most bicubic's (ties within
    ``BAND_TIE s2`` count as equal).  The figures go into
    ``decision``.
    """
    width, band_height = pattern.width, pilot.band_height
    ids, band = pilot.ids, pilot.band
    image = band.radiance.reshape(band_height, width, 3)

    def band_tracer(pixel_xy, *, stream=SeedStream.EDGES, aovs=True, radiance=True,
                    replay=False, pad=False):
        index = pixel_xy[:, 1] * width + pixel_xy[:, 0]
        pixels = band.take(index)
        return replace(ids.take(index), radiance=pixels.radiance, alpha=pixels.alpha,
                       variance=pixels.variance, seconds=0.0)

    sub = SamplePattern(width, band_height, pattern.rows[pilot.rows], pattern.cols)
    recon = reconstruct(sub, pilot.grid, params, mode, band_tracer)
    bicubic = reconstruct(sub, pilot.grid, params, "bicubic")
    untraced = ~recon.traced_mask
    if not untraced.any():
        return True
    noise = float(np.mean(band.variance) / max(band.spp, 1)) if band.variance is not None \
        else 0.0
    decision.band_mse_mrt = float(np.mean((recon.image - image)[untraced] ** 2))
    decision.band_mse_bicubic = float(np.mean((bicubic.image - image)[untraced] ** 2))
    decision.band_noise = noise
    # differences of rounding, or far below the band's own noise, are not of accuracy
    tiny = 1e-9 * float(np.mean(image ** 2)) + BAND_TIE * noise
    return (decision.band_mse_mrt <= 2.0 * noise + tiny
            and decision.band_mse_mrt <= decision.band_mse_bicubic + tiny)


def rest_of_grid(pattern: SamplePattern, pilot: Pilot, tracer: Tracer) -> SparseTrace:
    """The grid's trace: the pilot's rows and the rest, traced now, in grid order.

    Its ``seconds`` are both traces' (the band's are not included).
    """
    nr, nc = pattern.grid_shape
    rest_rows = np.setdiff1d(np.arange(nr), pilot.rows)
    rest = tracer(pattern.pixel_xy.reshape(nr, nc, 2)[rest_rows].reshape(-1, 2),
                  stream=SeedStream.GRID, replay=True)
    merged = merge_rows(pattern, pilot.rows, pilot.grid, rest_rows, rest)
    return replace(merged, seconds=pilot.grid.seconds + rest.seconds)


def merge_rows(pattern: SamplePattern, rows_a: np.ndarray, trace_a: SparseTrace,
               rows_b: np.ndarray, trace_b: SparseTrace) -> SparseTrace:
    """Two traces of disjoint grid rows, as one trace in grid order."""
    nr, nc = pattern.grid_shape
    order = np.empty(nr, dtype=np.int64)
    order[np.concatenate([rows_a, rows_b])] = np.arange(nr)

    def merge(a, b):
        both = np.concatenate([a.reshape(len(rows_a), nc, -1), b.reshape(len(rows_b), nc, -1)])
        return both[order].reshape((nr * nc,) + a.shape[1:])
    # every per-sample array (radiance, albedo, ids, alpha, ...), where both have it
    per_sample = {f.name: merge(getattr(trace_a, f.name), getattr(trace_b, f.name))
                  for f in fields(trace_a)
                  if isinstance(getattr(trace_a, f.name), np.ndarray)
                  and isinstance(getattr(trace_b, f.name), np.ndarray)}
    return replace(trace_a, seconds=0.0, **per_sample)


@functools.cache
def reconstruction_seconds_per_pixel() -> float:
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
