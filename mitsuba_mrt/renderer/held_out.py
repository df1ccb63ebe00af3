"""``auto``'s check of an MRT image: pixels it did not trace, traced now.

A share of the pixels the MRT reconstructed (:func:`held_out_pixels`) is
traced twice, each time at half the scene's spp with other random numbers,
in one launch.  The two traces are independent of the image and of each
other: the mean squared difference between the image and their mean, less
that mean's noise (a quarter of the two traces' mean squared difference),
estimates the image's squared error there without a reference, whatever the
sampler's stratification; that noise over the pixel filter's effective area
estimates a full render's, the default target (``examples/held_out_check.py``
measures both estimates against the truth).
Every value is clipped to what a display shows, [0, 1], first, so that a
rare bright sample does not swamp what the other pixels say.  Both are
relative RMS errors over the pixels a display shows unclipped
(:func:`~mitsuba_mrt.recon.metrics.relative_error`), as ``auto``'s other
estimates (:mod:`.pilot`, :mod:`.progressive`) are.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..recon.metrics import relative_error
from ..types import SeedStream

#: The share of the image's pixels the check traces, and the fewest it
#: traces: enough that the estimate's own scatter is small beside the margin
#: it decides (a thousand pixels and more), few enough that it costs about a
#: hundredth of a full render.
CHECK_SHARE, CHECK_MIN = 1 / 128, 1024


@dataclass(frozen=True)
class HeldOut:
    """What the check found: the image's estimated error at the held-out
    pixels, a full render's there, how many pixels it traced and its seconds."""

    error: float
    full_error: float
    pixels: int
    seconds: float


def held_out_pixels(traced: np.ndarray, share: float = CHECK_SHARE,
                    minimum: int = CHECK_MIN) -> np.ndarray:
    """Flat indices of pixels not ``traced`` (a (height, width) mask), spread
    evenly over them in row-major order: ``share`` of all pixels, at least
    ``minimum``, at most every untraced one.

    Examples
    --------
    >>> traced = np.zeros((4, 4), bool); traced[::2, ::2] = True
    >>> held_out_pixels(traced, share=0.25, minimum=2).tolist()
    [1, 5, 9, 13]
    """
    return spread(np.flatnonzero(~traced.ravel()), traced.size, share, minimum)


def spread(candidates: np.ndarray, pixels: int, share: float = CHECK_SHARE,
           minimum: int = CHECK_MIN) -> np.ndarray:
    """``share`` of an image's ``pixels`` (at least ``minimum``, at most all
    of them) of ``candidates``, spread evenly over them in their order.

    Examples
    --------
    >>> spread(np.arange(10, 20), 40, share=0.1, minimum=2).tolist()
    [10, 12, 15, 17]
    """
    count = min(len(candidates), max(minimum, int(round(share * pixels))))
    if count == 0:
        return candidates
    return candidates[(np.arange(count) * len(candidates)) // count]


def check_image(image: np.ndarray, traced: np.ndarray, tracer, area: float) -> HeldOut:
    """Trace :func:`held_out_pixels` of ``image`` (height, width, 3; its
    ``traced`` mask) twice with ``tracer`` at half its spp and estimate the
    image's error and a full render's (pixel filter of effective ``area``)
    there (see the module)."""
    begin = time.perf_counter()
    width = image.shape[1]
    index = held_out_pixels(traced)
    if len(index) == 0:  # every pixel traced: the image is a full render's
        return HeldOut(0.0, 0.0, 0, time.perf_counter() - begin)
    xy = np.stack([index % width, index // width], axis=1)
    # each pixel twice in one launch: a sampler draws other numbers for each lane
    trace = replace(tracer, spp=max(tracer.spp // 2, 1))(
        np.concatenate([xy, xy]), stream=SeedStream.CHECK, aovs=False, replay=True)
    mine = np.clip(image.reshape(-1, 3)[index], 0.0, 1.0)
    squared, noise = squared_error(mine, *np.split(trace.radiance, 2))
    return HeldOut(relative_error(squared, mine), relative_error(noise / area, mine),
                   len(index), time.perf_counter() - begin)


def squared_error(image: np.ndarray, first: np.ndarray, second: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(the squared error of ``image``, the squared noise of the mean of
    ``first`` and ``second``), per value, estimated from those two independent
    renders of the same pixels (see the module); every value clipped to [0, 1].

    Examples
    --------
    >>> squared, noise = squared_error(np.array([0.8]), np.array([0.4]), np.array([0.6]))
    >>> [round(float(v), 6) for v in (squared[0], noise[0])]
    [0.08, 0.01]
    """
    image, first, second = (np.clip(v, 0.0, 1.0) for v in (image, first, second))
    noise = _mean_noise(first, second)
    return (image - (first + second) / 2) ** 2 - noise, noise


def _mean_noise(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """The squared noise of the mean of two independent renders of the same
    pixels, in expectation: a quarter of their squared difference."""
    return (first - second) ** 2 / 4


def noise_lanes(xy: np.ndarray, spp: int, full_spp: int) -> tuple[np.ndarray, int]:
    """(the lanes that trace a full render's noise at the pixels ``xy`` in
    a launch of ``spp`` samples a lane, the lanes a half takes): ``xy``
    ``2 k`` times over, so that each half, ``k`` lanes a pixel, holds about
    half of ``full_spp``, the scene's spp (:func:`lanes_noise`).

    Examples
    --------
    >>> lanes, k = noise_lanes(np.array([[3, 4], [5, 6]]), 8, 64)
    >>> k, len(lanes), lanes[2].tolist()
    (4, 16, [3, 4])
    """
    k = max(1, round(max(full_spp // 2, 1) / spp))
    return np.tile(xy, (2 * k, 1)), k


def lanes_noise(radiance: np.ndarray, k: int, spp: int, full_spp: int) -> np.ndarray:
    """A full render's squared noise (n, 3) at ``full_spp`` per pixel,
    before its pixel filter spreads it, from the ``radiance`` of
    :func:`noise_lanes`' lanes traced at ``spp``: the noise of the mean of
    the two halves' means, both clipped to [0, 1] (as
    :func:`squared_error`'s), scaled from the halves' ``2 k spp`` samples to
    ``full_spp``.  As the check's, it holds whatever stratification the
    sampler gives a lane's samples, and the noise of a pixel whose samples
    are rarely bright, which clipping single samples would hide.
    """
    first, second = np.clip(radiance.reshape(2, k, -1, 3).mean(axis=1), 0.0, 1.0)
    return _mean_noise(first, second) * (2 * k * spp / full_spp)
