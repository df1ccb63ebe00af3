"""Measuring one point of the ``denoise`` experiment (:class:`DenoiseRunner`).

The same warm-up, alternating rounds and converged reference as
:class:`~.measure.PointRunner`, over a ladder of spp instead of one, and the
full render denoised by OIDN beside it; last, every MRT mode on a trace
whose values are all the converged reference's (:data:`~.records.NOISE_FREE`).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import replace

import numpy as np

from ..modes import reconstruct
from ..recon.denoise import denoise_image
from ..recon.metrics import paper_error, psnr
from .experiments import (FULL, OIDN, OIDN_NOAUX, OIDN_QUALITIES, Experiment, Point, Setting,
                          denoised_name, setting_pairs)
from .measure import EXTRA_ROUNDS_SECONDS, MAX_REPEATS, PointRunner, failure_status, no_tick
from .memory import Memory
from .records import NOISE_FREE, DenoiseRow, Run, Runs, Stages

#: Warm-up rounds of a denoise point. Most kernels compile in the first; a
#: trace may compile once more in a later round when the spp before it
#: changed (``idpass`` at 1 spp: about 1.4 s at 128 x 128), which the lower
#: median of the timed rounds leaves out.
DENOISE_WARMUP_ROUNDS = 1


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
                rows.append(replace(out, status=failure_status(exc)))
                continue
            rows.append(replace(out, error_converged=paper_error(image, converged),
                                psnr_converged=psnr(image, converged)))
        return rows

    def _round(self, warm: bool = False, tick: bool = True) -> None:
        """Everything once: the guides, then per spp the full render and its OIDN
        denoisings, then every MRT method; ``warm``: the first calls, not kept."""
        from ..renderer.guides import render_guides

        step = self.tick if tick else no_tick
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
                    except Exception as exc:  # noqa: BLE001 - e.g. OIDN missing: go on
                        self.failed[key] = failure_status(exc)
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
                    self.failed[(s, m, spp)] = failure_status(exc)
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
            return replace(out, error_converged=paper_error(runs.image, self.converged),
                           psnr_converged=psnr(runs.image, self.converged))

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
