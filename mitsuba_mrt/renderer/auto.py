"""Mode ``auto``: denoised passes, a full render or the MRT, by measurement.

:func:`run_auto` takes the first of these that applies (under the default
target a plan that an earlier default render of the scene in this process
kept, :mod:`.kept_plans`, is taken again before them, without the probes,
the check or the estimates that chose it: :func:`_again`):

1. A noise-free scene (:func:`noise_free`, a small probe, where the
   integrator samples no area light or environment:
   :func:`~.scene_query.surely_noisy`): the full render, which is exact.
2. The default target (no time limit, no ``noise_threshold``), OIDN
   installed, at least :data:`HOME_MIN_SPP` spp: an MRT image where the
   scene's kind says it wins (:func:`unmeasured_plan`): :data:`HOME` (mode
   ``idpass``, its grid denoised) on the report's kind of scene (every
   surface diffuse, every light a point), and where no environment map
   lights the scene on images of :data:`WIDE_PIXELS` or more and on smaller
   ones with a textured diffuse surface and no surface that transmits light,
   each where its id pass has at most :data:`WIDE_EDGE_SHARE` of its pixels
   at an edge between ids;
   :data:`SKY` (mode ``refine``, its grid denoised) under an environment
   map and on smaller images without one where a surface mirrors or
   transmits light and none is textured.  Below :data:`WIDE_PIXELS` pixels
   every such plan but the report's kind's traces a denser grid at fewer spp
   (:func:`spread`).  The image is kept where its held-out check
   (:mod:`.held_out`, :func:`keeps`) finds it near a full render's quality,
   else the passes render the image after it.  Under a
   time limit (OIDN installed, at least :data:`HOME_MIN_SPP` spp) such a
   plan, unchecked, where the process's earlier renders of the scene kept it,
   at the most spp expected to end within the limit (:func:`_measured_within`,
   :mod:`.kept_plans`), else the
   :data:`HOME` plan where the grid probe says it ends within the limit
   (:func:`_mrt_within`).
3. Under a time limit too short for one pass and OIDN on the whole image
   (judged from the first round of an earlier time-limited render of the
   scene in this process, else from the preview's own grid, traced first):
   a *preview*, mode ``fast``, its grid denoised (:data:`PREVIEW`): one
   sample per grid pixel, and more where the limit leaves time
   (:mod:`.preview`); not denoised (:data:`UNDENOISED`) where OIDN would
   end past the limit even right after the grid's first launch.
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
   where they stopped.

:func:`plan_without_pilot` is the plan where nothing is worth measuring
(the scalar variant, small jobs): the full render.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import mitsuba as mi
import numpy as np

from ..modes.plan import Candidate, Plan, choose
from ..recon.denoise import denoise_seconds, expected_seconds, oidn_available, preset
from ..recon.ids import edge_share
from ..recon.sampling import SamplePattern, every_pixel
from ..runtime.jit import kernel_seconds
from ..runtime.recent import keep, note, typical
from ..types import MRTParams, SeedStream, SparseTrace
from . import kept_plans
from .held_out import HeldOut
from .pilot import effective_area, run_pilot
from .preview import preview_grid
from .progressive import FIRST_ROUND, LaunchCost, Progress, needed_spp, predict, run_passes
from .replay import recordings, token
from .scene_query import (environment_map, has_mirrors, lit_diffuse_by_points,
                          sampler_bakes_spp, surely_noisy, textured_diffuse_shapes,
                          transmits)
from .trace import trace_shapes

#: Below this many samples (pixels x spp) ``auto`` renders in full without a
#: pilot: the pilot's own launches would cost more than any plan could save.
AUTO_MIN_SAMPLES = 1 << 21
#: The share of a time limit the passes may plan to fill (the final OIDN
#: call's time is planned within it; the rest is for the machine's noise and
#: a fresh process's first uses: at 0.97 first renders took up to 1.16 times
#: a quarter of a full render).
TIME_MARGIN = 0.93
#: A pass (1 spp with albedo and normals) costs about this many plain samples:
#: a full render's cost, predicted from the passes' own.
PASS_SAMPLES = 2.0
#: Rounds of passes before their estimates may end them (a noise-free scene's
#: target of 0 ends them after the first).
CHECK_AFTER_ROUNDS = 3
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
#: The plan where one pass and OIDN on the whole image would overrun a time
#: limit: the MRT's cheapest image, a tenth of the pixels' samples (its
#: grid, one sample each, more where the limit leaves time) denoised and
#: reconstructed.
PREVIEW = Candidate("fast+oidn", "mrt", 1, mode="fast", denoise=True)
PREVIEW_REASON = "a preview: one pass and OIDN on every pixel would overrun the time limit"
#: The preview where OIDN's call, even right after the grid's first launch,
#: would end past :data:`PREVIEW_SLACK` times the limit: its grid as traced.
UNDENOISED = Candidate("fast", "mrt", 1, mode="fast", denoise=False)
UNDENOISED_NOTE = "OIDN would end past the time limit: the preview is not denoised"
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

#: Under a time limit, what denoising textured diffuse surfaces as their
#: shading (:attr:`.progressive.Passes.shading`) adds to a pass's last OIDN
#: call, as a share of its expected time: finding the textured pixels and
#: the division (on the gallery's textured scenes at 256 px, 2 cores, the
#: shading call took 1.17 times a plain one, and finding the pixels 0.1-0.35
#: times more, the most right after OIDN's or Dr.Jit's threads have run).
SHADING_EXTRA = 0.5

#: The plan, under the default target, where every surface is diffuse and
#: every light a point, spot or directional one
#: (:func:`~.scene_query.lit_diffuse_by_points`, the report's own scenes):
#: mode ``idpass`` at the scene's spp, OIDN on its grid.  There its ids hold
#: every edge of shape and shadow and its error meets a full render's noise
#: for less than the denoised passes take (``bench rival``'s Fig. 1 row).
HOME = Candidate("idpass+oidn", "mrt", 0, mode="idpass", denoise=True)
HOME_REASON = "diffuse surfaces lit by point lights alone: the MRT's id pass, denoised grid"
#: The fewest spp for :data:`HOME`: below them the id pass costs too large a
#: share of the render, and the passes' few rounds cost little.
HOME_MIN_SPP = 16
#: :data:`HOME` on other scenes, under the same conditions: images of at least
#: this many pixels (512 x 512) lit by no environment map
#: (:func:`~.scene_query.environment_map`).  There the grid resolves the
#: shading the ids do not hold, and the id pass's albedo the textures that
#: OIDN blurs; on smaller images the grid's spacing is coarse beside the
#: scene's detail (``bench rival`` at 256 px: ``idpass+oidn`` behind the
#: alternative on five of nine gallery scenes).
WIDE_PIXELS = 1 << 18
WIDE_REASON = "512 x 512 pixels or more, no environment map: the MRT's id pass, denoised grid"
#: :data:`HOME` on a smaller image where a diffuse surface is textured
#: (:func:`~.scene_query.textured_diffuse_shapes`) and no surface transmits
#: light (:func:`~.scene_query.transmits`): the id pass gives the texture at
#: every pixel and the grid only the shading beneath it, which is smooth.
#: Through glass the ids see one shape where an image of the scene lies
#: (``room`` at 256 px: the check rejects ``idpass+oidn``, then the passes).
TEXTURED_REASON = ("textured diffuse surfaces, nothing transmits light: the MRT's id pass "
                   "gives the texture, denoised grid")
#: The reasons whose plan gives way to the passes where too many of the
#: image's pixels lie at an edge between ids (:func:`_edge_tested`).
EDGE_TESTED = (WIDE_REASON, TEXTURED_REASON)
#: :data:`HOME` on such an image is traced only where at most this share of
#: its pixels lie at an edge between shapes, then between ids
#: (:func:`~mitsuba_mrt.recon.ids.edge_share` of the id pass, which
#: ``idpass`` then reuses): where more do, the regions are small beside the
#: grid's spacing and hold few of its samples each (``bench rival`` at 512
#: px: ``instanced``, 5.5 %, is the one gallery scene where ``idpass+oidn``
#: is no better than the passes; the others have 1.1-3.6 %).
WIDE_EDGE_SHARE = 0.045
#: The plan, under the same conditions, where an environment map lights the
#: scene: mode ``refine``, OIDN on its grid.  Light from every direction
#: shades the inside of a shape slowly, which the grid holds; where it does
#: not, at the shapes' edges and their reflections of the map, ``refine``
#: traces the pixels (``bench rival``: 0.76-0.91x the alternative's error
#: on the gallery's two such scenes at 256 and 512 px, where ``idpass+oidn``
#: is 1.07-1.72x and the passes about 1.0x).
SKY = Candidate("refine+oidn", "mrt", 0, mode="refine", denoise=True)
SKY_REASON = "an environment map's light: the MRT's refined edges, denoised grid"
#: :data:`SKY` on a smaller image without an environment map where a surface
#: mirrors or transmits light (:func:`~.scene_query.has_mirrors`,
#: :func:`~.scene_query.transmits`) and none is a textured diffuse one: what
#: they show is an image of the scene that no id tells apart, which ``refine``
#: traces at its edges, and without textures the passes cannot denoise the
#: shading alone, so they need most of the scene's spp to meet a full
#: render's noise (``bench rival`` at 256 px: ``cornell``, the passes at
#: 0.6 of a full render's time; with textures, ``room``, they meet it at 0.2).
SPECULAR_REASON = "mirrors or glass, no texture: the MRT's refined edges, denoised grid"
#: :data:`HOME`'s and :data:`SKY`'s image is kept where its held-out check estimates its RMS
#: error at most this many times a full render's noise (the default target);
#: else the passes render the image.  The RMS error weighs the MRT's few
#: pixels at edges more than the report's mean absolute error does: on the
#: bench's scenes where that image meets the target by the report's metric,
#: the check's estimate is 0.5-1.3 times the noise.
CHECK_SLACK = 1.5
#: :data:`SKY`'s plans, and :data:`HOME`'s on scenes other than the report's
#: kind, on images of fewer than :data:`WIDE_PIXELS`: the grid spreads the
#: same samples over this many times the pixels (``sample_fraction``), at
#: that share of the spp.  There the default grid's spacing is coarse beside
#: the scene's detail, and ``refine`` traces its edges' pixels at the grid's
#: spp (``examples/grid_spread.py``).
SMALL_IMAGE_SPREAD = 2

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
#: The reason of :data:`HOME` taken under a time limit (``{}``: its kind's).
WITHIN_REASON = "{}; within the time limit"

#: Seconds from a time-limited render's start to the end of its first round
#: of passes, per traced objects and pixel count, from the last such render
#: in this process whose kernels were all replayed: what tells a limit too
#: short for one pass and OIDN before a pass is traced.  A time that gives a
#: preview is dropped: a preview traces no round, so one slow round would
#: otherwise give previews for good.
_first_round_s: dict = {}
#: The seconds the last OIDN call of a time-limited render's passes took,
#: per the same keys and whether it denoised textures as their shading,
#: from the last such render: the next one leaves at least this for it after
#: a first round (OIDN's expected time leaves out a filter made anew).
_final_denoise_s: dict = {}
#: The passes' launches (:class:`~.progressive.LaunchCost`), per traced
#: objects and pixel count, of the last :data:`KEPT_COSTS` such keys: what
#: the next render's passes plan from.
_launch_costs: dict = {}
KEPT_COSTS = 16
#: What the grid probe took beyond its kernels when it recorded them, per
#: the same keys (the last :data:`KEPT_COSTS`): about what the passes' first
#: launch adds by recording theirs (both trace the integrator anew), which
#: a replayed probe's time does not show.
_probe_recording_s: dict = {}
#: The grid probe's kernel run time per the same keys (the last
#: :data:`KEPT_COSTS`), from its last replay: where it says :data:`HOME`
#: cannot end within a time limit, the next render of the scene is not
#: probed for it (:func:`_mrt_within`).
_probe_execute: dict = {}
#: The seconds a preview's stages after its grid took (OIDN on the grid, the
#: reconstruction, the finish), the last :data:`PREVIEW_AFTER_CALLS` per the
#: same keys (the last :data:`KEPT_COSTS`): the next preview of the scene
#: leaves their median for them (:func:`_filled_preview`), where the first
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
#: The reason of a plan :func:`_again` takes (``{}``: the kept plan's).
AGAIN_REASON = "{}; kept from this process's earlier render of the scene"
#: The reason of a plan :func:`_measured_within` takes (``{}``: its kind's,
#: then its spp and expected seconds).
MEASURED_REASON = ("{}; at {} spp, {:.3g} s expected from this process's renders of "
                   "the scene: within the time limit")


@dataclass
class AutoOutcome:
    """``auto``'s plan, and the image when the passes made it (``grid``: the
    preview's grid, where tracing it told the plan; ``check``: the plan's
    MRT image is to be checked, :func:`keeps`; ``id_pass``: the image's id
    pass, where the plan traced it; ``preview_key``: a preview's key, under
    which :func:`note_preview_after` keeps what its later stages take;
    ``kept_key``: a kept plan's key (:mod:`.kept_plans`), under which
    :func:`~.kept_plans.note_render` keeps what its render took)."""

    plan: Plan
    image: np.ndarray | None = None
    alpha: np.ndarray | None = None
    progress: Progress | None = None
    grid: SparseTrace | None = None
    check: bool = False
    id_pass: SparseTrace | None = None
    preview_key: tuple | None = None
    kept_key: tuple | None = None


def keeps(held: HeldOut) -> bool:
    """Whether an MRT image chosen without a pilot (:data:`HOME`, :data:`SKY`)
    whose check found ``held`` is kept.

    Examples
    --------
    >>> keeps(HeldOut(error=0.012, full_error=0.01, pixels=2048, seconds=0.01))
    True
    >>> keeps(HeldOut(error=0.02, full_error=0.01, pixels=2048, seconds=0.01))
    False
    """
    return held.error <= CHECK_SLACK * held.full_error


def plan_without_pilot(width: int, height: int, spp: int, jit: bool,
                       params: MRTParams) -> Plan | None:
    """The plan where nothing is worth measuring (a full render), else None.

    The scalar variant traces pixel by pixel in Python while ``mi.render``
    runs Mitsuba's multithreaded C++ loop, so only a full render can win
    there; below ``AUTO_MIN_SAMPLES`` samples the passes' launches would cost
    more than they could save, unless a time limit asks for what fits it or
    a noise threshold for an estimated error.
    """
    if jit and (width * height * spp >= AUTO_MIN_SAMPLES or params.time_limit is not None
                or params.noise_threshold is not None):
        return None
    reason = ("the scalar variant renders in full" if not jit
              else "too few samples for a plan to pay")
    return Plan(Candidate("full", "full", spp), reason, time_limit=params.time_limit,
                target_error=params.noise_threshold)


def run_auto(scene: mi.Scene, pattern: SamplePattern, tracer, params: MRTParams,
             started: float, escape: bool = True, on_round=None) -> AutoOutcome:
    """The plan of the module; the image too where the passes made it.

    ``started`` is the render's ``time.perf_counter()`` at its start: a time
    limit is counted from it.  Without ``escape`` the passes run to the
    target whatever the first round predicts.  ``on_round(stage, done)``
    hears of every round of passes.
    """
    spp, limit = tracer.spp, params.time_limit
    width, height = pattern.width, pattern.height
    denoise = oidn_available()
    notes = [] if denoise else ["Intel Open Image Denoise is not installed (pip install "
                                "mitsuba-oidn): the plan considers no denoising"]
    if not denoise and limit is None:
        return AutoOutcome(Plan(Candidate("full", "full", spp), "no denoiser: the full render",
                                target_error=params.noise_threshold, notes=notes))
    key = scene_key(scene, tracer, width * height)
    kept_key = key + plan_key(tracer, params)  # (a kept plan's key)
    default = limit is None and params.noise_threshold is None
    if escape and default and denoise:
        outcome = _again(scene, tracer, key, kept_key, width, height, notes, on_round)
        if outcome is not None:
            return outcome
    probe_start = time.perf_counter()
    if (escape and default and not surely_noisy(scene, tracer.integrator)
            and noise_free(tracer, width, height)):
        return AutoOutcome(Plan(Candidate("full", "full", spp, error=0.0),
                                "noise-free: the full render is exact", target_error=0.0,
                                pilot_s=time.perf_counter() - probe_start, notes=notes))
    traced = _Traced()
    if escape and denoise and default and spp >= HOME_MIN_SPP:
        outcome, traced = _mrt_by_kind(scene, tracer, params, width, height, notes, probe_start)
        if outcome is not None:
            return outcome
    area = effective_area(tracer.sensor.film().rfilter())
    deadline = None if limit is None else started + TIME_MARGIN * limit
    surfaces, found, probed = None, False, None
    if escape and limit is not None and denoise and params.noise_threshold is None \
            and spp >= HOME_MIN_SPP:
        outcome = _measured_within(kept_key, started, limit, notes,
                                   sampler_bakes_spp(tracer.sensor.sampler()))
        if outcome is not None:
            return outcome
        outcome, traced, probed = _mrt_within(scene, pattern, tracer, params, started, notes,
                                              key)
        if outcome is not None:
            return outcome
    if limit is not None and denoise:
        outcome, surfaces, found = _preview_first(scene, pattern, tracer, params, started, key,
                                                  notes, probed, traced)
        if outcome is not None:
            _note_baked(_launch_costs.get(key), notes)
            return _filled_preview(outcome, pattern, tracer, params, started, key)
    if denoise and not found:
        surfaces = _surfaces(scene, tracer, width, height, traced.shape_index())
    recorded = recordings()
    costs, measured = {}, []

    def stop_early(progress: Progress, pass_s: float):
        """Whether passes are the wrong plan for the target: the reason, or
        None.  Where more passes would cost more than a full render, the
        planner weighs them against the others (:func:`_measured_plan`);
        where it chooses them, they go on from here, without a way out."""
        if deadline is not None:
            # the first round, once traced, is denoised however late it ends: OIDN on
            # it costs less than a preview would (its time tells the next render's plan)
            if (progress.spp <= FIRST_ROUND and recordings() == recorded
                    and not progress.history):
                # one pass, no estimate, and no recording (whose cost would not come again)
                _first_round_s[key] = time.perf_counter() - started
            return None
        if not denoise:
            return None
        target = params.noise_threshold or progress.full_error
        if measured or (target > 0 and (params.noise_threshold is None
                                        or len(progress.history) < CHECK_AFTER_ROUNDS)):
            # the full render's own noise: passes to the scene's spp meet it at
            # a full render's cost, near enough; or too few rounds to tell
            return None
        needed = needed_spp(progress.history, target)  # the spp of the final image
        # (the passes stop at the scene's spp: past it, their candidate is what they reach there)
        reached = min(needed, spp)
        costs.update(passes=max(reached - progress.spp, 0.0) * pass_s,
                     full=spp * pass_s / PASS_SAMPLES, mrt=params.sample_fraction * spp * pass_s,
                     passes_spp=reached, target=target, full_error=progress.full_error,
                     passes_error=target if needed <= spp else predict(progress.history, spp))
        if costs["passes"] <= costs["full"]:
            return None
        begin = time.perf_counter()
        measured.append(_measured_plan(scene, pattern, tracer, params, progress, costs, notes))
        progress.estimate_s += time.perf_counter() - begin  # (the passes' check, if they go on)
        return None if measured[0].choice.kind == "denoised" else STOPPED_REASON

    if limit is not None:
        max_spp = spp * LIMIT_SPP_FACTOR
    elif params.noise_threshold is None:
        max_spp = max(FIRST_ROUND, int(spp * DEFAULT_SPP_SHARE))
    else:
        max_spp = spp
    image, alpha, progress = run_passes(
        tracer, width, height, quality=params.denoise_quality,
        target_error=params.noise_threshold, deadline=deadline,
        max_spp=max_spp, full_spp=spp, area=area,
        denoise=denoise, stop_early=stop_early if escape else None, on_round=on_round,
        surfaces=surfaces, cost=_kept_cost(key, tracer))
    if image is not None:
        if deadline is not None and denoise:
            _keep(_final_denoise_s, (key, progress.shading), progress.denoise_s)
        name, kind = ("full+oidn", "denoised") if denoise else ("passes", "passes")
        choice = Candidate(name, kind, progress.spp, denoise=denoise,
                           seconds=progress.trace_s + progress.denoise_s,
                           error=progress.predicted, quality=progress.quality or None,
                           shading=progress.shading, clean_texture=progress.clean_texture)
        plan = Plan(choice, f"{'denoised ' if denoise else ''}passes: {progress.stopped}",
                    target_error=params.noise_threshold or (
                        None if limit is not None else progress.full_error),
                    time_limit=limit, pilot_s=progress.estimate_s, notes=notes,
                    passes=list(progress.history))
        if default and denoise:  # (the next default render of the scene takes them again)
            kept_plans.note_passes(kept_key, choice, plan.reason)
        if measured:  # (the planner chose the passes, which went on)
            plan.reason, plan.candidates = measured[0].reason, measured[0].candidates
        return AutoOutcome(plan, image, alpha, progress, id_pass=traced.id_pass)
    return AutoOutcome(measured[0])


def _again(scene, tracer, key: tuple, kept_key: tuple, width: int, height: int,
           notes: list, on_round) -> AutoOutcome | None:
    """Under the default target: the plan an earlier default render of
    ``kept_key`` (``key``, :func:`scene_key`, and :func:`plan_key`) in this
    process kept (:func:`~.kept_plans.plan_again`), without the probes, the
    check or the estimates that chose it; an MRT plan to be rendered (its
    time kept for ``kept_key``), the passes' image at their kept spp and
    preset (their launch kept for ``key``'s time-limited passes,
    :func:`_kept_cost`); else None."""
    kept = kept_plans.plan_again(kept_key)
    if kept is None:
        return None
    choice, reason = kept
    plan = Plan(choice, AGAIN_REASON.format(reason), notes=notes)
    if choice.kind == "mrt":
        return AutoOutcome(plan, kept_key=kept_key)
    surfaces = _surfaces(scene, tracer, width, height) if choice.shading else None
    image, alpha, progress = run_passes(
        tracer, width, height, quality=choice.quality, target_error=None, deadline=None,
        max_spp=choice.spp, full_spp=tracer.spp, area=1.0, surfaces=surfaces,
        on_round=on_round, cost=_kept_cost(key, tracer), fixed=True)
    plan.choice = replace(choice, seconds=progress.trace_s + progress.denoise_s)
    return AutoOutcome(plan, image, alpha, progress)


def _mrt_by_kind(scene, tracer, params: MRTParams, width: int, height: int, notes: list,
                 probe_start: float) -> tuple[AutoOutcome | None, _Traced]:
    """(the outcome of :func:`unmeasured_plan`'s MRT plan, its image to be
    checked, or None: the passes; what the plan traced of every pixel).  A
    large or textured image's plan (:data:`EDGE_TESTED`) gives way to the
    passes, with a note, where too many of its pixels lie at an edge between
    ids (:func:`_edge_tested`)."""
    chosen = unmeasured_plan(scene, width * height)
    if chosen is None:
        return None, _Traced()
    traced = _Traced()
    if chosen[1] in EDGE_TESTED:
        traced, too_many = _edge_tested(scene, tracer, params, width, height, notes)
        if too_many:
            return None, traced
    id_pass = traced.id_pass  # (a trace of the image: not the plan's time)
    pilot_s = time.perf_counter() - probe_start - (0.0 if id_pass is None else id_pass.seconds)
    choice = spread(chosen[0], chosen[1], tracer.spp, params.sample_fraction, width * height)
    return AutoOutcome(Plan(choice, chosen[1], pilot_s=pilot_s, notes=notes), check=True,
                       id_pass=id_pass), traced


def spread(chosen: Candidate, reason: str, spp: int, fraction: float,
           pixels: int) -> Candidate:
    """``chosen``, an MRT plan of :func:`unmeasured_plan` for ``reason``, at
    the render's ``spp`` and grid ``fraction``; on an image of fewer than
    :data:`WIDE_PIXELS` ``pixels`` of another kind than the report's, its
    grid :data:`SMALL_IMAGE_SPREAD` times denser at as many times fewer spp.

    Examples
    --------
    >>> spread(SKY, SKY_REASON, 64, 0.1, 256 * 256).label
    'refine+oidn @ 32 spp, grid of 20 % of the pixels'
    >>> spread(HOME, HOME_REASON, 64, 0.1, 256 * 256).label
    'idpass+oidn @ 64 spp'
    """
    if pixels >= WIDE_PIXELS or reason == HOME_REASON:
        return replace(chosen, spp=spp)
    return replace(chosen, spp=max(1, math.ceil(spp / SMALL_IMAGE_SPREAD)),
                   fraction=min(1.0, SMALL_IMAGE_SPREAD * fraction))


def _edge_tested(scene, tracer, params: MRTParams, width: int, height: int,
                 notes: list) -> tuple[_Traced, bool]:
    """(the pixels traced, whether more than :data:`WIDE_EDGE_SHARE` of them
    lie at an edge between ids: too many for :data:`EDGE_TESTED`'s plans).

    Each pixel's ids are traced first, without the albedo (one ray a pixel
    and its lights' shadow rays: a tenth of the id pass's cost), and the id
    pass only where few enough pixels lie at an edge between them.
    """
    xy = every_pixel(width, height)
    ids_alone = tracer(xy, stream=SeedStream.ID_PASS, radiance=False, albedo=False,
                       replay=True)
    if _too_many_edges(ids_alone.ids(params.rule_for("idpass")), width, height, notes):
        return _Traced(shapes=ids_alone.shape_index), True
    return _Traced(_id_pass(tracer, width, height), ids_alone.shape_index), False


def _too_many_edges(ids: np.ndarray, width: int, height: int, notes: list) -> bool:
    """Whether more than :data:`WIDE_EDGE_SHARE` of the pixels lie at an edge
    between ``ids`` (the pixels'; a note says so where they do)."""
    share = edge_share(ids.reshape(height, width))
    if share > WIDE_EDGE_SHARE:
        notes.append(f"{share:.1%} of the pixels at an edge between ids: "
                     f"too many for the MRT's grid")
    return share > WIDE_EDGE_SHARE


def _kept_cost(key: tuple, tracer) -> LaunchCost:
    """The launches kept for ``key`` (new where there are none, of
    ``tracer``'s sampler), now the most recently used of :data:`_launch_costs`;
    a 1-spp launch among its :attr:`~.progressive.LaunchCost.replays` where
    another trace recorded its layout (a full render denoised, at 1 spp)."""
    cost = _keep(_launch_costs, key, _launch_costs.get(key) or LaunchCost(
        spp_compiles=sampler_bakes_spp(tracer.sensor.sampler())))
    cost.replays = frozenset([1] if tracer.pass_recorded(1) else [])
    return cost


def _keep(table: dict, key: tuple, value):
    """``value`` kept for ``key`` in ``table`` as its most recently used
    entry, of the last :data:`KEPT_COSTS`; returned."""
    return keep(table, key, value, KEPT_COSTS)


def _preview_first(scene, pattern: SamplePattern, tracer, params: MRTParams, started: float,
                   key: tuple, notes: list, probed: "_Probe | None" = None,
                   traced: "_Traced | None" = None
                   ) -> tuple[AutoOutcome | None, tuple | None, bool]:
    """Under a time limit: (the preview's outcome where one pass and OIDN on
    the whole image would end after :data:`PREVIEW_SLACK` times the limit
    (:data:`PROBED_SLACK` times, where a probe tells the pass's time),
    else None; the passes' textured surfaces (:func:`_surfaces`) and whether
    they were looked up, which took time the question then counts).  Where
    denoising the textured surfaces as their shading would end past the
    limit itself (:data:`SHADING_EXTRA`) but plain OIDN would not, the
    passes go without them (None, looked up).
    ``probed``: the grid probe, where :func:`_mrt_within` has made it;
    ``traced``: what it traced of every pixel."""
    width, height, limit = pattern.width, pattern.height, params.time_limit
    preview = Plan(PREVIEW, PREVIEW_REASON, time_limit=limit, notes=notes)
    first_s = _first_round_s.get(key)
    launches = _kept_cost(key, tracer)
    if first_s is None and launches.replayed:
        # earlier passes measured a pass (a probe can record its kernels anew)
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
    probed = probed or _grid_probe(pattern, tracer)  # the preview's own grid: a pass's cost
    end = started + PROBED_SLACK * limit
    grid, pass_s = probed.grid, probed.pass_s
    if launches.spp_compiles and launches.launches:
        # a sampler that bakes its spp launches only spp launched before: the
        # probe's sample scaled to the least of them (which counts the kernels'
        # fixed part spp times), or the launches' line where it says less (a
        # recorded launch may hold a compilation it could not tell apart)
        spp = launches.cheapest()
        pass_s = min(probed.host + spp * (probed.pass_s - probed.host), launches(spp))
    pass_s += _passes_recording_s(key, probed)

    def due(shading: bool) -> bool:
        return _preview_due(end, time.perf_counter() + pass_s, width * height,
                            params.denoise_quality, shading, key)
    if due(False):
        return AutoOutcome(preview, grid=grid), None, False
    if textured and not due(True):
        # the passes' textured pixels, then the same question with their time spent
        surfaces = _surfaces(scene, tracer, width, height,
                             None if traced is None else traced.shape_index())
        if not due(surfaces is not None):
            return None, surfaces, True
    # the passes, denoised plainly: the shading's extra time would end past the limit
    return (AutoOutcome(preview, grid=grid) if due(False) else None), None, True


def _note_baked(launches: LaunchCost | None, notes: list) -> None:
    """Say why the preview was taken (:data:`BAKED_NOTE`) where the passes'
    ``launches`` (:data:`_launch_costs`) plan a pass only at an spp above 1
    that they traced before."""
    if launches is not None and launches.spp_compiles and launches.launches:
        cheapest = launches.cheapest()
        if cheapest > 1:
            notes.append(BAKED_NOTE.format(cheapest))


def _filled_preview(outcome: AutoOutcome, pattern: SamplePattern, tracer, params: MRTParams,
                    started: float, key: tuple) -> AutoOutcome:
    """``outcome``, the preview, its grid pooled from as many 1-spp launches
    as end before the limit (its :data:`TIME_MARGIN`) less what the stages
    after the grid are expected to take (:func:`_preview_after`):
    :func:`.preview.preview_grid`.  Where those stages would end past
    :data:`PREVIEW_SLACK` times the limit even right after the grid's first
    launch (a fresh process's first trace and OIDN call), the preview goes
    without OIDN (:data:`UNDENOISED_NOTE`)."""
    after = _preview_after(key, pattern, params.denoise_quality)
    grid = preview_grid(outcome.grid, pattern, tracer,
                        started + TIME_MARGIN * params.time_limit - after)
    plan = outcome.plan
    plan.choice = replace(plan.choice, spp=grid.spp)
    outcome = replace(outcome, grid=grid, preview_key=key)
    if time.perf_counter() + after > started + PREVIEW_SLACK * params.time_limit:
        plan.choice = replace(plan.choice, name=UNDENOISED.name, denoise=False)
        plan.notes.append(UNDENOISED_NOTE)
    return outcome


def _preview_after(key: tuple, pattern: SamplePattern, quality: str) -> float:
    """The seconds a preview's stages after its grid (OIDN on the grid, the
    reconstruction, the finish) are expected to take: the median of the last
    denoised previews' of ``key`` (:data:`_preview_after_s`); else
    :data:`FINISH_PER_PIXEL`'s bound (before OIDN's first call at the
    preview's quality, that call's expected time on top, which holds its
    set-up), or where less, the largest time per pixel beyond OIDN of this
    process's last previews (:data:`_preview_rate`) and OIDN's expected
    time."""
    kept = _preview_after_s.get(key)
    if kept:
        return typical(kept)
    quality = preset(quality)
    pixels, oidn = pattern.width * pattern.height, expected_seconds(pattern.count, quality)
    first_call = denoise_seconds(pattern.count, quality) is None
    bound = FINISH_PER_PIXEL * pixels + (oidn if first_call else 0.0)
    return min(bound, max(_preview_rate) * pixels + oidn) if _preview_rate else bound


def note_preview_after(key: tuple, seconds: float, denoise: float, pixels: int) -> None:
    """Keep what the stages after a preview's grid took (``seconds``, of
    which OIDN ``denoise``; 0 without OIDN) on an image of ``pixels``: for
    the next preview of ``key`` where it was denoised
    (:data:`_preview_after_s`), and as a time per pixel beyond OIDN for
    the first preview of another scene (:data:`_preview_rate`)."""
    if denoise > 0.0:
        note(_keep(_preview_after_s, key, _preview_after_s.get(key, [])), seconds,
             PREVIEW_AFTER_CALLS)
    note(_preview_rate, max(seconds - denoise, 0.0) / pixels, PREVIEW_RATE_CALLS)


def scene_key(scene: mi.Scene, tracer, pixels: int) -> tuple:
    """The key of what earlier renders took (:data:`_launch_costs` and the
    other tables of the module): the traced objects and the image's pixel count."""
    return token((scene, tracer.sensor, tracer.integrator)), pixels


def plan_key(tracer, params: MRTParams) -> tuple:
    """What a kept plan's key (:mod:`.kept_plans`) adds to :func:`scene_key`'s:
    the spp and the parameters but the time limit and quality target."""
    return tracer.spp, replace(params, time_limit=None, noise_threshold=None)


def _measured_within(key: tuple, started: float, limit: float, notes: list,
                     bakes: bool) -> AutoOutcome | None:
    """Under a time limit: the MRT plan of the default target that a render
    of ``key`` (:func:`scene_key` and :func:`plan_key`) in this process kept
    by its check, at the most spp expected to end within :data:`TIME_MARGIN`
    of the limit (:func:`~.kept_plans.plan_within`; ``bakes``: the sampler
    compiles kernels per spp), unchecked; else None."""
    left = started + TIME_MARGIN * limit - time.perf_counter()
    kept = kept_plans.plan_within(key, left, bakes)
    if kept is None:
        return None
    choice, reason = kept
    plan = Plan(choice, MEASURED_REASON.format(reason, choice.spp, choice.seconds),
                time_limit=limit, notes=notes, pilot_s=time.perf_counter() - started)
    return AutoOutcome(plan, kept_key=key)


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
    if launches is not None and (launches.launches or 1 in launches.replays):
        return 0.0
    return max(_probe_recording_s.get(key, 0.0) - probed.host, 0.0)


def unmeasured_plan(scene: mi.Scene, pixels: int) -> tuple[Candidate, str] | None:
    """The MRT plan the scene's kind and ``pixels`` point to (:data:`HOME`,
    :data:`SKY`), with its reason, or None: the passes."""
    if lit_diffuse_by_points(scene):
        return HOME, HOME_REASON
    if environment_map(scene):
        return SKY, SKY_REASON
    if pixels >= WIDE_PIXELS:
        return HOME, WIDE_REASON
    textured = textured_diffuse_shapes(scene).any()
    if textured and not transmits(scene):
        return HOME, TEXTURED_REASON
    if not textured and (has_mirrors(scene) or transmits(scene)):
        return SKY, SPECULAR_REASON
    return None


def _surfaces(scene, tracer, width: int, height: int,
              shape_index: np.ndarray | None = None) -> tuple | None:
    """(each pixel's shape index, :func:`textured_diffuse_shapes`) where the
    scene has a textured diffuse surface, else None: the shape of every
    pixel's centre ray (``shape_index`` where given, else
    :func:`~.trace.trace_shapes`), for the passes to find the textured pixels."""
    textured = textured_diffuse_shapes(scene)
    if not textured.any():
        return None
    if shape_index is not None:
        return shape_index, textured
    return trace_shapes(scene, tracer.sensor, every_pixel(width, height), replay=True), textured


class _Traced(NamedTuple):
    """What planning traced of every pixel: the id pass (:func:`_id_pass`)
    and each pixel's shape (the centre ray's, from the ids :func:`_edge_tested`
    traced), None where not."""

    id_pass: SparseTrace | None = None
    shapes: np.ndarray | None = None

    def shape_index(self) -> np.ndarray | None:
        """Each pixel's shape index, where either trace gives it, else None."""
        if self.shapes is not None:
            return self.shapes
        return None if self.id_pass is None else self.id_pass.shape_index


def _id_pass(tracer, width: int, height: int) -> SparseTrace:
    """The image's id pass, as mode ``idpass`` traces it (and then reuses)."""
    return tracer(every_pixel(width, height), stream=SeedStream.ID_PASS, radiance=False,
                  replay=True)


class _Probe(NamedTuple):
    """The grid probe (:func:`_grid_probe`): the preview's grid trace, the
    seconds a pass over every pixel is expected to take, the trace's kernels'
    run time, what it took beyond them, whether it recorded its kernels (a
    process's first trace of the scene) and what compiling those not in
    Dr.Jit's caches took of ``host`` (once per machine, not per process)."""

    grid: SparseTrace
    pass_s: float
    execute: float
    host: float
    recorded: bool
    compile: float = 0.0


def _grid_probe(pattern: SamplePattern, tracer) -> _Probe:
    """The preview's grid trace (:data:`PREVIEW`'s spp), and the seconds a
    pass over every pixel is expected to take: the trace's kernels' run
    time scaled to every pixel, times :data:`PASS_OVER_GRID`, plus what the
    trace took beyond its kernels (launching them, reading them back, and
    in a fresh process the first use of the scene and the kernels)."""
    begin, recorded = time.perf_counter(), recordings()
    with kernel_seconds() as spent:
        grid = replace(tracer, spp=PREVIEW.spp)(pattern.pixel_xy, stream=SeedStream.GRID,
                                                replay=True)
    host = max(time.perf_counter() - begin - spent.execute, 0.0)
    pixels = pattern.width * pattern.height
    return _Probe(grid, host + PASS_OVER_GRID * spent.execute * pixels / pattern.count,
                  spent.execute, host, recordings() > recorded, min(spent.compile, host))


def _mrt_within(scene, pattern: SamplePattern, tracer, params: MRTParams, started: float,
                notes: list, key: tuple) -> tuple[AutoOutcome | None, _Traced, _Probe | None]:
    """Under a time limit: (:data:`HOME`'s outcome where the scene's kind
    points to it (:func:`unmeasured_plan`) and it is expected to end within
    :data:`TIME_MARGIN` of the limit, else None; what it traced of every
    pixel (:class:`_Traced`); the grid probe where it was made).

    The grid probe's kernel time tells the plan's traces (the grid at the
    scene's spp: :data:`GRID_OVER_PROBE`; the id pass, traced only where
    :data:`ID_PASS_OVER_PROBE` times it fits, then measured), the pixels
    its other stages (:data:`FINISH_PER_PIXEL`), and a first trace of the
    scene in this process what recording the grid's kernels adds.  A sampler
    that compiles kernels per spp (:func:`~.scene_query.sampler_bakes_spp`)
    is not planned so in such a process: its compilation cannot be told.
    The plan's image is not checked (:func:`keeps`): the check's fallback,
    the passes, would start after the limit.  Where the last replayed probe
    of ``key`` (:data:`_probe_execute`) says the plan cannot end within the
    limit, no probe is traced.
    """
    width, height = pattern.width, pattern.height
    chosen = unmeasured_plan(scene, width * height)
    if chosen is None or chosen[0] is not HOME:
        return None, _Traced(), None
    end = started + TIME_MARGIN * params.time_limit

    def rest(execute: float, host: float = 0.0) -> float:
        """The plan's time after its id pass, from the probe's kernel run time."""
        return GRID_OVER_PROBE * tracer.spp * execute + FINISH_PER_PIXEL * width * height + host

    def ends_late(execute: float, host: float = 0.0) -> bool:
        """Whether the plan, its id pass included, would end after ``end``."""
        return time.perf_counter() + ID_PASS_OVER_PROBE * execute + rest(execute, host) > end

    known = _probe_execute.get(key)
    if known is not None and ends_late(known):
        return None, _Traced(), None
    probed = _grid_probe(pattern, tracer)
    if probed.recorded and sampler_bakes_spp(tracer.sensor.sampler()):
        return None, _Traced(), probed
    if not probed.recorded:
        _keep(_probe_execute, key, probed.execute)
    host = probed.host if probed.recorded else 0.0
    if ends_late(probed.execute, host):
        return None, _Traced(), probed
    if chosen[1] in EDGE_TESTED:
        traced, too_many = _edge_tested(scene, tracer, params, width, height, notes)
        if too_many:
            return None, traced, probed
    else:
        traced = _Traced(_id_pass(tracer, width, height))
    if time.perf_counter() + rest(probed.execute, host) > end:
        return None, traced, probed
    plan = Plan(replace(chosen[0], spp=tracer.spp), WITHIN_REASON.format(chosen[1]),
                time_limit=params.time_limit, notes=notes,
                pilot_s=time.perf_counter() - started - traced.id_pass.seconds)
    return AutoOutcome(plan, id_pass=traced.id_pass), traced, probed


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


def noise_free(tracer, width: int, height: int) -> bool:
    """Whether a lattice of :data:`PROBE_SIDE` x :data:`PROBE_SIDE` pixels
    over the image (their cells' centres) comes out the same from two sets
    of random numbers (a deterministic scene: its full render has no noise).

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
    # (equal up to the order in which a pixel's samples were summed)
    return bool(np.isfinite(probe.radiance).all()) and np.allclose(first, second, rtol=1e-5,
                                                                   atol=1e-6)


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
