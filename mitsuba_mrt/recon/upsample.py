"""Scene-agnostic upsampling of a traced grid (no ids, no albedo).

``upsample_nearest`` copies the nearest traced pixel, ``upsample_spline``
fits an interpolating bicubic spline through the grid (a tensor grid, so
``scipy.interpolate.RectBivariateSpline`` applies, one channel at a time).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import RectBivariateSpline

from .sampling import SamplePattern


def upsample_nearest(pattern: SamplePattern, values: np.ndarray) -> np.ndarray:
    """Nearest-neighbour upsampling of per-sample ``values`` (n, channels).

    Examples
    --------
    >>> from mitsuba_mrt.recon.sampling import SamplePattern
    >>> p = SamplePattern(4, 1, np.array([0]), np.array([0, 3]))
    >>> upsample_nearest(p, np.array([[1.0], [2.0]]))[0, :, 0]
    array([1., 1., 2., 2.])
    """
    return pattern.nearest_image(values)


def upsample_spline(pattern: SamplePattern, values: np.ndarray, degree: int = 3) -> np.ndarray:
    """Interpolating spline upsampling (bicubic for ``degree=3``).

    The degree drops where the grid has too few rows or columns.

    Examples
    --------
    >>> from mitsuba_mrt.recon.sampling import grid_pattern
    >>> p = grid_pattern(20, 20, 0.2)
    >>> plane = (p.pixel_xy[:, :1] + 2.0 * p.pixel_xy[:, 1:]).astype(float)
    >>> bool(np.allclose(upsample_spline(p, plane)[7, 5, 0], 5 + 2 * 7))
    True
    """
    values = np.asarray(values, dtype=np.float64)
    nr, nc = pattern.grid_shape
    grid = values.reshape(nr, nc, -1)
    if nr == 1 or nc == 1:
        return upsample_nearest(pattern, values)
    ky, kx = min(degree, nr - 1), min(degree, nc - 1)
    out = np.empty((pattern.height, pattern.width, grid.shape[2]))
    rows, cols = np.arange(pattern.height), np.arange(pattern.width)
    for c in range(grid.shape[2]):
        spline = RectBivariateSpline(pattern.rows, pattern.cols, grid[..., c], kx=ky, ky=kx, s=0)
        out[..., c] = spline(rows, cols, grid=True)
    return out
