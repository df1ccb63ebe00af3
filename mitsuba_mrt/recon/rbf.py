"""The numerical kernel of the interpolator: a linear radial basis function.

``s(x) = sum_j w_j |x - c_j| + p(x)`` with ``p`` a polynomial of degree
``degree`` (-1: none, which is the legacy ``scipy.interpolate.Rbf`` with
``function='linear'`` that the report used; 0: a constant; 1: an affine
function, which makes the interpolant exact for linear fields).  This module
knows nothing of images or ids; :mod:`mitsuba_mrt.recon.interpolate` calls it.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy.spatial.distance import cdist

from . import rbf_fast
from ..errors import MRTError
from .rbf_solve import solve_linear_rbf_at

#: Elements of the distance matrix evaluated at once (about 32 MB of float64).
EVAL_BLOCK_ELEMENTS = 1 << 22


class LinearRBF:
    """Linear RBF interpolant through ``values`` at ``centres``.

    Parameters
    ----------
    centres : array_like, shape (n, d)
        Distinct points.
    values : array_like, shape (n,) or (n, k)
        Finite data values; each column is interpolated independently with
        the same system matrix.
    degree : {-1, 0, 1}
        Degree of the added polynomial.  Directions along which the centres
        do not vary (collinear points) are dropped from the polynomial, so
        the system stays non-singular.

    Examples
    --------
    >>> rbf = LinearRBF([[0, 0], [1, 0], [0, 1]], [1.0, 2.0, 3.0], degree=1)
    >>> float(rbf([[1, 1]])[0])
    4.0
    """

    def __init__(self, centres, values, degree: int = -1):
        centres = np.asarray(centres, dtype=np.float64)
        values = np.asarray(values, dtype=np.float64)
        if centres.ndim != 2 or centres.shape[0] == 0:
            raise MRTError(f"centres must be a non-empty (n, d) array, got shape {centres.shape}")
        self._vector = values.ndim == 2
        values = values.reshape(len(values), -1)
        if len(values) != len(centres):
            raise MRTError(f"got {len(centres)} centres but {len(values)} values")
        if degree not in (-1, 0, 1):
            raise MRTError(f"degree must be -1, 0 or 1, got {degree}")
        if not (np.isfinite(centres).all() and np.isfinite(values).all()):
            raise MRTError("RBF centres and values must be finite")
        # integer 2-D centres (pixels) for the fast evaluation; None: dense only
        self._pixel_centres = None
        if (centres.shape[1] == 2 and np.abs(centres).max() < rbf_fast.MAX_COORDINATE
                and np.array_equal(centres, np.round(centres))):
            self._pixel_centres = centres.astype(np.int64)
        # Shift and scale for conditioning; phi(r) = r is homogeneous, so the
        # interpolant itself does not change.
        self._shift = centres.mean(axis=0)
        extent = float(np.ptp(centres, axis=0).max()) / 2.0
        self._scale = extent if extent > 0.0 else 1.0
        self._centres = (centres - self._shift) / self._scale
        self._degree = degree
        self._basis = self._polynomial_basis(self._centres, degree)
        try:
            self._weights, self._poly_coeffs = solve_linear_rbf_at(
                self._centres, self._poly(self._centres), values)
        except (np.linalg.LinAlgError, scipy.linalg.LinAlgError):
            raise MRTError("RBF system is singular: centres must be distinct") from None

    @staticmethod
    def _polynomial_basis(points: np.ndarray, degree: int) -> np.ndarray:
        """Orthonormal directions of the affine part that the points span."""
        if degree < 1:
            return np.zeros((points.shape[1], 0))
        _, s, vt = np.linalg.svd(points, full_matrices=False)
        keep = s > 1e-9 * max(s.max(initial=0.0), 1e-300)
        return vt[keep].T

    def _poly(self, points: np.ndarray) -> np.ndarray:
        if self._degree < 0:
            return np.zeros((len(points), 0))
        return np.hstack([np.ones((len(points), 1)), points @ self._basis])

    def __call__(self, points) -> np.ndarray:
        """Evaluate at ``points`` (m, d); returns (m,) or (m, k).

        Integer-valued 2-D points and centres (pixels) are evaluated with
        :func:`mitsuba_mrt.recon.rbf_fast.grid_distance_sum` when its cost model
        says that this beats the dense evaluation; the result then differs
        from the dense one by well under ``1e-4`` (typically ``1e-5``) of the
        largest value of each channel.  Everything else is evaluated densely.
        """
        points = np.asarray(points)
        if points.ndim != 2 or points.shape[1] != self._centres.shape[1]:
            raise MRTError(f"points must be an (m, {self._centres.shape[1]}) array, "
                           f"got shape {points.shape}")
        pixels = self._fast_points(points)
        if pixels is not None:
            out = rbf_fast.grid_distance_sum(self._pixel_centres,
                                             self._weights / self._scale, pixels)
            if self._degree >= 0:
                out += self._poly((pixels - self._shift) / self._scale) @ self._poly_coeffs
            return out if self._vector else out[:, 0]
        points = (points.astype(np.float64) - self._shift) / self._scale
        out = np.empty((len(points), self._weights.shape[1]))
        step = max(1, EVAL_BLOCK_ELEMENTS // len(self._centres))
        for start in range(0, len(points), step):
            chunk = points[start:start + step]
            out[start:start + step] = (cdist(chunk, self._centres) @ self._weights
                                       + self._poly(chunk) @ self._poly_coeffs)
        return out if self._vector else out[:, 0]

    def _fast_points(self, points: np.ndarray) -> np.ndarray | None:
        """``points`` as int64 pixels if the fast evaluation applies, else None."""
        if (self._pixel_centres is None or len(points) == 0 or self._weights.shape[1] == 0
                or points.dtype.kind not in "iuf"):
            return None
        # column by column: min(axis=0) of an (m, 2) array is much slower
        lo = np.array([column.min() for column in points.T], dtype=np.float64)
        hi = np.array([column.max() for column in points.T], dtype=np.float64)
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()
                and max(-lo.min(), hi.max()) < rbf_fast.MAX_COORDINATE):
            return None
        if not rbf_fast.pays_off(self._pixel_centres, self._weights.shape[1], lo, hi, len(points)):
            return None
        if points.dtype.kind == "f" and not np.array_equal(points, np.round(points)):
            return None
        return points.astype(np.int64, copy=False)
