"""Stage 1: which pixels are traced (the report's regular grid).

The report traces every (column, row) pair of a regular grid that includes
the image borders: ``n = floor(f * W * H)`` pixels are asked for,
``a = floor(sqrt(n))`` columns at ``linspace(0, W - 1, a)`` (truncated to
int) and ``b = ceil(n / a)`` rows at ``linspace(0, H - 1, b)``.  The report
used square images only; here ``a = floor(sqrt(n * W / H))``, which is the
same for square images and keeps the grid square-ish for others (so that
``f = 1`` traces every pixel of any image).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import MRTError


def check_fraction(name: str, value: float) -> float:
    """Return ``value`` as a float if it lies in (0, 1], else raise MRTError."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise MRTError(f"{name} must be a number in (0, 1], got {value!r}") from None
    if not (0.0 < value <= 1.0):  # also rejects NaN
        raise MRTError(f"{name} must be in (0, 1], got {value}")
    return value


@dataclass(frozen=True)
class SamplePattern:
    """The traced pixels: every pair of ``rows`` x ``cols``.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    rows, cols : ndarray of int64
        Sorted, unique pixel rows (0 = top) and columns of the grid.
    """

    width: int
    height: int
    rows: np.ndarray
    cols: np.ndarray

    @property
    def grid_shape(self) -> tuple[int, int]:
        """(number of grid rows, number of grid columns)."""
        return len(self.rows), len(self.cols)

    @property
    def count(self) -> int:
        """Number of traced pixels."""
        return len(self.rows) * len(self.cols)

    @cached_property
    def pixel_xy(self) -> np.ndarray:
        """(count, 2) int array of (column, row), rows outer, columns inner."""
        cc, rr = np.meshgrid(self.cols, self.rows)
        return np.stack([cc.ravel(), rr.ravel()], axis=1)

    @cached_property
    def mask(self) -> np.ndarray:
        """(height, width) bool image, True at traced pixels."""
        m = np.zeros((self.height, self.width), dtype=bool)
        m[np.ix_(self.rows, self.cols)] = True
        return m

    @cached_property
    def nearest_rows(self) -> np.ndarray:
        """(height,) index into ``rows`` of the grid row nearest to each image row."""
        return _nearest_indices(self.rows, self.height)

    @cached_property
    def nearest_cols(self) -> np.ndarray:
        """(width,) index into ``cols`` of the grid column nearest to each image column."""
        return _nearest_indices(self.cols, self.width)

    def nearest_image(self, grid_values: np.ndarray) -> np.ndarray:
        """Every pixel takes the value of its nearest traced pixel.

        ``grid_values`` is either per sample, (count, ...), or grid-shaped,
        (rows, cols, ...).

        On a tensor grid the Euclidean nearest sample is the nearest row
        and nearest column, chosen independently (ties go to the lower one).
        """
        grid = np.asarray(grid_values)
        if grid.shape[:2] != self.grid_shape:  # per-sample values (count, ...)
            grid = grid.reshape(self.grid_shape + grid.shape[1:])
        return grid.take(self.nearest_rows, axis=0).take(self.nearest_cols, axis=1)

    @cached_property
    def pixel_index(self) -> np.ndarray:
        """(count,) flat index ``row * width + col`` of each traced pixel, rows outer."""
        return (self.rows[:, None] * self.width + self.cols[None, :]).ravel()

    def put_traced(self, image: np.ndarray, values: np.ndarray) -> None:
        """Write per-sample ``values`` (count, ...) into ``image`` (height, width, ...)
        at the traced pixels, in place."""
        values = np.asarray(values)
        if image.flags.c_contiguous:  # one gather-free scatter over flat pixels
            image.reshape((-1,) + image.shape[2:])[self.pixel_index] = values.reshape(
                (self.count,) + image.shape[2:])
        else:
            image[np.ix_(self.rows, self.cols)] = values.reshape(
                self.grid_shape + image.shape[2:])

    def to_image(self, grid_values: np.ndarray, fill=0) -> np.ndarray:
        """Scatter per-sample values (count, ...) into a full image."""
        grid_values = np.asarray(grid_values)
        out = np.full((self.height, self.width) + grid_values.shape[1:], fill,
                      dtype=grid_values.dtype)
        out[np.ix_(self.rows, self.cols)] = grid_values.reshape(
            self.grid_shape + grid_values.shape[1:])
        return out


def _nearest_indices(positions: np.ndarray, length: int) -> np.ndarray:
    pixels = np.arange(length)
    upper = np.clip(np.searchsorted(positions, pixels), 1, max(len(positions) - 1, 1))
    lower = upper - 1
    if len(positions) == 1:
        return np.zeros(length, dtype=np.int64)
    take_upper = positions[upper] - pixels < pixels - positions[lower]
    return np.where(take_upper, upper, lower)


def cell_coordinates(positions: np.ndarray, length: int) -> tuple[np.ndarray, np.ndarray]:
    """For each pixel 0..length-1: the grid cell ``i`` with
    ``positions[i] <= x <= positions[i + 1]`` and the fraction ``t`` across it.

    Examples
    --------
    >>> i, t = cell_coordinates(np.array([0, 4, 8]), 9)
    >>> i.tolist(), t.tolist()
    ([0, 0, 0, 0, 1, 1, 1, 1, 1], [0.0, 0.25, 0.5, 0.75, 0.0, 0.25, 0.5, 0.75, 1.0])
    """
    x = np.arange(length)
    if len(positions) < 2:
        return np.zeros(length, dtype=np.int64), np.zeros(length)
    i = np.clip(np.searchsorted(positions, x, side="right") - 1, 0, len(positions) - 2)
    lo, hi = positions[i], positions[i + 1]
    return i, np.clip((x - lo) / (hi - lo), 0.0, 1.0)


def every_pixel(width: int, height: int) -> np.ndarray:
    """(column, row) of every pixel of a ``width`` x ``height`` image, rows
    outer: a full pass's pixels, in the order of the image's rows.

    Examples
    --------
    >>> every_pixel(2, 2).tolist()
    [[0, 0], [1, 0], [0, 1], [1, 1]]
    """
    xy = np.empty((height, width, 2), dtype=np.int64)  # (written once: no meshgrid copies)
    xy[..., 0] = np.arange(width)
    xy[..., 1] = np.arange(height)[:, None]
    return xy.reshape(-1, 2)


def grid_pattern(width: int, height: int, sample_fraction: float) -> SamplePattern:
    """The report's grid of traced pixels.

    Parameters
    ----------
    width, height : int
        Image size in pixels (each >= 1).
    sample_fraction : float
        Fraction of the pixels to trace, in (0, 1].

    Returns
    -------
    SamplePattern

    Examples
    --------
    >>> p = grid_pattern(200, 200, 0.1)
    >>> p.grid_shape, p.count
    ((64, 63), 4032)
    """
    sample_fraction = check_fraction("sample_fraction", sample_fraction)
    width, height = int(width), int(height)
    if width < 1 or height < 1:
        raise MRTError(f"image size must be at least 1 x 1, got {width} x {height}")
    n = max(1, math.floor(sample_fraction * width * height))
    a = min(max(1, math.isqrt(n) if width == height else math.floor(math.sqrt(n * width / height))), width)
    b = min(math.ceil(n / a), height)
    cols = np.unique(np.linspace(0, width - 1, a).astype(np.int64))
    rows = np.unique(np.linspace(0, height - 1, b).astype(np.int64))
    return SamplePattern(width, height, rows, cols)
