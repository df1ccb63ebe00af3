"""Measuring one point of an experiment: every method, timed and metered, and its rows.

For each point (a scene file with its ``<default>`` values and spp) the
scene is loaded once, and :class:`PointRunner` then

1. *warms up*: every method is called once (Dr.Jit compiles its kernels
   then; that first-call time is the ``warmup_s`` column);
2. runs *timed rounds*, ``repeats`` times the full render and every method
   in turn, alternating, in this process; a point whose full render is fast
   gets more rounds, until the full render's timed runs add up to
   ``min_seconds`` (a median of three millisecond runs on a busy machine is
   noise), at most :data:`MAX_REPEATS` rounds and
   :data:`EXTRA_ROUNDS_SECONDS` of extra wall time (the ``repeats`` column
   holds the rounds run);
3. *detects a stochastic integrator* by rendering with a second seed; then
   every row's ``error_converged`` is measured against a *converged
   reference* (the mean of :data:`CONVERGED_FACTOR` full renders with other
   seeds; kept in ``<cache>/<scene>_<res>_<spp>.npy`` when the experiment
   caches it, ``spp`` being the reference's), and
4. times the *full render at other spp* (1, 4, 16 ...), for the
   ``full-equal-time`` row of every method: the full render at the spp whose
   median time is closest to that method's; and each of those renders
   *denoised by OIDN* (quality :data:`~.experiments.OIDN_BASELINE_QUALITY`),
   with the albedo and normal of Mitsuba's ``aov`` integrator at 1 spp and
   without them, the aux render and the denoising timed into its total, for
   the ``oidn-equal-time`` and ``oidn-noaux-equal-time`` rows (none, with a
   warning, where pyoidn is not installed);
5. writes one :class:`MethodRow` per method and setting: the lower median of
   its totals, with the stage times of that same run, and the errors and
   lowest pixel value of its image.

A method that raises, or returns NaN or Inf, gets a row whose ``status``
says so; the sweep goes on.

The ``denoise`` experiment measures its points with :class:`DenoiseRunner`:
the same warm-up, alternating rounds and converged reference, over a ladder
of spp instead of one, and the full render denoised by OIDN beside it.
"""

from __future__ import annotations

import math
import sys
import time
import tracemalloc
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..imageio import atomic_path
from .experiments import (EQUAL_TIME, FULL, OIDN, OIDN_BASELINE_QUALITY,
                          OIDN_EQUAL_TIME, OIDN_NOAUX, OIDN_NOAUX_EQUAL_TIME, OIDN_QUALITIES,
                          Experiment, Point, Setting, available_methods, denoised_name,
                          setting_pairs)

#: Timed seconds of the full render below which a point gets more rounds.
MIN_TIMED_SECONDS = 1.0
#: Most timed rounds of one point.
MAX_REPEATS = 25
#: Wall seconds after which a point gets no more extra rounds.
EXTRA_ROUNDS_SECONDS = 10.0

#: Warm-up rounds of a denoise point. Most kernels compile in the first; a
#: trace may compile once more in a later round when the spp before it
#: changed (``idpass`` at 1 spp: about 1.4 s at 128 x 128), which the lower
#: median of the timed rounds leaves out.
DENOISE_WARMUP_ROUNDS = 1

#: Converged reference of a stochastic point: the mean of this many full
#: renders (other seeds), so it has this factor times the point's spp.
CONVERGED_FACTOR = 16


# --------------------------------------------------------------------------- memory

def _proc_status_kb(field_name: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field_name + ":"):
                return int(line.split()[1])
    raise OSError(f"no {field_name} in /proc/self/status")


@dataclass
class Memory:
    """Peak memory of one call, and its rise over what was resident before, in MB."""

    peak_mb: float = math.nan
    delta_mb: float = math.nan


class MemoryMeter:
    """Peak memory of one call.

    On Linux: the process's peak resident set (``VmHWM``), reset before the
    call by writing 5 to ``/proc/self/clear_refs`` (source ``vmhwm``).
    Elsewhere: the peak of Python's own allocations, numpy's included, from
    :mod:`tracemalloc` (source ``tracemalloc``; Dr.Jit's memory is missed).
    """

    def __init__(self):
        self.source = "tracemalloc"
        try:
            self._reset()
            _proc_status_kb("VmHWM")
            self.source = "vmhwm"
        except (OSError, ValueError):
            pass

    @staticmethod
    def _reset():
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")

    @contextmanager
    def measure(self):
        """Yield a :class:`Memory` that is filled in when the block ends."""
        out = Memory()
        if self.source == "vmhwm":
            self._reset()
            base = _proc_status_kb("VmRSS")
            yield out
            peak = _proc_status_kb("VmHWM")
            out.peak_mb, out.delta_mb = peak / 1024.0, max(peak - base, 0) / 1024.0
        else:
            started = not tracemalloc.is_tracing()
            if started:
                tracemalloc.start()
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            try:
                yield out
                peak = tracemalloc.get_traced_memory()[1]
            finally:
                if started:
                    tracemalloc.stop()
            out.peak_mb, out.delta_mb = peak / 2**20, max(peak - base, 0) / 2**20


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


# --------------------------------------------------------------------------- the runner

def _no_tick():
    """The progress bar counts the requested rounds only."""


def _failure(exc: BaseException) -> str:
    """The status of a run that raised: one line."""
    if isinstance(exc, KeyboardInterrupt):
        raise exc
    message = str(exc).strip().splitlines()
    return f"failed: {type(exc).__name__}: {message[0] if message else ''}"


def _paper_error(image, reference):
    from ..recon.metrics import paper_error

    return paper_error(image, reference)


def _psnr(image, reference):
    from ..recon.metrics import psnr

    return psnr(image, reference)


class PointRunner:
    """Measures every method of one point; :meth:`run` returns its rows and images.

    A runner measures one point once: it keeps what it measured, step by
    step, on itself.
    """

    def __init__(self, experiment: Experiment, point: Point, methods: list, repeats: int,
                 scenes_dir: Path, meter: MemoryMeter, env: dict, tick,
                 min_seconds: float = MIN_TIMED_SECONDS, cache_dir: Path | None = None):
        self.exp, self.point, self.methods = experiment, point, methods
        self.repeats, self.scenes_dir, self.meter, self.env = repeats, scenes_dir, meter, env
        self.tick = tick
        self.min_seconds = min_seconds  # timed seconds of the full render to reach
        self.cache_dir = cache_dir  # converged references kept here (None: not kept)
        self.modes = available_methods()
        self.mrt_methods = [m for m in methods if m != FULL]

    def run(self, keep_images_for: int | None) -> tuple[list, PointImages | None]:
        """Measure the point; keep the images of setting ``keep_images_for`` (None: none)."""
        self._load()
        self._warm_up()
        rounds = self._timed_rounds()
        stochastic = self._is_stochastic()
        self.converged = self._converged_reference() if stochastic else None
        candidates = self._full_at_other_spp() if stochastic else {self.point.spp: self.full}
        self.denoised = self._denoised(candidates) if stochastic else {}
        self.tick()
        rows = self._rows(rounds, stochastic, candidates)
        for (s, m), status in self.failed.items():
            print(f"warning: {m} at {self.point.scene} {self.point.settings[s].label}: {status}",
                  file=sys.stderr)
        return rows, self._images(keep_images_for)

    # one call, timed and metered
    def _full(self, spp, seed=0) -> tuple[np.ndarray, Run]:
        from ..renderer.api import render_reference

        with self.meter.measure() as mem:
            image, seconds = render_reference(self.scene, spp=spp, seed=seed)
        return image, Run(Stages(seconds, 0.0, 0.0, seconds), mem)

    def _mrt(self, mode, setting: Setting):
        from ..renderer.api import render

        with self.meter.measure() as mem:
            result = render(self.scene, spp=self.point.spp, seed=0, mode=mode, **setting.params)
        t = result.timings
        return result, Run(Stages(t.trace, t.edges, t.interpolate, t.total), mem)

    # the steps of run()
    def _load(self) -> None:
        from ..renderer.scene import load_scene

        point = self.point
        self.scene = load_scene(self.scenes_dir / point.scene, **point.defines)
        self.width, self.height = (int(v) for v in self.scene.sensors()[0].film().crop_size())
        self.full = Runs()
        self.runs = {pair: Runs() for pair in setting_pairs(point, self.mrt_methods)}
        self.failed = {}
        self.converged = None

    def _warm_up(self) -> None:
        """The first call of everything (Dr.Jit compiles here): the ``warmup_s`` column."""
        self.full.warmup = self._full(self.point.spp)[1].total
        self.tick()
        for (s, m), r in self.runs.items():
            try:
                result, _ = self._mrt(self.modes[m], self.point.settings[s])
                r.warmup = result.timings.total
            except Exception as exc:  # noqa: BLE001 - a broken mode must not end the sweep
                self.failed[(s, m)] = _failure(exc)
            self.tick()

    def _timed_rounds(self) -> int:
        """Alternating rounds: the full render, then every method at every setting.

        Runs of milliseconds get more rounds, until the full render has
        ``min_seconds`` (at most MAX_REPEATS rounds or EXTRA_ROUNDS_SECONDS of
        wall time), since a median of 3 is noise at that scale. Returns the
        number of rounds.
        """
        point, full = self.point, self.full
        rounds, begin = 0, time.perf_counter()
        while rounds < self.repeats or (
                sum(full.totals) < self.min_seconds and rounds < MAX_REPEATS
                and time.perf_counter() - begin < EXTRA_ROUNDS_SECONDS):
            tick = self.tick if rounds < self.repeats else _no_tick
            rounds += 1
            full.add(*self._full(point.spp))
            tick()
            for (s, m), r in self.runs.items():
                if (s, m) not in self.failed:
                    self._time_method(s, m, r)
                tick()
        full.traced, full.spp = self.width * self.height, point.spp
        return rounds

    def _time_method(self, s: int, m: str, r: Runs) -> None:
        try:
            result, run = self._mrt(self.modes[m], self.point.settings[s])
        except Exception as exc:  # noqa: BLE001 - a broken mode must not end the sweep
            self.failed[(s, m)] = _failure(exc)
            return
        r.add(result.image, run)
        r.traced, r.spp = int(result.traced_mask.sum()), int(result.spp)
        r.mode_used = result.mode_used

    def _is_stochastic(self) -> bool:
        """Whether a second seed renders a different image."""
        second, _ = self._full(self.point.spp, seed=1)
        return not np.allclose(second, self.full.image, rtol=0.0, atol=1e-6)

    def _converged_reference(self) -> np.ndarray:
        """The converged reference: from the cache when it holds one of this size."""
        path = self._cache_path()
        if path is not None and path.is_file():
            try:
                image = np.load(path)
            except (OSError, ValueError):
                image = None
            if (image is not None and image.shape == (self.height, self.width, 3)
                    and np.isfinite(image).all()):
                return image
        image = self._render_converged()
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(path) as tmp, open(tmp, "wb") as f:
                np.save(f, image)
        return image

    def _cache_path(self) -> Path | None:
        if self.cache_dir is None:
            return None
        point = self.point
        res = point.defines.get("res", self.width)
        return (Path(self.cache_dir)
                / f"{Path(point.scene).stem}_{res}_{CONVERGED_FACTOR * point.spp}.npy")

    def _render_converged(self) -> np.ndarray:
        """The mean of CONVERGED_FACTOR full renders with other seeds."""
        return np.mean([self._full(self.point.spp, seed=1000 + k)[0]
                        for k in range(CONVERGED_FACTOR)], axis=0)

    def _full_at_other_spp(self) -> dict:
        """Timed full renders at spp = 1, 4, 16 ... -> :class:`Runs`, the point's own included.

        Squares, what the stratified sampler takes: every one below the
        point's spp, then up until one is as slow as the slowest method (at
        most CONVERGED_FACTOR times the point's spp).
        """
        point = self.point
        candidates = {point.spp: self.full}
        slowest = max((r.median().total for r in self.runs.values() if r.runs), default=0.0)
        spp = 1
        while spp <= CONVERGED_FACTOR * point.spp:
            if spp not in candidates:
                cand = Runs(spp=spp, traced=self.width * self.height)
                cand.warmup = self._full(spp)[1].total
                for _ in range(self.repeats):
                    cand.add(*self._full(spp))
                candidates[spp] = cand
            if spp >= point.spp and candidates[spp].median().total >= slowest:
                break
            spp *= 4
        return candidates

    def _denoised(self, candidates: dict) -> dict:
        """{method: {spp: Runs}}: every candidate full render denoised by OIDN, as
        ``oidn`` (with the ``aov`` guides) and ``oidn-noaux``; {} without pyoidn.

        A run's total is the render's median total plus the denoising (and,
        with guides, the 1-spp aux render's median); each is timed
        ``repeats`` times after a first, untimed call of each.
        """
        from ..errors import MRTError
        from ..recon.denoise import denoise_image
        from ..renderer.guides import render_guides

        try:
            render_guides(self.scene)  # first calls: the aux kernel, OIDN's filters
            aux_runs = [render_guides(self.scene) for _ in range(max(self.repeats, 1))]
            aux_s = float(np.median([s for _, _, s in aux_runs]))
            albedo, normal, _ = aux_runs[-1]
            kinds = {OIDN: (albedo, normal), OIDN_NOAUX: (None, None)}
            for guides in kinds.values():
                denoise_image(self.full.image, *guides, quality=OIDN_BASELINE_QUALITY)
        except MRTError as exc:  # pyoidn missing or not loading: no OIDN rows
            print(f"warning: no {OIDN} baselines at {self.point.scene}: {exc}", file=sys.stderr)
            return {}
        out = {}
        for method, guides in kinds.items():
            out[method] = {}
            for spp, cand in sorted(candidates.items()):
                full = cand.median()
                runs = Runs(spp=spp, traced=cand.traced or self.width * self.height)
                for _ in range(max(self.repeats, 1)):
                    begin = time.perf_counter()
                    image = denoise_image(cand.image, *guides, quality=OIDN_BASELINE_QUALITY)
                    seconds = time.perf_counter() - begin + (aux_s if guides[0] is not None
                                                             else 0.0)
                    runs.add(image, Run(Stages(full.total, 0.0, 0.0, full.total + seconds,
                                               seconds), full.memory))
                out[method][spp] = runs
        return out

    def _rows(self, rounds: int, stochastic: bool, candidates: dict) -> list:
        """Rows: the full render (at every spp tried, if asked), then every method,
        each followed by the full render and the OIDN baselines at equal time when
        the point is stochastic."""
        point, exp = self.point, self.exp
        base = MethodRow(experiment=exp.name, scene=point.scene, x_name=exp.x_name,
                         integrator=point.integrator, defines=point.defines_text,
                         width=self.width, height=self.height, repeats=rounds,
                         reference_s=self.full.median().total, stochastic=stochastic,
                         converged_spp=CONVERGED_FACTOR * point.spp if stochastic else "",
                         peak_memory_source=self.meter.source, **self.env)
        rows = []
        first = point.settings[0]
        full_setting = Setting(first.params if len(point.settings) == 1 else {},
                               first.x if len(point.settings) == 1 else point.x,
                               "full render", point.group)
        rows.append(self._row(base, FULL, None, self.full, full_setting))
        if stochastic and exp.full_spp_sweep:
            for spp, cand in sorted(candidates.items()):
                if spp != point.spp:
                    rows.append(self._row(base, FULL, None, cand,
                                          Setting({}, math.nan, f"spp={spp}", point.group)))
            for method, by_spp in self.denoised.items():
                for spp, runs in by_spp.items():
                    label = f"spp={spp}, quality={OIDN_BASELINE_QUALITY}"
                    rows.append(self._row(base, method, None, runs,
                                          Setting({}, math.nan, label, point.group)))
        for (s, m), r in self.runs.items():
            setting = point.settings[s]
            if (s, m) in self.failed:
                rows.append(self._row(base, m, self.modes[m], r, setting,
                                      status=self.failed[(s, m)]))
                continue
            rows.append(self._row(base, m, self.modes[m], r, setting))
            if stochastic and rows[-1].ok:
                t = rows[-1].total_s
                for name, pool in ((EQUAL_TIME, candidates),
                                   (OIDN_EQUAL_TIME, self.denoised.get(OIDN, {})),
                                   (OIDN_NOAUX_EQUAL_TIME, self.denoised.get(OIDN_NOAUX, {}))):
                    if pool:
                        spp = min(pool, key=lambda c: abs(math.log(pool[c].median().total / t)))
                        rows.append(self._row(base, name, None, pool[spp], setting,
                                              matched_method=m))
        return rows

    def _row(self, base: MethodRow, method: str, mode, runs: Runs, setting: Setting,
             **extra) -> MethodRow:
        """The row of ``runs``: the median run's times, the last image's errors."""
        point = self.point
        out = replace(base, method=method, mode=mode or "", group=setting.group or point.group,
                      setting=setting.label, x=setting.x, spp=runs.spp or point.spp,
                      sample_fraction=setting.params.get("sample_fraction", math.nan),
                      filter_sigma=setting.params.get("filter_sigma", math.nan),
                      filter_cutoff=setting.params.get("filter_cutoff", math.nan),
                      traced_pixels=runs.traced, warmup_s=runs.warmup, status="ok",
                      matched_method="")
        if runs.runs:
            median = runs.median()
            out = replace(out, trace_s=median.stages.trace, edges_s=median.stages.edges,
                          interpolate_s=median.stages.interpolate, total_s=median.total,
                          total_min_s=min(runs.totals), total_max_s=max(runs.totals),
                          relative_time=median.total / base.reference_s,
                          peak_memory_mb=max(r.memory.peak_mb for r in runs.runs),
                          memory_delta_mb=max(r.memory.delta_mb for r in runs.runs))
            bad = int((~np.isfinite(runs.image)).any(axis=-1).sum())
            if bad:  # timed, but no error: say so in the status
                return replace(out, status=f"failed: {bad} pixels of the image are NaN or Inf",
                               **extra)
            reference = self.full.image
            out = replace(out, error=_paper_error(runs.image, reference),
                          psnr_db=_psnr(runs.image, reference),
                          min_value=float(runs.image.min()))
            if self.converged is not None:
                out = replace(out, error_converged=_paper_error(runs.image, self.converged),
                              psnr_converged_db=_psnr(runs.image, self.converged))
        return replace(out, **extra)

    def _images(self, setting: int | None) -> PointImages | None:
        if setting is None:
            return None
        kept = {m: self.runs[(setting, m)] for m in self.mrt_methods
                if (setting, m) not in self.failed and self.runs[(setting, m)].image is not None}
        return PointImages(self.converged if self.converged is not None else self.full.image,
                           self.converged is not None,
                           {m: r.image for m, r in kept.items()},
                           {m: r.mode_used for m, r in kept.items()})

    @staticmethod
    def ticks(experiment: Experiment, point: Point, methods: list, repeats: int) -> int:
        """Steps of :meth:`run` that tick the progress bar."""
        pairs = setting_pairs(point, [m for m in methods if m != FULL])
        return (1 + len(pairs)) * (repeats + 1) + 1


# --------------------------------------------------------------------------- denoise

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


class _ConvergedTracer:
    """A tracer whose radiance is the converged reference's at the pixels asked for."""

    def __init__(self, tracer, converged: np.ndarray):
        self.tracer, self.converged = tracer, converged

    def values(self, pixel_xy: np.ndarray) -> np.ndarray:
        return self.converged[pixel_xy[:, 1], pixel_xy[:, 0]].astype(np.float64)

    def __call__(self, pixel_xy, *, radiance: bool = True, **kwargs):
        trace = self.tracer(pixel_xy, radiance=radiance, **kwargs)
        return replace(trace, radiance=self.values(pixel_xy)) if radiance else trace


class DenoiseRunner(PointRunner):
    """Measures one point of the denoise experiment; :meth:`run` returns its rows.

    At every spp of the experiment's ladder that the scene's sampler takes
    (``stratified`` rounds 2 up to 4, 8 to 9 ...; each count is run once):
    the full render; ``oidn`` and ``oidn-noaux`` at each of
    :data:`~.experiments.OIDN_QUALITIES` (that same full render, denoised
    with and without the ``aov`` integrator's albedo and normal at 1 spp,
    their render and the denoising timed into the total); every MRT method
    at every setting (without and with ``denoise``), at the ladder's spp or
    at the setting's own (:attr:`~.experiments.Setting.ladder`, which may go
    beyond the ladder's top). Warm-up, alternating
    rounds (more where the ladder's full renders are fast) and the converged
    reference are those of :class:`PointRunner`.

    Last, every MRT mode once more at the top spp with every traced value
    replaced by the converged reference's (setting :data:`NOISE_FREE`, no
    time): the error its reconstruction leaves without any noise, which no
    denoiser of the traced pixels can remove.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.ladder_asked = tuple(self.exp.ladder) or (self.point.spp,)

    @staticmethod
    def ticks(experiment: Experiment, point: Point, methods: list, repeats: int) -> int:
        ladder = tuple(experiment.ladder) or (point.spp,)
        per_round = len(ladder) + sum(
            len(point.settings[s].ladder or ladder)
            for s, _ in setting_pairs(point, [m for m in methods if m != FULL]))
        return per_round * (repeats + DENOISE_WARMUP_ROUNDS) + 1

    def run(self, keep_images_for: int | None = None) -> tuple[list, None]:
        from ..renderer.guides import sampler_spp

        self._load()
        self.sampler = sampler_spp(self.scene, self.point.spp)[0]

        def taken(asked):
            return sorted({sampler_spp(self.scene, n)[1] for n in asked})

        self.ladder = taken(self.ladder_asked)
        self.full_at = {spp: Runs(spp=spp) for spp in self.ladder}
        self.oidn = {(m, q, spp): Runs(spp=spp) for spp in self.ladder
                     for m in (OIDN, OIDN_NOAUX) for q in OIDN_QUALITIES}
        self.mrt = {(s, m, spp): Runs(spp=spp)
                    for s, m in setting_pairs(self.point, self.mrt_methods)
                    for spp in taken(self.point.settings[s].ladder or self.ladder_asked)}
        per_round = len(self.ladder) + len(self.mrt)
        skipped = self.ticks(self.exp, self.point, self.mrt_methods, self.repeats) - 1 - (
            per_round * (self.repeats + DENOISE_WARMUP_ROUNDS))
        self.failed = {}
        for _ in range(DENOISE_WARMUP_ROUNDS):
            self._round(warm=True)
        rounds, begin = 0, time.perf_counter()
        top = self.full_at[self.ladder[-1]]
        while rounds < self.repeats or (
                sum(top.totals) < self.min_seconds and rounds < MAX_REPEATS
                and time.perf_counter() - begin < EXTRA_ROUNDS_SECONDS):
            self._round(tick=rounds < self.repeats)
            rounds += 1
        self.converged = self._converged_reference()
        self.tick()
        for _ in range(skipped):
            self.tick()  # the spp the sampler rounded onto another
        for key, status in self.failed.items():
            print(f"warning: {key[1]} at {self.point.scene} spp={key[-1]}: {status}",
                  file=sys.stderr)
        return self._denoise_rows() + self._noise_free_rows(), None

    def _noise_free_rows(self) -> list:
        from ..modes import reconstruct
        from ..renderer.api import GridTracer, render
        from ..renderer.scene import unwrap

        top, converged = self.ladder[-1], self.converged
        setting = self.point.settings[0]
        rows = []
        for m in self.mrt_methods:
            mode = self.modes[m]
            if mode == "auto":  # its pilot traces beyond the grid's streams
                continue
            out = DenoiseRow(scene=self.point.scene, group=self.point.group,
                             sampler=self.sampler, method=m, setting=NOISE_FREE, spp=top)
            try:
                result = render(self.scene, spp=top, seed=0, mode=mode, **setting.params)
                tracer = _ConvergedTracer(GridTracer(self.scene, self.scene.sensors()[0],
                                                     unwrap(self.scene).nested, top, 0),
                                          converged)
                trace = replace(result.trace, radiance=tracer.values(result.pattern.pixel_xy))
                image = reconstruct(result.pattern, trace, result.params, mode, tracer).image
            except Exception as exc:  # noqa: BLE001 - a broken mode must not end the sweep
                rows.append(replace(out, status=_failure(exc)))
                continue
            rows.append(replace(out, error_converged=_paper_error(image, converged),
                                psnr_converged=_psnr(image, converged)))
        return rows

    def _round(self, warm: bool = False, tick: bool = True) -> None:
        """Everything once: the guides, then per spp the full render and its OIDN
        denoisings, then every MRT method; ``warm``: the first calls, not kept."""
        from ..recon.denoise import denoise_image
        from ..renderer.guides import render_guides

        step = self.tick if tick else _no_tick
        with self.meter.measure() as mem:
            albedo, normal, aux_s = render_guides(self.scene)
        for spp in self.ladder:
            image, run = self._full(spp)
            if not warm:
                self.full_at[spp].add(image, run)
            for method in (OIDN, OIDN_NOAUX):
                guides = (albedo, normal) if method == OIDN else (None, None)
                for quality in OIDN_QUALITIES:
                    key = (method, quality, spp)
                    if key in self.failed:
                        continue
                    try:
                        begin = time.perf_counter()
                        out = denoise_image(image, *guides, quality=quality)
                        seconds = time.perf_counter() - begin + (aux_s if method == OIDN else 0)
                    except Exception as exc:  # noqa: BLE001 - e.g. pyoidn missing: go on
                        self.failed[key] = _failure(exc)
                        continue
                    if not warm:
                        self.oidn[key].add(out, Run(
                            Stages(run.total, 0.0, 0.0, run.total + seconds, seconds),
                            Memory(max(run.memory.peak_mb, mem.peak_mb), run.memory.delta_mb)))
            step()
        for (s, m, spp), r in self.mrt.items():
            if (s, m, spp) not in self.failed:
                try:
                    result, run = self._mrt_at(self.modes[m], self.point.settings[s], spp)
                except Exception as exc:  # noqa: BLE001 - a broken mode must not end the sweep
                    self.failed[(s, m, spp)] = _failure(exc)
                else:
                    if not warm:
                        r.add(result.image, run)
            step()

    def _mrt_at(self, mode, setting: Setting, spp: int):
        from ..renderer.api import render

        with self.meter.measure() as mem:
            result = render(self.scene, spp=spp, seed=0, mode=mode, **setting.params)
        t = result.timings
        return result, Run(Stages(t.trace, t.edges, t.interpolate, t.total, t.denoise), mem)

    def _denoise_rows(self) -> list:
        point = self.point
        top = self.full_at[self.ladder[-1]]
        reference_s = top.median().total if top.runs else math.nan
        base = DenoiseRow(scene=point.scene, group=point.group, sampler=self.sampler)

        def row(method, setting, runs: Runs, spp, status=None) -> DenoiseRow:
            out = replace(base, method=method, setting=setting, spp=spp)
            if status is not None:
                return replace(out, status=status)
            median = runs.median()
            out = replace(out, total_s=median.total, relative_time=median.total / reference_s,
                          denoise_s=median.stages.denoise)
            bad = int((~np.isfinite(runs.image)).any(axis=-1).sum())
            if bad:
                return replace(out, status=f"failed: {bad} pixels of the image are NaN or Inf")
            return replace(out, error_converged=_paper_error(runs.image, self.converged),
                           psnr_converged=_psnr(runs.image, self.converged))

        rows = [row(FULL, f"sampler={self.sampler}", self.full_at[spp], spp)
                for spp in self.ladder]
        for method in (OIDN, OIDN_NOAUX):
            for quality in OIDN_QUALITIES:
                for spp in self.ladder:
                    key = (method, quality, spp)
                    rows.append(row(method, f"quality={quality}", self.oidn[key], spp,
                                    self.failed.get(key)))
        for (s, m, spp), r in self.mrt.items():
            setting = point.settings[s]
            rows.append(row(denoised_name(m, setting.params), setting.label, r, r.spp,
                            self.failed.get((s, m, spp))))
        return rows
