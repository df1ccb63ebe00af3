"""The typed contracts between the stages: parameters, traces, results.

Plain dataclasses, serialised with :func:`dataclasses.asdict`; nothing here
imports Mitsuba.
"""

from __future__ import annotations

import enum
import math
import numbers
from collections import Counter
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Protocol

import numpy as np

from .errors import MRTError
from .recon.denoise import QUALITIES
from .recon.edges import check_filter_sigma
from .recon.ids import ID_RULES, encode_ids
from .recon.sampling import check_fraction


#: Denoisers the traced grid can go through before the reconstruction.
DENOISERS = ("none", "oidn")
#: ``denoise_quality``'s settings: ``auto``, then OIDN's presets, fastest first.
DENOISE_QUALITIES = ("auto",) + QUALITIES


#: :class:`MRTParams`' numeric fields (kept as Python numbers); of them, those
#: that are integers and those that may be None.
_NUMBERS = ("sample_fraction", "filter_sigma", "filter_cutoff", "max_inpoints", "num_cappoints",
            "rbf_degree", "noise_smoothing", "time_limit", "noise_threshold")
_INTEGERS = ("max_inpoints", "num_cappoints", "rbf_degree")
_OPTIONAL = ("time_limit", "noise_threshold")


@dataclass(frozen=True)
class MRTParams:
    """Parameters of the reconstruction, named as in the report.

    Attributes
    ----------
    sample_fraction : float
        Fraction of the pixels traced on the grid, in (0, 1].
    filter_sigma : float
        Sigma (pixels) of the Gaussian id smoothing, in [0, 100].
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
    denoise : {'none', 'oidn'}
        Denoise the traced grid before reconstructing it (``oidn``: Intel
        Open Image Denoise, with the trace's albedo and normals); ``refine``
        then denoises its whole image once more, as its edge pixels are
        traced at the full spp.
    denoise_quality : {'auto', 'fast', 'balanced', 'high'}
        OIDN's quality preset for ``denoise="oidn"``: ``balanced`` and
        ``high`` run a larger network than ``fast``, slower and usually more
        accurate (docs/BENCHMARKS.md, Denoising).  ``auto``: ``high`` on the
        traced grid (a small image; ``fast`` on a time-limited preview's),
        ``fast`` on a whole image, but for the last call of ``auto``'s
        passes, which takes ``high`` where its extra time buys more than
        more passes would.
    noise_smoothing : float
        In ``fast``, ``refine`` and ``idpass``, average each traced grid
        value with the neighbours of its id that agree with it within this
        many noise standard deviations (the trace's own variance) before
        interpolating; traced pixels keep their traced value; 0: off.
    time_limit : float or None
        Mode ``auto``: seconds the whole render may take; denoised passes
        fill them (None: no limit).
    noise_threshold : float or None
        Mode ``auto``: the largest estimated relative RMS error accepted;
        the passes end when they meet it (None: a full render's own noise
        at the scene's spp, or, with ``time_limit`` alone, the best in time).
    """

    sample_fraction: float = 0.1
    filter_sigma: float = 1.0
    filter_cutoff: float = 0.05
    max_inpoints: int = 2000
    num_cappoints: int = 10
    id_rule: str = "auto"
    rbf_degree: int = -1
    denoise: str = "none"
    denoise_quality: str = "auto"
    noise_smoothing: float = 1.5
    time_limit: float | None = None
    noise_threshold: float | None = None

    def __post_init__(self):
        for name in _NUMBERS:  # (Python floats: a NumPy scalar or an int is taken as one)
            value = getattr(self, name)
            if name in _OPTIONAL and value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                what = "a finite number > 0" if name in _OPTIONAL else "a number"
                raise MRTError(f"{name} must be {what}, got {value!r}")
            if name not in _INTEGERS:
                object.__setattr__(self, name, float(value))
            elif float(value).is_integer():  # (else refused below)
                object.__setattr__(self, name, int(value))
        check_fraction("sample_fraction", self.sample_fraction)
        check_filter_sigma(self.filter_sigma)
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
        if self.denoise not in DENOISERS:
            raise MRTError(f"denoise must be one of {', '.join(DENOISERS)}, got {self.denoise!r}")
        if self.denoise_quality not in DENOISE_QUALITIES:
            raise MRTError(f"denoise_quality must be one of {', '.join(DENOISE_QUALITIES)}, "
                           f"got {self.denoise_quality!r}")
        if not (math.isfinite(self.noise_smoothing) and self.noise_smoothing >= 0):
            raise MRTError(f"noise_smoothing must be a finite number >= 0, "
                           f"got {self.noise_smoothing}")
        for name in ("time_limit", "noise_threshold"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise MRTError(f"{name} must be a finite number > 0, got {value}")

    def rule_for(self, mode: str) -> str:
        """The id rule in force for ``mode`` (``auto`` resolved)."""
        if self.id_rule != "auto":
            return self.id_rule
        return "paper" if mode == "paper" else "exact"

    def with_(self, **changes) -> "MRTParams":
        """A copy with some fields changed (None values are ignored); these
        same parameters where none is."""
        changes = {k: v for k, v in changes.items() if v is not None}
        unknown = sorted(set(changes) - {f.name for f in fields(self)})
        if unknown:
            raise MRTError(f"unknown MRT parameter {unknown[0]!r}; the parameters are "
                           f"{', '.join(f.name for f in fields(self))}")
        return replace(self, **changes) if changes else self

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
        Albedo of the pixel's first hits for the view direction, in [0, 1]
        (0 on a miss).
    shape_index : ndarray of int64, shape (n,)
        0 for background, else 1 + the shape's position in :func:`ordered_shapes`.
    visible_lights : ndarray of uint32, shape (n,)
        Bit k set when tracked light k is unoccluded from the hit point.
    num_lights : int
        Number of tracked lights (point, spot and directional lights, at most 32).
    spp : int
        Samples per pixel actually taken (the sampler may round the request:
        ``stratified`` takes the next square power of two).
    seconds : float
        Wall time of the trace, kernel compilation included.
    shadow_rays : bool
        False when light visibility was known without shadow rays (no
        tracked light, or a single sphere or planar shape).
    path_id : ndarray of int64, shape (n,), optional
        The chain of shapes met along specular (mirror) bounces, the shape
        hit inside an instance's group and the side of the surface seen
        (front or back), encoded as one integer (equal to ``shape_index``
        without mirrors and instances, on the front of a surface).
    alpha : ndarray, shape (n,), optional
        Alpha as ``mi.render`` develops it: the share of the pixel's samples
        whose camera ray hit something (None where radiance was not traced).
    normal : ndarray, shape (n, 3), optional
        World-space shading normal at the pixel-centre hit (0 on a miss);
        None where the AOVs were not traced.
    variance : ndarray, shape (n, 3), optional
        Variance of one sample's RGB about the pixel's mean: the pixel's
        noise is about ``sqrt(variance / spp)``.
    curved_mirror : ndarray of bool, shape (n,), optional
        True where the pixel-centre ray first hits a curved mirror (see
        :func:`mitsuba_mrt.renderer.scene_query.curved_mirror_indices`); None when the
        scene has none.
    odd : ndarray, shape (n, 3), optional
        Mean radiance of the pixel's odd-numbered samples (the second, the
        fourth, ...), where the trace was asked for its halves; else None.
    albedo_per_shape : bool
        Every shape's albedo is one colour (plain diffuse BSDFs, see
        :func:`mitsuba_mrt.renderer.scene_query.albedo_per_shape`), so every
        id's is too: radiance needs no division by albedo to be interpolated
        (a pixel straddling two shapes mixes their albedos, as its radiance).
    emitter : ndarray of bool, shape (n,), optional
        True where the pixel-centre ray hits a shape that emits light (an
        area light); None when the scene has none or the ids were not traced.
    filter_reach : int
        How many pixels beyond its own a pixel's samples reach (Chebyshev),
        through the pixel filter they were developed with: 0 for the box
        filter, 1 for Mitsuba's tent, 2 for its gaussian.
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
    alpha: np.ndarray | None = None
    variance: np.ndarray | None = None
    normal: np.ndarray | None = None
    odd: np.ndarray | None = None
    albedo_per_shape: bool = False
    emitter: np.ndarray | None = None
    filter_reach: int = 0

    @property
    def sees_spread_light(self) -> bool:
        """Whether a traced pixel sees a light that the pixel filter spreads
        over its neighbours (``emitter`` somewhere, ``filter_reach`` > 0):
        where a light's halo (:func:`mitsuba_mrt.recon.ids.light_halo`) may be."""
        return self.filter_reach > 0 and self.emitter is not None and bool(self.emitter.any())

    def ids(self, rule: str) -> np.ndarray:
        """Region ids of the traced pixels under ``rule`` (see :mod:`mitsuba_mrt.recon.ids`).

        The exact rule labels a pixel that sees a mirror by the chain of
        shapes along its specular path (``path_id``); the paper rule, like
        the report, by the first shape hit.
        """
        shapes = self.shape_index if rule == "paper" or self.path_id is None else self.path_id
        return encode_ids(shapes, self.visible_lights, self.num_lights, rule)

    def take(self, index) -> "SparseTrace":
        """The trace of the pixels at ``index`` (an index array or a slice),
        with the same ``seconds``."""
        n = len(self.radiance)
        return replace(self, **{f.name: value[index] for f in fields(self)
                                if isinstance(value := getattr(self, f.name), np.ndarray)
                                and len(value) == n})


@dataclass
class KernelCounts:
    """Dr.Jit kernels that a render did not find in memory: ``compiled`` anew,
    or loaded ``from_disk`` (Dr.Jit's on-disk cache of compiled kernels).
    Their seconds are part of the stages that launched them."""

    compiled: int = 0
    from_disk: int = 0


@dataclass
class Timings:
    """Seconds spent per stage; ``other`` makes the parts add up to ``total``.

    ``trace`` is the grid's trace (every pixel's, for a denoised full
    render); ``trace_more`` every pixel traced beyond the grid (edges for
    ``refine``, the id pass and thin regions for ``idpass``); ``check``
    ``auto``'s pilot; ``full_render`` the full render that ``auto`` may
    choose.  ``compile`` counts the kernels the render compiled (a count, not
    seconds).
    """

    trace: float = 0.0
    trace_more: float = 0.0
    check: float = 0.0
    denoise: float = 0.0
    edges: float = 0.0
    interpolate: float = 0.0
    full_render: float = 0.0
    other: float = 0.0
    total: float = 0.0
    compile: KernelCounts = field(default_factory=KernelCounts)

    def close(self, total: float) -> "Timings":
        """Set ``total`` and put what the stages do not account for into ``other``."""
        self.total = total
        self.other = max(0.0, total - (self.trace + self.trace_more + self.check + self.denoise
                                       + self.edges + self.interpolate + self.full_render))
        return self


@dataclass
class TracedCounts:
    """Pixels traced with the nested integrator, by why they were traced.

    ``grid`` the sample grid's; ``more`` the mode's own beyond the grid
    (edges for ``refine``, thin regions for ``idpass``); ``full`` a full
    render's (``auto``'s pilot keeps none of the pixels it traces).
    """

    grid: int = 0
    more: int = 0
    full: int = 0

    @property
    def total(self) -> int:
        return self.grid + self.more + self.full


@dataclass
class Skips:
    """Shortcuts a scene allowed, counted where they were taken.

    Attributes
    ----------
    shadow_rays : int
        Light visibility known without shadow rays (no tracked light,
        or a single sphere or planar shape).
    edge_finding : int
        A single id: no edges to find.
    albedo_division : int
        Albedo constant within every id: radiance interpolated directly.
    constant_ids : int
        Ids whose samples are all equal, filled rather than interpolated.
    background : int
        A black background filled rather than interpolated.
    """

    shadow_rays: int = 0
    edge_finding: int = 0
    albedo_division: int = 0
    constant_ids: int = 0
    background: int = 0

    def add(self, other: "Skips") -> "Skips":
        """Add ``other``'s counts to these; returns self."""
        for name, value in asdict(other).items():
            setattr(self, name, getattr(self, name) + value)
        return self


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
    timings : Timings
        ``edges``, ``interpolate`` and, for modes that trace more, ``trace_more``.
    skips : Skips
    stats : Counter
        Counts: ``regions``, and per mode ``rbf``, ``no_samples``,
        ``edge_pixels``, ``refined_pixels``, ``sliver_pixels``, ...
    mixed : ndarray of bool, shape (height, width), or None
        Pixels whose value mixes their region's light with a neighbouring
        region's (``idpass``'s edge pixels that show two surfaces,
        :mod:`mitsuba_mrt.recon.mixed`); None for modes that do not mix.
    """

    image: np.ndarray
    ids: np.ndarray
    traced_mask: np.ndarray
    timings: Timings = field(default_factory=Timings)
    skips: Skips = field(default_factory=Skips)
    stats: Counter = field(default_factory=Counter)
    mixed: np.ndarray | None = None


class SeedStream(enum.IntEnum):
    """Which sampler seed (an offset to the render's seed) a trace uses.

    Each kind of trace has its own, so that no two traces of the same pixel
    reuse random numbers.  ``BAND`` (``auto``'s full-width pilot rows)
    shares the grid's, and ``REST`` (the rows a fallback full render adds
    after the band) the edges', since they never trace the same pixels.
    """

    GRID = 0
    BAND = 0
    EDGES = 1
    REST = 1
    PILOT = 2
    ID_PASS = 3
    SLIVERS = 4
    ROUGH = 5
    #: ``auto``'s pilot: its two reference halves, then its 1-spp traces
    #: (``LADDER + k`` for the k-th)
    REFERENCE = 6
    #: ``auto``'s check of an MRT image (:mod:`mitsuba_mrt.renderer.held_out`)
    CHECK = 7
    LADDER = 16
    #: ``auto``'s preview: its grid's k-th launch after the first (``PREVIEW + k``)
    PREVIEW = 4096


class Tracer(Protocol):
    """Traces more pixels for the modes that need them (``refine``, ``idpass``).

    ``pixel_xy`` is (n, 2) of (column, row); with ``radiance`` the nested
    integrator runs, with ``aovs`` the id AOVs (albedo, shape, lights) are
    traced; what is not traced is zero.  ``replay`` says the same number of
    pixels is traced again on the next render of the image (the grid, the id
    pass): its kernels are recorded once and replayed after.  ``pad`` says
    a set like it but of another size is traced on the next render
    (``refine``'s edges, thin regions): the set is padded to one of a few
    sizes, whose kernels are recorded once and replayed after.  Without
    ``albedo`` the trace's albedo is zero (a set whose ids alone are used).
    """

    def __call__(self, pixel_xy: np.ndarray, *, stream: SeedStream = SeedStream.EDGES,
                 aovs: bool = True, radiance: bool = True,
                 replay: bool = False, pad: bool = False,
                 albedo: bool = True) -> "SparseTrace": ...


def check_radiance(radiance: np.ndarray, where: str = "traced pixels") -> None:
    """Raise MRTError, naming how many, if any pixel's radiance is NaN or Inf."""
    if np.isfinite(radiance).all():  # one flat pass: the common case
        return
    bad = ~np.isfinite(radiance).all(axis=-1)
    if bad.any():
        raise MRTError(f"the nested integrator returned NaN or Inf radiance at "
                       f"{int(bad.sum())} of {bad.size} {where}")


def is_integer(value) -> bool:
    """Whether ``value`` is an integer (a Python or NumPy one; not a bool)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def check_spp(spp) -> int:
    """``spp`` as an int, if it is an integer >= 1, else MRTError.

    Examples
    --------
    >>> check_spp(4), check_spp(np.int64(4))
    (4, 4)
    """
    if not is_integer(spp):
        raise MRTError(f"spp must be an integer >= 1, got {spp!r}")
    if spp < 1:
        raise MRTError(f"spp must be >= 1, got {spp}")
    return int(spp)


def check_seed(seed) -> int:
    """``seed`` as an int, if a sampler takes it (a 32-bit unsigned
    integer), else MRTError.

    Examples
    --------
    >>> check_seed(7), check_seed(np.uint32(7))
    (7, 7)
    """
    if not is_integer(seed) or not 0 <= seed < 1 << 32:
        raise MRTError(f"seed must be an integer in [0, 2^32), got {seed!r}")
    return int(seed)
