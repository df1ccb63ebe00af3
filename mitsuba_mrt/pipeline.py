"""The reconstruction: traced samples in, full image out (no Mitsuba here).

``ids -> edge finder -> interpolation -> compose``, each stage a module of
its own; this module validates the parameters once and times the stages.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from .compose import compose, demodulate, region_albedo
from .edges import quadtree_fill, smooth_ids
from .errors import MRTError
from .ids import ID_RULES
from .interpolate import interpolate_regions
from .sampling import SamplePattern, check_fraction


@dataclass(frozen=True)
class MRTParams:
    """Parameters of the reconstruction, named as in the report.

    Attributes
    ----------
    sample_fraction : float
        Fraction of the pixels traced on the grid, in (0, 1].
    filter_sigma : float
        Sigma (pixels) of the Gaussian id smoothing, >= 0.
    filter_cutoff : float
        Normalised cutoff of the id smoothing, in [0, 1].
    max_inpoints : int
        Most RBF centres per id.
    num_cappoints : int
        Brightest and darkest samples kept as capstones (each).
    id_rule : {'paper', 'exact'}
        How ids are made from shape and light visibility (see ``ids``).
    rbf_degree : {-1, 0, 1}
        Polynomial degree added to the linear RBF (-1: the report's).
    """

    sample_fraction: float = 0.1
    filter_sigma: float = 1.0
    filter_cutoff: float = 0.05
    max_inpoints: int = 2000
    num_cappoints: int = 10
    id_rule: str = "paper"
    rbf_degree: int = -1

    def __post_init__(self):
        check_fraction("sample_fraction", self.sample_fraction)
        if not (math.isfinite(self.filter_sigma) and self.filter_sigma >= 0):
            raise MRTError(f"filter_sigma must be a finite number >= 0, got {self.filter_sigma}")
        if not 0.0 <= self.filter_cutoff <= 1.0:
            raise MRTError(f"filter_cutoff must be in [0, 1], got {self.filter_cutoff}")
        if int(self.max_inpoints) != self.max_inpoints or self.max_inpoints < 1:
            raise MRTError(f"max_inpoints must be an integer >= 1, got {self.max_inpoints}")
        if int(self.num_cappoints) != self.num_cappoints or self.num_cappoints < 0:
            raise MRTError(f"num_cappoints must be an integer >= 0, got {self.num_cappoints}")
        if self.id_rule not in ID_RULES:
            raise MRTError(f"id_rule must be one of {', '.join(ID_RULES)}, got {self.id_rule!r}")
        if self.rbf_degree not in (-1, 0, 1):
            raise MRTError(f"rbf_degree must be -1, 0 or 1, got {self.rbf_degree}")

    def with_(self, **changes) -> "MRTParams":
        """A copy with some fields changed (None values are ignored)."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class Reconstruction:
    """A reconstructed image and how it was made.

    Attributes
    ----------
    image : ndarray, shape (height, width, 3)
        Linear radiance; traced pixels hold their traced values exactly.
    ids : ndarray of int64, shape (height, width)
        Region id of every pixel after the edge finder.
    traced_mask : ndarray of bool, shape (height, width)
    timings : dict
        Seconds spent in ``edges`` and ``interpolate`` (compose included).
    stats : Counter
        Region counts: ``regions``, ``rbf``, ``constant``, ``no_samples``.
    """

    image: np.ndarray
    ids: np.ndarray
    traced_mask: np.ndarray
    timings: dict = field(default_factory=dict)
    stats: Counter = field(default_factory=Counter)


def reconstruct(pattern: SamplePattern, sample_ids: np.ndarray, radiance: np.ndarray,
                albedo: np.ndarray, params: MRTParams = MRTParams()) -> Reconstruction:
    """Reconstruct the full image from the traced grid (report Algorithms 2 and 3).

    Parameters
    ----------
    pattern : SamplePattern
        The traced grid.
    sample_ids : ndarray of int, shape (pattern.count,)
        Region id of each traced pixel (see :func:`mitsuba_mrt.ids.encode_ids`).
    radiance, albedo : ndarray, shape (pattern.count, 3)
        Traced radiance and surface albedo, rows outer, columns inner.
    params : MRTParams

    Examples
    --------
    >>> from mitsuba_mrt.sampling import grid_pattern
    >>> p = grid_pattern(8, 8, 0.25)
    >>> rad = np.ones((p.count, 3)); alb = np.full((p.count, 3), 0.5)
    >>> out = reconstruct(p, np.ones(p.count, int), rad, alb)
    >>> float(out.image.min()), float(out.image.max())
    (1.0, 1.0)
    """
    sample_ids = np.asarray(sample_ids, dtype=np.int64)
    radiance = np.asarray(radiance, dtype=np.float64)
    albedo = np.asarray(albedo, dtype=np.float64)
    n = pattern.count
    if sample_ids.shape != (n,) or radiance.shape[0] != n or albedo.shape != radiance.shape:
        raise MRTError(f"expected {n} traced samples with matching radiance and albedo")
    bad = ~np.isfinite(radiance).all(axis=1)
    if bad.any():
        raise MRTError(f"the nested integrator returned NaN or Inf radiance at "
                       f"{int(bad.sum())} of {n} traced pixels")
    timings = {}
    start = time.perf_counter()
    ids = quadtree_fill(pattern, sample_ids.reshape(pattern.grid_shape))
    ids = smooth_ids(ids, params.filter_sigma, params.filter_cutoff)
    timings["edges"] = time.perf_counter() - start

    start = time.perf_counter()
    interp = interpolate_regions(
        ids, pattern.pixel_xy, sample_ids, demodulate(radiance, albedo),
        max_inpoints=params.max_inpoints, num_cappoints=params.num_cappoints,
        rbf_degree=params.rbf_degree)
    image = compose(interp.values, region_albedo(ids, pattern.pixel_xy, sample_ids, albedo),
                    pattern.mask, radiance)
    timings["interpolate"] = time.perf_counter() - start
    stats = Counter(interp.counts)
    stats["regions"] = int(len(np.unique(ids)))
    return Reconstruction(image, ids, pattern.mask, timings, stats)
