"""Ground-truth fields, hypothesis strategies and checks for the stress suite.

A *case* is a small set of generation parameters (image size, fraction,
layout of the ids, kind of values, albedo, scale, seed); :meth:`Case.field`
turns it into full-resolution arrays deterministically, so hypothesis
shrinks the parameters and a failing case prints as a short, readable
call.  The traced grid and the tracer of ``refine`` / ``idpass`` read the
same field, as a renderer would.

The property checks return a list of problems (strings) and a measure;
:func:`check` records them for the summary table and fails the example
(profiles ``fast`` and ``repro``: hypothesis then shrinks it), or only
records it (``thorough``, which keeps going to count failure rates and
fails the test at the end).
"""

from __future__ import annotations

import math
import os
import traceback
from collections import defaultdict
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from hypothesis import note, strategies as st

from mitsuba_mrt import MRTParams, SparseTrace, grid_pattern, reconstruct

MODES = ("paper", "fast", "refine", "idpass")
F32_MAX = float(np.finfo(np.float32).max)

LAYOUTS = ("one", "halfplane", "disc", "voronoi", "checker", "line", "diagonal",
           "staircase", "noise", "cells", "few")
#: value kinds, simplest first (hypothesis shrinks towards the first)
VALUES = ("constant", "perid", "zero", "smooth", "noise", "spiky", "mixed")
#: albedo kinds; the first three are constant within every id
ALBEDOS = ("one", "perid", "zero", "varying", "tiny")
CONSTANT_ALBEDOS = ("one", "perid", "zero", "tiny")

STRESS_PROFILE = os.environ.get("MITSUBA_MRT_STRESS", "fast")
SOFT = STRESS_PROFILE == "thorough"


# --------------------------------------------------------------------------- fields

@dataclass
class Field:
    """Full-resolution ground truth: what a full trace would return."""

    shape_index: np.ndarray    # (h, w) int64
    radiance: np.ndarray       # (h, w, 3) float64
    albedo: np.ndarray         # (h, w, 3) float64
    visible: np.ndarray        # (h, w) uint32
    num_lights: int = 0
    noise: float = 0.0         # a pixel's noise, relative to its radiance (0: noise-free)

    @property
    def height(self):
        return self.shape_index.shape[0]

    @property
    def width(self):
        return self.shape_index.shape[1]

    def at(self, pixel_xy, aovs=True, radiance=True) -> SparseTrace:
        xy = np.asarray(pixel_xy, dtype=np.int64).reshape(-1, 2)
        r, c = xy[:, 1], xy[:, 0]
        n = len(xy)
        values = self.radiance[r, c].copy() if radiance else np.zeros((n, 3))
        return SparseTrace(
            values,
            self.albedo[r, c].copy() if aovs else np.zeros((n, 3)),
            self.shape_index[r, c].copy() if aovs else np.zeros(n, np.int64),
            self.visible[r, c].copy() if aovs else np.zeros(n, np.uint32),
            self.num_lights, 1, 0.0,
            # the variance a noisy trace reports (1 spp: of the pixel's mean too);
            # it scales with the radiance, as a renderer's does
            variance=(self.noise * values) ** 2 if radiance and self.noise else None)

    def tracer(self, pixel_xy, *, stream=None, aovs=True, radiance=True,
               replay=False, pad=False, albedo=True) -> SparseTrace:
        """The modes' :class:`mitsuba_mrt.types.Tracer` (noise-free: ``stream`` is unused)."""
        return self.at(pixel_xy, aovs, radiance)

    def ids(self, rule: str) -> np.ndarray:
        """(h, w) region id of every pixel under ``rule``."""
        full = SparseTrace(np.zeros((self.shape_index.size, 3)), np.zeros((self.shape_index.size, 3)),
                           self.shape_index.ravel(), self.visible.ravel(), self.num_lights, 1, 0.0)
        return full.ids(rule).reshape(self.shape_index.shape)

    def with_radiance(self, radiance) -> "Field":
        return replace(self, radiance=np.asarray(radiance, dtype=np.float64))

    def with_shapes(self, shape_index) -> "Field":
        return replace(self, shape_index=np.asarray(shape_index, dtype=np.int64))


def _layout(layout: str, h: int, w: int, rng, pattern) -> np.ndarray:
    """(h, w) raw labels 0..k-1."""
    yy, xx = np.mgrid[:h, :w].astype(np.float64)
    if layout == "one":
        return np.zeros((h, w), np.int64)
    if layout == "halfplane":
        theta = rng.uniform(0, 2 * np.pi)
        x0, y0 = rng.uniform(0, w), rng.uniform(0, h)
        return (((xx - x0) * np.cos(theta) + (yy - y0) * np.sin(theta)) > 0).astype(np.int64)
    if layout == "disc":
        x0, y0 = rng.uniform(-1, w), rng.uniform(-1, h)
        radius = rng.uniform(0.5, max(h, w))
        return (((xx - x0) ** 2 + (yy - y0) ** 2) < radius ** 2).astype(np.int64)
    if layout == "voronoi":
        k = int(rng.integers(2, 9))
        sx, sy = rng.uniform(0, w, k), rng.uniform(0, h, k)
        d = (xx[..., None] - sx) ** 2 + (yy[..., None] - sy) ** 2
        return np.argmin(d, axis=-1).astype(np.int64)
    if layout == "checker":
        period = int(rng.integers(1, 7))
        return ((xx // period + yy // period) % 2).astype(np.int64)
    if layout == "line":  # a one-pixel row or column
        ids = np.zeros((h, w), np.int64)
        if rng.random() < 0.5:
            ids[int(rng.integers(0, h)), :] = 1
        else:
            ids[:, int(rng.integers(0, w))] = 1
        return ids
    if layout == "diagonal":  # a one-pixel diagonal line
        d = int(rng.integers(-h + 1, w))
        if rng.random() < 0.5:
            return (xx - yy == d).astype(np.int64)
        return (xx + yy == d + h - 1).astype(np.int64)
    if layout == "staircase":  # a diagonal edge
        return (xx > yy + int(rng.integers(-h + 1, w))).astype(np.int64)
    if layout == "noise":
        return rng.integers(0, int(rng.integers(2, 5)), (h, w)).astype(np.int64)
    if layout == "cells":  # every grid sample its own id (its nearest pixels)
        return pattern.nearest_image(np.arange(pattern.count)).astype(np.int64)
    if layout == "few":  # an id that only one or two grid samples carry
        ids = np.zeros((h, w), np.int64)
        picks = rng.choice(pattern.count, size=min(int(rng.integers(1, 3)), pattern.count),
                           replace=False)
        xy = pattern.pixel_xy[picks]
        ids[xy[:, 1], xy[:, 0]] = 1
        return ids
    raise ValueError(layout)


def _values(kind: str, labels: np.ndarray, rng) -> np.ndarray:
    """(h, w, 3) non-negative values of about unit scale."""
    h, w = labels.shape
    k = int(labels.max()) + 1
    yy, xx = np.mgrid[:h, :w].astype(np.float64)
    u, v = xx / max(w, 1), yy / max(h, 1)
    if kind == "mixed":  # each id its own kind
        simple = ("constant", "perid", "zero", "smooth", "noise", "spiky")
        chosen = rng.integers(0, len(simple), size=k)
        parts = np.stack([_values(name, labels, rng) for name in simple])
        return parts[chosen[labels], yy.astype(np.int64), xx.astype(np.int64)]
    if kind == "zero":
        return np.zeros((h, w, 3))
    if kind == "constant":
        return np.broadcast_to(rng.uniform(0.1, 2.0, 3), (h, w, 3)).copy()
    if kind == "perid":
        return rng.uniform(0.1, 2.0, (k, 3))[labels]
    if kind in ("smooth", "spiky"):
        a, b, c, d = (rng.uniform(0, 1, (k, 3)) for _ in range(4))
        f1, f2 = rng.uniform(0, 3, (k, 1)), rng.uniform(0, 3, (k, 1))
        uu, vv, lab = u[..., None], v[..., None], labels
        out = (a[lab] + b[lab] * uu + c[lab] * vv
               + d[lab] * (1 + np.sin(2 * np.pi * (f1[lab] * uu + f2[lab] * vv))))
        if kind == "spiky":
            spikes = rng.random((h, w)) < 0.08
            out[spikes] *= 10.0 ** rng.uniform(1, 4, (int(spikes.sum()), 1))
        return out
    if kind == "noise":
        return rng.uniform(0, 1, (h, w, 3))
    if kind == "huge":  # near float32's largest finite value
        return rng.uniform(0.01, 1.0, (h, w, 3)) * F32_MAX
    raise ValueError(kind)


def _albedo(kind: str, labels: np.ndarray, rng) -> np.ndarray:
    h, w = labels.shape
    k = int(labels.max()) + 1
    if kind == "one":
        return np.ones((h, w, 3))
    if kind == "zero":
        return np.zeros((h, w, 3))
    if kind == "perid":
        table = rng.uniform(0.05, 1.0, (k, 3))
        table[rng.random((k, 3)) < 0.15] = 0.0  # a mirror-like channel now and then
        return table[labels]
    if kind == "tiny":  # divided by, just above compose.ALBEDO_EPS
        return rng.choice([1e-5, 3e-5, 0.1], size=(k, 3))[labels]
    if kind == "varying":
        yy, xx = np.mgrid[:h, :w].astype(np.float64)
        if rng.random() < 0.5:
            return rng.uniform(0.01, 1.0, (h, w, 3))
        return (0.5 + 0.45 * np.sin(xx[..., None] * rng.uniform(0.2, 2, 3)
                                    + yy[..., None] * rng.uniform(0.2, 2, 3)))
    raise ValueError(kind)


@dataclass(frozen=True)
class Case:
    """Generation parameters of one stress case (shrinks and prints well)."""

    height: int
    width: int
    fraction: float
    layout: str = "one"
    values: str = "constant"
    albedo: str = "one"
    exponent: int = 0          # values are scaled by 10 ** exponent
    seed: int = 0
    background: bool = False   # label 0 is the background (shape 0)
    precision: str = "f32"     # f32: radiance rounded to float32, as Mitsuba returns it
    rbf_degree: int = -1       # MRTParams.rbf_degree (paper mode only)
    noise: float = 0.0         # Field.noise: the variance the trace reports

    @cached_property
    def pattern(self):
        return grid_pattern(self.width, self.height, self.fraction)

    @cached_property
    def field(self) -> Field:
        rng = np.random.default_rng(self.seed)
        labels = _layout(self.layout, self.height, self.width, rng, self.pattern)
        values = _values(self.values, labels, rng)
        if self.values != "huge":
            values = values * 10.0 ** self.exponent
        values = np.minimum(values, F32_MAX)
        if self.precision == "f32":
            values = values.astype(np.float32).astype(np.float64)
        albedo = _albedo(self.albedo, labels, rng)
        shapes = labels if self.background else labels + 1
        return Field(shapes.astype(np.int64), values, albedo,
                     np.zeros(labels.shape, np.uint32), 0, self.noise)

    @property
    def params(self) -> MRTParams:
        return MRTParams(sample_fraction=self.fraction, rbf_degree=self.rbf_degree)

    def run(self, mode: str, fld: Field | None = None):
        fld = self.field if fld is None else fld
        return reconstruct(self.pattern, fld.at(self.pattern.pixel_xy), self.params, mode,
                           fld.tracer)

    def snippet(self, mode: str, fld: Field | None = None) -> str:
        """A standalone reproduction (arrays written out when the image is small)."""
        fld = self.field if fld is None else fld
        lines = ["import numpy as np",
                 "from mitsuba_mrt import reconstruct, SparseTrace, MRTParams, grid_pattern"]
        if fld.shape_index.size <= 64:
            lines += [f"shape_index = np.array({fld.shape_index.tolist()!r})",
                      "field = " + _array_code(fld.radiance, fld.shape_index),
                      "albedo = " + _array_code(fld.albedo, fld.shape_index)]
        else:
            lines += ["import sys; sys.path.insert(0, 'tests')",
                      "from stress.stress_support import Case",
                      f"f = {self!r}.field",
                      "shape_index, field, albedo = f.shape_index, f.radiance, f.albedo"]
        lines += [
            "def tracer(xy, *, stream=None, aovs=True, radiance=True, replay=False, pad=False,",
            "           albedo=True):",
            "    r, c = xy[:, 1], xy[:, 0]; n = len(xy)",
            "    return SparseTrace(field[r, c] if radiance else np.zeros((n, 3)),",
            "                       albedo[r, c] if aovs else np.zeros((n, 3)),",
            "                       shape_index[r, c] if aovs else np.zeros(n, np.int64),",
            "                       np.zeros(n, np.uint32), 0, 1, 0.0,",
            f"                       variance=({self.noise!r} * field[r, c]) ** 2 "
            f"if radiance and {self.noise!r} else None)",
            f"p = grid_pattern({self.width}, {self.height}, {self.fraction!r})",
            f"out = reconstruct(p, tracer(p.pixel_xy), MRTParams(sample_fraction={self.fraction!r}, "
            f"rbf_degree={self.rbf_degree}), {mode!r}, tracer)",
        ]
        return "\n".join(lines)


def _array_code(values: np.ndarray, shapes: np.ndarray) -> str:
    """Short Python for a (h, w, 3) array: one value, one value per shape, or literal."""
    flat = values.reshape(-1, 3)
    if (flat == flat[0]).all():
        return f"np.full({values.shape}, {flat[0].tolist()!r})"
    labels = np.unique(shapes)
    table = {int(v): values[shapes == v] for v in labels}
    if all((t == t[0]).all() for t in table.values()) and labels.max() < 64:
        rows = [table[v][0].tolist() if v in table else [0.0, 0.0, 0.0]
                for v in range(int(labels.max()) + 1)]
        return f"np.array({rows!r})[shape_index]"
    return f"np.array({values.tolist()!r})"


# --------------------------------------------------------------------------- strategies

#: the trace's reported noise, relative to the radiance: none, slight, heavy
NOISES = st.sampled_from((0.0, 0.05, 0.5))

FRACTIONS = st.one_of(st.sampled_from([1.0, 0.5, 0.25, 0.1, 1e-9, 1e-300]),
                      st.floats(0.005, 1.0))


@st.composite
def cases(draw, *, layouts=LAYOUTS, values=VALUES, albedos=ALBEDOS, exponents=(-30, 30),
          max_side=48, degrees=(-1, 0, 1), precisions=("f32", "f64")):
    height = draw(st.integers(1, max_side))
    width = draw(st.integers(1, max_side))
    return Case(height=height, width=width, fraction=draw(FRACTIONS),
                layout=draw(st.sampled_from(layouts)), values=draw(st.sampled_from(values)),
                albedo=draw(st.sampled_from(albedos)),
                exponent=draw(st.integers(*exponents)),
                seed=draw(st.integers(0, 2 ** 16)), background=draw(st.booleans()),
                precision=draw(st.sampled_from(precisions)),
                rbf_degree=draw(st.sampled_from(degrees)), noise=draw(NOISES))


@st.composite
def degenerate_cases(draw):
    """Tiny or one-dimensional images, extreme fractions, ids on few samples."""
    thin = draw(st.integers(1, 3))
    long = draw(st.integers(1, 48))
    height, width = (thin, long) if draw(st.booleans()) else (long, thin)
    return Case(height=height, width=width,
                fraction=draw(st.sampled_from([1.0, 1e-300, 1e-9, 0.3, 0.05, 0.7])),
                layout=draw(st.sampled_from(("one", "cells", "few", "line", "diagonal",
                                             "staircase", "noise", "checker"))),
                values=draw(st.sampled_from(VALUES)),
                albedo=draw(st.sampled_from(ALBEDOS)),
                exponent=draw(st.integers(-30, 30)),
                seed=draw(st.integers(0, 2 ** 16)), background=draw(st.booleans()),
                precision="f32", rbf_degree=draw(st.sampled_from((-1, 0, 1))),
                noise=draw(NOISES))


# --------------------------------------------------------------------------- region helpers

def region_samples(case: Case, mode: str, out, fld: Field | None = None):
    """{id: (k, 3) radiance of the traced pixels that carry it} (grid and extra)."""
    fld = case.field if fld is None else fld
    truth = fld.ids(case.params.rule_for(mode))
    mask = out.traced_mask
    ids, values = truth[mask], fld.radiance[mask]
    return {int(v): values[ids == v] for v in np.unique(ids)}


def bound_tolerance(lo, hi):
    """Per channel: 1e-6 of the range plus float32 rounding of the bounds."""
    return 1e-6 * (hi - lo) + 2.0 ** -20 * np.maximum(np.abs(lo), np.abs(hi)) + 1e-300


def ratio(a, b):
    return float(a) / float(b) if b else (math.inf if a else 0.0)


# --------------------------------------------------------------------------- recording

@dataclass
class Tally:
    cases: int = 0
    failures: int = 0
    kinds: dict = field(default_factory=lambda: defaultdict(int))
    worst: float = 0.0          # largest measure of a failure (property-specific)
    smallest: tuple | None = None  # (area, case, mode, problems) of the smallest failure


TALLIES: dict[tuple[str, str], Tally] = defaultdict(Tally)


def _exception_kind(exc: BaseException) -> str:
    frames = traceback.extract_tb(exc.__traceback__)
    inner = [f for f in frames if "mitsuba_mrt" in f.filename] or frames
    where = f"{os.path.basename(inner[-1].filename)}:{inner[-1].name}" if inner else "?"
    return f"{type(exc).__name__} in {where}"


def check(prop: str, mode: str, case: Case, body):
    """Run ``body() -> (problems, measure)``, record it and fail the example.

    With the ``thorough`` profile a failure is recorded, not raised, so that
    every example runs; the test fails at the end (:func:`finish`).
    """
    tally = TALLIES[(prop, mode)]
    tally.cases += 1
    try:
        problems, measure = body()
    except Exception as exc:  # noqa: BLE001 - every crash is a finding
        if not SOFT:
            note(case.snippet(mode))
            raise
        problems, measure = [f"raised {_exception_kind(exc)}: {exc}"], 0.0
        kind = _exception_kind(exc)
    else:
        kind = problems[0].split(":")[0][:40] if problems else None
    if not problems:
        return
    tally.failures += 1
    tally.kinds[kind] += 1
    tally.worst = max(tally.worst, measure)
    area = (case.height * case.width, case.pattern.count)
    if tally.smallest is None or area < tally.smallest[0]:
        tally.smallest = (area, case, mode, problems)
    if not SOFT:
        note(case.snippet(mode))
        raise AssertionError(f"{prop}/{mode}: " + "; ".join(problems[:5]))


def finish(prop: str, mode: str):
    """In the thorough profile: fail the test if any of its examples failed."""
    tally = TALLIES.get((prop, mode))
    if SOFT and tally is not None and tally.failures:
        _, case, m, problems = tally.smallest
        raise AssertionError(
            f"{prop}/{mode}: {tally.failures} of {tally.cases} cases failed "
            f"({dict(tally.kinds)}); smallest: {case!r}: {'; '.join(problems[:3])}\n"
            + case.snippet(m))
