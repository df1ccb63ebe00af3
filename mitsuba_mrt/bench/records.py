"""What measuring a point records: its timed runs, its rows and its images.

A method's timed calls are :class:`Run` s (seconds by :class:`Stages`, the
:class:`~.memory.Memory` of the call), gathered per method and setting in a
:class:`Runs`; a point's result is a :class:`MethodRow` per method and
setting (a :class:`DenoiseRow` in the ``denoise`` experiment), whose fields
are the CSV's columns, and the :class:`PointImages` of one setting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .memory import Memory

#: Converged reference of a stochastic point: the mean of this many full
#: renders (other seeds), so it has this factor times the point's spp.
CONVERGED_FACTOR = 16


# --------------------------------------------------------------------------- runs

@dataclass
class Stages:
    """Seconds of one call by stage; a full render is all ``trace``."""

    trace: float
    edges: float
    interpolate: float
    total: float
    denoise: float = 0.0


@dataclass
class Run:
    """One timed call of a method."""

    stages: Stages
    memory: Memory

    @property
    def total(self) -> float:
        return self.stages.total


@dataclass
class Runs:
    """Every timed run of one method at one setting, and what the last one made."""

    runs: list = field(default_factory=list)
    warmup: float = math.nan
    image: np.ndarray | None = None
    traced: int = 0
    spp: int = 0
    mode_used: str = ""

    def add(self, image: np.ndarray, run: Run) -> None:
        self.runs.append(run)
        self.image = image

    @property
    def totals(self) -> list:
        return [r.total for r in self.runs]

    def median(self) -> Run:
        """The run of the lower median total."""
        order = np.argsort(self.totals, kind="stable")
        return self.runs[int(order[(len(order) - 1) // 2])]


# --------------------------------------------------------------------------- rows

@dataclass
class MethodRow:
    """One row of a bench CSV: one method at one setting of one point.

    The fields, in order, are the CSV's columns; a number not measured is NaN.
    ``min_value`` is the lowest value of any channel of the image (below 0:
    negative radiance, which a full render does not make).
    """

    experiment: str = ""
    scene: str = ""
    group: str = ""
    method: str = ""
    mode: str = ""
    setting: str = ""
    x_name: str = ""
    x: float = math.nan
    sample_fraction: float = math.nan
    filter_sigma: float = math.nan
    filter_cutoff: float = math.nan
    integrator: str = ""
    spp: int = 0
    defines: str = ""
    width: int = 0
    height: int = 0
    traced_pixels: int = 0
    repeats: int = 0
    trace_s: float = math.nan
    edges_s: float = math.nan
    interpolate_s: float = math.nan
    total_s: float = math.nan
    total_min_s: float = math.nan
    total_max_s: float = math.nan
    warmup_s: float = math.nan
    reference_s: float = math.nan
    relative_time: float = math.nan
    error: float = math.nan
    psnr_db: float = math.nan
    stochastic: bool = False
    converged_spp: int | str = ""
    error_converged: float = math.nan
    psnr_converged_db: float = math.nan
    min_value: float = math.nan
    matched_method: str = ""
    peak_memory_mb: float = math.nan
    memory_delta_mb: float = math.nan
    peak_memory_source: str = ""
    status: str = "ok"
    variant: str = ""
    mitsuba: str = ""
    drjit: str = ""
    cpu_count: int = 0
    cpu_model: str = ""
    machine: str = ""
    platform: str = ""
    python: str = ""

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def shown_error(self) -> float:
        """The error a plot shows: against the converged reference when there is one."""
        return self.error_converged if math.isfinite(self.error_converged) else self.error


#: Columns that hold a finite number in every row whose status is ``ok``.
FINITE_COLUMNS = ("width", "height", "traced_pixels", "trace_s", "edges_s", "interpolate_s",
                  "total_s", "warmup_s", "reference_s", "relative_time", "error",
                  "peak_memory_mb")


@dataclass
class PointImages:
    """The images of one setting at a point, for a picture.

    ``reference`` is the converged reference when the point is stochastic
    (``converged``), else the full render; ``methods`` maps a method name to
    its image, and ``modes_used`` to the mode that ran (what ``auto`` chose).
    """

    reference: np.ndarray
    converged: bool
    methods: dict
    modes_used: dict


#: The denoise experiment's CSV columns, in order (the first fields of :class:`DenoiseRow`).
DENOISE_COLUMNS = ("scene", "method", "setting", "spp", "total_s", "relative_time",
                   "error_converged", "psnr_converged")


@dataclass
class DenoiseRow:
    """One row of the denoise experiment: a method at one setting and spp of one point.

    The fields up to ``psnr_converged`` are the CSV's (:data:`DENOISE_COLUMNS`);
    ``relative_time`` is over the full render at the top of the ladder, and
    the errors are against the converged reference. The rest is for the
    markdown: the scene's ``group``, its ``sampler``, the median ``denoise_s``
    stage of an MRT with ``denoise`` (the aux render plus OIDN for ``oidn``),
    the run's ``status``.
    """

    scene: str = ""
    method: str = ""
    setting: str = ""
    spp: int = 0
    total_s: float = math.nan
    relative_time: float = math.nan
    error_converged: float = math.nan
    psnr_converged: float = math.nan
    group: str = ""
    sampler: str = ""
    denoise_s: float = math.nan
    status: str = "ok"

    @property
    def ok(self) -> bool:
        return self.status == "ok"


#: The setting of the denoise experiment's rows of a noise-free trace.
NOISE_FREE = "noise-free trace"

