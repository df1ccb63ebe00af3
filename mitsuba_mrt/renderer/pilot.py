"""``auto``'s pilot: every candidate's cost and error, measured on strips of the image.

The pilot traces a few full-width strips of the image (:data:`STRIP_COUNT`,
each spanning grid rows, :func:`strips_of`) in the ways the candidates
would:

- a reference: the strips' pixels with the nested integrator alone, as two
  independent halves of ``REFERENCE_SHARE`` of the scene's spp (what a full
  render pays per sample; the halves' per-pixel sample variance is the
  noise);
- the strips at 1 spp, :data:`LADDER`'s largest number of times, with a box
  pixel filter and the albedo and normals of the same samples: summed, the
  denoised full render at each spp of the ladder;
- the grid rows inside the strips with the id AOVs at the scene's spp, and
  the strips' id pass: each MRT mode's image of the strips, the pixels it
  traces beyond the grid taken from the first reference half.

A candidate's error is its mean squared difference to a reference it is
independent of, less that reference's own noise (its variance, known from
the samples, or from the halves' difference where the sampler stratifies
them): an estimate of its squared error against the converged image,
without one.  A full render's error is its noise alone, from the same
variance.  Errors are relative RMS: the root of that mean over the pixels a
display shows unclipped (reference below 1), over the reference's mean
square there.  Costs are the strips' times (kernel compilation left out)
scaled to the image.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import mitsuba as mi
import numpy as np

from ..modes.plan import Candidate
from ..recon.denoise import denoise_image, oidn_available, preset
from ..recon.metrics import relative_error
from ..recon.sampling import SamplePattern
from ..runtime.jit import kernel_seconds
from ..types import MRTParams, SeedStream, SparseTrace
from .pipeline import mrt_image
from .pixel_filter import filter_table
from .scene_query import sampler_bakes_spp

#: Strips the pilot traces, spread over the image's height.
STRIP_COUNT = 2
#: Each strip spans at least this many rows, and about this share of the image's.
STRIP_MIN_ROWS, STRIP_SHARE = 16, 1 / 32
#: The reference's spp, both halves together, as a share of the scene's.
REFERENCE_SHARE = 0.5
#: Samples per pixel of the denoised full renders the pilot predicts.
LADDER = (1, 2, 4, 8)
#: The MRT modes among the candidates.
MRT_MODES = ("fast", "refine", "idpass")


@dataclass(frozen=True)
class Strip:
    """Full-width rows ``top`` to ``top + height - 1``; ``grid_rows`` indexes
    the pattern's rows inside, the first at ``top``, the last at the bottom."""

    top: int
    height: int
    grid_rows: np.ndarray


@dataclass
class PilotResult:
    """The pilot's candidates, with what it spent."""

    candidates: list
    full_error: float
    pixels: int
    compile_s: float
    notes: list


def strips_of(pattern: SamplePattern) -> list[Strip]:
    """:data:`STRIP_COUNT` strips centred at equal steps down the image, each
    from one grid row to another at least ``STRIP_MIN_ROWS`` rows on (fewer
    where the image has too few grid rows)."""
    rows = pattern.rows
    want = max(STRIP_MIN_ROWS, round(pattern.height * STRIP_SHARE))
    out = []
    for k in range(1, STRIP_COUNT + 1):
        centre = pattern.height * k / (STRIP_COUNT + 1)
        first = int(np.clip(np.searchsorted(rows, centre - want / 2), 0, len(rows) - 2))
        last = int(np.searchsorted(rows, rows[first] + want - 1))
        last = min(max(last, first + 1), len(rows) - 1)
        if out and first <= out[-1].grid_rows[-1]:
            continue  # overlaps the last: too few rows for two strips
        out.append(Strip(int(rows[first]), int(rows[last] - rows[first] + 1),
                         np.arange(first, last + 1)))
    return out


def effective_area(rfilter) -> float:
    """Pixels over which a full render spreads each sample: its noise
    variance is a lone pixel's over this (1 for a box filter)."""
    table = filter_table(rfilter)
    return float(1.0 / (np.sum(table.pdf ** 2) * table.cell)) ** 2


def _timed(trace_fn, *args, **kwargs) -> tuple[SparseTrace, float]:
    """(trace, seconds of it that compiled kernels)."""
    with kernel_seconds() as spent:
        out = trace_fn(*args, **kwargs)
    return out, spent.compile


def run_pilot(scene: mi.Scene, pattern: SamplePattern, tracer, params: MRTParams,
              target_error: float | None = None, budget: float | None = None,
              denoised: bool = True) -> PilotResult:
    """Measure the candidates on :func:`strips_of` ``pattern`` (see the module).

    ``target_error`` (None: the full render's at the scene's spp, unless a
    ``budget`` is given) and ``budget`` (seconds) let it skip the MRT's
    candidates, and their traces, where their grid alone would cost more than
    the cheapest candidate already known to meet the target, or than the budget.
    Without ``denoised`` the denoised full renders are left out (``auto``'s
    passes measure those themselves, :mod:`.progressive`).
    """
    strips = strips_of(pattern)
    width, spp, pixels = pattern.width, tracer.spp, pattern.width * pattern.height
    xy = _strip_xy(strips, width)
    n = len(xy)
    half = replace(tracer, spp=max(1, round(spp * REFERENCE_SHARE / 2)))
    # both halves in one trace: each copy of a pixel draws samples of its own
    halves, compile_ref = _timed(half, np.tile(xy, (2, 1)), stream=SeedStream.REFERENCE,
                                 aovs=False, replay=True)
    ref_a, ref_b = halves.take(slice(0, n)), halves.take(slice(n, 2 * n))
    # (a sampler that bakes its spp stratifies a pixel's samples)
    ref = Reference.of(ref_a, ref_b, stratified=sampler_bakes_spp(tracer.sensor.sampler()))
    sample_s = max(halves.seconds - compile_ref, 0.0) / (2 * n * half.spp)
    area = effective_area(tracer.sensor.film().rfilter())
    candidates = [Candidate("full", "full", s, seconds=pixels * s * sample_s,
                            error=ref.full_error(s, area), compile_s=compile_ref)
                  for s in _halvings(spp)]
    result = PilotResult(candidates, ref.full_error(spp, area), 2 * n, compile_ref, [])
    denoising = oidn_available()
    if denoising and denoised:
        count = min(LADDER[-1], spp)
        ones, compile_box = _timed(replace(tracer, spp=1), np.tile(xy, (count, 1)),
                                   stream=SeedStream.LADDER, replay=True, box=True)
        ladder = [ones.take(slice(k * n, (k + 1) * n)) for k in range(count)]
        result.pixels += count * n
        result.compile_s += compile_box
        one_px = max(ones.seconds - compile_box, 0.0) / (count * n)
        aov_px = one_px * spp  # the grid's cost per pixel, until it is measured
        candidates += _denoised(ref, strips, width, ladder, params, pixels, one_px, aov_px,
                                spp, compile_box)
    elif not denoising:
        result.notes.append("Intel Open Image Denoise is not installed (pip install mitsuba-oidn): "
                            "the plan considers no denoising")
    if target_error is None and budget is None:
        target_error = result.full_error
    affordable = _affordable(candidates, target_error, budget)
    if pattern.count * spp * sample_s > affordable:
        result.notes.append("the MRT's grid alone costs more than the best plan: "
                            "its modes were not measured")
        return result
    _add_mrt(result, scene, pattern, strips, ref, ref_a, tracer, params, denoising, affordable)
    return result


def _affordable(candidates: list, target_error: float | None, budget: float | None) -> float:
    """The most a further candidate may cost to be chosen: the cheapest
    known one that meets the target, and the budget."""
    meeting = [c.seconds for c in candidates
               if target_error is not None and c.error <= target_error]
    return min(meeting + ([budget] if budget is not None else []) + [float("inf")])


def _add_mrt(result: PilotResult, scene, pattern: SamplePattern, strips: list, ref: "Reference",
             ref_a: SparseTrace, tracer, params: MRTParams, denoising: bool,
             affordable: float) -> None:
    """Trace the strips' grid rows and id pass; add each MRT mode's candidate."""
    nr, nc = pattern.grid_shape
    grid_xy = np.concatenate([pattern.pixel_xy.reshape(nr, nc, 2)[s.grid_rows].reshape(-1, 2)
                              for s in strips])
    xy_count = len(ref.mean)
    grid, compile_grid = _timed(tracer, grid_xy, stream=SeedStream.PILOT, replay=True)
    ids, compile_ids = _timed(tracer, _strip_xy(strips, pattern.width), stream=SeedStream.ID_PASS,
                              radiance=False, replay=True)
    result.pixels += len(grid_xy) + xy_count
    result.compile_s += compile_grid + compile_ids
    pixels = pattern.width * pattern.height
    grid_px = max(grid.seconds - compile_grid, 0.0) / len(grid_xy)
    ids_s = max(ids.seconds - compile_ids, 0.0) * pixels / xy_count
    mrt_image(scene, SamplePattern(pattern.width, strips[0].height,
                                   pattern.rows[strips[0].grid_rows] - strips[0].top,
                                   pattern.cols),
              grid.take(slice(0, len(strips[0].grid_rows) * nc)), params, "fast", None)  # warm-up
    for denoise in ((False, True) if denoising else (False,)):
        for mode in MRT_MODES:
            floor = grid_px * pattern.count + (ids_s if mode == "idpass" else 0.0)
            if floor > affordable:
                continue
            result.candidates.append(_mrt(scene, pattern, strips, ref, ref_a, ids, grid, params,
                                          mode, denoise, grid_px, ids_s, compile_grid
                                          + (compile_ids if mode == "idpass" else 0.0)))


def _strip_xy(strips: list, width: int) -> np.ndarray:
    """(column, row) of every pixel of ``strips``, strip after strip."""
    return np.concatenate([np.stack(np.meshgrid(np.arange(width),
                                                np.arange(s.top, s.top + s.height)),
                                    -1).reshape(-1, 2) for s in strips])


def _halvings(spp: int) -> list[int]:
    """``spp``, its half, its quarter, ... down to 1."""
    out = [int(spp)]
    while out[-1] > 1:
        out.append(out[-1] // 2)
    return out


@dataclass
class Reference:
    """The pilot's reference of the strips, and errors measured against it.

    ``a`` and ``b`` are its two independent halves, ``mean`` both together;
    ``variance`` a single sample's per pixel; ``noise_b`` and ``noise_mean``
    the variance of ``b`` and of ``mean`` per pixel: the sample variance
    over their spp, or, where the sampler stratifies a pixel's samples
    (their mean varies less than that says), from the halves' own
    difference (its square is twice a half's variance).
    """

    a: np.ndarray
    b: np.ndarray
    mean: np.ndarray
    spp_a: int
    spp_b: int
    variance: np.ndarray
    noise_b: np.ndarray
    noise_mean: np.ndarray

    @classmethod
    def of(cls, a: SparseTrace, b: SparseTrace, stratified: bool = False) -> "Reference":
        """The reference of halves ``a`` and ``b`` (of equal spp where ``stratified``)."""
        mean = (a.radiance * a.spp + b.radiance * b.spp) / (a.spp + b.spp)
        variance = 0.5 * (a.variance + b.variance)
        if stratified:
            half = 0.5 * (a.radiance - b.radiance) ** 2
            noise_b, noise_mean = half, 0.5 * half
        else:
            noise_b, noise_mean = variance / b.spp, variance / (a.spp + b.spp)
        return cls(a.radiance, b.radiance, mean, a.spp, b.spp, variance, noise_b, noise_mean)

    def relative(self, squared: np.ndarray) -> float:
        """The relative RMS error of per-pixel squared errors (n, 3)
        (:func:`mitsuba_mrt.recon.metrics.relative_error`)."""
        return relative_error(squared, self.mean)

    def full_error(self, spp: int, area: float) -> float:
        """A full render's error at ``spp``: its noise."""
        return self.relative(self.variance / (spp * area))

    def against_mean(self, image: np.ndarray) -> float:
        """The error of ``image`` (n, 3), independent of the reference, as displayed."""
        return self.relative((shown(image) - self.mean) ** 2 - self.noise_mean)


def shown(image: np.ndarray) -> np.ndarray:
    """``image`` clipped to what a display shows, [0, 1]: an error beyond
    (a light's radiance spread over its surround) is seen as no larger.
    The reference is never clipped, so its noise still averages out."""
    return np.clip(image, 0.0, 1.0)


def _denoised(ref: Reference, strips: list, width: int, ladder: list, params: MRTParams,
              pixels: int, one_px: float, grid_px: float, spp: int,
              compile_s: float) -> list[Candidate]:
    """The denoised full renders of :data:`LADDER`: each strip's sum of the
    first ``s`` 1-spp traces through OIDN, guided by their albedo and normals."""
    made, calls = [], []
    for s in [s for s in LADDER if s <= len(ladder)]:
        radiance = sum(t.radiance for t in ladder[:s]) / s
        albedo = sum(t.albedo for t in ladder[:s]) / s
        # the strips stacked into one image: one OIDN call (their seams are few rows)
        shape = (len(radiance) // width, width, 3)
        begin = time.perf_counter()
        image = denoise_image(radiance.reshape(shape), albedo.reshape(shape),
                              ladder[0].normal.reshape(shape),
                              quality=preset(params.denoise_quality)).reshape(-1, 3)
        calls.append((time.perf_counter() - begin) / len(radiance))
        made.append((s, image))
    # OIDN's first calls set up its device and filter: the fastest call is its cost
    oidn_px = min(calls)
    return [Candidate("full+oidn", "denoised", s, denoise=True,
                      seconds=pixels * (one_px + (grid_px - one_px) * (s - 1) / max(spp - 1, 1)
                                        + oidn_px),
                      error=ref.against_mean(image), compile_s=compile_s)
            for s, image in made]


def _mrt(scene, pattern: SamplePattern, strips: list, ref: Reference, ref_a: SparseTrace,
         ids: SparseTrace, grid: SparseTrace, params: MRTParams, mode: str, denoise: bool,
         grid_px: float, ids_s: float, compile_s: float) -> Candidate:
    """An MRT mode's candidate: each strip reconstructed from its grid rows,
    the pixels the mode traces beyond the grid served from the first
    reference half (their error is then the render's noise at them, the
    variance over the spp, where no denoiser runs over them)."""
    params = params.with_(denoise="oidn" if denoise else "none")
    width = pattern.width
    squared, seconds, more, start, grid_start = np.empty_like(ref.mean), 0.0, 0, 0, 0
    for strip in strips:
        stop = start + strip.height * width
        sub = SamplePattern(width, strip.height, pattern.rows[strip.grid_rows] - strip.top,
                            pattern.cols)
        part = grid.take(slice(grid_start, grid_start + sub.count))
        grid_start += sub.count

        def serve(pixel_xy, *, base=start, **_):
            index = base + pixel_xy[:, 1] * width + pixel_xy[:, 0]
            traced = ref_a.take(index)
            return replace(ids.take(index), radiance=traced.radiance, alpha=traced.alpha,
                           variance=traced.variance, spp=grid.spp, seconds=0.0)

        begin = time.perf_counter()
        made = mrt_image(scene, sub, part, params, mode, serve)
        seconds += time.perf_counter() - begin
        image = made.recon.image.reshape(-1, 3)
        served = (made.recon.traced_mask & ~sub.mask).ravel()
        more += int(served.sum())
        err = (shown(image) - ref.b[start:stop]) ** 2 - ref.noise_b[start:stop]
        if not (denoise and mode == "refine"):
            err[served] = ref.variance[start:stop][served] / grid.spp
        squared[start:stop] = err
        start = stop
    n, pixels = len(ref.mean), pattern.width * pattern.height
    trace_s = grid_px * (pattern.count + more * pixels / n) + (ids_s if mode == "idpass" else 0.0)
    name = mode + ("+oidn" if denoise else "")
    return Candidate(name, "mrt", grid.spp, mode=mode, denoise=denoise,
                     seconds=trace_s + seconds * pixels / n, error=ref.relative(squared),
                     compile_s=compile_s)
