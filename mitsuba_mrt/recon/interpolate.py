"""Stage 4: per-region interpolation (the report's Algorithm 3).

Every id region is interpolated only from known samples of the same id, by
a linear RBF (:class:`mitsuba_mrt.recon.rbf.LinearRBF`) through "capstone"
samples (convex-hull vertices, the brightest, the darkest) plus evenly
spaced secondary samples, at most ``max_inpoints`` centres in all.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from .compose import query_workers
from ..errors import MRTError
from .ids import run_starts
from .rbf import LinearRBF
from .rbf_solve import BYTES_PER_PAIR
from ..runtime.allocator import available_memory

#: Centres of one RBF beyond which the memory its solve needs is checked
#: (:data:`~.rbf_solve.BYTES_PER_PAIR`, 0.2 GB at this many) before it is made.
CHECKED_CENTRES = 4096
#: The share of the memory available that one RBF's solve may take.
RBF_MEMORY_SHARE = 0.5

#: Relative spread below which an id's samples count as all equal.
CONSTANT_RTOL = 1e-6


@dataclass
class InterpolationResult:
    """Output of :func:`interpolate_regions`.

    Attributes
    ----------
    values : ndarray, shape (height, width, channels)
        Interpolated values at every pixel (known pixels included).
    counts : Counter
        How each region was handled: ``rbf``; ``constant`` (all
        samples equal, or one sample: filled, not interpolated), of which
        ``background`` (the background, id 0); ``no_samples`` (an
        id that no sample carries, filled from the nearest sample of any id).
    centres : dict
        Number of RBF centres used per id.
    """

    values: np.ndarray
    counts: Counter = field(default_factory=Counter)
    centres: dict = field(default_factory=dict)


def select_centres(xy: np.ndarray, brightness: np.ndarray, max_inpoints: int = 2000,
                   num_cappoints: int = 10) -> np.ndarray:
    """Indices of the samples that the report's RBF is built on.

    With fewer than ``max_inpoints`` samples, all of them.  Otherwise the
    capstones (convex-hull vertices, the ``num_cappoints`` brightest and
    darkest) and an evenly spaced subset of the rest, up to
    ``max_inpoints`` in all.

    Examples
    --------
    >>> xy = np.stack(np.meshgrid(np.arange(10), np.arange(10)), -1).reshape(-1, 2)
    >>> len(select_centres(xy, xy[:, 0] * 1.0, max_inpoints=20, num_cappoints=2))
    20
    """
    n = len(xy)
    if n < max_inpoints:
        return np.arange(n)
    order = np.argsort(brightness, kind="stable")
    caps = [order[:num_cappoints], order[n - num_cappoints:], _hull_vertices(xy)]
    caps = np.unique(np.concatenate(caps))
    rest = np.setdiff1d(np.arange(n), caps, assume_unique=True)
    room = max_inpoints - len(caps)
    if room <= 0 or len(rest) == 0:
        return caps
    picks = np.unique(np.linspace(0, len(rest) - 1, min(room, len(rest))).round().astype(np.int64))
    return np.union1d(caps, rest[picks])


def _hull_vertices(xy: np.ndarray) -> np.ndarray:
    """Convex-hull vertex indices; the two end points when the samples are collinear."""
    try:
        return ConvexHull(xy).vertices
    except (QhullError, ValueError):
        centred = xy - xy.mean(axis=0)
        axis = np.linalg.svd(centred, full_matrices=False)[2][0]
        proj = centred @ axis
        return np.array([np.argmin(proj), np.argmax(proj)])


def _is_constant(values: np.ndarray) -> bool:
    """Whether the samples' spread is at most ``CONSTANT_RTOL`` of their
    largest magnitude (relative: the decision does not depend on the scale)."""
    spread = np.ptp(values, axis=0).max()
    return spread <= CONSTANT_RTOL * float(np.abs(values).max())


def power_of_two_above(magnitude: float) -> float:
    """The least power of two above ``magnitude`` (> 0), 1 for 0: dividing by
    it is exact and brings the values into (-1, 1).

    Examples
    --------
    >>> power_of_two_above(3.0e38) == 2.0 ** 128, power_of_two_above(0.5), power_of_two_above(0.0)
    (True, 1.0, 1.0)
    """
    return math.ldexp(1.0, math.frexp(magnitude)[1]) if magnitude > 0 else 1.0


def check_rbf_memory(centres: int, available: int | None = None) -> None:
    """MRTError where an RBF through ``centres`` centres would need more than
    :data:`RBF_MEMORY_SHARE` of the memory available (``available`` bytes;
    by default :func:`~mitsuba_mrt.runtime.allocator.available_memory`'s):
    its dense solve grows with their square, and the report's
    ``max_inpoints`` of 2000 bounds them for that reason.

    Examples
    --------
    >>> check_rbf_memory(2000)
    >>> check_rbf_memory(100_000, available=16 << 30)
    Traceback (most recent call last):
    ...
    mitsuba_mrt.errors.MRTError: an RBF through 100000 centres needs 111.8 GiB for its solve, more than 50% of the 16.0 GiB available: lower max_inpoints (the report's is 2000)
    """
    if centres <= CHECKED_CENTRES and available is None:
        return
    available = available_memory() if available is None else available
    need = BYTES_PER_PAIR * centres * centres
    if available is not None and need > RBF_MEMORY_SHARE * available:
        raise MRTError(f"an RBF through {centres} centres needs {need / 2 ** 30:.1f} GiB "
                       f"for its solve, more than {RBF_MEMORY_SHARE:.0%} of the "
                       f"{available / 2 ** 30:.1f} GiB available: lower max_inpoints "
                       f"(the report's is 2000)")


def interpolate_regions(id_map: np.ndarray, sample_xy: np.ndarray, sample_ids: np.ndarray,
                        sample_values: np.ndarray, *, max_inpoints: int = 2000,
                        num_cappoints: int = 10, rbf_degree: int = -1) -> InterpolationResult:
    """Interpolate ``sample_values`` over each region of ``id_map``.

    Parameters
    ----------
    id_map : ndarray of int, shape (height, width)
        Region id of every pixel (from the edge finder).
    sample_xy : ndarray of int, shape (n, 2)
        (column, row) of each known sample.
    sample_ids : ndarray of int, shape (n,)
        Id of each sample, as traced.
    sample_values : ndarray of float, shape (n, channels)
        Finite values to interpolate (irradiance in the MRT).
    max_inpoints, num_cappoints : int
        The report's limits on the RBF centres.
    rbf_degree : {-1, 0, 1}
        Polynomial degree of the RBF (-1 is the report's).

    Returns
    -------
    InterpolationResult

    Examples
    --------
    >>> ids = np.zeros((3, 3), dtype=int)
    >>> xy = np.array([[0, 0], [2, 0], [0, 2], [2, 2]])
    >>> vals = (xy[:, :1] + 10.0 * xy[:, 1:]).astype(float)
    >>> res = interpolate_regions(ids, xy, np.zeros(4, int), vals, rbf_degree=1)
    >>> float(res.values[1, 1, 0])
    11.0
    """
    id_map = np.asarray(id_map)
    sample_xy = np.asarray(sample_xy, dtype=np.int64)
    sample_ids = np.asarray(sample_ids)
    sample_values = np.asarray(sample_values, dtype=np.float64)
    if sample_values.ndim == 1:
        sample_values = sample_values[:, None]
    n = len(sample_xy)
    if n == 0:
        raise MRTError("cannot interpolate from zero samples")
    if sample_ids.shape != (n,) or sample_values.shape[0] != n:
        raise MRTError("sample_xy, sample_ids and sample_values must have the same length")
    if not np.isfinite(sample_values).all():
        raise MRTError("sample values must be finite (NaN or Inf in the traced radiance?)")
    if max_inpoints < 1 or num_cappoints < 0:
        raise MRTError("max_inpoints must be >= 1 and num_cappoints >= 0")
    height, width = id_map.shape
    result = InterpolationResult(np.zeros((height, width, sample_values.shape[1])))
    flat_ids = id_map.ravel()
    order = np.argsort(flat_ids, kind="stable")
    sorted_ids = flat_ids[order]  # runs of equal ids: no second sort for np.unique
    starts = run_starts(sorted_ids)
    region_ids = sorted_ids[starts]
    bounds = np.append(starts, len(order))
    sample_order = np.argsort(sample_ids, kind="stable")
    sample_region, sample_starts = np.unique(sample_ids[sample_order], return_index=True)
    sample_bounds = dict(zip(sample_region.tolist(), zip(
        sample_starts, np.append(sample_starts[1:], n))))
    out = result.values.reshape(-1, sample_values.shape[1])
    nearest_tree = None
    for k, region in enumerate(region_ids.tolist()):
        pixels = order[bounds[k]:bounds[k + 1]]
        if region not in sample_bounds:
            if nearest_tree is None:
                nearest_tree = cKDTree(sample_xy)
            xy = np.stack([pixels % width, pixels // width], axis=1)
            out[pixels] = sample_values[nearest_tree.query(xy, workers=query_workers(len(xy)))[1]]
            result.counts["no_samples"] += 1
            continue
        lo, hi = sample_bounds[region]
        members = sample_order[lo:hi]
        values = sample_values[members]
        if len(members) == 1 or _is_constant(values):
            out[pixels] = values.mean(axis=0)
            result.counts["constant"] += 1
            if region == 0:
                result.counts["background"] += 1
            continue
        xy = sample_xy[members].astype(np.float64)
        chosen = select_centres(xy, values.mean(axis=1), max_inpoints, num_cappoints)
        # values over a power of two (exact): the solve and the evaluation
        # see the same numbers at any scale, and none near float overflow
        unit = power_of_two_above(float(np.abs(values).max()))
        check_rbf_memory(len(chosen))
        rbf = LinearRBF(xy[chosen], values[chosen] / unit, degree=rbf_degree)
        out[pixels] = rbf(np.stack([pixels % width, pixels // width], axis=1)) * unit
        result.counts["rbf"] += 1
        result.centres[region] = len(chosen)
    return result
