"""A full render in passes, denoised: a time limit and a noise threshold for Mitsuba's JIT variants.

Every pass traces each pixel once more (1 spp, a box pixel filter, the
albedo and shading normal of the same samples as OIDN's guides), and the
passes go on in rounds that double their number until the denoised image's
estimated error meets the target, the next round would overrun the time
left, or the spp reach the cap; then the mean of the passes goes through
OIDN once.  Blender Cycles' time limit and noise threshold work the same way.

The error needs no reference: after a round of ``k`` passes, the mean of
the even passes is denoised and compared with the mean of the odd ones,
which are independent of it; their difference, less the odd mean's own
noise (the passes' per-pixel variance over ``k / 2``), estimates the squared
error of the image denoised from ``k / 2`` passes, and the last two rounds
say how fast it falls (:func:`predict`).  It is measured on a few strips of
rows (``rows``), so that it costs a fraction of an OIDN call.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..recon.denoise import denoise_image
from ..types import SeedStream

#: 1-spp copies of every pixel one trace takes at most (memory: lanes).
MAX_COPIES = 8
#: Passes of the first round (the fewest that give a variance and two halves).
FIRST_ROUND = 2
#: How fast a denoised image's error falls with the spp, ``spp ** -rate``,
#: until two rounds have measured it; and the range a measured rate is held in.
DEFAULT_RATE, RATE_RANGE = 0.5, (0.2, 1.0)


@dataclass
class Passes:
    """Running sums of the passes so far, per pixel (flat, ``(n, 3)``)."""

    count: int = 0
    even: np.ndarray | None = None
    odd: np.ndarray | None = None
    square: np.ndarray | None = None
    albedo: np.ndarray | None = None
    normal: np.ndarray | None = None
    alpha: np.ndarray | None = None

    def add(self, radiance, albedo, normal, alpha) -> None:
        if self.count == 0:
            zero = np.zeros_like(radiance)
            self.even, self.odd, self.square = zero.copy(), zero.copy(), zero.copy()
            self.albedo, self.normal = np.zeros_like(albedo), np.zeros_like(normal)
            self.alpha = np.zeros(len(radiance))
        (self.even if self.count % 2 == 0 else self.odd)[...] += radiance
        self.square += radiance ** 2
        self.albedo += albedo
        self.normal += normal
        if alpha is not None:
            self.alpha += alpha
        self.count += 1

    @property
    def mean(self) -> np.ndarray:
        return (self.even + self.odd) / self.count

    @property
    def variance(self) -> np.ndarray:
        """A single pass's variance per pixel and channel (unbiased)."""
        mean = self.mean
        return np.maximum(self.square / self.count - mean ** 2, 0.0) * (
            self.count / max(self.count - 1, 1))


@dataclass
class Progress:
    """What the passes did: their spp, seconds, and the estimates on the way.

    ``history`` holds (spp of the half that was denoised, its estimated
    relative error); ``predicted`` the error predicted for the final image;
    ``stopped`` why the passes ended.
    """

    spp: int = 0
    trace_s: float = 0.0
    estimate_s: float = 0.0
    denoise_s: float = 0.0
    history: list = field(default_factory=list)
    predicted: float | None = None
    full_error: float | None = None
    stopped: str = ""


def predict(history: list, spp: int) -> float:
    """The denoised error at ``spp`` from ``history`` [(spp, error), ...] (the
    last two give the rate, else :data:`DEFAULT_RATE`).

    Examples
    --------
    >>> round(predict([(1, 0.4), (2, 0.2)], 4), 6)
    0.1
    >>> round(predict([(1, 0.4)], 4), 6)
    0.2
    """
    (s1, e1) = history[-1]
    rate = DEFAULT_RATE
    if len(history) >= 2 and history[-2][1] > 0 and e1 > 0:
        (s0, e0) = history[-2]
        rate = math.log(e0 / e1) / math.log(s1 / s0)
        rate = min(max(rate, RATE_RANGE[0]), RATE_RANGE[1])
    return e1 * (spp / s1) ** -rate


def relative_error(squared: np.ndarray, reference: np.ndarray) -> float:
    """Root of the mean of ``squared`` (n, 3) over the pixels a display shows
    unclipped (``reference`` below 1), over the mean square of ``reference``
    there: the planner's relative RMS error."""
    shown = (reference <= 1.0).all(axis=1)
    if not shown.any():
        return 0.0
    power = max(float(np.mean(reference[shown] ** 2)), 1e-12)
    return float(np.sqrt(max(float(np.mean(squared[shown])), 0.0) / power))


def run_passes(tracer, width: int, height: int, rows: np.ndarray, *, quality: str,
               target_error: float | None, deadline: float | None, max_spp: int,
               full_spp: int, area: float, denoise: bool = True,
               stop_early=None, on_round=None) -> tuple[np.ndarray, np.ndarray, Progress]:
    """Trace passes until the target, the deadline or ``max_spp``; return
    (image (height, width, 3), alpha (height, width), :class:`Progress`).

    ``rows`` are the image rows the error is estimated on; ``full_spp`` and
    ``area`` (:func:`mitsuba_mrt.renderer.pilot.effective_area`) give a full
    render's own error at the scene's spp, the default target.  ``deadline``
    is a ``time.perf_counter()`` value.  ``stop_early(progress, pass_s)``,
    called after the first round, may end the passes (return a reason).
    ``on_round(stage, done)`` hears of each round (``done``: spp over ``max_spp``).
    Without ``denoise`` the image is the passes' mean.
    """
    xy = np.stack(np.meshgrid(np.arange(width), np.arange(height)), -1).reshape(-1, 2)
    n = len(xy)
    crop = (rows[:, None] * width + np.arange(width)[None, :]).ravel()
    one = replace(tracer, spp=1)
    passes, progress, launch = Passes(), Progress(), 0
    round_size, pass_s, oidn_px = FIRST_ROUND, 0.0, 0.0
    while True:
        begin = time.perf_counter()
        done = 0
        while done < round_size:
            copies = max(2, min(MAX_COPIES, round_size - done))
            trace = one(np.tile(xy, (copies, 1)), stream=SeedStream.LADDER + launch,
                        aovs=True, ids=False, box=True, replay=True)
            launch += 1
            for k in range(copies):
                part = slice(k * n, (k + 1) * n)
                passes.add(trace.radiance[part], trace.albedo[part], trace.normal[part],
                           None if trace.alpha is None else trace.alpha[part])
            done += copies
        spent = time.perf_counter() - begin
        progress.trace_s += spent
        pass_s = spent / done
        progress.spp = passes.count
        begin = time.perf_counter()
        mean = passes.mean[crop]
        variance = passes.variance[crop]
        progress.full_error = relative_error(variance / (full_spp * area), mean)
        if denoise:
            half = passes.count // 2
            shape = (len(rows), width, 3)
            denoised = denoise_image((passes.even[crop] / half).reshape(shape),
                                     (passes.albedo[crop] / passes.count).reshape(shape),
                                     (passes.normal[crop] / passes.count).reshape(shape),
                                     quality=quality).reshape(-1, 3)
            oidn_px = (time.perf_counter() - begin) / len(crop)
            squared = (np.clip(denoised, 0.0, 1.0) - passes.odd[crop] / half) ** 2 - variance / half
            progress.history.append((half, relative_error(squared, mean)))
            progress.predicted = predict(progress.history, passes.count)
        else:
            progress.predicted = relative_error(variance / passes.count, mean)
        progress.estimate_s += time.perf_counter() - begin
        if on_round is not None:
            on_round(f"passes ({passes.count} spp)", min(passes.count / max_spp, 1.0))
        target = progress.full_error if target_error is None and deadline is None \
            else target_error
        if target is not None and progress.predicted <= target:
            progress.stopped = "met the target"
            break
        if len(progress.history) <= 1 and stop_early is not None:
            reason = stop_early(progress, pass_s)
            if reason:
                progress.stopped = reason
                return None, None, progress
        next_size = passes.count  # the next round doubles the passes
        if passes.count + next_size > max_spp:
            progress.stopped = f"reached {passes.count} spp"
            break
        if deadline is not None and (time.perf_counter() + next_size * pass_s
                                     + oidn_px * n > deadline):
            progress.stopped = "the time limit"
            break
        round_size = next_size
    image = passes.mean
    if denoise:
        begin = time.perf_counter()
        image = denoise_image(image.reshape(height, width, 3),
                              (passes.albedo / passes.count).reshape(height, width, 3),
                              (passes.normal / passes.count).reshape(height, width, 3),
                              quality=quality).reshape(-1, 3)
        progress.denoise_s = time.perf_counter() - begin
    return (image.reshape(height, width, 3),
            (passes.alpha / passes.count).reshape(height, width), progress)
