"""Mode ``auto``: denoised passes, a full render or the MRT, by measurement.

:func:`run_auto` takes the first of these that applies (under the default
target a plan that an earlier default render of the scene in this process
kept, :mod:`.kept_plans`, is taken again before them, without the probes,
the check or the estimates that chose it: :func:`_again`):

1. A noise-free scene, or a nearly noise-free one (:func:`probe_noise`, a
   small probe, where the integrator samples no area light or environment:
   :func:`~.scene_query.surely_noisy`): the full render, which is exact or
   beyond what denoised passes and the MRT reach.
2. The default target (no time limit, no ``noise_threshold``), OIDN
   installed, at least :data:`~.auto_plans.HOME_MIN_SPP` spp: an MRT image
   where the scene's kind says it wins (:mod:`.auto_plans`), kept where its
   held-out check (:mod:`.held_out`) finds it near a full render's quality,
   else the passes render the image after it.  Without OIDN, under the
   default target: :func:`~.auto_plans.plain_plan`'s (``idpass``, or
   ``refine`` through glass or under an environment map, undenoised),
   checked the same way, else the full render, which the scene's next
   renders then take; with a ``noise_threshold``, the full render.
3. Under a time limit (:mod:`.auto_limit`): an MRT plan that this process's
   renders of the scene kept, or :data:`~.auto_plans.HOME` where the grid
   probe says it ends in time; a *preview* (mode ``fast``, its grid
   denoised) where one pass and OIDN on the whole image would overrun it.
   Without OIDN, the plan a default render kept, where it fits, or
   :data:`~.auto_plans.PLAIN` where the probe says it ends in time.
4. Otherwise the image in denoised passes (:mod:`.progressive`): each pass
   is part of the image, and the passes measure how good the denoised image
   gets, so planning costs little.  Under a time limit they fill it;
   without one they go on until the estimated error meets the target (by
   default a full render's own noise at the scene's spp, the passes capped
   at half that spp).  Where a round (the third on) predicts that meeting
   a ``noise_threshold`` in passes costs more than a full render, a pilot
   (:mod:`.pilot`) measures the MRT's modes on strips of the image and the
   planner (:func:`mitsuba_mrt.modes.plan.choose`) picks the cheapest
   candidate that meets it, else the most accurate (the passes' candidate:
   what they reach within the scene's spp); passes it picks go on from
   where they stopped (:class:`_Weighing`).

:func:`plan_without_pilot` is the plan where nothing is worth measuring
(the scalar variant, small jobs): the full render.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import mitsuba as mi
import numpy as np

from ..modes.plan import Candidate, Plan, choose
from ..recon.denoise import oidn_available
from ..recon.metrics import relative_error
from ..recon.sampling import SamplePattern
from ..types import MRTParams, SeedStream
from . import kept_plans
from .auto_limit import (TIME_MARGIN, kept_cost, measured_within, mrt_within,
                         note_final_denoise, note_first_round, plain_probe_due, plan_memory_key,
                         plan_within, remember_launches)
from .auto_plans import (HOME_MIN_SPP, PLAIN, AutoOutcome, Traced, find_surfaces, mrt_by_kind,
                         plain_plan)
from .pilot import effective_area, run_pilot
from .progressive import FIRST_ROUND, Progress, needed_spp, predict, run_passes
from .replay import recordings, token
from .scene import plugin_name
from .scene_query import sampler_bakes_spp, surely_noisy

#: Below this many samples (pixels x spp) ``auto`` renders in full without a
#: pilot: the pilot's own launches would cost more than any plan could save.
AUTO_MIN_SAMPLES = 1 << 21

#: A pass (1 spp with albedo and normals) costs about this many plain samples:
#: a full render's cost, predicted from the passes' own.
PASS_SAMPLES = 2.0
#: Rounds of passes before their estimates may end them (a noise-free scene's
#: target of 0 ends them after the first).
CHECK_AFTER_ROUNDS = 3
#: The plan's note where OIDN is not installed.
NO_OIDN_NOTE = ("Intel Open Image Denoise is not installed (pip install mitsuba-oidn): "
                "the plan considers no denoising")
#: The plan's reason where OIDN is not installed and nothing else is to gain.
NO_DENOISER_REASON = "no denoiser: the full render"
#: Why passes under a noise threshold stopped to let the planner weigh them.
STOPPED_REASON = "more passes would cost more than a full render"
#: Under a time limit the passes may take up to this many times the scene's spp.
LIMIT_SPP_FACTOR = 4
#: Under the default target they stop at this share of it: the round that
#: doubles them to the scene's spp costs a full render, the rounds before it
#: included, and a full render's own noise is the target.
DEFAULT_SPP_SHARE = 0.5
#: Pixels of the probe that tells a noise-free scene (traced with two seeds),
#: a lattice of this many per side spread over the image: its cost grows
#: with them, and a noisy scene is noisy in nearly every pixel the lattice
#: spreads over (one it misses is rendered in full: ``mi.render``'s image,
#: not denoised).
PROBE_SIDE = 16

#: A full render whose estimated relative RMS error (:func:`probe_noise`) is
#: below this is the default plan: nothing cheaper meets its quality.  With
#: ``path`` at 64 spp, the report's scene of one plane under one point light
#: (0.0002) took denoised passes at 1.35 times the full render's time and
#: 37 times its error (OIDN's own); a sphere over a floor under a point
#: light (variants of camera and shape: 0.002-0.006 over eight seeds; with a
#: box filter 0.007-0.008, left to the passes) took ``idpass+oidn``, which
#: missed its check, then passes: 1.1-1.6 times the time.  The estimate
#: varies with the seed by up to a third; the report's other scenes have
#: 0.006 (one sphere) to 0.14, the gallery 0.033-0.070.
NEARLY_EXACT = 0.005

#: The reason of a plan :func:`_again` takes (``{}``: the kept plan's).
AGAIN_REASON = "{}; kept from this process's earlier render of the scene"
#: ... where an earlier process's render of the scene chose it (:mod:`mitsuba_mrt.runtime.memory`).
RECALLED_REASON = "{}; remembered from an earlier process's render of the scene"


def plan_without_pilot(width: int, height: int, spp: int, jit: bool,
                       params: MRTParams, integrator: mi.Integrator | None = None
                       ) -> Plan | None:
    """The plan where nothing is worth measuring (a full render), else None.

    An ``integrator`` that is not a sampling integrator (``ptracer`` traces
    from the lights) renders no chosen pixels, only a whole image.  The
    scalar variant traces pixel by pixel in Python while ``mi.render``
    runs Mitsuba's multithreaded C++ loop, so only a full render can win
    there; below ``AUTO_MIN_SAMPLES`` samples the passes' launches would cost
    more than they could save, unless a time limit asks for what fits it or
    a noise threshold for an estimated error.
    """
    if integrator is not None and not isinstance(integrator, mi.SamplingIntegrator):
        reason = f"a {plugin_name(integrator)} renders whole images only"
    elif jit and (width * height * spp >= AUTO_MIN_SAMPLES or params.time_limit is not None
                  or params.noise_threshold is not None):
        return None
    else:
        reason = ("the scalar variant renders in full" if not jit
                  else "too few samples for a plan to pay")
    return Plan(Candidate("full", "full", spp), reason, time_limit=params.time_limit,
                target_error=params.noise_threshold)


@dataclass
class _Job:
    """What the steps of :func:`run_auto` read: the render's objects and
    start, the keys of what earlier renders of the scene took
    (:func:`scene_key`, and with :func:`plan_key` a kept plan's), the
    plan's notes and whether OIDN is installed."""

    scene: mi.Scene
    pattern: SamplePattern
    tracer: object
    params: MRTParams
    started: float
    key: tuple
    kept_key: tuple
    notes: list
    denoise: bool


def run_auto(scene: mi.Scene, pattern: SamplePattern, tracer, params: MRTParams,
             started: float, escape: bool = True, on_round=None) -> AutoOutcome:
    """The plan of the module; the image too where the passes made it.

    ``started`` is the render's ``time.perf_counter()`` at its start: a time
    limit is counted from it.  Without ``escape`` the passes run to the
    target whatever the first round predicts.  ``on_round(stage, done)``
    hears of every round of passes.
    """
    denoise = oidn_available()
    notes = [] if denoise else [NO_OIDN_NOTE]
    key = scene_key(scene, tracer, pattern.width * pattern.height)
    job = _Job(scene, pattern, tracer, params, started, key,
               key + plan_key(tracer, params), notes, denoise)
    default = params.time_limit is None and params.noise_threshold is None
    outcome, traced, surfaces, found = None, Traced(), None, False
    if escape and default:
        outcome, traced = _by_default(job, on_round)
    elif params.time_limit is not None and denoise:
        outcome, traced, surfaces, found = plan_within(
            scene, pattern, tracer, params, started, key, job.kept_key, notes, escape)
    elif params.time_limit is not None and escape:
        outcome, traced = _plain_within(job)
    if outcome is not None:
        return outcome
    if not denoise and params.time_limit is None:  # (``mi.render``'s own image)
        return AutoOutcome(Plan(Candidate("full", "full", tracer.spp), NO_DENOISER_REASON,
                                target_error=params.noise_threshold, notes=notes))
    if denoise and not found:
        surfaces = find_surfaces(scene, tracer, pattern.width, pattern.height,
                                 traced.shape_index())
    return _passes(job, traced, surfaces, escape, on_round)


def _by_default(job: _Job, on_round) -> tuple[AutoOutcome | None, Traced]:
    """Under the default target: (the plan kept from an earlier render
    (:func:`_again`), the exact full render of a noise-free scene, or the
    MRT plan the scene's kind points to (:func:`~.auto_plans.mrt_by_kind`;
    without OIDN, :func:`~.auto_plans.plain_plan`'s, its image to be
    checked), else None: the passes, or without OIDN the full render; what
    was traced of every pixel)."""
    scene, tracer = job.scene, job.tracer
    width, height = job.pattern.width, job.pattern.height
    outcome = _again(scene, tracer, job.key, job.kept_key, width, height, job.notes, on_round)
    if outcome is not None:
        return outcome, Traced()
    probe_start = time.perf_counter()
    exact = _noise_free_plan(scene, tracer, width, height, job.notes, probe_start)
    if exact is not None:
        return exact, Traced()
    if tracer.spp < HOME_MIN_SPP:
        return None, Traced()
    if not job.denoise:
        chosen, reason = plain_plan(scene)
        return AutoOutcome(Plan(replace(chosen, spp=tracer.spp), reason, notes=job.notes,
                                pilot_s=time.perf_counter() - probe_start), check=True), Traced()
    return mrt_by_kind(scene, tracer, job.params, width, height, job.notes, probe_start)


def _plain_within(job: _Job) -> tuple[AutoOutcome | None, Traced]:
    """Under a time limit without OIDN (and without a ``noise_threshold``,
    at least :data:`~.auto_plans.HOME_MIN_SPP` spp): (the MRT plan a default
    render of the scene kept, where it measured it within the limit
    (:func:`~.auto_limit.measured_within`), or :data:`~.auto_plans.PLAIN`'s
    outcome, on a scene of its kind, where the grid probe says it ends in
    time (:func:`~.auto_limit.mrt_within`), else None: the passes; what it
    traced of every pixel)."""
    scene, tracer, params = job.scene, job.tracer, job.params
    if params.noise_threshold is not None or tracer.spp < HOME_MIN_SPP:
        return None, Traced()
    pixels = job.pattern.width * job.pattern.height
    outcome = measured_within(job.kept_key, job.started, params.time_limit, job.notes,
                              sampler_bakes_spp(tracer.sensor.sampler()), pixels, params)
    if outcome is not None:
        return outcome, Traced()
    chosen = plain_plan(scene)
    if chosen[0] is not PLAIN or not plain_probe_due(job.key, tracer, job.started,
                                                     params.time_limit, pixels):
        return None, Traced()
    outcome, traced, _ = mrt_within(scene, job.pattern, tracer, params, job.started, job.notes,
                                    job.key, chosen)
    return outcome, traced


def _noise_free_plan(scene, tracer, width: int, height: int, notes: list,
                     probe_start: float) -> AutoOutcome | None:
    """The full render where the scene is noise-free, or nearly
    (:func:`probe_noise` below :data:`NEARLY_EXACT`; asked only where
    :func:`~.scene_query.surely_noisy` cannot tell), else None."""
    if surely_noisy(scene, tracer.integrator):
        return None
    noise = probe_noise(tracer, width, height)
    if noise >= NEARLY_EXACT:
        return None
    reason = ("noise-free: the full render is exact" if noise == 0.0 else
              f"nearly noise-free (a full render's estimated error {noise:.4f}): the full "
              f"render, which neither denoised passes nor the MRT meet")
    return AutoOutcome(Plan(Candidate("full", "full", tracer.spp, error=noise), reason,
                            target_error=noise, pilot_s=time.perf_counter() - probe_start,
                            notes=notes))


def _passes(job: _Job, traced: Traced, surfaces: tuple | None, escape: bool,
            on_round) -> AutoOutcome:
    """The image in passes (:func:`~.progressive.run_passes`), denoised where
    OIDN is installed: to the target, or filling the time limit; or, where
    the planner weighed them and chose another plan (:class:`_Weighing`),
    that plan."""
    tracer, params = job.tracer, job.params
    spp, limit, denoise = tracer.spp, params.time_limit, job.denoise
    deadline = None if limit is None else job.started + TIME_MARGIN * limit
    weighing = _Weighing(job, deadline)
    if limit is not None:
        max_spp = spp * LIMIT_SPP_FACTOR
    elif params.noise_threshold is None:
        max_spp = max(FIRST_ROUND, int(spp * DEFAULT_SPP_SHARE))
    else:
        max_spp = spp
    image, alpha, progress = run_passes(
        tracer, job.pattern.width, job.pattern.height, quality=params.denoise_quality,
        target_error=params.noise_threshold, deadline=deadline, max_spp=max_spp,
        full_spp=spp, area=effective_area(tracer.sensor.film().rfilter()), denoise=denoise,
        stop_early=weighing if escape else None, on_round=on_round, surfaces=surfaces,
        cost=kept_cost(job.key, tracer, denoise))
    remember_launches(job.key, tracer)
    if image is None:
        return AutoOutcome(weighing.plan)
    if deadline is not None and denoise:
        note_final_denoise(job.key, progress.shading, progress.denoise_s)
    name, kind = ("full+oidn", "denoised") if denoise else ("passes", "passes")
    choice = Candidate(name, kind, progress.spp, denoise=denoise,
                       seconds=progress.trace_s + progress.denoise_s,
                       error=progress.predicted, quality=progress.quality or None,
                       shading=progress.shading, clean_texture=progress.clean_texture)
    plan = Plan(choice, f"{'denoised ' if denoise else ''}passes: {progress.stopped}",
                target_error=params.noise_threshold or (
                    None if limit is not None else progress.full_error),
                time_limit=limit, pilot_s=progress.estimate_s, notes=job.notes,
                passes=list(progress.history))
    if limit is None and params.noise_threshold is None and denoise:
        # (the next default render of the scene takes them again)
        kept_plans.note_plan(job.kept_key, choice, plan.reason,
                             plan_memory_key(job.kept_key, tracer))
    if weighing.plan is not None:  # (the planner chose the passes, which went on)
        plan.reason, plan.candidates = weighing.plan.reason, weighing.plan.candidates
    return AutoOutcome(plan, image, alpha, progress, id_pass=traced.id_pass)


class _Weighing:
    """The passes' ``stop_early`` (:func:`~.progressive.run_passes`): whether
    passes are the wrong plan for the target, after each round.

    Where more passes would cost more than a full render, the planner weighs
    them against the others (:func:`_measured_plan`, once; its plan is
    :attr:`plan`); where it chooses them, they go on from there, without a
    way out, else they stop (:data:`STOPPED_REASON`).  Under a time limit
    it weighs nothing, and keeps the first round's time where it recorded
    no kernel (:func:`~.auto_limit.note_first_round`).
    """

    def __init__(self, job: _Job, deadline: float | None):
        self.job, self.deadline = job, deadline
        self.recorded = recordings()
        self.plan: Plan | None = None

    def __call__(self, progress: Progress, pass_s: float) -> str | None:
        job, params = self.job, self.job.params
        if self.deadline is not None:
            # the first round, once traced, is denoised however late it ends: OIDN on
            # it costs less than a preview would (its time tells the next render's plan)
            if (progress.spp <= FIRST_ROUND and recordings() == self.recorded
                    and not progress.history):
                # one pass, no estimate, and no recording (whose cost would not come again)
                note_first_round(job.key, time.perf_counter() - job.started)
            return None
        if not job.denoise:
            return None
        target = params.noise_threshold or progress.full_error
        if self.plan is not None or (target > 0 and (params.noise_threshold is None
                                                     or len(progress.history)
                                                     < CHECK_AFTER_ROUNDS)):
            # the full render's own noise: passes to the scene's spp meet it at
            # a full render's cost, near enough; or too few rounds to tell
            return None
        spp = job.tracer.spp
        needed = needed_spp(progress.history, target)  # the spp of the final image
        # (the passes stop at the scene's spp: past it, their candidate is what they reach there)
        reached = min(needed, spp)
        costs = dict(passes=max(reached - progress.spp, 0.0) * pass_s,
                     full=spp * pass_s / PASS_SAMPLES, mrt=params.sample_fraction * spp * pass_s,
                     passes_spp=reached, target=target, full_error=progress.full_error,
                     passes_error=target if needed <= spp else predict(progress.history, spp))
        if costs["passes"] <= costs["full"]:
            return None
        begin = time.perf_counter()
        self.plan = _measured_plan(job.scene, job.pattern, job.tracer, params, progress, costs,
                                   job.notes)
        progress.estimate_s += time.perf_counter() - begin  # (the passes' check, if they go on)
        return None if self.plan.choice.kind == "denoised" else STOPPED_REASON


def _again(scene, tracer, key: tuple, kept_key: tuple, width: int, height: int,
           notes: list, on_round) -> AutoOutcome | None:
    """Under the default target: the plan an earlier default render of
    ``kept_key`` (``key``, :func:`scene_key`, and :func:`plan_key`) in this
    process kept, or one in an earlier process remembered
    (:func:`~.kept_plans.plan_again`), without the probes, the
    check or the estimates that chose it; an MRT plan to be rendered (its
    time kept for ``kept_key``), the full render (without OIDN, where the
    MRT's image missed its check), the passes' image at their kept spp and
    preset (their launch kept for ``key``'s time-limited passes,
    :func:`kept_cost`); else None."""
    kept = kept_plans.plan_again(kept_key, plan_memory_key(kept_key, tracer))
    if kept is None:
        return None
    choice, reason, recalled = kept
    plan = Plan(choice, (RECALLED_REASON if recalled else AGAIN_REASON).format(reason),
                notes=notes)
    if choice.kind == "mrt":
        return AutoOutcome(plan, kept_key=kept_key)
    if choice.kind == "full":  # (without OIDN, where the MRT's image missed its check)
        return AutoOutcome(plan)
    surfaces = find_surfaces(scene, tracer, width, height) if choice.shading else None
    image, alpha, progress = run_passes(
        tracer, width, height, quality=choice.quality, target_error=None, deadline=None,
        max_spp=choice.spp, full_spp=tracer.spp, area=1.0, surfaces=surfaces,
        on_round=on_round, cost=kept_cost(key, tracer), fixed=True)
    remember_launches(key, tracer)
    plan.choice = replace(choice, seconds=progress.trace_s + progress.denoise_s)
    return AutoOutcome(plan, image, alpha, progress)


def scene_key(scene: mi.Scene, tracer, pixels: int) -> tuple:
    """The key of what earlier renders took (the tables of
    :mod:`.auto_limit`, :mod:`.kept_plans`): the traced objects and the image's pixel count."""
    return token((scene, tracer.sensor, tracer.integrator)), pixels


def plan_key(tracer, params: MRTParams) -> tuple:
    """What a kept plan's key (:mod:`.kept_plans`) adds to :func:`scene_key`'s:
    the spp, the parameters but the time limit and quality target, and
    whether OIDN is installed (a plan made without it is not one with it)."""
    return tracer.spp, replace(params, time_limit=None, noise_threshold=None), oidn_available()


def probe_noise(tracer, width: int, height: int) -> float:
    """A full render's estimated relative RMS error
    (:func:`~mitsuba_mrt.recon.metrics.relative_error`, its noise at the
    scene's spp through the film's filter), from a lattice of
    :data:`PROBE_SIDE` x :data:`PROBE_SIDE` pixels over the image (their
    cells' centres), each traced with two sets of random numbers: 0 where
    they come out the same (a deterministic scene, whose full render has no
    noise).

    One small launch, before the passes: their first round, with its guides
    and the denoiser's estimates, costs several full renders of such a scene.
    """
    columns = np.unique((np.arange(PROBE_SIDE) + 0.5) * width // PROBE_SIDE).astype(np.int64)
    rows = np.unique((np.arange(PROBE_SIDE) + 0.5) * height // PROBE_SIDE).astype(np.int64)
    xy = np.stack(np.meshgrid(columns, rows), axis=-1).reshape(-1, 2)
    # each pixel twice in one launch: a sampler draws other numbers for each lane
    probe = replace(tracer, spp=min(tracer.spp, 2))(np.concatenate([xy, xy]),
                                                    stream=SeedStream.PILOT, aovs=False,
                                                    replay=True)
    first, second = probe.radiance[:len(xy)], probe.radiance[len(xy):]
    if not np.isfinite(probe.radiance).all():
        return math.inf
    # (equal up to the order in which a pixel's samples were summed)
    if np.allclose(first, second, rtol=1e-5, atol=1e-6):
        return 0.0
    # one sample's variance is half the squared difference times the samples of
    # each; a full render's pixel averages spp samples spread over the filter's area
    samples = min(tracer.spp, 2) / (tracer.spp * effective_area(tracer.sensor.film().rfilter()))
    return relative_error((first - second) ** 2 / 2.0 * samples, (first + second) / 2.0)


def _measured_plan(scene, pattern, tracer, params: MRTParams, progress: Progress, costs: dict,
                   notes: list) -> Plan:
    """The planner's choice among a full render, more passes and the MRT's modes
    (measured by the pilot where its grid is cheaper than both others and
    the job is not small: :data:`AUTO_MIN_SAMPLES`), the passes having
    stopped to weigh them (:data:`STOPPED_REASON`)."""
    begin = time.perf_counter()
    candidates = [Candidate("full", "full", tracer.spp, seconds=costs["full"],
                            error=costs["full_error"]),
                  Candidate("full+oidn", "denoised", math.ceil(costs["passes_spp"]),
                            denoise=True, seconds=costs["passes"], error=costs["passes_error"])]
    pixels = 0
    samples = pattern.width * pattern.height * tracer.spp  # (a small job's pilot would not pay)
    if (costs["target"] > 0 and costs["mrt"] < min(costs["full"], costs["passes"])
            and samples >= AUTO_MIN_SAMPLES):
        pilot = run_pilot(scene, pattern, tracer, params, costs["target"],
                          min(costs["full"], costs["passes"]), denoised=False)
        candidates += [c for c in pilot.candidates if c.kind == "mrt"]
        notes += pilot.notes
        pixels = pilot.pixels
    plan = choose(candidates, target_error=costs["target"])
    plan.reason = f"{STOPPED_REASON}; {plan.reason}"
    plan.pilot_s = progress.trace_s + progress.estimate_s + time.perf_counter() - begin
    plan.pilot_pixels, plan.notes, plan.passes = pixels, notes, list(progress.history)
    return plan
