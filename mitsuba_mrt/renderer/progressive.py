"""A full render in passes, denoised: a time limit and a noise threshold for Mitsuba's JIT variants.

Every pass traces each pixel once more (a box pixel filter; the first
:data:`GUIDE_PASSES` also the albedo and shading normal of the same
samples, OIDN's guides), and the passes go on in rounds that double their
number (or, near the target, add what the estimates say it lacks:
:func:`to_target`) until the denoised image's estimated error meets it, the
next round would overrun the time left (then smaller launches fill what is
left of it), or the spp reach the cap; then the mean of the passes goes
through OIDN once (with ``quality="auto"`` at the preset
:func:`final_quality` picks).  A round is one launch, its odd and even samples its
two halves (under a time limit, a sampler that compiles kernels per spp
launches the spp whose kernels it has and a few squares,
:data:`~.auto_limit.LADDER`).  Blender Cycles'
time limit and noise threshold work the same way.

The error needs no reference: after a round of ``k`` passes, the mean of
one half of them is denoised and compared with the mean of the other,
which are independent of it; their difference, less the odd mean's own
noise (from the two means' difference), estimates the squared
error of the image denoised from ``k / 2`` passes, and the last two rounds
say how fast it falls (:func:`predict`); a round that ends the passes at
their cap is not estimated, only predicted.  A sampler that stratifies a
pixel's samples (all of Mitsuba's but ``independent``) makes its odd and
even samples no independent halves (their difference overstates the noise,
and the estimate said 0): there the whole round is denoised and compared
with every other estimated row traced again in the same launch (other
lanes, so other random numbers), less those pixels' noise (half the two's squared
difference).  It is measured on a quarter of the
rows (:func:`estimate_rows`), so that it costs a fraction of an OIDN call.
The default target, a full render's own error at the scene's spp, is
measured there too, where a round's halves are its odd and even samples:
some of those pixels traced again in the first round's launch, after the
image's, as lanes enough for two halves of half the scene's spp each
(:func:`~.held_out.noise_lanes`; one launch records one kernel layout, not
two).  With a sampler that stratifies it is the passes' samples' variance
over the scene's spp, as if they were independent, which overstates a full
render's noise: there the estimates are of a round's image denoised on the
strips alone, which has more error than the final image, and a traced
target ran the passes on well past a full render's quality.
Under a time limit alone no error is estimated: the passes only fill the
time, less what the last OIDN call is expected to take
(:func:`~mitsuba_mrt.recon.denoise.expected_seconds`): a launch of 1 spp,
then launches of as many spp as the launches' cost so far says fit
(:class:`~.launch_cost.LaunchCost`: a launch's fixed part makes a few large launches
cheaper than many small ones, as one launch is the alternative's).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..recon.denoise import (CLEAN_TEXTURE_SPP, denoise_image, denoise_seconds,
                             denoise_shading, expected_seconds, preset, texture_seconds,
                             textured_pixels)
from ..recon.metrics import relative_error
from ..recon.sampling import every_pixel
from ..runtime.jit import kernel_seconds
from ..types import SeedStream
from .held_out import lanes_noise, noise_lanes, spread
from .launch_cost import ROUND_SAFETY, LaunchCost
from .pixel_filter import pixel_weights, through_filter
from .replay import recorded_during
from .scene_query import sample_count_at_most, sampler_bakes_spp

#: Passes of the first round (the fewest that give a variance and two halves).
FIRST_ROUND = 2
#: For the default target (a full render's own noise) the first round traces
#: this share of the scene's spp: where a denoised render's error usually
#: meets that noise, so that one round, and one launch, often end the passes.
DEFAULT_FIRST_SHARE = 1 / 8
#: How fast a denoised image's error falls with the spp, ``spp ** -rate``,
#: until two rounds have measured it (the slow end of what OIDN's curves
#: show between 4 and 8 spp); and the range a measured rate is held in.
DEFAULT_RATE, RATE_RANGE = 0.2, (0.2, 1.0)
#: A round after the first aims this far below the target (its estimate is
#: noisy): where the last round nearly met it, the next adds what
#: :func:`needed_spp` says it lacks, rather than doubling the passes (a
#: sampler that compiles kernels per spp keeps doubling: a new spp compiles).
TARGET_MARGIN = 0.95
#: Passes that also trace the albedo and normals, OIDN's guides (they cost
#: about half a sample more each, and the guides converge long before the
#: colour), or the whole first round where it has more.
GUIDE_PASSES = 4
#: Passes before an estimate may say the target is met: 1 spp against 1
#: spp is the noisiest estimate, and a firefly can make it say 0.
MIN_SPP_MET = 4
#: Strips of rows the error is estimated on (a quarter of the image's rows),
#: and the most pixels they hold in all (a 256 x 256 image's quarter): more
#: would cost the rounds' OIDN calls without making the estimate surer.
ESTIMATE_STRIPS, ESTIMATE_PIXELS = 4, 1 << 14
#: OIDN's ``high`` preset against ``fast``, on these images: how much longer
#: its call takes (2 cores, 256-512 px), and the share of ``fast``'s error it
#: leaves in :func:`final_quality`'s rule: the value whose choices lose least
#: at equal time on ``bench rival``'s curves (256 and 512 px, and fresh
#: processes': 0.2-1.3 % of the error at 2-32 spp; 0.93, the median share at
#: equal spp from 8 spp on, lost 8-15 % at 2-4 spp, where ``high`` gains less).
HIGH_COST, HIGH_GAIN = 1.9, 0.96
#: Each pass's radiance is clipped at this for the estimates, as a display
#: (and the report's metric) clips: a bright sample's excess is noise the
#: estimates cannot average out.
ESTIMATE_CLIP = 1.0

#: Whether the passes denoise the textured diffuse surfaces as their shading
#: (:attr:`Passes.shading`; ``examples/auto_choices.py`` turns it off to
#: measure what it gives).
SHADING = True


@dataclass
class Passes:
    """Running sums of the passes so far, per pixel (flat, ``(n, 3)``).

    The image is the sum over every pixel (``total``); the estimates read
    ``halves``, the sums of the two independent halves over the pixels of
    ``crop`` alone, each trace's half means clipped at :data:`ESTIMATE_CLIP`
    first, so that a rare bright sample (a caustic's firefly) does not swamp
    what the other pixels say; and for the variance (where
    :attr:`reads_variance`), ``clipped`` and ``square``, the sums of each
    trace's pixel means and of its samples' squares, means and variances
    clipped likewise.  ``guides`` counts the
    samples that traced the guides, ``guide_spp`` how many should.  Counts
    are samples per pixel.  Without ``estimated`` (nothing is estimated: a
    time limit alone, a plan an earlier render measured) only the image,
    the guides and alpha are summed, and the traces need no variance.  With
    ``companion`` (a sampler that stratifies a pixel's samples: its odd and
    even ones are no independent halves) every launch goes into half 0, and
    half 1 is the same launch's samples, in lanes of their own, of the
    pixels of ``crop`` at the positions ``companion`` (every other row:
    :meth:`add_companion`); the estimates read those alone.
    """

    crop: np.ndarray
    count: int = 0
    guides: int = 0
    guide_spp: int = GUIDE_PASSES
    total: np.ndarray | None = None
    halves: list = field(default_factory=list)
    half_counts: list = field(default_factory=lambda: [0, 0])
    square: np.ndarray | None = None
    clipped: np.ndarray | None = None
    albedo: np.ndarray | None = None
    normal: np.ndarray | None = None
    alpha: np.ndarray | None = None
    textured: np.ndarray | None = None
    companion: np.ndarray | None = None
    estimated: bool = True
    #: A full render's squared noise (:func:`~.held_out.lanes_noise`) at the
    #: positions ``noise_at`` of ``crop``: the default target's, where traced;
    #: until the first launch traces it, the pixels and the scene's spp
    #: (``noise_due``), and then its share of that launch's seconds (``noise_s``).
    noise: np.ndarray | None = None
    noise_at: np.ndarray | None = None
    noise_due: tuple | None = None
    noise_s: float = 0.0

    def add(self, trace, half: int | None, guides: bool) -> None:
        """Add ``trace`` (every pixel, at its spp) to half 0 or 1, or, for
        ``half`` None, its even-numbered samples to half 0 and its odd ones
        (``trace.odd``) to half 1 (the halves and the variance only where
        :attr:`estimated`)."""
        spp, n = trace.spp, len(trace.radiance)
        self.total = _plus(self.total, spp, trace.radiance)
        if self.estimated:
            self._add_estimates(trace, half)
        if guides:
            self.albedo = _plus(self.albedo, spp, trace.albedo)
            self.normal = _plus(self.normal, spp, trace.normal)
            self.guides += spp
        if trace.alpha is not None:
            self.alpha = _plus(self.alpha, spp, trace.alpha)
        self.albedo = np.zeros((n, 3)) if self.albedo is None else self.albedo
        self.normal = np.zeros((n, 3)) if self.normal is None else self.normal
        self.alpha = np.zeros(n) if self.alpha is None else self.alpha
        self.count += spp

    def _add_estimates(self, trace, half: int | None) -> None:
        """:meth:`add`'s sums over ``crop`` for the estimates."""
        spp, radiance = trace.spp, trace.radiance
        if not self.halves:
            self.halves = [np.zeros((len(self.crop), 3)), np.zeros((len(self.crop), 3))]
            self.square = np.zeros((len(self.crop), 3))
            self.clipped = np.zeros((len(self.crop), 3))
        clipped = np.minimum(radiance[self.crop], ESTIMATE_CLIP)
        if half is None:
            odd_spp = spp // 2
            odd = trace.odd[self.crop]
            even = (spp * radiance[self.crop] - odd_spp * odd) / (spp - odd_spp)
            for k, (mean, count) in enumerate(((even, spp - odd_spp), (odd, odd_spp))):
                self.halves[k] += count * np.minimum(mean, ESTIMATE_CLIP)
                self.half_counts[k] += count
        else:
            self.halves[half] += spp * clipped
            self.half_counts[half] += spp
        if self.reads_variance:
            self.square += spp * (np.minimum(trace.variance[self.crop], ESTIMATE_CLIP ** 2)
                                  + clipped ** 2)
            self.clipped += spp * clipped

    def add_companion(self, trace) -> None:
        """Add ``trace`` (the pixels ``crop[companion]``, independent of the
        passes) to half 1."""
        self.halves[1][self.companion] += trace.spp * np.minimum(trace.radiance, ESTIMATE_CLIP)
        self.half_counts[1] += trace.spp

    @property
    def compared(self):
        """The positions in ``crop`` where both halves have samples."""
        return slice(None) if self.companion is None else self.companion

    @property
    def mean(self) -> np.ndarray:
        return self.total / self.count

    def half_mean(self, half: int) -> np.ndarray:
        """The mean of one half over ``crop`` (clipped, see the class)."""
        return self.halves[half] / self.half_counts[half]

    def guide(self, index=slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """(albedo, normal): the means of the samples that traced them."""
        return self.albedo[index] / self.guides, self.normal[index] / self.guides

    def find_textured(self, surfaces: tuple, max_spp: int) -> None:
        """After the first round that traced the guides, mark the pixels on
        textured diffuse surfaces (``surfaces``: see :func:`run_passes`) in
        :attr:`textured`; where there are some, every later pass traces the
        guides too (up to ``max_spp``), as the division wants every sample's albedo."""
        if self.textured is not None or self.count != self.guides:
            return
        self.textured = textured_pixels(surfaces[0], self.guide()[0], surfaces[1])
        if self.shading:
            self.guide_spp = max_spp

    @property
    def shading(self) -> bool:
        """Whether some pixels lie on textured diffuse surfaces (``textured``):
        those are denoised as their shading
        (:func:`~mitsuba_mrt.recon.denoise.denoise_shading`), and every pass
        traces the guides, as the division wants the albedo of the
        radiance's own samples."""
        return SHADING and self.textured is not None and bool(self.textured.any())

    def denoised(self, color: np.ndarray, index, shape: tuple, quality: str,
                 shading: bool = False, clean_texture: bool = False) -> np.ndarray:
        """``color`` (the pixels ``index``) denoised with the guides; with
        ``shading``, the textured pixels as their shading (``clean_texture``:
        multiplied back by the albedo denoised)."""
        albedo, normal = (v.reshape(shape) for v in self.guide(index))
        color = color.reshape(shape)
        if not shading:
            return denoise_image(color, albedo, normal, quality=quality).reshape(-1, 3)
        return denoise_shading(color, albedo, normal, self.textured[index].reshape(shape[:2]),
                               quality, clean_texture).reshape(-1, 3)

    def half_noise(self) -> np.ndarray:
        """The squared noise of half 1's mean per pixel of ``crop`` and channel,
        from the halves' own difference (two independent means of ``a`` and
        ``b`` samples differ by a sample's variance times ``1 / a + 1 / b`` in
        mean square): of the clipped values the estimates compare, which the
        samples' variance, clipped per trace, is not."""
        a, b = self.half_counts
        return (self.half_mean(0) - self.half_mean(1)) ** 2 * (a / (a + b))

    @property
    def reads_variance(self) -> bool:
        """Whether the estimates read :attr:`variance`: not where a full
        render's noise is traced (:attr:`noise`), which the halves' own
        difference then meets; the launches develop it only where they do."""
        return self.estimated and self.noise is None and self.noise_due is None

    @property
    def variance(self) -> np.ndarray:
        """A single sample's variance per pixel of ``crop`` and channel (unbiased)."""
        mean = self.clipped / self.count
        return np.maximum(self.square / self.count - mean ** 2, 0.0) * (
            self.count / max(self.count - 1, 1))


def _plus(total: np.ndarray | None, spp: int, values: np.ndarray) -> np.ndarray:
    """``total`` (None: nothing yet) plus ``spp`` times ``values``, in place
    where there is a total."""
    if total is None:
        return spp * values
    total += spp * values
    return total


@dataclass
class Progress:
    """What the passes did: their spp, seconds, and the estimates on the way.

    ``history`` holds (spp of the half that was denoised, its estimated
    relative error); ``predicted`` the error predicted for the final image
    (denoised at ``fast``); ``stopped`` why the passes ended; ``quality``
    the preset of the last OIDN call; ``shading`` whether it denoised the
    textured diffuse surfaces as their shading, ``clean_texture`` whether
    it multiplied that back by the albedo denoised too (at most
    :data:`~mitsuba_mrt.recon.denoise.CLEAN_TEXTURE_SPP`, where the time allows).
    """

    spp: int = 0
    trace_s: float = 0.0
    estimate_s: float = 0.0
    denoise_s: float = 0.0
    history: list = field(default_factory=list)
    predicted: float | None = None
    full_error: float | None = None
    stopped: str = ""
    quality: str = ""
    shading: bool = False
    clean_texture: bool = False


def rate_of(history: list) -> float:
    """How fast the error falls with the spp, ``spp ** -rate``: the slope of
    a line through ``history``'s positive points in log-log (all of them, so
    that one noisy round moves it little), held in :data:`RATE_RANGE`;
    :data:`DEFAULT_RATE` until two points have been measured.

    Examples
    --------
    >>> round(rate_of([(1, 0.4), (2, 0.2), (4, 0.1)]), 6)
    1.0
    >>> rate_of([(1, 0.4)])
    0.2
    """
    points = [(math.log(s), math.log(e)) for s, e in history if e > 0]
    if len(points) < 2:
        return DEFAULT_RATE
    x, y = np.array(points).T
    slope = float(np.polyfit(x, y, 1)[0])
    return min(max(-slope, RATE_RANGE[0]), RATE_RANGE[1])


def predict(history: list, spp: int) -> float:
    """The denoised error at ``spp``, from the last of ``history``
    [(spp, error), ...] at :func:`rate_of`'s rate.

    Examples
    --------
    >>> round(predict([(1, 0.4), (2, 0.2)], 4), 6)
    0.1
    >>> round(predict([(1, 0.4)], 32), 6)
    0.2
    """
    (s1, e1) = history[-1]
    return e1 * (spp / s1) ** -rate_of(history)


def needed_spp(history: list, target: float) -> float:
    """The spp at which :func:`predict` meets ``target`` (inf for a target of 0).

    Examples
    --------
    >>> round(needed_spp([(1, 0.4), (2, 0.2)], 0.1), 6)
    4.0
    """
    if target <= 0:
        return math.inf
    (s1, e1) = history[-1]
    if e1 <= target:
        return float(s1)
    return s1 * (e1 / target) ** (1.0 / rate_of(history))


def to_target(history: list, target: float, count: int, most: int) -> int:
    """The passes of the next round: as many as :func:`needed_spp` says
    bring ``count`` passes to :data:`TARGET_MARGIN` times ``target``,
    rounded up to an even number (both halves grow alike), from
    :data:`FIRST_ROUND` to ``most`` (the doubling).

    Examples
    --------
    >>> to_target([(2, 0.14), (4, 0.1)], 0.07, 8, 8)   # 8 passes predict 0.0714: 2 more
    2
    >>> to_target([(4, 0.2)], 0.1, 8, 8)                # far over: the doubling
    8
    """
    needed = needed_spp(history, target * TARGET_MARGIN)
    size = math.ceil(needed - count) if math.isfinite(needed) else most
    return int(min(max(size + size % 2, FIRST_ROUND), most))


def final_quality(trace_s: float, fast_s: float, rate: float,
                  time_left: float | None = None, high_s: float | None = None) -> str:
    """The preset of the passes' last OIDN call: ``high`` where its extra time
    over ``fast`` would take less off the error as more passes than ``high``
    does, and fits ``time_left``; else ``fast``.

    ``trace_s`` is the passes' tracing time; ``fast_s`` and ``high_s`` what
    the call takes at either preset (``high_s`` None: :data:`HIGH_COST` times
    ``fast_s``); more passes' error falls as ``spp ** -rate``,
    ``high``'s is :data:`HIGH_GAIN` of ``fast``'s.

    Examples
    --------
    >>> final_quality(1.0, 0.1, 0.2), final_quality(0.2, 0.1, 0.2)
    ('high', 'fast')
    >>> final_quality(1.0, 0.1, 0.2, time_left=0.05)
    'fast'
    >>> final_quality(0.01, 0.1, 0.2, high_s=0.05)
    'high'
    """
    # (a first call's share can make ``fast``'s expected time the longer)
    extra = max((HIGH_COST * fast_s if high_s is None else high_s) - fast_s, 0.0)
    if trace_s <= 0 or fast_s <= 0 or (time_left is not None and extra > time_left):
        return "fast"
    return "high" if (1 + extra / trace_s) ** -rate > HIGH_GAIN else "fast"


def estimate_rows(height: int, width: int) -> np.ndarray:
    """The rows the error is estimated on: :data:`ESTIMATE_STRIPS` strips
    spread down the image: a quarter of its rows, or fewer where those hold
    more than :data:`ESTIMATE_PIXELS` pixels, but at least 16 rows a strip
    (all rows of a small image).

    Examples
    --------
    >>> [len(estimate_rows(h, w)) for h, w in ((256, 256), (512, 512), (1000, 1000), (48, 48))]
    [64, 64, 64, 48]
    """
    rows_each = max(16, min(height // 16, ESTIMATE_PIXELS // (ESTIMATE_STRIPS * width)))
    if ESTIMATE_STRIPS * rows_each >= height:
        return np.arange(height)
    starts = [round((k + 0.5) * height / ESTIMATE_STRIPS - rows_each / 2)
              for k in range(ESTIMATE_STRIPS)]
    return np.concatenate([np.arange(s, s + rows_each) for s in starts])


def _trace_pass(passes: Passes, tracer, xy: np.ndarray, spp: int, launch: int,
                half: int | None, guides: bool) -> float:
    """Trace every pixel at ``spp`` (launch number ``launch``: its own seed)
    into ``half`` of ``passes`` (None: its even and odd samples into each,
    or with :attr:`Passes.companion` all of it into half 0, and in the same
    launch the companion's pixels into half 1), with the guides where
    ``guides``, and where :attr:`Passes.noise_due` the target's noise lanes
    after them (:attr:`Passes.noise`); the share of the launch's lanes that
    are the image's pixels is returned.

    The companion's pixels follow the image's in one launch: a sampler draws
    each lane's numbers apart (a stratifying one permutes each pixel slot's
    strata apart), so they are independent of the same pixels' samples, and
    one launch records one kernel layout, not two (in a fresh process each
    layout costs its tracing).
    """
    companion = half is None and passes.companion is not None
    pixels = np.concatenate([xy, xy[passes.crop[passes.companion]]]) if companion else xy
    if passes.noise_due is not None:  # (after the image's pixels, as a companion's)
        lanes, k = noise_lanes(passes.noise_due[0], spp, passes.noise_due[1])
        pixels = np.concatenate([pixels, lanes])
    trace = replace(tracer, spp=spp)(pixels, stream=SeedStream.LADDER + launch, aovs=guides,
                                     ids=False, box=True, replay=True,
                                     halves=half is None and not companion,
                                     variance=passes.reads_variance)
    if passes.noise_due is not None:
        passes.noise = lanes_noise(trace.radiance[len(pixels) - len(lanes):], k, spp,
                                   passes.noise_due[1])
        passes.noise_due = None
        trace = trace.take(slice(0, len(pixels) - len(lanes)))
    if companion:
        passes.add(trace.take(slice(0, len(xy))), 0, guides)
        passes.add_companion(trace.take(slice(len(xy), None)))
    else:
        passes.add(trace, half, guides)
    return len(xy) / len(pixels)


def _estimate(passes: Passes, progress: Progress, width: int, quality: str, full_spp: int,
              area: float, denoise: bool) -> None:
    """Add the round's estimates to ``progress`` (see the module): the error
    of the image denoised from half the passes so far (its history), the
    prediction for all of them, and a full render's own at ``full_spp``;
    without ``denoise``, the passes' mean's error."""
    if not denoise:
        variance = passes.variance
        mean = (passes.halves[0] if passes.companion is not None
                else passes.halves[0] + passes.halves[1]) / passes.count
        progress.predicted = relative_error(variance / passes.count, mean)
        progress.full_error = relative_error(variance / (full_spp * area), mean)
        return
    shape = (len(passes.crop) // width, width, 3)
    denoised = passes.denoised(passes.half_mean(0), passes.crop, shape, quality)
    squared = ((np.clip(denoised, 0.0, 1.0) - passes.half_mean(1)) ** 2
               - passes.half_noise())
    both = passes.compared
    progress.history.append((passes.half_counts[0], relative_error(squared[both],
                                                                   denoised[both])))
    progress.predicted = predict(progress.history, passes.count)
    if passes.noise is None:
        progress.full_error = relative_error(passes.variance / (full_spp * area), denoised)
    else:
        progress.full_error = relative_error(passes.noise / area, denoised[passes.noise_at])


def _oidn_s(quality: str, fast_s: float, pixels: int) -> float:
    """Seconds OIDN is expected to take on ``pixels`` at ``quality``:
    ``fast_s`` at ``fast``, else :func:`~mitsuba_mrt.recon.denoise.expected_seconds`."""
    if quality == "fast":
        return fast_s
    return expected_seconds(pixels, quality)


def _final_preset(quality: str, progress: Progress, trace_s: float, fast_s: float,
                  time_left: float | None, pixels: int) -> str:
    """``quality``, or for ``auto`` :func:`final_quality`'s choice for an
    image of ``pixels``.  Before any ``high`` call in the process, and with
    no time limit to keep, ``high``'s call is weighed as :data:`HIGH_COST`
    times ``fast``'s, not at its prior (a time limit's margin: twice a call's
    time, which would leave ``high`` unchosen where it pays).  More passes'
    error is taken to fall at :data:`DEFAULT_RATE`, as the alternative's
    curves fall from 8 to 32 spp, not at the rounds' rate: measured between
    half-spp estimates, that is steeper (``materials`` and
    ``envmap_objects`` at 256 px: 0.33 and 0.46 against 0.17-0.19)."""
    if quality != "auto":
        return quality
    high_s = expected_seconds(pixels, "high")
    if time_left is None and denoise_seconds(pixels, "high") is None:
        high_s = None
    return final_quality(trace_s, fast_s, DEFAULT_RATE, time_left, high_s)


def _fill(passes: Passes, progress: Progress, tracer, xy: np.ndarray, until: float,
          cost: LaunchCost, max_spp: int, launch: int, halves: bool, exact=None,
          least: int = 1, companion: float = 1.0) -> None:
    """Passes that fill the time before ``until`` (a ``time.perf_counter()``
    value) that a whole round does not: launches of the most spp that
    ``cost`` expects to end by then (times :data:`ROUND_SAFETY`; a new count
    records, or compiles, before it replays), while one does, each of the
    count ``exact(spp)`` the sampler takes (:func:`~.scene_query.sample_count_at_most`).
    With ``halves`` each launch goes into both halves, else into one half
    and the next into the other; a launch has at least ``least`` spp (2
    where both halves are to have samples).  ``companion``: what a launch
    takes with its companion over what it takes alone (``cost``'s)."""
    while passes.count < max_spp:
        fits = cost.fits((until - time.perf_counter()) / (ROUND_SAFETY * companion))
        spp = min(max_spp - passes.count, fits)
        spp = exact(spp) if exact is not None and spp > 0 else spp
        if spp < least:
            return
        progress.trace_s += _launch(passes, tracer, xy, spp, launch,
                                    None if halves else launch % 2, cost)
        launch += 1
        progress.spp = passes.count


def _trace_round(passes: Passes, tracer, xy: np.ndarray, size: int, launch: int,
                 halves: bool, cost: LaunchCost) -> int:
    """A round of ``size`` passes in one launch (number ``launch``; the next
    launch's number is returned), its time added to ``cost``: with
    ``halves`` its odd and even samples are the two halves, else all of it
    goes into half 0."""
    _launch(passes, tracer, xy, size, launch, None if halves else 0, cost)
    return launch + 1


def _launch(passes: Passes, tracer, xy: np.ndarray, spp: int, launch: int, half: int | None,
            cost: LaunchCost) -> float:
    """:func:`_trace_pass` (with the launch's companion where one is due); its
    seconds returned.  ``cost`` gets the launch as if it traced the image's
    pixels alone (its trace kernels' time scaled to their share), and whether it
    recorded: a time limit alone traces no companion, and plans its
    launches from these."""
    guides, noise = passes.count < passes.guide_spp, passes.noise_due is not None
    begin, count = time.perf_counter(), passes.count
    with kernel_seconds() as spent, recorded_during() as made:
        share = _trace_pass(passes, tracer, xy, spp, launch, half, guides)
    seconds = time.perf_counter() - begin
    # the spp the sampler took (a square for some); a recording call traces the
    # kernels, which run, or compile, when read back after it
    recording_s = made.seconds
    alone = recording_s + share * (seconds - recording_s)
    if noise:  # (the noise's lanes: Passes.noise_s)
        passes.noise_s = (1.0 - share) * (seconds - recording_s)
    cost.add(passes.count - count, alone, made.count > 0, spent.compile,
             None if not spent.widest else share * spent.widest, recording_s=recording_s)
    return seconds


def run_passes(tracer, width: int, height: int, *, quality: str,
               target_error: float | None, deadline: float | None, max_spp: int,
               full_spp: int, area: float, denoise: bool = True,
               stop_early=None, on_round=None, surfaces: tuple | None = None,
               cost: LaunchCost | None = None, fixed: bool = False
               ) -> tuple[np.ndarray, np.ndarray, Progress]:
    """Trace passes until the target, the deadline or ``max_spp``; return
    (image (height, width, 3), alpha (height, width), :class:`Progress`).

    The error is estimated on :func:`estimate_rows`; the default target is
    a full render's own error there at ``full_spp``, the scene's spp, with a
    pixel filter of effective ``area``
    (:func:`mitsuba_mrt.renderer.pilot.effective_area`): traced where the
    image is denoised and the sampler does not stratify (:func:`_noise_due`),
    else from the passes' own samples (see the module).  ``deadline``
    is a ``time.perf_counter()`` value.  ``stop_early(progress, pass_s)``,
    called after every round, may end the passes (return a reason).
    ``on_round(stage, done)`` hears of each round (``done``: spp over ``max_spp``).
    Without ``denoise`` the image is the passes' mean (no guides traced)
    through the film's filter (:func:`~.pixel_filter.through_filter`: its
    pixels' samples, box-filtered, spread as ``mi.render``'s).  Under a deadline, a
    sampler that compiles kernels per spp (:func:`.scene_query.sampler_bakes_spp`)
    launches the spp launched before and ``cost``'s ladder where they fit, as
    the default rounds launched them (a launch in one half, the guides
    throughout).  ``surfaces`` (each pixel's shape index, and per shape
    index whether it is a textured diffuse surface:
    :func:`~.scene_query.textured_diffuse_shapes`) lets
    the last OIDN call denoise the textured pixels as their shading
    (:attr:`Passes.shading`).  ``cost`` holds the launches of earlier
    renders of the same objects and image size (a launch of an spp among
    them is taken to replay), and gets this render's.  ``fixed``: one
    launch of ``max_spp`` and OIDN at ``quality``, nothing estimated (a plan
    an earlier render measured).
    """
    xy = every_pixel(width, height)
    n = len(xy)
    rows = estimate_rows(height, width)
    passes = Passes((rows[:, None] * width + np.arange(width)[None, :]).ravel())
    progress, launch = Progress(), 0
    layout = _lay_out(passes, tracer, len(rows), width, n, fixed, deadline, target_error)
    if (layout.estimates and denoise and target_error is None and deadline is None
            and passes.companion is None):
        _noise_due(passes, xy, full_spp)
    cost = LaunchCost(spp_compiles=layout.bakes) if cost is None else cost
    final, quality = quality, preset(quality)  # (the estimates' preset)
    round_size, oidn_s = _first_round(fixed, layout.estimates, deadline, target_error, cost,
                                      layout.exact, max_spp, full_spp, n,
                                      quality if denoise else None)
    if not denoise:  # (no OIDN call: no guides)
        passes.guide_spp = 0
    elif deadline is not None and layout.bakes:
        passes.guide_spp = max_spp
    else:
        passes.guide_spp = max(GUIDE_PASSES, round_size)
    while True:
        begin = time.perf_counter()
        # (a round's two halves serve the estimates alone)
        launch = _trace_round(passes, tracer, xy, round_size, launch, layout.estimates, cost)
        if surfaces is not None and denoise:
            passes.find_textured(surfaces, max_spp)
        # (the noise's lanes in the first launch are the estimates' time)
        spent = time.perf_counter() - begin - passes.noise_s
        progress.estimate_s += passes.noise_s
        progress.trace_s += spent
        passes.noise_s = 0.0
        progress.spp = passes.count
        next_size = passes.count  # the next round doubles the passes
        next_size = next_size if layout.exact is None else layout.exact(next_size)
        at_cap = passes.count + next_size > max_spp  # this round is the last
        if layout.estimates:
            oidn_s = _round_estimate(passes, progress, at_cap, width, n, quality, full_spp,
                                     area, denoise, oidn_s)
        if on_round is not None:
            on_round(f"passes ({passes.count} spp)", min(passes.count / max_spp, 1.0))
        target = progress.full_error if target_error is None and deadline is None \
            else target_error
        if (target is not None and progress.predicted <= target
                and passes.count >= MIN_SPP_MET):
            progress.stopped = "met the target"
            break
        if stop_early is not None:
            reason = stop_early(progress, spent / round_size)
            if reason:
                progress.stopped = reason
                return None, None, progress
        if at_cap:
            short = None not in (target, progress.predicted) and progress.predicted > target
            progress.stopped = f"reached {passes.count} spp" + (", short of the target"
                                                                 if short else "")
            break
        if deadline is not None and _out_of_time(passes, layout, cost, next_size, deadline,
                                                 oidn_s):
            progress.stopped = "the time limit"
            final = _fill_time(passes, progress, tracer, xy, layout, cost, final, deadline,
                               oidn_s, max_spp, launch)
            break
        round_size = next_size
        if not layout.bakes and target is not None and progress.history:
            round_size = to_target(progress.history, target, passes.count, next_size)
    alpha = (passes.alpha / passes.count).reshape(height, width)
    if denoise:
        image = _final_denoise(passes, progress, final, deadline, oidn_s, (height, width, 3))
        return image.reshape(height, width, 3), alpha, progress
    # the passes' mean, each pixel's own samples', through the film's filter as mi.render's
    weights = pixel_weights(tracer.sensor.film().rfilter())
    return (through_filter(passes.mean.reshape(height, width, 3), weights),
            through_filter(alpha[..., None], weights)[..., 0], progress)


def _noise_due(passes: Passes, xy: np.ndarray, full_spp: int) -> None:
    """Have the first launch trace the default target's noise
    (:attr:`Passes.noise`): a full render's at ``full_spp``, at
    :data:`~.held_out.CHECK_SHARE` of the image's pixels (at least
    :data:`~.held_out.CHECK_MIN`), spread evenly over the estimate strips.
    The passes' samples, each clipped to what a display shows, understate it
    where bright paths are common: they are clipped one by one, where a full
    render's mean keeps them."""
    passes.noise_at = spread(np.arange(len(passes.crop)), len(xy))
    passes.noise_due = (xy[passes.crop[passes.noise_at]], full_spp)


@dataclass
class _Layout:
    """How :func:`run_passes` launches its passes: whether it estimates their
    error (not under a time limit alone, nor for a plan an earlier render
    measured), whether the sampler compiles kernels per spp (``bakes``),
    the spp a launch of at most so many takes (``exact``; None: as many),
    and what a launch takes with its companion's pixels over what it takes
    alone (``companion``; :attr:`Passes.companion`)."""

    estimates: bool
    bakes: bool
    exact: Callable[[int], int] | None = None
    companion: float = 1.0


def _lay_out(passes: Passes, tracer, rows: int, width: int, pixels: int, fixed: bool,
             deadline: float | None, target_error: float | None) -> _Layout:
    """The :class:`_Layout` of :func:`run_passes`'s passes; ``passes`` told
    whether they are estimated and which pixels are their companion.

    A round is one launch, its halves its odd and even samples: a single
    launch keeps a stratifying sampler's strata whole (two launches of half
    the spp gave 1.3-1.6x the error of one on such scenes).  A time limit
    alone needs no estimates: the passes fill the time, in one half, and
    leave the last OIDN call its expected time.  Under a deadline a sampler
    that compiles kernels per spp keeps the default rounds' layout (all of a
    launch in one half, as beside their companion; the guides throughout),
    so that the spp launched before replay their kernels (a new spp's
    compilation is its :attr:`~.launch_cost.LaunchCost.record_s`), and a
    launch traces no more spp than planned."""
    sampler = tracer.sensor.sampler()
    bakes = sampler_bakes_spp(sampler)
    estimates = not fixed and not (deadline is not None and target_error is None)
    passes.estimated = estimates
    # a sampler that bakes its spp stratifies a pixel's samples: the estimates
    # take every other row of the strips again, in the same launches
    if estimates and bakes:
        passes.companion = np.flatnonzero(np.repeat(np.arange(rows) % 2 == 0, width))
    # (``cost`` holds launches without their companion: one traces its share of the pixels more)
    companion = 1.0 + (0.0 if passes.companion is None else len(passes.companion) / pixels)
    exact = (None if deadline is None or not bakes
             else (lambda spp: sample_count_at_most(sampler, spp)))
    return _Layout(estimates, bakes, exact, companion)


def _round_estimate(passes: Passes, progress: Progress, at_cap: bool, width: int, pixels: int,
                    quality: str, full_spp: int, area: float, denoise: bool,
                    oidn_s: float) -> float:
    """After a round of :func:`run_passes` that estimates: its estimate
    (:func:`_estimate`), or where it is the last round (``at_cap``) and
    earlier rounds were estimated, their prediction (its estimate would
    change no decision); the last OIDN call's expected seconds returned,
    from the estimate's call and earlier ones."""
    if denoise and progress.history and at_cap:
        progress.predicted = predict(progress.history, passes.count)
        return oidn_s
    begin = time.perf_counter()
    _estimate(passes, progress, width, quality, full_spp, area, denoise)
    oidn_s = expected_seconds(pixels, quality) if denoise else 0.0
    progress.estimate_s += time.perf_counter() - begin
    return oidn_s


def _out_of_time(passes: Passes, layout: _Layout, cost: LaunchCost, next_size: int,
                 deadline: float, oidn_s: float) -> bool:
    """Under a deadline, whether :func:`run_passes` ends its rounds and
    fills the time left (:func:`_fill_time`): at once without estimates
    (nothing is learnt from rounds) once a launch's cost is measured (a
    round of :data:`FIRST_ROUND` passes, or a launch an earlier render
    replayed: the first, if it recorded, is not a launch's cost); else where
    the next round, times :data:`~.launch_cost.ROUND_SAFETY`, and the last
    OIDN call would end past ``deadline``."""
    if not layout.estimates and (passes.count >= FIRST_ROUND or cost.replayed):
        return True
    round_s = layout.companion * cost(next_size)
    return time.perf_counter() + ROUND_SAFETY * round_s + oidn_s > deadline


def _fill_time(passes: Passes, progress: Progress, tracer, xy: np.ndarray, layout: _Layout,
               cost: LaunchCost, final: str, deadline: float, oidn_s: float, max_spp: int,
               launch: int) -> str:
    """Launches (:func:`_fill`) in what the last OIDN call leaves of the time
    before ``deadline``; that call's preset returned (:func:`_final_preset`,
    for the time the passes will have had)."""
    n = len(xy)
    left = max(deadline - time.perf_counter() - oidn_s, 0.0)
    final = _final_preset(final, progress, progress.trace_s + left, oidn_s, left, n)
    _fill(passes, progress, tracer, xy, deadline - _oidn_s(final, oidn_s, n), cost, max_spp,
          launch, halves=layout.estimates, exact=layout.exact,
          least=2 if layout.estimates else 1, companion=layout.companion)
    return final


def _first_round(fixed: bool, estimates: bool, deadline: float | None,
                 target_error: float | None, cost: LaunchCost, exact, max_spp: int,
                 full_spp: int, pixels: int, quality: str | None) -> tuple[int, float]:
    """(the first round's passes, the last OIDN call's expected seconds so
    far) for :func:`run_passes`: a measured plan's ``max_spp`` at once; under
    a time limit alone a launch as large as earlier renders' launches say
    fits beside OIDN at ``quality`` (None: no OIDN), else the cheapest; for
    the default target :data:`DEFAULT_FIRST_SHARE` of a full render's spp;
    else :data:`FIRST_ROUND`."""
    if fixed:
        return max_spp, 0.0
    if not estimates:
        oidn_s = 0.0 if quality is None else expected_seconds(pixels, quality)
        size = min(cost.first(deadline - time.perf_counter() - oidn_s), max_spp)
        return (size if exact is None else exact(size)), oidn_s
    if target_error is None and deadline is None:
        return min(max(FIRST_ROUND, 2 * round(full_spp * DEFAULT_FIRST_SHARE / 2)), max_spp), 0.0
    return FIRST_ROUND, 0.0


def _final_denoise(passes: Passes, progress: Progress, final: str, deadline: float | None,
                   oidn_s: float, shape: tuple) -> np.ndarray:
    """The passes' mean through the last OIDN call, at ``final``'s preset
    (:func:`_final_preset`), textured surfaces as their shading where every
    pass traced the guides; what it chose and took go into ``progress``."""
    n = shape[0] * shape[1]
    progress.shading = passes.shading and passes.guides == passes.count
    left = None if deadline is None else deadline - time.perf_counter() - oidn_s
    progress.quality = _final_preset(final, progress, progress.trace_s, oidn_s, left, n)
    begin = time.perf_counter()
    # under a time limit the texture is cleaned in what the passes left of
    # it, not at the cost of an spp (1 spp had 12-35 % more error than 2)
    progress.clean_texture = (
        progress.shading and passes.count <= CLEAN_TEXTURE_SPP
        and (deadline is None or deadline - begin
             >= _oidn_s(progress.quality, oidn_s, n) + texture_seconds(n)))
    image = passes.denoised(passes.mean, slice(None), shape, progress.quality,
                            progress.shading, progress.clean_texture)
    progress.denoise_s = time.perf_counter() - begin
    return image
