"""Noise-aware smoothing of the traced grid, before it is interpolated.

A traced pixel of a stochastic integrator carries the noise of its samples,
and an interpolator that passes through the grid spreads that noise over
the pixels between.  The trace knows each pixel's noise (the variance of
its samples), so each grid value is replaced by a weighted mean of itself
and the samples of its id in its 3 x 3 grid neighbourhood, each weighted
by ``exp(-d^2 / (2 strength^2))``, where ``d`` is the two samples'
difference in units of their combined noise (averaged over channels), and
a neighbour noisier than the sample by the ratio of their noise (as an
inverse-variance mean would: a sample beside a light, whose filter reaches
it, is bright and very noisy, and within its noise of anything).
Neighbours that differ by much more than the noise (a highlight, a
shadow's edge, another object) get no weight, so structure stays; noise
on smooth shading averages down.  Samples without noise (a deterministic
integrator) are left as they are.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..runtime.threads import for_row_blocks_of
from .llvm_arrays import available
from .smooth_jit import smooth_grid_jit

#: Default strength: how many noise standard deviations apart two samples
#: may be and still be averaged (the weight falls to 0.61 there).
SMOOTHING = 1.5


def smooth_grid(grid_ids: np.ndarray, values: np.ndarray, noise: np.ndarray,
                strength: float = SMOOTHING, fixed: np.ndarray | None = None,
                use_jit: bool | None = None) -> np.ndarray:
    """Grid values averaged with their same-id neighbours that agree within the noise.

    Parameters
    ----------
    grid_ids : ndarray of int, shape (nr, nc)
        Each grid sample's id; samples of other ids are never mixed in.
    values : ndarray, shape (nr, nc, C)
        The samples' values (finite).
    noise : ndarray, shape (nr, nc, C)
        Variance of each value's noise (of the pixel's mean, not of one
        sample), >= 0.
    strength : float
        Width of the weight in noise standard deviations; 0 returns
        ``values`` unchanged.
    fixed : ndarray of bool, shape (nr, nc), optional
        Samples neither changed nor used for their neighbours (fireflies).
    use_jit : bool, optional
        Run it as one Dr.Jit kernel (:mod:`.smooth_jit`); default: where
        Dr.Jit's LLVM backend is usable.  The tests hold the two together.

    Returns
    -------
    ndarray, shape (nr, nc, C), float64
        A weighted mean of same-id values of the 3 x 3 neighbourhood, so
        within their range; ``values`` where the noise is 0 or the sample is
        ``fixed``.

    Examples
    --------
    >>> ids = np.zeros((1, 3), dtype=int)
    >>> values = np.array([[[1.0], [1.2], [1.0]]])
    >>> smooth_grid(ids, values, np.full((1, 3, 1), 0.04))[0, :, 0].round(3)
    array([1.094, 1.072, 1.094])
    >>> smooth_grid(ids, values, np.zeros((1, 3, 1)))[0, :, 0]   # no noise: unchanged
    array([1. , 1.2, 1. ])
    """
    values = np.asarray(values, dtype=np.float64)
    if strength <= 0 or values.size == 0:
        return values
    noise = np.asarray(noise, dtype=np.float64)
    nr, nc, channels = values.shape
    usable = np.ones((nr, nc), dtype=bool) if fixed is None else ~np.asarray(fixed, dtype=bool)
    scale = -0.5 / (strength * strength * channels)
    if use_jit is None:
        use_jit = available()
    if use_jit:
        return smooth_grid_jit(grid_ids, values, noise, usable, scale)
    out = np.empty_like(values)

    def rows(lo: int, hi: int) -> np.ndarray:  # (a row's mean reads the rows beside it)
        return _smoothed_block(grid_ids[lo:hi], values[lo:hi], noise[lo:hi], usable[lo:hi],
                               scale)
    for_row_blocks_of(rows, out, halo=1)
    return out


def _smoothed_block(grid_ids: np.ndarray, values: np.ndarray, noise: np.ndarray,
                    usable: np.ndarray, scale: float) -> np.ndarray:
    """:func:`smooth_grid` of a block of whole rows, a new array (its first
    and last rows lack the neighbours beyond the block). Each pixel's
    result depends only on its 3 x 3 neighbourhood, elementwise, so a
    block's inner rows are bit for bit those of the whole grid's."""
    nr, nc, channels = values.shape
    total = values.copy()          # the sample itself, weight 1
    weight = np.ones((nr, nc))
    # the shifts' temporaries, made once: a fresh array costs its pages
    scratch = _Scratch(np.empty((nr, nc, channels)), np.empty((nr, nc, channels)),
                       np.empty((nr, nc)))
    # a pair's weight before ``usable`` is the same from either end: each
    # shift's is kept for the opposite shift, which reads the same pairs
    pairs = {}
    level = noise.mean(axis=-1)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if not (dy or dx):
                continue
            # the overlap of the grid and its shift by (dy, dx): here <- there
            here = (slice(max(0, -dy), nr - max(0, dy)), slice(max(0, -dx), nc - max(0, dx)))
            there = (slice(max(0, dy), nr + min(0, dy)), slice(max(0, dx), nc + min(0, dx)))
            base = pairs.pop((-dy, -dx), None)
            if base is None:
                base = pairs[dy, dx] = _pair_weights(values[here], values[there], noise[here],
                                                     noise[there], scale,
                                                     grid_ids[here] == grid_ids[there], scratch)
            size = base.shape
            w = np.multiply(base, usable[there], out=scratch.per_sample[:size[0], :size[1]])
            # a neighbour noisier than the sample counts for less (its noise over
            # the sample's: the inverse-variance weight, at most 1)
            share = np.divide(level[here], level[there], out=np.ones(base.shape),
                              where=level[there] > level[here])
            np.multiply(w, share, out=w)
            weighted = np.multiply(values[there], w[..., None],
                                   out=scratch.first[:size[0], :size[1]])
            total[here] += weighted
            weight[here] += w
    out = np.divide(total, weight[..., None], out=total)
    keep = ~usable | (noise.max(axis=-1) <= 0)
    out[keep] = values[keep]
    return out


class _Scratch(NamedTuple):
    """:func:`smooth_grid`'s reused temporaries: two of the values' shape, one
    of the grid's (each shift and pair takes views of their overlap)."""

    first: np.ndarray
    second: np.ndarray
    per_sample: np.ndarray


def _pair_weights(a: np.ndarray, b: np.ndarray, noise_a: np.ndarray, noise_b: np.ndarray,
                  scale: float, same_id: np.ndarray, scratch: _Scratch) -> np.ndarray:
    """The weights of the pairs of samples ``a`` and ``b`` (elementwise):
    ``exp(scale * sum_c d_c^2 / combined noise_c)``, 0 across ids; the same
    for (``b``, ``a``), bit for bit.  Its temporaries are views of ``scratch``."""
    rows, cols = same_id.shape
    diff = np.subtract(a, b, out=scratch.first[:rows, :cols])
    combined = np.add(noise_a, noise_b, out=scratch.second[:rows, :cols])
    silent = ~(combined > 0)
    # where no noise: 0 for equal samples, else never averaged
    unweighed = np.where(diff[silent] == 0, 0.0, np.inf)
    squared = np.multiply(diff, diff, out=diff)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.divide(squared, combined, out=combined)
    ratio[silent] = unweighed
    weights = np.sum(ratio, axis=-1)
    np.multiply(weights, scale, out=weights)
    np.exp(weights, out=weights)
    return np.multiply(weights, same_id, out=weights)
