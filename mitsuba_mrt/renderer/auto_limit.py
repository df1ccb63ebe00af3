"""``auto`` under a time limit: what fits, judged from what this process measured.

Before the passes (:mod:`.progressive`) fill a time limit, ``auto`` asks
whether something else fits it better: an MRT plan a default render of the
scene kept (:func:`measured_within`), :data:`~.auto_plans.HOME` where the
grid probe says it ends in time (:func:`mrt_within`; on a denser grid where
the limit leaves the time), or a preview, where
one pass and OIDN on every pixel would overrun the limit
(:func:`preview_first`, :func:`filled_preview`).  What the process's
earlier renders took (their first round, their last OIDN call, the passes'
launches, the grid probe, a preview's stages after its grid) is kept here,
per scene key, to plan the next one; the passes' launches, the grid
probe and a fresh process's preview stages also for later processes
(:mod:`mitsuba_mrt.runtime.memory`),
which plan from them where they have measured nothing themselves (a
remembered probe is not traced again: it takes a fifth of the smallest limits).
"""

from __future__ import annotations

import hashlib
import math
import time
from collections.abc import Callable
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ..modes.plan import Candidate, Plan
from ..recon.denoise import (calls_at, denoise_seconds, expected_seconds, grid_preset,
                             preset, prior_seconds)
from ..recon.ids import edge_share
from ..recon.sampling import SamplePattern
from ..runtime import memory
from ..runtime.jit import kernel_seconds
from ..runtime.recent import keep, note, typical
from ..types import MRTParams, SeedStream, SparseTrace
from . import kept_plans
from .auto_plans import (EDGE_TESTED, HOME, HOME_MIN_SPP, AutoOutcome, Traced, edge_tested,
                         find_surfaces, trace_id_pass, unmeasured_plan)
from .preview import preview_grid
from .launch_cost import LaunchCost
from .replay import recorded_during
from .scene_query import (description_key, sample_count_at_most, sampler_bakes_spp,
                          textured_diffuse_shapes)

#: The share of a time limit the passes may plan to fill (the final OIDN
#: call's time is planned within it; the rest is for the machine's noise and
#: a fresh process's first uses: at 0.97 first renders took up to 1.16 times
#: a quarter of a full render).
TIME_MARGIN = 0.93

#: Where the sampler bakes its spp into the kernels, the spp (as the sampler
#: takes them) a time-limited render's launches may have besides those
#: launched before (:func:`launch_ladder`): the squares to 64, which
#: ``stratified`` and ``multijitter`` take.  Where only the spp launched
#: before were taken, a scene's first time-limited render filled its time
#: with launches of 1 spp, each a stratum of its own.
LADDER = tuple(k * k for k in range(2, 9))

#: The plan where one pass and OIDN on the whole image would overrun a time
#: limit: the MRT's cheapest image, a tenth of the pixels' samples (its
#: grid, one sample each, more where the limit leaves time) denoised and
#: reconstructed.
PREVIEW = Candidate("fast+oidn", "mrt", 1, mode="fast", denoise=True)
PREVIEW_REASON = "a preview: one pass and OIDN on every pixel would overrun the time limit"
#: OIDN's preset for a preview's grid where ``denoise_quality`` is ``auto``
#: (:func:`preview_params`): the one its time is planned at
#: (:func:`_preview_after`), not the MRT's usual grid preset, which costs
#: more and a preview has the least time.
PREVIEW_QUALITY = "fast"
#: The preview where OIDN's call, even right after the grid's first launch,
#: would end past :data:`PREVIEW_SLACK` times the limit: its grid as traced.
UNDENOISED = Candidate("fast", "mrt", 1, mode="fast", denoise=False)
UNDENOISED_NOTE = "OIDN would end past the time limit: the preview is not denoised"
#: The preview where even its reconstruction, right after the grid's first
#: launch, would end past :data:`PREVIEW_SLACK` times the limit (a limit
#: that a fresh process's first trace nearly fills): the grid upsampled,
#: a fraction of the reconstruction's time.
UPSAMPLED = Candidate("bicubic", "mrt", 1, mode="bicubic", denoise=False)
UPSAMPLED_NOTE = ("the reconstruction would end past the time limit: the preview is the grid "
                  "upsampled (bicubic)")
#: The note of a preview taken where a pass could be planned only at an spp
#: traced before in the process (``{}``), as the sampler bakes its spp into
#: its kernels: a pass of 1 spp would record kernels whose compilation, where
#: Dr.Jit's disk cache lacks them, no probe tells.
BAKED_NOTE = ("the sampler bakes its sample count into its kernels: a pass at 1 spp, never "
              "launched in this process, might compile them for seconds, and the cheapest "
              "launched, at {} spp, does not fit")
#: How far one pass and OIDN may end past a time limit before the preview is
#: taken instead: the preview's error is several times a pass's, and a limit
#: is held to within 10 %.
PREVIEW_SLACK = 1.1
#: ... where the pass's time is the grid probe's guess rather than earlier
#: passes' measure (the process's first passes of the scene): a fresh
#: process's first pass took 1.15-1.5 times the guess (``two_sensors`` at
#: 256 px), so the pass and OIDN must be expected to end within the limit
#: itself.
PROBED_SLACK = 1.0

#: Under a time limit, a process's first passes of a scene are launched
#: without the grid probe where the limit is at least this many times
#: OIDN's first-call prior for the image
#: (:func:`~mitsuba_mrt.recon.denoise.prior_seconds`): a fresh process's
#: first 1-spp pass over every pixel took 0.46-2.54 times that prior on the
#: gallery at 256 and 512 px on the Intel VM (``examples/first_calls.py
#: --passes 256 512``; its kernels' recording, as the probe's, is
#: most of it at 256 px), so that a pass and the call end within the
#: passes' share of the limit (:data:`TIME_MARGIN`), and the probe, as long
#: again, would only take time from the passes.
UNPROBED_OVER_OIDN = 4.0

#: Under a time limit, what denoising textured diffuse surfaces as their
#: shading (:attr:`.progressive.Passes.shading`) adds to a pass's last OIDN
#: call, as a share of its expected time: finding the textured pixels and
#: the division (on the gallery's textured scenes at 256 px, 2 cores, the
#: shading call took 1.17 times a plain one, and finding the pixels 0.1-0.35
#: times more, the most right after OIDN's or Dr.Jit's threads have run).
SHADING_EXTRA = 0.5

#: A pass of every pixel (1 spp, box filter, guides) over the preview's grid
#: trace's kernel time scaled to as many pixels (that trace also follows
#: each pixel's centre for its ids): 0.65-0.81 on the gallery at 256 px.
PASS_OVER_GRID = 0.75

#: Under a time limit, :data:`HOME`'s grid at the scene's spp is expected to
#: take at most this many times the grid probe's kernel time (1 spp) per spp
#: (the probe's share that does not grow with the spp, its ids and albedo,
#: makes the measured ratio 0.42-0.74 on the gallery at 512 px).
GRID_OVER_PROBE = 0.75
#: ... and its id pass at most this many times the probe's kernel time, before
#: it is traced (6-31 on the gallery at 512 px: it is traced, and its time
#: counted, only where even this much would fit).
ID_PASS_OVER_PROBE = 32.0
#: ... and the stages after its traces (OIDN on the grid, the reconstruction)
#: this many seconds a pixel (0.29-0.38 us warm on the gallery at 400-512 px).
FINISH_PER_PIXEL = 0.45e-6
#: A process's first preview: its stages after the grid but OIDN took at most
#: (fixed seconds, seconds a pixel), and its OIDN call on the grid at most
#: :data:`PREVIEW_FIRST_OIDN` times the call's expected time
#: (``examples/first_calls.py --previews 256 384 512 768``, two runs on the
#: AMD VM of docs/BENCHMARKS.md: 0.018-0.114 s, 0.70-1.87 times).  Their sum
#: bounds those stages where it is less than :data:`FINISH_PER_PIXEL`'s bound
#: (from about 450 px a side: 0.12 s against 0.14 s at 512 px, where they took
#: 0.07-0.10 s).
PREVIEW_FIRST_REST = (0.036, 0.14e-6)
PREVIEW_FIRST_OIDN = 2.0
#: What a preview's reconstruction without OIDN (mode ``fast``) is expected
#: to take per image pixel in a fresh process: this much, plus
#: :data:`RECONSTRUCTION_PER_EDGE` times the share of the grid's samples on an
#: id edge (on the gallery at 256 px, 2 cores: 0.27-0.44 us, the most where
#: edges are many, ``cornell`` and ``instanced``; the fit is within 17 %
#: above and 12 % below).  Where it would end past the limit's slack, the
#: grid is upsampled instead.
RECONSTRUCTION_PER_PIXEL, RECONSTRUCTION_PER_EDGE = 0.25e-6, 0.8e-6
#: The denser grids :data:`HOME` may take under a time limit that leaves it
#: time beyond the default grid's (:func:`denser_grid`): two sizes, so that
#: the renders of a scene keep to them (each size is a first call of OIDN's
#: on its shape).  Past 0.3 the error fell by at most 4 % (``idpass+oidn``
#: on Fig. 1 at 400 px and ``checker_border`` at 256, for 1.5 times the time).
DENSER_GRIDS = (0.2, 0.3)
#: Without OIDN, the least a process's first undenoised ``idpass`` of a scene
#: at 64 spp can take under a time limit: this many seconds and as many a
#: pixel again, of which the grid's half goes with the spp
#: (:func:`plain_probe_due`).  A fresh process's ``idpass`` at 64 spp and the
#: grid probe before it took at least this on the gallery's scenes of
#: :data:`~.auto_plans.PLAIN`'s kind (``two_sensors``: 0.19 s at 256 px, 0.50
#: at 512; the others up to 0.71 and 1.84; its grid and its id pass about
#: half each; 2 cores): under it the probe, the first trace of the scene and
#: a fifth to four fifths of such a limit, only delays the passes after it.
PLAIN_FLOOR = (0.085, 1.6e-6)
#: The reason of :data:`HOME` taken under a time limit (``{}``: its kind's).
WITHIN_REASON = "{}; within the time limit"

#: Seconds from a time-limited render's start to the end of its first round
#: of passes, per traced objects and pixel count, from the last such render
#: in this process whose kernels were all replayed (the last
#: :data:`KEPT_COSTS` keys): what tells a limit too
#: short for one pass and OIDN before a pass is traced.  A time that gives a
#: preview is dropped: a preview traces no round, so one slow round would
#: otherwise give previews for good.
_first_round_s: dict = {}
#: The seconds the last OIDN call of a time-limited render's passes took,
#: per the same keys and whether it denoised textures as their shading,
#: from the last such render: the next one leaves at least this for it after
#: a first round (OIDN's expected time leaves out a filter made anew).
_final_denoise_s: dict = {}
#: The passes' launches (:class:`~.launch_cost.LaunchCost`), per traced
#: objects and pixel count, of the last :data:`KEPT_COSTS` such keys: what
#: the next render's passes plan from.
_launch_costs: dict = {}
KEPT_COSTS = 16
#: Per the same keys (the last :data:`KEPT_COSTS`), the key of the scene in
#: what earlier processes measured (:func:`_memory_key`).
_memory_keys: dict = {}
#: What the grid probe took beyond its kernels when it recorded them, per
#: the same keys (the last :data:`KEPT_COSTS`): about what the passes' first
#: launch adds by recording theirs (both trace the integrator anew), which
#: a replayed probe's time does not show.
_probe_recording_s: dict = {}
#: The grid probe's kernel run time per the same keys (the last
#: :data:`KEPT_COSTS`), from its last replay, or before any, what an earlier
#: process remembered (:func:`_recalled_probe`): where it says :data:`HOME`
#: cannot end within a time limit, the next render of the scene is not
#: probed for it (:func:`mrt_within`).
_probe_execute: dict = {}
#: The seconds a preview's stages after its grid took (OIDN on the grid, the
#: reconstruction, the finish), the last :data:`PREVIEW_AFTER_CALLS` per the
#: same keys (the last :data:`KEPT_COSTS`): the next preview of the scene
#: leaves their median for them (:func:`filled_preview`), where the first
#: leaves :data:`FINISH_PER_PIXEL`'s bound, which holds a fresh process's
#: first uses.
_preview_after_s: dict = {}
PREVIEW_AFTER_CALLS = 3
#: The seconds per image pixel that the stages after a preview's grid took
#: beyond OIDN (the reconstruction, the finish), the last
#: :data:`PREVIEW_RATE_CALLS` previews in this process, of any scene, with
#: OIDN or without: the first preview of a scene in a process that has made
#: others leaves their largest for them, OIDN's expected time on top, where
#: that is less than :data:`FINISH_PER_PIXEL`'s fresh-process bound.
_preview_rate: list = []
PREVIEW_RATE_CALLS = 8

#: The reason of a plan :func:`measured_within` takes (``{}``: its kind's,
#: then its spp and expected seconds).
MEASURED_REASON = ("{}; at {} spp, {:.3g} s expected from this process's renders of "
                   "the scene: within the time limit")


def plan_within(scene, pattern: SamplePattern, tracer, params: MRTParams, started: float,
                key: tuple, kept_key: tuple, notes: list, escape: bool = True
                ) -> tuple[AutoOutcome | None, Traced, tuple | None, bool]:
    """Under a time limit, OIDN installed: (the outcome of a plan other than
    the passes where one fits the limit better, else None; what was traced
    of every pixel; the passes' textured surfaces and whether they were
    looked up, :func:`preview_first`).

    Without a ``noise_threshold``, at least :data:`~.auto_plans.HOME_MIN_SPP`
    spp and with ``escape``: an MRT plan a default render of ``kept_key``
    kept (:func:`measured_within`), else :data:`~.auto_plans.HOME` where the
    grid probe says it ends in time (:func:`mrt_within`).  Then the
    preview (:func:`filled_preview`) where one pass and OIDN would overrun
    the limit."""
    traced, probed = Traced(), None
    if escape and params.noise_threshold is None and tracer.spp >= HOME_MIN_SPP:
        outcome = measured_within(kept_key, started, params.time_limit, notes,
                                  sampler_bakes_spp(tracer.sensor.sampler()),
                                  pattern.width * pattern.height, params)
        if outcome is not None:
            return outcome, traced, None, False
        outcome, traced, probed = mrt_within(scene, pattern, tracer, params, started, notes,
                                             key)
        if outcome is not None:
            return outcome, traced, None, False
    outcome, surfaces, found = preview_first(scene, pattern, tracer, params, started, key,
                                             notes, probed, traced)
    if outcome is not None:
        note_baked(key, notes)
        outcome = filled_preview(outcome, pattern, tracer, params, started, key)
    return outcome, traced, surfaces, found


def kept_cost(key: tuple, tracer, guides: bool = True) -> LaunchCost:
    """The launches kept for ``key`` (where there are none, those an earlier
    process remembered, :func:`remember_launches`, else none, of
    ``tracer``'s sampler), now the most recently used of :data:`_launch_costs`;
    launches of 1 and 2 spp among its :attr:`~.launch_cost.LaunchCost.replays`
    where another trace recorded their layout (a full render denoised; with
    the ``guides`` or, for passes not to be denoised, without), and where
    the sampler bakes its spp, :func:`launch_ladder`'s."""
    cost = _launch_costs.get(key)
    if cost is None:
        sampler = tracer.sensor.sampler()
        bakes = sampler_bakes_spp(sampler)
        recalled = memory.recall(_memory_key(key, tracer)) if memory.enabled() else None
        cost = LaunchCost.from_memory(recalled, bakes) or LaunchCost(spp_compiles=bakes)
        cost.ladder = launch_ladder(sampler) if bakes else frozenset()
    cost = _keep(_launch_costs, key, cost)
    cost.replays = frozenset(spp for spp in (1, 2) if tracer.pass_recorded(spp, guides))
    return cost


def launch_ladder(sampler) -> frozenset:
    """The spp a time-limited render's launches may have, besides those
    launched before, where ``sampler`` bakes its spp into the kernels: each
    of :data:`LADDER` as the sampler takes it (:func:`.scene_query.sample_count_at_most`)."""
    return frozenset(sample_count_at_most(sampler, spp) for spp in LADDER)


def remember_launches(key: tuple, tracer) -> None:
    """Keep the launches of ``key`` (:data:`_launch_costs`) for later
    processes that render the same scene (:mod:`mitsuba_mrt.runtime.memory`),
    where they have something new (:meth:`~.launch_cost.LaunchCost.memory_due`)."""
    cost = _launch_costs.get(key)
    if cost is not None and cost.memory_due() and memory.enabled():
        memory.remember(_memory_key(key, tracer), cost.memory())
        cost.note_remembered()


def _remember_probe(key: tuple, tracer, probed: "_Probe", count: int) -> None:
    """Keep the grid probe of ``count`` pixels for later processes that
    render the scene (:mod:`mitsuba_mrt.runtime.memory`), where it compiled
    nothing (a recording call runs the kernels it records): its kernel run
    time, and where it was the process's first recording (as a later
    process's first probe will be) what it took beyond them."""
    if memory.enabled() and probed.compile == 0.0 and probed.execute > 0.0:
        kept = {"execute": probed.execute, "count": int(count)}
        if probed.first:
            kept["host"] = probed.host
        memory.remember(f"{_memory_key(key, tracer)}/probe", kept)


def _recalled_probe(key: tuple, tracer) -> float | None:
    """The grid probe's kernel run time an earlier process remembered for
    ``key``'s scene (:func:`_remember_probe`), else None."""
    kept = _recalled(key, tracer)
    return None if kept is None else kept[0]


def _recalled_line(key: tuple, tracer, pattern: SamplePattern) -> "_Probe | None":
    """The grid probe an earlier process made of ``key``'s scene as its first
    trace of it (:func:`_remember_probe`), as :func:`_grid_probe` would
    return it in this process, without its grid; else None."""
    kept = _recalled(key, tracer)
    if kept is None or kept[1] is None:
        return None
    execute, host, count = kept
    return _Probe(None, _pass_seconds(host, execute, pattern.width * pattern.height, count),
                  execute, host, True, first=True)


def _recalled(key: tuple, tracer) -> tuple[float, float | None, int] | None:
    """(kernel run time, time beyond it where the probe was its process's
    first recording, else None, its pixels) of the grid probe an earlier
    process remembered for ``key``'s scene; None where none is remembered."""
    if not memory.enabled():
        return None
    kept = memory.recall(f"{_memory_key(key, tracer)}/probe") or {}

    def number(name: str, least: float = 0.0) -> float | None:
        value = kept.get(name)
        ok = isinstance(value, (int, float)) and least <= value < math.inf
        return float(value) if ok else None
    execute, host, count = number("execute"), number("host"), number("count", 1.0)
    if execute is None or execute <= 0.0:
        return None
    if count is None:  # (a line needs the pixels its kernel time was for)
        return execute, None, 1
    return execute, host, int(count)


def plan_memory_key(kept_key: tuple, tracer) -> str | None:
    """The key of a kept plan's key (:func:`~.auto.scene_key` and
    :func:`~.auto.plan_key`) in the memory of earlier processes: its scene's
    (:func:`_memory_key`) and a digest of its spp and parameters; None where
    the memory is off."""
    if not memory.enabled():
        return None
    rest = hashlib.sha256(repr(kept_key[2:]).encode()).hexdigest()[:16]
    return f"{_memory_key(kept_key[:2], tracer)}/plan/{rest}"


def _memory_key(key: tuple, tracer) -> str:
    """The key of ``key``'s scene (:func:`~.auto.scene_key`: the traced objects
    and the pixel count) in the memory of earlier processes (:func:`.scene_query.description_key`),
    worked out once per process (:data:`_memory_keys`)."""
    known = _memory_keys.get(key)
    if known is None:
        known = description_key(tracer.scene, tracer.sensor, tracer.integrator, key[-1])
    return _keep(_memory_keys, key, known)


def note_first_round(key: tuple, seconds: float) -> None:
    """Keep ``seconds``, from a time-limited render's start to the end of
    its first round of passes, all its kernels replayed, for the next
    render of ``key`` (:data:`_first_round_s`)."""
    _keep(_first_round_s, key, seconds)


def note_final_denoise(key: tuple, shading: bool, seconds: float) -> None:
    """Keep what a time-limited render's last OIDN call took (``shading``:
    textures denoised as their shading) for the next render of ``key``
    (:data:`_final_denoise_s`)."""
    _keep(_final_denoise_s, (key, shading), seconds)


def _keep(table: dict, key: tuple, value):
    """``value`` kept for ``key`` in ``table`` as its most recently used
    entry, of the last :data:`KEPT_COSTS`; returned."""
    return keep(table, key, value, KEPT_COSTS)


def measured_within(key: tuple, started: float, limit: float, notes: list,
                     bakes: bool, pixels: int, params: MRTParams) -> AutoOutcome | None:
    """Under a time limit: the MRT plan of the default target that a render
    of ``key`` (:func:`~.auto.scene_key` and :func:`~.auto.plan_key`) in this process kept
    by its check, at the most spp expected to end within :data:`TIME_MARGIN`
    of the limit (:func:`~.kept_plans.plan_within`; ``bakes``: the sampler
    compiles kernels per spp), unchecked, :data:`HOME`'s on a denser grid
    where the limit leaves time beyond its own (:func:`denser_grid`: a
    sampler that bakes its spp takes no spp it has not rendered); else None.
    ``pixels``: the image's."""
    left = started + TIME_MARGIN * limit - time.perf_counter()
    kept = kept_plans.plan_within(key, left, bakes)
    if kept is None:
        return None
    choice, reason = kept
    growing = kept_plans.growing_seconds(key, choice.spp)
    kept_key = key
    if choice.mode == HOME.mode and growing is not None:
        fraction = choice.fraction or params.sample_fraction
        extra = grid_extra(growing, fraction, pixels, params)
        denser = denser_grid(fraction, left - choice.seconds, extra)
        if denser is not None:  # (its time is not the kept plan's: not kept)
            choice = replace(choice, fraction=denser, seconds=choice.seconds + extra(denser))
            kept_key = None
    plan = Plan(choice, MEASURED_REASON.format(reason, choice.spp, choice.seconds),
                time_limit=limit, notes=notes, pilot_s=time.perf_counter() - started)
    return AutoOutcome(plan, kept_key=kept_key)


def plain_probe_due(key: tuple, tracer, started: float, limit: float, pixels: int) -> bool:
    """Without OIDN, under a time limit started at ``started``: whether
    :func:`mrt_within` may trace its grid probe of ``key``'s scene (of
    ``pixels`` pixels, at ``tracer``'s spp) for :data:`~.auto_plans.PLAIN`.
    Not where this process has traced nothing of the scene (the tracer is not
    :meth:`~.api.GridTracer.warm`), no probe of it is known (an earlier
    process's, :func:`_recalled_probe`) and the time left is under
    :data:`PLAIN_FLOOR`: there the plan, its first traces paying the
    scene's first uses, cannot end in time, and the passes go at once."""
    fixed, per_pixel = PLAIN_FLOOR
    floor = fixed + per_pixel * pixels * (1.0 + min(tracer.spp, 64) / 64) / 2
    if started + limit - time.perf_counter() >= floor or tracer.warm():
        return True
    return key in _probe_execute or _recalled_probe(key, tracer) is not None


def mrt_within(scene, pattern: SamplePattern, tracer, params: MRTParams, started: float,
                notes: list, key: tuple, chosen: tuple | None = None
                ) -> tuple[AutoOutcome | None, Traced, _Probe | None]:
    """Under a time limit: (:data:`HOME`'s outcome where the scene's kind
    points to it (:func:`unmeasured_plan`), or ``chosen``'s (a plan of mode
    ``idpass`` and its reason: without OIDN, :data:`~.auto_plans.PLAIN`),
    and it is expected to end within :data:`TIME_MARGIN` of the limit, else
    None; what it traced of every pixel (:class:`Traced`); the grid probe
    where it was made).

    The grid probe's kernel time tells the plan's traces (the grid at the
    scene's spp: :data:`GRID_OVER_PROBE`; the id pass, traced only where
    :data:`ID_PASS_OVER_PROBE` times it fits, then measured), the pixels
    its other stages (:data:`FINISH_PER_PIXEL`), and a first trace of the
    scene in this process what recording the grid's kernels adds.  A sampler
    that compiles kernels per spp (:func:`~.scene_query.sampler_bakes_spp`)
    is not planned so in such a process: its compilation cannot be told.
    Where the limit leaves time beyond the plan's, its grid is denser
    (:func:`denser_grid`).  The plan's image is not checked
    (:func:`~.auto_plans.keeps`): the check's fallback,
    the passes, would start after the limit.  Where the last replayed probe
    of ``key`` (:data:`_probe_execute`), or before any, the last probe an
    earlier process remembered (:func:`_recalled_probe`), says the plan
    cannot end within the limit, no probe is traced.
    """
    width, height = pattern.width, pattern.height
    chosen = chosen or unmeasured_plan(scene, width * height)
    if chosen is None or chosen[0].mode != HOME.mode:
        return None, Traced(), None
    end = started + TIME_MARGIN * params.time_limit

    def rest(execute: float, host: float = 0.0) -> float:
        """The plan's time after its id pass, from the probe's kernel run time."""
        return GRID_OVER_PROBE * tracer.spp * execute + FINISH_PER_PIXEL * width * height + host

    def ends_late(execute: float, host: float = 0.0) -> bool:
        """Whether the plan, its id pass included, would end after ``end``."""
        return time.perf_counter() + ID_PASS_OVER_PROBE * execute + rest(execute, host) > end

    known = _probe_execute.get(key)
    if known is None:  # (an earlier process's probe of the scene, read once)
        known = _recalled_probe(key, tracer)
        if known is not None:
            _keep(_probe_execute, key, known)
    if known is not None and ends_late(known):
        return None, Traced(), None
    probed = _grid_probe(pattern, tracer)
    _remember_probe(key, tracer, probed, pattern.count)
    if probed.recorded and sampler_bakes_spp(tracer.sensor.sampler()):
        return None, Traced(), probed
    if not probed.recorded:
        _keep(_probe_execute, key, probed.execute)
    host = probed.host if probed.recorded else 0.0
    if ends_late(probed.execute, host):
        return None, Traced(), probed
    if chosen[1] in EDGE_TESTED:
        traced, too_many = edge_tested(scene, tracer, params, width, height, notes)
        if too_many:
            return None, traced, probed
    else:
        traced = Traced(trace_id_pass(tracer, width, height))
    if time.perf_counter() + rest(probed.execute, host) > end:
        return None, traced, probed
    grid_s = GRID_OVER_PROBE * tracer.spp * probed.execute  # (the default grid's trace)
    fraction = denser_grid(params.sample_fraction,
                           end - time.perf_counter() - rest(probed.execute, host),
                           grid_extra(grid_s, params.sample_fraction, width * height, params))
    plan = Plan(replace(chosen[0], spp=tracer.spp, fraction=fraction),
                WITHIN_REASON.format(chosen[1]),
                time_limit=params.time_limit, notes=notes,
                pilot_s=time.perf_counter() - started - traced.id_pass.seconds)
    return AutoOutcome(plan, id_pass=traced.id_pass), traced, probed


def grid_extra(grid_s: float, fraction: float, pixels: int,
               params: MRTParams) -> Callable[[float], float]:
    """For :func:`denser_grid`: what a grid of ``f`` of an image's ``pixels``
    adds to the stages that grow with the grid, over a grid of ``fraction``
    whose trace takes ``grid_s``: the trace's share, and OIDN's on the
    grid (at ``params.denoise_quality``'s grid preset), each expected call on
    its own size."""
    quality = grid_preset(params.denoise_quality)
    least = max(round(fraction * pixels), 1)

    def extra(f: float) -> float:
        return (grid_s * (f / fraction - 1.0) + expected_seconds(round(f * pixels), quality)
                - expected_seconds(least, quality))
    return extra


def denser_grid(fraction: float, spare: float,
                extra: Callable[[float], float]) -> float | None:
    """The grid :data:`HOME` takes under a time limit: the densest of
    :data:`DENSER_GRIDS` whose extra samples fit ``spare``, the seconds its
    plan at the default grid ``fraction`` is expected to leave of the limit,
    where ``extra(f)`` is what a grid of ``f`` adds to the stages that grow
    with it (its trace and OIDN on it); None where none above ``fraction``
    does.  Where the limit is twice the default plan's time, every pixel at
    more spp through OIDN has less error than that plan, and the denser
    grid less than either.

    Examples
    --------
    >>> extra = lambda f: (f / 0.1 - 1.0) * 0.2  # (0.2 s a default grid)
    >>> denser_grid(0.1, 0.0, extra), denser_grid(0.1, 0.2, extra), denser_grid(0.1, 1.0, extra)
    (None, 0.2, 0.3)
    """
    fits = [f for f in DENSER_GRIDS if f > fraction and extra(f) <= spare]
    return max(fits, default=None)


def preview_first(scene, pattern: SamplePattern, tracer, params: MRTParams, started: float,
                   key: tuple, notes: list, probed: "_Probe | None" = None,
                   traced: "Traced | None" = None
                   ) -> tuple[AutoOutcome | None, tuple | None, bool]:
    """Under a time limit: (the preview's outcome where one pass and OIDN on
    the whole image would end after :data:`PREVIEW_SLACK` times the limit
    (:data:`PROBED_SLACK` times, where a probe tells the pass's time),
    else None; the passes' textured surfaces (:func:`find_surfaces`) and whether
    they were looked up, which took time the question then counts).  Where
    denoising the textured surfaces as their shading would end past the
    limit itself (:data:`SHADING_EXTRA`) but plain OIDN would not, the
    passes go without them (None, looked up).  A process's first passes of
    the scene are not probed where the time left is long enough for a pass
    and OIDN whatever the scene (:func:`_passes_fit_unprobed`): their first
    launch (:data:`~.launch_cost.UNMEASURED_FIRST`) measures them.  Where the probe tells a pass's
    time and the passes have no launch to plan from, the probe's line (its
    time beyond its kernels, and :data:`PASS_OVER_GRID` of its kernels' an
    spp) sizes their first launch (:attr:`.launch_cost.LaunchCost.prior`;
    it overstated a first launch of 1-8 spp by 1.1-2.8 times on the
    gallery at 256 and 512 px), where a new spp compiles nothing.
    ``probed``: the grid probe, where :func:`mrt_within` has made it;
    ``traced``: what it traced of every pixel."""
    width, height, limit = pattern.width, pattern.height, params.time_limit
    preview = Plan(PREVIEW, PREVIEW_REASON, time_limit=limit, notes=notes)
    first_s = _first_round_s.get(key)
    launches = kept_cost(key, tracer)
    if first_s is None and (launches.replayed or launches.recalled):
        # earlier passes measured a pass (a probe can record its kernels anew), or
        # an earlier process's did, its first launch what this one's will take
        first_s = time.perf_counter() - started + launches(launches.cheapest())
    textured = bool(textured_diffuse_shapes(scene).any())
    if first_s is not None:
        def late(shading: bool) -> bool:  # (the shading, which may go, within the limit)
            slack = PROBED_SLACK if shading else PREVIEW_SLACK
            return _preview_due(started + slack * limit, started + first_s,
                                width * height, params.denoise_quality, shading, key)
        if late(False):  # (the next render asks the launches' line or a probe)
            _first_round_s.pop(key, None)
            return AutoOutcome(preview), None, False
        return None, None, textured and late(True)  # (then denoised plainly)
    left = started + limit - time.perf_counter()
    if probed is None and not launches.launches and _passes_fit_unprobed(
            left, width * height, params.denoise_quality):
        # the passes' own first launch tells their cost: a probe would record
        # kernels of its own, about as long, for a question the time answers
        return None, None, textured and not _passes_fit_unprobed(
            left, width * height, params.denoise_quality, SHADING_EXTRA)
    if probed is None and not launches.launches:
        # an earlier process's first probe of the scene tells what this one's would
        probed = _recalled_line(key, tracer, pattern)
    if probed is None:  # the preview's own grid: a pass's cost
        probed = _grid_probe(pattern, tracer)
        _remember_probe(key, tracer, probed, pattern.count)
    end = started + PROBED_SLACK * limit
    grid, pass_s = probed.grid, probed.pass_s
    if launches.spp_compiles and launches.launches:
        # a sampler that bakes its spp launches only spp launched before: the
        # probe's sample scaled to the least of them (which counts the kernels'
        # fixed part spp times), or the launches' line where it says less (a
        # recorded launch may hold a compilation it could not tell apart)
        spp = launches.cheapest()
        pass_s = min(probed.host + spp * (probed.pass_s - probed.host), launches(spp))
    recording = _passes_recording_s(key, probed)
    pass_s += recording
    if not launches.launches and not launches.spp_compiles:
        # the passes' first launch sized by the probe's line, not 1 spp
        launches.prior = (probed.host + recording, probed.pass_s - probed.host)

    def due(shading: bool) -> bool:
        return _preview_due(end, time.perf_counter() + pass_s, width * height,
                            params.denoise_quality, shading, key)
    if due(False):
        return AutoOutcome(preview, grid=grid, grid_recording_s=probed.recording), None, False
    if textured and not due(True):
        # the passes' textured pixels, then the same question with their time spent
        surfaces = find_surfaces(scene, tracer, width, height,
                             None if traced is None else traced.shape_index())
        if not due(surfaces is not None):
            return None, surfaces, True
    # the passes, denoised plainly: the shading's extra time would end past the limit
    return (AutoOutcome(preview, grid=grid, grid_recording_s=probed.recording)
            if due(False) else None), None, True


def note_baked(key: tuple, notes: list) -> None:
    """Say why the preview was taken (:data:`BAKED_NOTE`) where the passes'
    launches for ``key`` (:data:`_launch_costs`) plan a pass only at an spp
    above 1 that they traced before."""
    launches = _launch_costs.get(key)
    if launches is not None and launches.spp_compiles and launches.launches:
        cheapest = launches.cheapest()
        if cheapest > 1:
            notes.append(BAKED_NOTE.format(cheapest))


def filled_preview(outcome: AutoOutcome, pattern: SamplePattern, tracer, params: MRTParams,
                    started: float, key: tuple) -> AutoOutcome:
    """``outcome``, the preview, its grid pooled from as many 1-spp launches
    as end before the limit (its :data:`TIME_MARGIN`) less what the stages
    after the grid are expected to take (:func:`_preview_after`):
    :func:`.preview.preview_grid`.  Where those stages would end past
    :data:`PREVIEW_SLACK` times the limit even right after the grid's first
    launch (a fresh process's first trace and OIDN call), the preview goes
    without OIDN (:data:`UNDENOISED_NOTE`), and where even its
    reconstruction would (:func:`_reconstruction_late`), it is the grid
    upsampled (:data:`UPSAMPLED_NOTE`)."""
    after = _preview_after(key, pattern, params.denoise_quality, tracer)
    grid = preview_grid(outcome.grid, pattern, tracer,
                        started + TIME_MARGIN * params.time_limit - after,
                        outcome.grid_recording_s)
    plan = outcome.plan
    plan.choice = replace(plan.choice, spp=grid.spp)
    outcome = replace(outcome, grid=grid, preview_key=key)
    end = started + PREVIEW_SLACK * params.time_limit
    if time.perf_counter() + after > end:
        plan.choice = replace(plan.choice, name=UNDENOISED.name, denoise=False)
        plan.notes.append(UNDENOISED_NOTE)
        if _reconstruction_late(end, pattern, grid.ids(params.rule_for("fast"))):
            plan.choice = replace(plan.choice, name=UPSAMPLED.name, mode=UPSAMPLED.mode)
            plan.notes.append(UPSAMPLED_NOTE)
    return outcome


def preview_preset(quality: str) -> str:
    """OIDN's preset for a preview's grid at a ``denoise_quality`` setting:
    ``auto`` is :data:`PREVIEW_QUALITY`."""
    return preset(quality, PREVIEW_QUALITY)


def preview_params(params: MRTParams) -> MRTParams:
    """``params`` for a preview's stages after its grid (:func:`preview_preset`)."""
    return params.with_(denoise_quality=preview_preset(params.denoise_quality))


def _reconstruction_late(end: float, pattern: SamplePattern, sample_ids: np.ndarray,
                         now: float | None = None) -> bool:
    """Whether the preview's reconstruction without OIDN, started ``now``
    (default: now), would end after ``end`` (``time.perf_counter()``
    values), from the grid's ids (:data:`RECONSTRUCTION_PER_PIXEL`)."""
    per_pixel = RECONSTRUCTION_PER_PIXEL + RECONSTRUCTION_PER_EDGE * edge_share(
        sample_ids.reshape(pattern.grid_shape))
    begin = time.perf_counter() if now is None else now
    return begin + per_pixel * pattern.width * pattern.height > end


def _preview_after(key: tuple, pattern: SamplePattern, quality: str, tracer) -> float:
    """The seconds a preview's stages after its grid (OIDN on the grid, the
    reconstruction, the finish) are expected to take: the median of the last
    denoised previews' of ``key`` (:data:`_preview_after_s`); before OIDN's
    first call at the preview's quality, the longest that earlier processes'
    first previews of the scene took (:func:`_recalled_preview_after`),
    where remembered; else a bound: :data:`FINISH_PER_PIXEL`'s, before that
    first call with its expected time on top (which holds its set-up) and at
    most :data:`PREVIEW_FIRST_REST`'s and :data:`PREVIEW_FIRST_OIDN`'s; or
    where less, the largest time per pixel beyond OIDN of this process's last
    previews (:data:`_preview_rate`) and OIDN's expected time."""
    kept = _preview_after_s.get(key)
    if kept:
        return typical(kept)
    quality = preview_preset(quality)
    pixels, oidn = pattern.width * pattern.height, expected_seconds(pattern.count, quality)
    first_call = denoise_seconds(pattern.count, quality) is None
    recalled = _recalled_preview_after(key, tracer, quality, pattern.count) if first_call else None
    if recalled is not None:
        return recalled
    bound = FINISH_PER_PIXEL * pixels
    if first_call:  # (what a fresh process's first previews took: less from about 450 px)
        fixed, per_pixel = PREVIEW_FIRST_REST
        bound = min(bound + oidn, fixed + per_pixel * pixels + PREVIEW_FIRST_OIDN * oidn)
    return min(bound, max(_preview_rate) * pixels + oidn) if _preview_rate else bound


def note_preview_after(key: tuple, seconds: float, denoise: float, pixels: int,
                       tracer, quality: str, grid: int) -> None:
    """Keep what the stages after a preview's grid took (``seconds``, of
    which OIDN ``denoise``; 0 without OIDN) on an image of ``pixels``: for
    the next preview of ``key`` where it was denoised
    (:data:`_preview_after_s`), and as a time per pixel beyond OIDN for
    the first preview of another scene (:data:`_preview_rate`).  Where its
    OIDN call (at ``quality``, on a grid of ``grid`` pixels) was the
    process's first at that quality, as a fresh process's preview makes it,
    also for later processes' first previews of the scene
    (:func:`_remember_preview_after`)."""
    if denoise > 0.0:
        note(_keep(_preview_after_s, key, _preview_after_s.get(key, [])), seconds,
             PREVIEW_AFTER_CALLS)
        if calls_at(quality) == 1:
            _remember_preview_after(key, tracer, seconds, quality, grid)
    note(_preview_rate, max(seconds - denoise, 0.0) / pixels, PREVIEW_RATE_CALLS)


def _remember_preview_after(key: tuple, tracer, seconds: float, quality: str,
                            grid: int) -> None:
    """Keep ``seconds``, what a process's first preview of ``key``'s scene
    took after its grid (OIDN's first call at ``quality``, on ``grid``
    pixels, in it), with the last earlier ones (:data:`PREVIEW_AFTER_CALLS`),
    for later processes (:mod:`mitsuba_mrt.runtime.memory`)."""
    if not memory.enabled():
        return
    memory_key = _preview_memory_key(key, tracer)
    kept = _remembered_preview_after(memory.recall(memory_key), quality, grid)
    note(kept, float(seconds), PREVIEW_AFTER_CALLS)
    memory.remember(memory_key, {"quality": quality, "grid": int(grid), "seconds": kept})


def _recalled_preview_after(key: tuple, tracer, quality: str, grid: int) -> float | None:
    """The longest of what earlier processes' first previews of ``key``'s
    scene took after their grid (:func:`_remember_preview_after`), at
    ``quality`` on a grid of ``grid`` pixels; None where none is remembered
    (or the memory is off, or no ``tracer`` names the scene)."""
    if tracer is None or not memory.enabled():
        return None
    kept = _remembered_preview_after(memory.recall(_preview_memory_key(key, tracer)),
                                     quality, grid)
    return max(kept, default=None)


def _preview_memory_key(key: tuple, tracer) -> str:
    """The key of ``key``'s scene's previews in the memory of earlier processes."""
    return f"{_memory_key(key, tracer)}/preview"


def _remembered_preview_after(value: dict | None, quality: str, grid: int) -> list:
    """The seconds a remembered ``value`` holds for previews at ``quality``
    on a grid of ``grid`` pixels (finite, positive); [] for any other."""
    value = value or {}
    seconds = value.get("seconds")
    if (value.get("quality") != quality or value.get("grid") != int(grid)
            or not isinstance(seconds, list)):
        return []
    return [float(v) for v in seconds
            if isinstance(v, (int, float)) and not isinstance(v, bool) and 0.0 < v < math.inf]


def _passes_recording_s(key: tuple, probed: "_Probe") -> float:
    """What the passes' first launch for ``key`` is expected to add to the
    pass ``probed`` predicts by recording its kernels: 0 where the passes have
    launched for ``key`` before or another trace recorded their 1-spp launch
    (they replay) or the probe itself recorded
    (its time holds a recording); else what the probe's recording took
    beyond its replays (:data:`_probe_recording_s`), kept from the render
    whose probe recorded, less what compiling kernels took of it: a kernel
    compiled once is on disk for every later process, so a compilation kept
    would hold every later render of the process to previews."""
    if probed.recorded:
        _keep(_probe_recording_s, key, probed.host - probed.compile)
        return 0.0
    launches = _launch_costs.get(key)
    if launches is not None and (launches.launched_here or 1 in launches.replays):
        return 0.0
    return max(_probe_recording_s.get(key, 0.0) - probed.host, 0.0)


class _Probe(NamedTuple):
    """The grid probe (:func:`_grid_probe`): the preview's grid trace, the
    seconds a pass over every pixel is expected to take, the trace's kernels'
    run time, what it took beyond them, whether it recorded its kernels (a
    process's first trace of the scene), what compiling those not in
    Dr.Jit's caches took of ``host`` (once per machine, not per process) and
    whether it was the process's first recording of all (its ``host`` holds
    the first uses a fresh process pays); what of it recorded the kernels
    (``recording``: a replay of the grid saves it).
    ``grid`` is None for a probe an earlier process made (:func:`_recalled_line`)."""

    grid: SparseTrace | None
    pass_s: float
    execute: float
    host: float
    recorded: bool
    compile: float = 0.0
    first: bool = False
    recording: float = 0.0


def _grid_probe(pattern: SamplePattern, tracer) -> _Probe:
    """The preview's grid trace (:data:`PREVIEW`'s spp), and the seconds a
    pass over every pixel is expected to take: the trace's kernels' run
    time scaled to every pixel, times :data:`PASS_OVER_GRID`, plus what the
    trace took beyond its kernels (launching them, reading them back, and
    in a fresh process the first use of the scene and the kernels)."""
    begin = time.perf_counter()
    with kernel_seconds() as spent, recorded_during() as made:
        grid = replace(tracer, spp=PREVIEW.spp)(pattern.pixel_xy, stream=SeedStream.GRID,
                                                replay=True)
    host = max(time.perf_counter() - begin - spent.execute, 0.0)
    pass_s = _pass_seconds(host, spent.execute, pattern.width * pattern.height, pattern.count)
    return _Probe(grid, pass_s, spent.execute, host, made.count > 0,
                  min(spent.compile, host), made.first, made.seconds)


def _pass_seconds(host: float, execute: float, pixels: int, count: int) -> float:
    """A pass over ``pixels`` pixels expected from a grid probe of ``count``
    pixels: what the probe took beyond its kernels (``host``), and its
    kernels' run time (``execute``) scaled to the pixels, times
    :data:`PASS_OVER_GRID`."""
    return host + PASS_OVER_GRID * execute * pixels / count


def _passes_fit_unprobed(left: float, pixels: int, quality: str, extra: float = 0.0) -> bool:
    """Whether ``left`` seconds leave a process's first pass over ``pixels``
    and OIDN's call at ``quality`` (``extra`` share longer) so much time
    that no probe need ask: at least :data:`UNPROBED_OVER_OIDN` times the
    call's first-call prior (:func:`~mitsuba_mrt.recon.denoise.prior_seconds`)."""
    return left >= UNPROBED_OVER_OIDN * (1.0 + extra) * prior_seconds(pixels, preset(quality))


def _preview_due(end: float, first_end: float, pixels: int, quality: str,
                 shading: bool = False, key: tuple | None = None) -> bool:
    """Whether OIDN on ``pixels`` after a first round ending at
    ``first_end`` would end after ``end`` (both ``time.perf_counter()``
    values); with ``shading``, textured surfaces denoised as their shading
    (:data:`SHADING_EXTRA`); at least what the last such call for ``key``
    took (:data:`_final_denoise_s`)."""
    oidn = expected_seconds(pixels, preset(quality)) * (1.0 + (SHADING_EXTRA if shading
                                                               else 0.0))
    oidn = max(oidn, _final_denoise_s.get((key, shading), 0.0))
    return first_end + oidn > end
