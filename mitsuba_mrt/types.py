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

from .compose import albedo_constant_per_id, compose, demodulate, region_albedo, safe_albedo
from .edges import quadtree_fill, region_boxes, smooth_ids
from .errors import MRTError
from .ids import ID_RULES, encode_ids
from .interpolate import interpolate_regions
from .sampling import SamplePattern, check_fraction
from .threads import jit_workers_parked


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
    id_rule : {'auto', 'paper', 'exact'}
        How ids are made from shape and light visibility (see ``ids``);
        ``auto``: the report's rule in mode ``paper``, ``exact`` elsewhere.
    rbf_degree : {-1, 0, 1}
        Polynomial degree added to the linear RBF (-1: the report's).
    """

    sample_fraction: float = 0.1
    filter_sigma: float = 1.0
    filter_cutoff: float = 0.05
    max_inpoints: int = 2000
    num_cappoints: int = 10
    id_rule: str = "auto"
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
        if self.id_rule not in ("auto",) + ID_RULES:
            raise MRTError(f"id_rule must be one of auto, {', '.join(ID_RULES)}, "
                           f"got {self.id_rule!r}")
        if self.rbf_degree not in (-1, 0, 1):
            raise MRTError(f"rbf_degree must be -1, 0 or 1, got {self.rbf_degree}")

    def rule_for(self, mode: str) -> str:
        """The id rule in force for ``mode`` (``auto`` resolved)."""
        if self.id_rule != "auto":
            return self.id_rule
        return "paper" if mode == "paper" else "exact"

    def with_(self, **changes) -> "MRTParams":
        """A copy with some fields changed (None values are ignored)."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class SparseTrace:
    """What the trace learnt at each traced pixel.

    Attributes
    ----------
    radiance : ndarray, shape (n, 3)
        Mean radiance of the pixel's samples, from the nested integrator.
    albedo : ndarray, shape (n, 3)
        Diffuse reflectance at the pixel-centre hit (0 on a miss or a mirror).
    shape_index : ndarray of int64, shape (n,)
        0 for background, else 1 + the shape's position in :func:`ordered_shapes`.
    visible_lights : ndarray of uint32, shape (n,)
        Bit k set when tracked light k is unoccluded from the hit point.
    num_lights : int
        Number of tracked lights (point and spot lights, at most 32).
    spp : int
        Samples per pixel actually taken (the sampler may round the request:
        ``stratified`` takes the next square power of two).
    seconds : float
        Wall time of the trace, kernel compilation included.
    shadow_rays : bool
        False when light visibility was known without shadow rays (no
        point or spot light, or a single sphere or planar shape).
    path_id : ndarray of int64, shape (n,), optional
        The chain of shapes met along specular (mirror) bounces, encoded
        as one integer (equal to ``shape_index`` without mirrors).
    curved_mirror : ndarray of bool, shape (n,), optional
        True where the pixel-centre ray first hits a curved mirror (see
        :func:`mitsuba_mrt.trace.curved_mirror_indices`); None when the
        scene has none.
    """

    radiance: np.ndarray
    albedo: np.ndarray
    shape_index: np.ndarray
    visible_lights: np.ndarray
    num_lights: int
    spp: int
    seconds: float
    shadow_rays: bool = True
    path_id: np.ndarray | None = None
    curved_mirror: np.ndarray | None = None

    def ids(self, rule: str) -> np.ndarray:
        """Region ids of the traced pixels under ``rule`` (see :mod:`mitsuba_mrt.ids`).

        The exact rule labels a pixel that sees a mirror by the chain of
        shapes along its specular path (``path_id``); the paper rule, like
        the report, by the first shape hit.
        """
        shapes = self.shape_index if rule == "paper" or self.path_id is None else self.path_id
        return encode_ids(shapes, self.visible_lights, self.num_lights, rule)


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


def check_radiance(radiance: np.ndarray, where: str = "traced pixels") -> None:
    """Raise MRTError, naming how many, if any pixel's radiance is NaN or Inf."""
    if np.isfinite(radiance).all():  # one flat pass: the common case
        return
    bad = ~np.isfinite(radiance).all(axis=-1)
    if bad.any():
        raise MRTError(f"the nested integrator returned NaN or Inf radiance at "
                       f"{int(bad.sum())} of {bad.size} {where}")


def paper_reconstruct(pattern: SamplePattern, trace: SparseTrace, params: MRTParams,
                      tracer=None) -> Reconstruction:
    """The report's reconstruction (Algorithms 2 and 3), mode ``paper``.

    Parameters
    ----------
    pattern : SamplePattern
        The traced grid.
    trace : SparseTrace
        Radiance and AOVs of the traced pixels, rows outer, columns inner.
    params : MRTParams
    tracer : callable, optional
        Unused: this mode traces nothing beyond the grid.
    """
    sample_ids = trace.ids(params.rule_for("paper"))
    timings = {}
    stats = Counter()
    start = time.perf_counter()
    if np.all(sample_ids == sample_ids[0]):
        ids = np.full((pattern.height, pattern.width), sample_ids[0], dtype=np.int64)
        stats["skipped_edge_finding"] += 1
    else:
        grid_ids = sample_ids.reshape(pattern.grid_shape)
        ids = smooth_ids(quadtree_fill(pattern, grid_ids), params.filter_sigma,
                         params.filter_cutoff, boxes=region_boxes(pattern, grid_ids))
    timings["edges"] = time.perf_counter() - start

    start = time.perf_counter()
    # one albedo per id: radiance interpolates as albedo x irradiance would
    modulated = not albedo_constant_per_id(sample_ids, safe_albedo(trace.albedo))
    interp = interpolate_regions(
        ids, pattern.pixel_xy, sample_ids,
        demodulate(trace.radiance, trace.albedo) if modulated else trace.radiance,
        max_inpoints=params.max_inpoints, num_cappoints=params.num_cappoints,
        rbf_degree=params.rbf_degree)
    if modulated:
        albedo = region_albedo(ids, pattern.pixel_xy, sample_ids, trace.albedo,
                               nearest=pattern.nearest_image(np.arange(pattern.count)))
        image = compose(interp.values, albedo, pattern.mask, trace.radiance)
    else:
        stats["skipped_albedo_division"] += 1
        image = interp.values
        pattern.put_traced(image, trace.radiance)
    timings["interpolate"] = time.perf_counter() - start
    stats.update(interp.counts)
    # every id of the map was interpolated, filled as constant, or had no samples
    stats["regions"] = sum(interp.counts[key] for key in ("rbf", "skipped_constant_ids",
                                                          "no_samples"))
    return Reconstruction(image, ids, pattern.mask, timings, stats)


#: Reconstruction modes by name: ``fn(pattern, trace, params, tracer) -> Reconstruction``.
MODES = {"paper": paper_reconstruct}


def register_mode(name: str, function) -> None:
    """Make a reconstruction function available as ``mode=name``."""
    MODES[name] = function


def reconstruct(pattern: SamplePattern, trace: SparseTrace, params: MRTParams = MRTParams(),
                mode: str = "paper", tracer=None) -> Reconstruction:
    """Reconstruct the full image from the traced grid with one of :data:`MODES`.

    Parameters
    ----------
    pattern : SamplePattern
        The traced grid.
    trace : SparseTrace
        Radiance and AOVs of the traced pixels, rows outer, columns inner.
    params : MRTParams
    mode : str
        A key of :data:`MODES` (``paper``, ``nearest``, ``bicubic``, ...).
    tracer : callable, optional
        ``tracer(pixel_xy, seed_offset=1, aovs=True, radiance=True) ->
        SparseTrace`` traces more pixels (with the nested integrator when
        ``radiance``, with the id AOVs when ``aovs``), for modes that refine.

    Examples
    --------
    >>> from mitsuba_mrt.sampling import grid_pattern
    >>> p = grid_pattern(8, 8, 0.25)
    >>> t = SparseTrace(np.ones((p.count, 3)), np.full((p.count, 3), 0.5),
    ...                 np.ones(p.count, int), np.ones(p.count, np.uint32), 1, 1, 0.0)
    >>> out = reconstruct(p, t)
    >>> float(out.image.min()), float(out.image.max())
    (1.0, 1.0)
    """
    if mode not in MODES:
        raise MRTError(f"unknown mode {mode!r}; choose one of {', '.join(MODES)}")
    n = pattern.count
    shapes = (trace.radiance.shape, trace.albedo.shape, trace.shape_index.shape,
              trace.visible_lights.shape)
    if shapes != ((n, 3), (n, 3), (n,), (n,)):
        raise MRTError(f"expected {n} traced samples with radiance, albedo and ids, got {shapes}")
    check_radiance(trace.radiance)
    with jit_workers_parked():  # none of Dr.Jit's workers busy-waits beside numpy
        return MODES[mode](pattern, trace, params, tracer)
