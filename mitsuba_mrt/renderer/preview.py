"""``auto``'s preview under a time limit: the grid, at as many samples as fit.

The preview (mode ``fast``, its grid denoised) is what ``auto`` renders
where one pass and OIDN on every pixel would overrun a time limit.  Its
grid is traced at one sample per pixel first: that launch also tells the
plan what a pass would cost.  Where the limit leaves time after it, more
1-spp launches of the same pixels, each with a seed of its own, replay the
first's kernels (a sampler that bakes its spp into them compiles none) and
are pooled into one trace of their mean: its noise falls with their number
while the reconstruction's cost stays the same.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..recon.sampling import SamplePattern
from ..types import SeedStream, SparseTrace
from .develop import sample_variance
from .replay import recorded_during

#: The most 1-spp launches a preview's grid pools: a bound the time rarely
#: leaves room for (a preview is taken where one pass of every pixel does not
#: fit, and this many launches of a tenth of the pixels trace more than one).
PREVIEW_MAX_SPP = 16


def pooled(traces: list[SparseTrace]) -> SparseTrace:
    """One trace of the samples of ``traces``, traces of the same pixels.

    Means of the radiance, albedo and alpha (weighted by each trace's spp),
    the variance of one sample about the pooled mean, the pixel-centre ids
    and normals of the first trace (the same in every one), the seconds
    added up.

    Examples
    --------
    >>> one = SparseTrace(radiance=np.array([[1.0, 0, 0]]), albedo=np.full((1, 3), 0.5),
    ...                   shape_index=np.array([1]), visible_lights=np.zeros(1, np.uint32),
    ...                   num_lights=0, spp=1, seconds=0.1, variance=np.zeros((1, 3)))
    >>> two = replace(one, radiance=np.array([[3.0, 0, 0]]))
    >>> both = pooled([one, two])
    >>> both.spp, both.radiance[0].tolist(), both.variance[0].tolist(), round(both.seconds, 6)
    (2, [2.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.2)
    """
    first = traces[0]
    if len(traces) == 1:
        return first
    weights = np.array([t.spp for t in traces], dtype=np.float64)
    share = weights / weights.sum()

    def mean(values: list[np.ndarray]) -> np.ndarray:
        return sum(w * np.asarray(v, dtype=np.float64) for w, v in zip(share, values))

    radiance = mean([t.radiance for t in traces])
    second = mean([np.asarray(t.variance if t.variance is not None else 0.0, dtype=np.float64)
                   + np.asarray(t.radiance, dtype=np.float64) ** 2 for t in traces])
    variance = sample_variance(second, radiance)
    alpha = None if first.alpha is None else mean([t.alpha for t in traces])
    return replace(first, radiance=radiance, albedo=mean([t.albedo for t in traces]),
                   alpha=alpha, variance=variance, spp=int(weights.sum()),
                   seconds=sum(t.seconds for t in traces), odd=None)


def preview_grid(grid: SparseTrace | None, pattern: SamplePattern, tracer,
                 until: float, recording_s: float = 0.0) -> SparseTrace:
    """The preview's grid: ``grid`` (its first 1-spp launch, of which
    ``recording_s`` recorded its kernels; traced here where None), pooled
    with more 1-spp launches while the next is expected to end by ``until``
    (a ``time.perf_counter()`` value), at most :data:`PREVIEW_MAX_SPP` in
    all.  A launch is expected to take what the last one took, less what
    recording took in it: the next replays what it recorded (its first uses
    of the scene, in a fresh process, still counted: a bound above a
    replay's time)."""
    one = replace(tracer, spp=1)
    if grid is None:
        with recorded_during() as made:
            grid = one(pattern.pixel_xy, stream=SeedStream.GRID, replay=True)
        recording_s = made.seconds
    traces, step = [grid], max(grid.seconds - recording_s, 0.0)
    while len(traces) < PREVIEW_MAX_SPP and time.perf_counter() + step <= until:
        begin = time.perf_counter()
        traces.append(one(pattern.pixel_xy, stream=SeedStream.PREVIEW + len(traces),
                          replay=True))
        step = time.perf_counter() - begin
    return pooled(traces)
