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
   warning, where mitsuba-oidn is not installed);
5. writes one :class:`MethodRow` per method and setting: the lower median of
   its totals, with the stage times of that same run, and the errors and
   lowest pixel value of its image.

A method that raises, or returns NaN or Inf, gets a row whose ``status``
says so; the sweep goes on.

The ``denoise`` experiment measures its points with
:class:`.measure_denoise.DenoiseRunner`, a :class:`PointRunner`: the same
warm-up, alternating rounds and converged reference, over a ladder of spp
instead of one, and the full render denoised by OIDN beside it.  What a
point records (runs, rows, images) is :mod:`.records`; its memory,
:mod:`.memory`.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import MRTError
from ..imageio import atomic_path
from ..recon.denoise import denoise_image
from ..recon.metrics import paper_error, psnr
from .experiments import (EQUAL_TIME, FULL, OIDN, OIDN_BASELINE_QUALITY, OIDN_EQUAL_TIME,
                          OIDN_NOAUX, OIDN_NOAUX_EQUAL_TIME, Experiment, Point, Setting,
                          available_methods, setting_pairs)
from .memory import MemoryMeter
from .records import CONVERGED_FACTOR, MethodRow, PointImages, Run, Runs, Stages

#: Timed seconds of the full render below which a point gets more rounds.
MIN_TIMED_SECONDS = 1.0
#: Most timed rounds of one point.
MAX_REPEATS = 25
#: Wall seconds after which a point gets no more extra rounds.
EXTRA_ROUNDS_SECONDS = 10.0


# --------------------------------------------------------------------------- the runner

def no_tick():
    """The progress bar counts the requested rounds only."""


def failure_status(exc: BaseException) -> str:
    """The status of a run that raised: one line."""
    if isinstance(exc, KeyboardInterrupt):
        raise exc
    message = str(exc).strip().splitlines()
    return f"failed: {type(exc).__name__}: {message[0] if message else ''}"


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
                self.failed[(s, m)] = failure_status(exc)
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
            tick = self.tick if rounds < self.repeats else no_tick
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
            self.failed[(s, m)] = failure_status(exc)
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
        ``oidn`` (with the ``aov`` guides) and ``oidn-noaux``; {} without OIDN.

        A run's total is the render's median total plus the denoising (and,
        with guides, the 1-spp aux render's median); each is timed
        ``repeats`` times after a first, untimed call of each.
        """
        from ..renderer.guides import render_guides

        try:
            render_guides(self.scene)  # first calls: the aux kernel, OIDN's filters
            aux_runs = [render_guides(self.scene) for _ in range(max(self.repeats, 1))]
            aux_s = float(np.median([s for _, _, s in aux_runs]))
            albedo, normal, _ = aux_runs[-1]
            kinds = {OIDN: (albedo, normal), OIDN_NOAUX: (None, None)}
            for guides in kinds.values():
                denoise_image(self.full.image, *guides, quality=OIDN_BASELINE_QUALITY)
        except MRTError as exc:  # OIDN missing or not loading: no OIDN rows
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
            out = replace(out, error=paper_error(runs.image, reference),
                          psnr_db=psnr(runs.image, reference),
                          min_value=float(runs.image.min()))
            if self.converged is not None:
                out = replace(out, error_converged=paper_error(runs.image, self.converged),
                              psnr_converged_db=psnr(runs.image, self.converged))
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
