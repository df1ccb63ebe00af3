"""Mode ``auto``: the planner on synthetic numbers, the pilot, and the plan's execution."""

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import mitsuba as mi
import numpy as np
import pytest

import mitsuba_mrt
from mitsuba_mrt import MRTError, MRTParams
from mitsuba_mrt.modes.plan import Candidate, Plan, choose
from mitsuba_mrt.recon.denoise import release
from mitsuba_mrt.renderer import auto, auto_limit, auto_plans, kept_plans, launch_cost, pilot
from mitsuba_mrt.recon.sampling import grid_pattern
from mitsuba_mrt.renderer.preview import PREVIEW_MAX_SPP
from mitsuba_mrt.runtime.recent import typical
from mitsuba_mrt.types import KernelCounts, Timings

from helpers import SCENES
from helpers import ball_scene_xml as scene_xml

ROOT = Path(__file__).resolve().parents[2]


def box_film():
    """A fake tracer's film: a box pixel filter (the passes' mean is the image)."""
    return SimpleNamespace(rfilter=lambda: SimpleNamespace(radius=lambda: 0.5,
                                                           eval=lambda x: 1.0))


def test_by_default_the_passes_stop_at_half_the_scenes_spp(variant, monkeypatch):
    # the round to the scene's spp would cost a full render, the rounds before included
    from mitsuba_mrt.renderer import progressive

    monkeypatch.setattr(progressive, "predict", lambda history, spp: 1.0)  # never met
    scene = mi.load_string(scene_xml(256, spp=64))
    result = mitsuba_mrt.render(scene)
    assert result.mode_used == "full+oidn" and result.spp == 32
    assert result.auto.reason == "denoised passes: reached 32 spp, short of the target"
    # rounds of 8, 8 and 16 spp; the last, which ends them at the cap, is not
    # estimated (its estimate would change no decision), only predicted
    assert [spp for spp, _ in result.auto.passes] == [4, 8]
    assert result.auto.choice.error == 1.0




# -- the planner, on synthetic costs and errors ------------------------------------------------

CANDIDATES = [Candidate("full", "full", 64, seconds=1.0, error=0.10),
              Candidate("full", "full", 16, seconds=0.25, error=0.20),
              Candidate("full+oidn", "denoised", 2, denoise=True, seconds=0.12, error=0.09),
              Candidate("full+oidn", "denoised", 8, denoise=True, seconds=0.30, error=0.06),
              Candidate("refine+oidn", "mrt", 64, mode="refine", denoise=True, seconds=0.45,
                        error=0.05, compile_s=0.5)]


def test_the_planner_takes_the_cheapest_that_meets_the_target():
    assert choose(CANDIDATES, target_error=0.10).choice is CANDIDATES[2]
    assert choose(CANDIDATES, target_error=0.07).choice is CANDIDATES[3]
    assert choose(CANDIDATES, target_error=0.05).choice is CANDIDATES[4]


def test_where_none_meets_the_target_the_planner_takes_the_most_accurate():
    plan = choose(CANDIDATES, target_error=0.01)
    assert plan.choice is CANDIDATES[4] and "most accurate" in plan.reason


def test_under_a_time_limit_the_planner_takes_the_best_that_fits():
    # compilation counts against a limit: refine+oidn's 0.45 + 0.5 s does not fit 0.5 s
    assert choose(CANDIDATES, time_limit=0.5).choice is CANDIDATES[3]
    assert choose(CANDIDATES, time_limit=1.0).choice is CANDIDATES[4]
    # a target within the limit: the cheapest that meets it
    assert choose(CANDIDATES, time_limit=1.0, target_error=0.09).choice is CANDIDATES[2]


def test_a_limit_nothing_fits_gives_the_cheapest_and_says_so():
    plan = choose(CANDIDATES, time_limit=0.01)
    assert plan.choice is CANDIDATES[2] and plan.reason.startswith("nothing fits")


def test_the_planner_needs_a_candidate():
    with pytest.raises(MRTError, match="at least one candidate"):
        choose([])


@pytest.mark.parametrize("name", ["time_limit", "noise_threshold"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf, "soon", True])
def test_bad_controls_are_one_line_errors(name, value):
    with pytest.raises(MRTError, match=f"^{name} must be a finite number > 0"):
        MRTParams(**{name: value})


@pytest.mark.parametrize("name", ["time_limit", "noise_threshold"])
def test_controls_of_auto_given_another_mode_are_one_line_errors(variant, name):
    scene = mi.load_string(scene_xml(32))
    with pytest.raises(MRTError, match=f"^{name} applies to mode auto only, not to mode 'refine'$"):
        mitsuba_mrt.render(scene, mode="refine", **{name: 1.0})


# -- the pilot and the plan's execution -------------------------------------------------------

@pytest.fixture(scope="module")
def scene(variant):
    return mi.load_string(scene_xml(512))  # 2^18 pixels x 8 spp: a pilot runs


def strip_pilot(scene, **kwargs):
    from mitsuba_mrt.recon.sampling import grid_pattern
    from mitsuba_mrt.renderer.api import GridTracer

    sensor = scene.sensors()[0]
    tracer = GridTracer(scene, sensor, scene.integrator(), 8, 0)
    return pilot.run_pilot(scene, grid_pattern(512, 512, 0.1), tracer, MRTParams(), **kwargs)


def test_the_pilot_measures_every_kind_of_candidate(scene):
    result = strip_pilot(scene, budget=1e6)  # no pruning: the MRT is measured too
    kinds = {c.kind for c in result.candidates}
    assert kinds == {"full", "denoised", "mrt"}
    assert all(c.seconds > 0 and c.error >= 0 for c in result.candidates)
    fulls = sorted((c for c in result.candidates if c.kind == "full"), key=lambda c: c.spp)
    # a full render's error is its noise: it halves as the spp quadruple
    assert fulls[-1].spp == 8 and fulls[0].spp == 1
    assert fulls[0].error == pytest.approx(fulls[-1].error * math.sqrt(8), rel=1e-9)
    denoised = sorted((c for c in result.candidates if c.kind == "denoised"),
                      key=lambda c: c.spp)
    assert [c.spp for c in denoised] == [1, 2, 4, 8]
    assert denoised[-1].error < 1.1 * denoised[0].error
    assert result.pixels > 0


def test_the_pilots_errors_follow_the_truth(scene):
    # a denoised 1-spp render beats a plain 1-spp render, as the pilot predicts
    by = {(c.name, c.spp): c for c in strip_pilot(scene, budget=1e6).candidates}
    truth = mitsuba_mrt.render_reference(scene, spp=256)[0]
    shown = (truth <= 1).all(axis=-1)
    plain = mitsuba_mrt.render_reference(scene, spp=1, seed=7)[0]
    error = float(np.sqrt(np.mean((np.clip(plain, 0, 1) - truth)[shown] ** 2)
                          / np.mean(truth[shown] ** 2)))
    assert by[("full", 1)].error == pytest.approx(error, rel=0.25)
    assert by[("full+oidn", 1)].error < by[("full", 1)].error


def forced(monkeypatch, candidate):
    monkeypatch.setattr(auto, "run_auto",
                        lambda *args, **kwargs: auto_plans.AutoOutcome(Plan(candidate, "test")))


def test_a_full_render_the_planner_chooses_is_mi_renders_own(scene, monkeypatch):
    forced(monkeypatch, Candidate("full", "full", 8))
    result = mitsuba_mrt.render(scene, seed=3)
    image = np.array(mi.render(scene, seed=3), dtype=np.float64)[..., :3]
    assert result.mode_used == "full" and result.auto.reason == "test"
    assert np.array_equal(result.image, image)


def test_a_noise_free_scene_is_rendered_in_full(variant):
    # matte has no noise: a probe before any pass tells, and the full render is exact
    scene = mi.load_string(scene_xml(512).replace(
        '<integrator type="path"><integer name="max_depth" value="4"/></integrator>',
        '<integrator type="matte"/>'))
    result = mitsuba_mrt.render(scene)
    assert result.mode_used == "full" and result.auto.reason.startswith("noise-free")
    assert result.auto.passes == [] and result.timings.denoise == 0
    assert np.array_equal(result.image, mitsuba_mrt.render_reference(scene)[0])


AREA_LIGHT = """<shape type="sphere"><point name="center" x="2" y="3" z="4"/><float name="radius" value="0.5"/>
    <emitter type="area"><rgb name="radiance" value="8"/></emitter></shape>"""
POINT_LIGHT = """<emitter type="point"><point name="position" x="2" y="3" z="4"/>
    <rgb name="intensity" value="40"/></emitter>"""


def test_diffuse_surfaces_under_point_lights_take_the_id_pass(variant):
    # the report's kind of scene: the MRT's id pass, its grid denoised, meets a
    # full render's noise (the default target) without the passes
    assert AREA_LIGHT in scene_xml(384)
    scene = mi.load_string(scene_xml(384, spp=16).replace(AREA_LIGHT, POINT_LIGHT))
    result = mitsuba_mrt.render(scene)
    assert result.mode_used == "idpass" and result.params.denoise == "oidn"
    assert result.auto.choice.label == "idpass+oidn @ 16 spp"
    assert result.auto.reason == auto_plans.HOME_REASON and not result.auto.passes
    truth = mitsuba_mrt.render_reference(scene, spp=256)[0]
    full = mitsuba_mrt.render_reference(scene)[0]
    assert np.mean((result.image - truth) ** 2) < np.mean((full - truth) ** 2)


def test_the_id_pass_plan_is_not_taken_under_a_limit_a_threshold_or_an_area_light(variant):
    from mitsuba_mrt.renderer.scene_query import lit_diffuse_by_points

    point_lit = mi.load_string(scene_xml(384, spp=16).replace(AREA_LIGHT, POINT_LIGHT))
    assert lit_diffuse_by_points(point_lit)
    assert not lit_diffuse_by_points(mi.load_string(scene_xml(384, spp=16)))
    glossy = scene_xml(384, spp=16).replace(AREA_LIGHT, POINT_LIGHT).replace(
        '<bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.2, 0.2"/></bsdf>',
        '<bsdf type="roughplastic"/>')
    assert not lit_diffuse_by_points(mi.load_string(glossy))
    for kwargs in ({"time_limit": 1e-6}, {"noise_threshold": 0.5}):
        assert mitsuba_mrt.render(point_lit, **kwargs).auto.reason != auto_plans.HOME_REASON


def test_a_time_limit_the_id_pass_plan_fits_takes_it_and_traces_the_id_pass_once(variant,
                                                                                monkeypatch):
    from mitsuba_mrt.renderer import trace

    scene = mi.load_string(scene_xml(384, spp=16).replace(AREA_LIGHT, POINT_LIGHT))
    plain = mitsuba_mrt.render(scene)  # (its kernels recorded: the process is warm)
    monkeypatch.setattr(kept_plans, "_plans", {})  # (the plan, planned anew)
    id_passes = []
    original = trace.trace_pixels

    def counting(*args, **kwargs):
        out = original(*args, **kwargs)
        radiance = args[7] if len(args) > 7 else kwargs.get("radiance", True)
        id_passes.extend([len(out.shape_index)] if not radiance else [])
        return out
    monkeypatch.setattr("mitsuba_mrt.renderer.api.trace_pixels", counting)
    result = mitsuba_mrt.render(scene, time_limit=60.0)
    plan = result.auto
    assert result.mode_used == "idpass" and result.params.denoise == "oidn"
    assert plan.reason == auto_limit.WITHIN_REASON.format(auto_plans.HOME_REASON)
    assert plan.time_limit == 60.0 and not plan.passes and plan.choice.error is None
    assert id_passes == [384 * 384]  # traced to be timed, then reused by the mode
    # the limit's time goes into the densest grid: the plan's image at that
    # grid (same seed), unchecked
    densest = auto_limit.DENSER_GRIDS[-1]
    assert plan.choice.fraction == densest and result.pattern.count > 2 * plain.pattern.count
    same = mitsuba_mrt.render(scene, mode="idpass", denoise="oidn", sample_fraction=densest)
    assert np.array_equal(result.image, same.image)


def test_a_time_limit_too_short_for_the_id_pass_plan_traces_no_id_pass(variant, monkeypatch):
    scene = mi.load_string(scene_xml(384, spp=16).replace(AREA_LIGHT, POINT_LIGHT))
    mitsuba_mrt.render(scene)

    def no_id_pass(*args):
        raise AssertionError("the id pass was traced")
    monkeypatch.setattr(auto_plans, "trace_id_pass", no_id_pass)
    monkeypatch.setattr(auto_limit, "trace_id_pass", no_id_pass)
    for limit in (1e-6, 0.02):
        assert mitsuba_mrt.render(scene, time_limit=limit).mode_used != "idpass"


def test_a_last_probe_that_rules_the_id_pass_plan_out_spares_the_next_render_s_probe(
        variant, monkeypatch):
    scene = mi.load_string(scene_xml(384, spp=16).replace(AREA_LIGHT, POINT_LIGHT))
    for limit in (None, 0.02):  # (kernels recorded: the probes below replay)
        mitsuba_mrt.render(scene, time_limit=limit)
    monkeypatch.setattr(auto_limit, "_probe_execute", {})
    monkeypatch.setattr(kept_plans, "_plans", {})  # (the plans, planned anew)
    probes = []
    within = auto_limit.mrt_within

    def spy(*args):
        out = within(*args)
        probes.append(out[2] is not None)
        return out
    monkeypatch.setattr(auto_limit, "mrt_within", spy)
    # the first render probes, and its probe says the plan cannot end in 20 ms; the
    # next is not probed for it; a longer limit is probed again, and takes the plan
    assert mitsuba_mrt.render(scene, time_limit=0.02).mode_used != "idpass"
    assert mitsuba_mrt.render(scene, time_limit=0.02).mode_used != "idpass"
    assert mitsuba_mrt.render(scene, time_limit=60.0).mode_used == "idpass"
    assert probes == [True, False, True] and len(auto_limit._probe_execute) == 1


def test_a_time_limit_takes_the_checked_plan_again_at_the_most_spp_that_fit(variant,
                                                                          monkeypatch):
    scene = mi.load_string(scene_xml(384, spp=16).replace(AREA_LIGHT, POINT_LIGHT))
    plain = mitsuba_mrt.render(scene)  # the default target: its check keeps the image
    assert plain.auto.reason == auto_plans.HOME_REASON
    ((key, kept),) = kept_plans._plans.items()
    assert kept.choice.label == "idpass+oidn @ 16 spp" and kept.reason == auto_plans.HOME_REASON
    assert 0 < kept.seconds[16][0] < plain.timings.total  # (its check left out)
    assert 0 < kept.growing[0] < 1  # (the growing traces' share of its seconds)

    def no_probe(*args):
        raise AssertionError("the plan was probed")
    monkeypatch.setattr(auto_limit, "DENSER_GRIDS", ())  # (the spp alone: the grid below)
    with monkeypatch.context() as m:
        m.setattr(auto_limit, "_grid_probe", no_probe)
        m.setattr(kept_plans, "MOST_SPP_FACTOR", 1)  # (the checked spp the most)
        result = mitsuba_mrt.render(scene, time_limit=60.0)
        plan = result.auto
        assert result.mode_used == "idpass" and result.params.denoise == "oidn"
        assert plan.reason == auto_limit.MEASURED_REASON.format(auto_plans.HOME_REASON, 16,
                                                          kept.seconds[16][0])
        assert plan.time_limit == 60.0 and plan.choice.seconds == kept.seconds[16][0]
        assert np.array_equal(result.image, plain.image)  # the same seed's image, unchecked
    assert len(kept.seconds[16]) == 2  # (the time-limited render's seconds too)
    more = mitsuba_mrt.render(scene, time_limit=60.0, spp=32)  # (another key: planned anew)
    assert not more.auto.reason.startswith(auto_plans.HOME_REASON + "; at")
    # a long limit: four times the spp; the time of a render that replayed is
    # kept (the first recorded), and the next expects it
    result = mitsuba_mrt.render(scene, time_limit=60.0)
    assert result.spp == 64 and result.auto.choice.error is None and 64 not in kept.seconds
    again = mitsuba_mrt.render(scene, time_limit=60.0)
    assert again.spp == 64 and kept.seconds[64] == [again.timings.total]
    assert mitsuba_mrt.render(scene, time_limit=60.0).auto.choice.seconds == again.timings.total
    # not taken where no spp would end within the limit, for other parameters,
    # or under a quality target
    kept.seconds = {16: [1e3]}
    assert not mitsuba_mrt.render(scene, time_limit=60.0).auto.reason.startswith(
        auto_plans.HOME_REASON + "; at")
    kept.seconds = {16: [0.0]}
    for kwargs in ({"sample_fraction": 0.2}, {"noise_threshold": 0.5}):
        other = mitsuba_mrt.render(scene, time_limit=60.0, **kwargs)
        assert not other.auto.reason.startswith(auto_plans.HOME_REASON + "; at")


def test_a_time_limit_the_checked_plan_leaves_time_in_takes_it_on_a_denser_grid(variant,
                                                                                monkeypatch):
    scene = mi.load_string(scene_xml(384, spp=16).replace(AREA_LIGHT, POINT_LIGHT))
    mitsuba_mrt.render(scene)  # the default target: its check keeps the plan
    ((key, kept),) = kept_plans._plans.items()
    monkeypatch.setattr(kept_plans, "MOST_SPP_FACTOR", 1)  # (no more spp: as a sampler
    # that bakes them, which takes only those rendered before)
    result = mitsuba_mrt.render(scene, time_limit=60.0)
    densest = auto_limit.DENSER_GRIDS[-1]
    assert result.mode_used == "idpass" and result.spp == 16
    assert result.auto.choice.fraction == densest
    assert result.auto.reason.startswith(auto_plans.HOME_REASON + "; at 16 spp")
    assert result.auto.choice.seconds > typical(kept.seconds[16])  # (the denser grid's)
    # the plan's image on that grid (same seed), unchecked; its time is not the plan's
    same = mitsuba_mrt.render(scene, mode="idpass", denoise="oidn", sample_fraction=densest)
    assert np.array_equal(result.image, same.image) and len(kept.seconds[16]) == 1
    # a limit the plan nearly fills: its own grid, its time kept
    kept.seconds = {16: [0.93 * 60.0 - 0.5]}
    result = mitsuba_mrt.render(scene, time_limit=60.0)
    assert result.mode_used == "idpass" and result.auto.choice.fraction is None
    assert len(kept.seconds[16]) == 2


def test_a_kept_plan_s_first_render_that_compiled_does_not_shrink_its_expected_time():
    # the checked render compiled its kernels: 0.5 s of its traces' 0.74 s and of
    # its 0.81 s; two renders of the plan again then took 0.28 s (of which the
    # traces 0.24 s).  At 20 of 32 spp a render takes about 0.2 s; the checked
    # render's 0.74 s of traces beside the 0.28 s median would expect 0.03 s
    choice = Candidate("refine+oidn", "mrt", 32, mode="refine", denoise=True)
    key = ("scene",)
    try:
        kept_plans.note_checked(key, choice, "", 0.81, Timings(trace=0.37, trace_more=0.37))
        for _ in range(2):
            kept_plans.note_render(key, 32, 0.28, replayed=True)
        expected = kept_plans._plans[key].expected(20)
        assert 0.17 < expected < 0.23
        assert kept_plans.plan_within(key, 0.1, bakes=False) is None
    finally:
        kept_plans.clear()


def test_a_checked_render_s_recordings_are_left_out_of_its_kept_time():
    # the checked render spent 0.09 s of its 0.27 s (0.2 s of it traces) recording
    # its traces' replays: a replay takes 0.18 s, of which the traces 0.11 s
    choice = Candidate("refine+oidn", "mrt", 32, mode="refine", denoise=True)
    key = ("scene",)
    try:
        kept_plans.note_checked(key, choice, "", 0.27, Timings(trace=0.12, trace_more=0.08),
                                recording_s=0.09)
        kept = kept_plans._plans[key]
        assert kept.seconds[32] == [pytest.approx(0.18)]
        assert kept.growing == [pytest.approx(0.11 / 0.18)]
        # more recording than the render's seconds (a clock's noise) keeps none
        kept_plans.note_checked(key, choice, "", 0.05, Timings(trace=0.04), recording_s=0.06)
        assert kept.seconds[32][-1] == 0.0 and kept.growing[-1] == 0.0
    finally:
        kept_plans.clear()


def test_an_idpass_plan_s_grid_share_leaves_out_only_its_grid_s_recording():
    # the checked render (0.6 s, its grid 0.3 s and its id pass 0.2 s) spent 0.3 s
    # recording, 0.1 s of it in its grid's trace: a replay takes 0.3 s, its grid
    # 0.2 s of it (the id pass's recording is none of the grid's)
    choice = Candidate("idpass+oidn", "mrt", 32, mode="idpass", denoise=True)
    key = ("scene",)
    try:
        kept_plans.note_checked(key, choice, "", 0.6, Timings(trace=0.3, trace_more=0.2),
                                recording_s=0.3, grid_recording_s=0.1)
        kept = kept_plans._plans[key]
        assert kept.seconds[32] == [pytest.approx(0.3)]
        assert kept.growing == [pytest.approx(0.2 / 0.3)]
        assert kept_plans.growing_seconds(key, 32) == pytest.approx(0.2)
    finally:
        kept_plans.clear()


def test_a_checked_render_gives_its_grid_s_own_recording_to_the_kept_plan(variant,
                                                                          monkeypatch):
    from mitsuba_mrt.recon.denoise import hidden

    seen = []
    real = kept_plans.note_checked
    monkeypatch.setattr(kept_plans, "note_checked", lambda *args: seen.append(args) or real(*args))
    scene = mi.load_string(scene_xml(384, spp=16))  # (its first traces: each records)
    with hidden():
        mitsuba_mrt.render(scene)
    (args,) = seen
    recording_s, grid_recording_s = args[5], args[7]
    assert 0.0 < grid_recording_s < recording_s  # the grid's, of the grid's and the id pass's


def test_a_sampler_that_bakes_its_spp_keeps_the_checked_plan_s_spp_under_a_time_limit(
        variant, monkeypatch):
    scene = mi.load_string(scene_xml(384, spp=16, sampler="stratified").replace(AREA_LIGHT,
                                                                             POINT_LIGHT))
    mitsuba_mrt.render(scene)  # (kept by its check)
    result = mitsuba_mrt.render(scene, time_limit=60.0)  # a new spp would compile
    assert result.auto.reason.startswith(auto_plans.HOME_REASON + "; at 16 spp")


def test_a_large_image_without_an_environment_map_takes_the_checked_id_pass(variant):
    # an area light, diffuse surfaces, 512 x 512: the id pass, its grid denoised,
    # kept because its held-out check finds it near a full render's noise
    result = mitsuba_mrt.render(mi.load_string(scene_xml(512, spp=16)))
    plan = result.auto
    assert result.mode_used == "idpass" and result.params.denoise == "oidn"
    assert plan.reason == auto_plans.WIDE_REASON and not plan.passes
    assert plan.pilot_pixels >= 2 * 1024 and plan.target_error > 0
    assert plan.choice.error <= auto_plans.CHECK_SLACK * plan.target_error
    assert result.timings.check >= plan.pilot_s - 1e-9 > 0


def test_the_large_images_id_pass_is_traced_once_for_the_gate_and_the_mode(variant,
                                                                            monkeypatch):
    from mitsuba_mrt.renderer import api
    from mitsuba_mrt.types import SeedStream

    id_passes = []
    trace = api.trace_pixels

    def counting(scene, sensor, integrator, pixel_xy, spp, seed, aovs, radiance, *rest):
        if seed == SeedStream.ID_PASS and not radiance and rest[4]:  # (with the albedo)
            id_passes.append(len(pixel_xy))
        return trace(scene, sensor, integrator, pixel_xy, spp, seed, aovs, radiance, *rest)

    monkeypatch.setattr(api, "trace_pixels", counting)
    scene = mi.load_string(scene_xml(512, spp=16))
    result = mitsuba_mrt.render(scene)
    assert result.mode_used == "idpass" and id_passes == [512 * 512]
    assert not result.auto.notes and result.timings.trace_more > 0
    # the image is the mode's own, its id pass traced anew
    direct = mitsuba_mrt.render(scene, mode="idpass", denoise="oidn")
    assert id_passes == [512 * 512] * 2 and np.array_equal(result.image, direct.image)


def test_a_large_image_with_many_edges_between_ids_takes_the_passes(variant, monkeypatch):
    from mitsuba_mrt.renderer import api
    from mitsuba_mrt.types import SeedStream

    scene = mi.load_string(scene_xml(512, spp=16))
    monkeypatch.setattr(auto_plans, "WIDE_EDGE_SHARE", 0.0)  # the ball's outline is too much
    id_traces = []
    trace = api.trace_pixels

    def spy(scene, sensor, integrator, pixel_xy, spp, seed, aovs, radiance, *rest):
        if seed == SeedStream.ID_PASS:  # (with the albedo or without)
            id_traces.append(aovs and rest[4])
        return trace(scene, sensor, integrator, pixel_xy, spp, seed, aovs, radiance, *rest)

    monkeypatch.setattr(api, "trace_pixels", spy)
    # the ids, traced without the albedo (a ray a pixel and its shadow rays), tell
    # it, and no id pass is traced
    result = mitsuba_mrt.render(scene)
    assert result.mode_used == "full+oidn" and result.auto.passes
    assert any("of the pixels at an edge between ids" in n for n in result.auto.notes)
    assert result.timings.trace_more == 0 and id_traces == [False]


def test_an_id_pass_image_that_misses_its_check_gives_way_to_the_passes(variant, monkeypatch):
    monkeypatch.setattr(auto_plans, "CHECK_SLACK", -1.0)  # no estimate is kept
    result = mitsuba_mrt.render(mi.load_string(scene_xml(512, spp=16)))
    plan = result.auto
    # the passes are kept, not the MRT's plan (nor its time, for a time limit)
    (kept,) = kept_plans._plans.values()
    assert kept.choice.kind == "denoised" and kept.choice.spp == result.spp
    assert result.mode_used == "full+oidn" and plan.passes
    assert plan.reason.startswith("idpass+oidn missed its check (")
    assert [c.name for c in plan.candidates] == ["idpass+oidn"]
    assert plan.candidates[0].error is not None and np.isfinite(result.image).all()
    # the MRT's image and its check are counted as the plan's, within the total
    assert result.timings.trace + result.timings.check <= result.timings.total + 1e-9


def test_an_environment_map_takes_the_checked_refined_edges_a_small_image_the_passes(variant):
    from mitsuba_mrt.renderer.scene_query import environment_map

    sky = ROOT / "scenes_xml" / "gallery" / "envmaps" / "sky.exr"

    def lit(res):
        return mi.load_string(scene_xml(res, spp=32).replace(
            "</sensor>", f'</sensor><emitter type="envmap"><string name="filename" '
                         f'value="{sky}"/></emitter>'))
    constant = scene_xml(256, spp=16).replace(
        "</sensor>", '</sensor><emitter type="constant"/>')
    assert environment_map(lit(256))
    assert not environment_map(mi.load_string(constant))
    assert not environment_map(mi.load_string(scene_xml(256, spp=16)))
    result = mitsuba_mrt.render(lit(512))
    assert result.auto.reason == auto_plans.SKY_REASON and result.mode_used == "refine"
    assert result.params.denoise == "oidn" and result.auto.choice.error is not None
    assert result.auto.choice.label == "refine+oidn @ 32 spp"  # (the scene's grid and spp)
    assert auto_plans.unmeasured_plan(lit(256), 256 * 256) is None
    assert mitsuba_mrt.render(lit(256)).auto.passes


def test_no_noise_probe_where_the_integrator_samples_an_area_light(scene, monkeypatch):
    from mitsuba_mrt.renderer.scene_query import surely_noisy

    assert surely_noisy(scene, scene.integrator())  # (path, an area light)
    point_lit = mi.load_string(scene_xml(64).replace(AREA_LIGHT, POINT_LIGHT))
    matte = mi.load_string(scene_xml(64).replace(
        '<integrator type="path"><integer name="max_depth" value="4"/></integrator>',
        '<integrator type="matte"/>'))
    assert not surely_noisy(point_lit, point_lit.integrator())
    assert not surely_noisy(matte, matte.integrator())  # (it samples no light)

    def no_probe(*args):
        raise AssertionError("probed")
    monkeypatch.setattr(auto, "probe_noise", no_probe)
    assert mitsuba_mrt.render(scene).mode_used == "full+oidn"


def test_the_noise_probe_tells_a_noisy_scene(scene):
    from mitsuba_mrt.renderer.api import GridTracer
    from mitsuba_mrt.renderer.auto import NEARLY_EXACT, probe_noise

    sensor = scene.sensors()[0]
    tracer = GridTracer(scene, sensor, scene.integrator(), 1, 0)
    assert probe_noise(tracer, 512, 512) > NEARLY_EXACT


def test_a_nearly_noise_free_scene_is_rendered_in_full(variant):
    # one plane under one point light: only the jittered pixel positions differ
    # from sample to sample; the denoised passes took 1.35x the full render's
    # time at 37x its error (OIDN's own)
    from mitsuba_mrt.renderer.api import GridTracer
    from mitsuba_mrt.renderer.auto import NEARLY_EXACT, probe_noise

    scene = mitsuba_mrt.load_scene(SCENES / "paper_objects_0.xml", res=192, integrator="path",
                                   spp=64, jitter="true")
    sensor = scene.sensors()[0]
    noise = probe_noise(GridTracer(scene, sensor, scene.integrator(), 64, 0), 192, 192)
    assert 0 < noise < NEARLY_EXACT / 2
    result = mitsuba_mrt.render(scene)
    assert result.mode_used == "full" and result.auto.reason.startswith("nearly noise-free")
    assert result.auto.target_error == noise and result.timings.denoise == 0
    assert np.array_equal(result.image, mitsuba_mrt.render_reference(scene)[0])
    # the ball scene under a point light at 16 spp is noisier: the MRT's plan, as before
    noisier = mi.load_string(scene_xml(192, spp=16).replace(AREA_LIGHT, POINT_LIGHT))
    noise = probe_noise(GridTracer(noisier, noisier.sensors()[0], noisier.integrator(), 16, 0),
                        192, 192)
    assert noise > 2 * NEARLY_EXACT


def test_by_default_the_passes_meet_the_full_renders_noise(scene):
    result = mitsuba_mrt.render(scene)
    plan = result.auto
    assert result.mode_used == "full+oidn" and plan.reason.startswith("denoised passes")
    assert result.traced.full == 512 * 512 and result.timings.denoise > 0
    assert plan.passes and plan.choice.error <= plan.target_error
    truth = mitsuba_mrt.render_reference(scene, spp=128)[0]
    full = mitsuba_mrt.render_reference(scene)[0]
    assert np.mean((result.image - truth) ** 2) < np.mean((full - truth) ** 2)


def _rendered_unchosen(monkeypatch, *scenes) -> list:
    """Default renders of ``scenes``, in order, during which choosing a plan
    anew (the probes, the held-out check, the passes' estimates) fails the test."""
    from mitsuba_mrt.renderer import api, progressive

    def not_again(*args, **kwargs):
        raise AssertionError("the plan was chosen anew")
    with monkeypatch.context() as m:
        for module, name in ((auto, "probe_noise"), (auto, "mrt_by_kind"),
                             (progressive, "_estimate"), (api, "check_image")):
            m.setattr(module, name, not_again)
        return [mitsuba_mrt.render(scene) for scene in scenes]


def test_a_default_render_takes_the_plan_its_scene_s_earlier_render_kept(variant,
                                                                         monkeypatch):
    point_lit = mi.load_string(scene_xml(384, spp=16).replace(AREA_LIGHT, POINT_LIGHT))
    area_lit = mi.load_string(scene_xml(384, spp=16))
    first = {name: mitsuba_mrt.render(s) for name, s in (("mrt", point_lit),
                                                          ("passes", area_lit))}
    assert first["mrt"].auto.reason == auto_plans.HOME_REASON and first["passes"].auto.passes
    # (the MRT plan rendered twice: Dr.Jit records a layout's first two calls)
    _, passes, mrt = _rendered_unchosen(monkeypatch, point_lit, area_lit, point_lit)
    # the MRT plan: the same image (the same seed), unchecked, its replay's time kept
    assert mrt.auto.reason == auto.AGAIN_REASON.format(auto_plans.HOME_REASON)
    assert mrt.auto.choice.label == "idpass+oidn @ 16 spp" and mrt.timings.check == 0
    assert np.array_equal(mrt.image, first["mrt"].image)
    (kept,) = [k for k in kept_plans._plans.values() if k.choice.kind == "mrt"]
    assert kept.seconds[16][-1] == mrt.timings.total
    # the passes: their spp in one launch, at their preset, nothing estimated
    plan = passes.auto
    assert plan.reason == auto.AGAIN_REASON.format(first["passes"].auto.reason)
    assert passes.spp == first["passes"].spp and not plan.passes
    assert plan.choice.quality == first["passes"].auto.choice.quality
    # chosen anew under a time limit (the passes' plan is no MRT plan to scale),
    # a quality target, or at another spp
    for kwargs in ({"time_limit": 60.0}, {"noise_threshold": 0.5}, {"spp": 32}):
        assert not mitsuba_mrt.render(area_lit, **kwargs).auto.reason.endswith(
            auto.AGAIN_REASON.format(""))


def test_a_new_process_takes_the_default_plan_an_earlier_process_remembered(
        variant, tmp_path, monkeypatch):
    from mitsuba_mrt.renderer.state import clear_caches

    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(tmp_path / "memory.json"))
    point_lit = mi.load_string(scene_xml(384, spp=16).replace(AREA_LIGHT, POINT_LIGHT))
    area_lit = mi.load_string(scene_xml(384, spp=16))
    clear_caches()  # (a process that rendered nothing yet)
    first = {name: mitsuba_mrt.render(s) for name, s in (("mrt", point_lit),
                                                          ("passes", area_lit))}
    assert first["mrt"].auto.reason == auto_plans.HOME_REASON and first["passes"].auto.passes
    clear_caches()  # the next process: nothing kept, the plans remembered
    mrt, passes = _rendered_unchosen(monkeypatch, point_lit, area_lit)
    assert mrt.auto.reason == auto.RECALLED_REASON.format(auto_plans.HOME_REASON)
    assert np.array_equal(mrt.image, first["mrt"].image)  # (the same plan, the same seed)
    assert passes.auto.reason == auto.RECALLED_REASON.format(first["passes"].auto.reason)
    assert passes.spp == first["passes"].spp and not passes.auto.passes
    # a time limit does not scale a remembered MRT plan that this process has not timed
    (kept,) = [k for k in kept_plans._plans.values() if k.choice.kind == "mrt"]
    assert kept.recalled and kept.seconds == {}
    assert kept_plans.plan_within(next(k for k, v in kept_plans._plans.items() if v is kept),
                                  60.0, bakes=False) is None
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", "off")  # nothing remembered: chosen anew
    clear_caches()
    assert mitsuba_mrt.render(point_lit).auto.reason == auto_plans.HOME_REASON


def test_an_mrt_plan_runs_its_mode_with_its_denoising(scene, monkeypatch):
    forced(monkeypatch, Candidate("fast+oidn", "mrt", 8, mode="fast", denoise=True))
    result = mitsuba_mrt.render(scene)
    assert result.mode == "auto" and result.mode_used == "fast"
    assert result.params.denoise == "oidn" and result.timings.denoise > 0


def test_a_time_limit_below_one_pass_and_oidn_gives_a_preview(scene, monkeypatch):
    release()  # OIDN's cost unknown (its prior stands in), no pass traced yet
    monkeypatch.setattr(auto_limit, "_reconstruction_late", lambda *args: False)
    result = mitsuba_mrt.render(scene, time_limit=1e-6)
    plan = result.auto
    # OIDN would end past the limit even right after the grid: the preview goes without
    assert plan.reason == auto_limit.PREVIEW_REASON and plan.choice == auto_limit.UNDENOISED
    assert result.mode == "auto" and result.mode_used == "fast" and result.spp == 1
    assert result.params.denoise == "none" and result.timings.denoise == 0
    assert plan.time_limit == 1e-6 and plan.passes == []
    assert np.isfinite(result.image).all() and result.traced.grid > 0
    assert plan.notes[0] == auto_limit.UNDENOISED_NOTE
    # (the overrun's reason: a kernel compiled where Dr.Jit's disk cache lacked it)
    why = ("which Dr.Jit keeps on disk for later renders" if result.timings.compile.compiled
           else "the time limit of 1e-06 s: the preview is the least this image costs here")
    assert plan.notes[-1].endswith(why)
    # the grid that told the plan is the preview's own: the image is the mode's
    direct = mitsuba_mrt.render(scene, mode="fast", spp=1, denoise="none")
    assert np.array_equal(result.image, direct.image)


def test_a_preview_whose_reconstruction_would_overrun_is_the_grid_upsampled(scene,
                                                                            monkeypatch):
    release()
    monkeypatch.setattr(auto_limit, "_preview_rate", [])
    result = mitsuba_mrt.render(scene, time_limit=1e-6)
    plan = result.auto
    assert plan.choice == auto_limit.UPSAMPLED and result.mode_used == "bicubic"
    assert plan.notes[:2] == [auto_limit.UNDENOISED_NOTE, auto_limit.UPSAMPLED_NOTE]
    assert plan.notes[-1].endswith("the preview is the least this image costs here")
    assert auto_limit._preview_rate == []  # (not a rate for the next fast preview)
    # the grid that told the plan is the upsampling's own: the image is the mode's
    direct = mitsuba_mrt.render(scene, mode="bicubic", spp=1, denoise="none")
    assert np.array_equal(result.image, direct.image)


def test_a_preview_s_reconstruction_is_expected_to_take_longer_where_ids_have_more_edges():
    pattern = grid_pattern(256, 256, 0.1)
    one = np.zeros(pattern.count, dtype=np.int64)  # one region: no edge
    rows, cols = np.indices(pattern.grid_shape)
    checker = ((rows + cols) % 2).ravel()  # every sample on an edge
    pixels = 256 * 256
    for ids, per_pixel in ((one, auto_limit.RECONSTRUCTION_PER_PIXEL),
                           (checker, auto_limit.RECONSTRUCTION_PER_PIXEL
                            + auto_limit.RECONSTRUCTION_PER_EDGE)):
        expected = per_pixel * pixels
        assert not auto_limit._reconstruction_late(1.01 * expected, pattern, ids, now=0.0)
        assert auto_limit._reconstruction_late(0.99 * expected, pattern, ids, now=0.0)


def test_a_preview_is_denoised_where_the_limit_leaves_oidn_room(scene, monkeypatch):
    monkeypatch.setattr(auto_limit, "_preview_due", lambda *args: True)
    monkeypatch.setattr(auto_limit, "UNPROBED_OVER_OIDN", 1e6)  # (the preview is asked)
    result = mitsuba_mrt.render(scene, time_limit=10.0)
    assert result.auto.choice.name == auto_limit.PREVIEW.name and result.params.denoise == "oidn"
    assert auto_limit.UNDENOISED_NOTE not in result.auto.notes and result.timings.denoise > 0


def test_a_time_limit_alone_estimates_nothing_and_ends_after_the_first_pass(scene,
                                                                            monkeypatch):
    # without the preview (which a limit this small gets) the first pass is denoised
    monkeypatch.setattr(auto_limit, "_preview_due", lambda *args: False)
    release()  # OIDN's cost unknown: the last call is expected to take its prior
    # no launch measured before: the first is the least, 1 spp (where earlier
    # renders replayed a larger launch, it may cost less than recording 1 spp)
    monkeypatch.setattr(auto_limit, "_launch_costs", {})
    result = mitsuba_mrt.render(scene, time_limit=1e-6)
    plan = result.auto
    assert plan.reason == "denoised passes: the time limit" and result.spp == 1
    assert plan.time_limit == 1e-6 and plan.target_error is None and plan.passes == []
    assert plan.choice.error is None and result.timings.check == 0.0


def test_a_time_limit_plans_from_earlier_passes_launches_not_a_new_probe(scene, monkeypatch):
    monkeypatch.setattr(auto_limit, "_launch_costs", {})  # (not earlier tests' launches)
    first = mitsuba_mrt.render(scene, time_limit=10.0)  # passes: their launches are kept
    assert first.auto.choice.kind == "denoised"
    # (its one launch, sized by the probe, recorded its kernels; this one replays them)
    assert mitsuba_mrt.render(scene, time_limit=10.0).auto.choice.kind == "denoised"
    monkeypatch.setattr(auto_limit, "_first_round_s", {})  # no first round's time to go by

    def probe(*args):
        raise AssertionError("the grid was probed")
    monkeypatch.setattr(auto_limit, "_grid_probe", probe)
    again = mitsuba_mrt.render(scene, time_limit=10.0)
    assert again.auto.choice.kind == "denoised"


def test_a_first_time_limit_sizes_its_first_launch_by_the_grid_probe(scene, monkeypatch):
    monkeypatch.setattr(auto_limit, "_launch_costs", {})  # (no launches to plan from)
    monkeypatch.setattr(auto_limit, "_first_round_s", {})
    # (a limit that leaves a pass and OIDN less than the unprobed share)
    monkeypatch.setattr(auto_limit, "UNPROBED_OVER_OIDN", 1e6)
    assert mitsuba_mrt.render(scene, time_limit=10.0).auto.choice.kind == "denoised"
    (cost,) = auto_limit._launch_costs.values()
    assert cost.prior is not None and cost.launches[0].spp > 1  # (not a 1-spp launch first)


def test_a_first_time_limit_far_above_oidn_is_not_probed(scene, monkeypatch):
    monkeypatch.setattr(auto_limit, "_launch_costs", {})
    monkeypatch.setattr(auto_limit, "_first_round_s", {})
    monkeypatch.setattr(auto_limit, "unmeasured_plan", lambda *args: None)  # (no MRT plan)

    def probe(*args):
        raise AssertionError("the grid was probed")
    monkeypatch.setattr(auto_limit, "_grid_probe", probe)
    assert mitsuba_mrt.render(scene, time_limit=10.0).auto.choice.kind == "denoised"
    (cost,) = auto_limit._launch_costs.values()
    assert cost.prior is None and cost.launches[0].spp == launch_cost.UNMEASURED_FIRST
    pixels = scene.sensors()[0].film().crop_size()
    assert not auto_limit._passes_fit_unprobed(
        1e-3, int(pixels[0] * pixels[1]), "fast")  # (a short limit asks the probe)


def test_a_new_process_plans_a_time_limit_from_what_an_earlier_one_remembered(
        scene, tmp_path, monkeypatch):
    from mitsuba_mrt.renderer.state import clear_caches

    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(tmp_path / "memory.json"))
    monkeypatch.setattr(auto_limit, "UNPROBED_OVER_OIDN", 1e6)  # (the limit asks the probe)
    monkeypatch.setattr(auto_limit, "unmeasured_plan", lambda *args: None)  # (no MRT plan)
    clear_caches()  # (a process that rendered nothing yet)
    first = mitsuba_mrt.render(scene, time_limit=10.0)
    assert first.auto.choice.kind == "denoised"
    (remembered,) = (cost.launches for cost in auto_limit._launch_costs.values())
    clear_caches()  # the next process: its own launches none, its probe not needed

    def probe(*args):
        raise AssertionError("the grid was probed")
    monkeypatch.setattr(auto_limit, "_grid_probe", probe)
    again = mitsuba_mrt.render(scene, time_limit=10.0)
    assert again.auto.choice.kind == "denoised"
    (cost,) = auto_limit._launch_costs.values()  # (the objects' token is new: their key too)
    recalled = [launch for launch in cost.launches if launch.elsewhere]
    assert [launch[:6] for launch in recalled] == [launch[:6] for launch in remembered]
    here = [launch for launch in cost.launches if not launch.elsewhere]
    assert here[0].recorded and here[0].first  # (this process's first launch records anew)
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", "off")  # nothing recalled: the probe is asked
    clear_caches()
    with pytest.raises(AssertionError, match="probed"):
        mitsuba_mrt.render(scene, time_limit=10.0)


def test_a_scene_s_launches_are_written_again_only_where_later_processes_lack_something(
        tmp_path, monkeypatch):
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(tmp_path / "memory.json"))
    monkeypatch.setattr(auto_limit, "_memory_key", lambda key, tracer: "scene")
    written = []
    monkeypatch.setattr(auto_limit.memory, "remember", lambda key, value: written.append(value))
    cost = launch_cost.LaunchCost()
    monkeypatch.setattr(auto_limit, "_launch_costs", {"key": cost})

    def launch(spp, recorded=False):
        cost.add(spp, 0.01 * spp, recorded=recorded)
        auto_limit.remember_launches("key", None)
    launch(8, recorded=True)
    launch(8)  # (its first replay: a kind the memory lacks)
    assert len(written) == 2
    for _ in range(launch_cost.KEPT_LAUNCHES - 1):  # the same again: nothing new
        launch(8)
    assert len(written) == 2
    launch(8)  # (as many launches as are kept since: their window moved on)
    launch(4)  # (a new spp)
    assert len(written) == 4 and written[-1]["launches"][-1][0] == 4


def test_a_grid_probe_is_remembered_where_it_compiled_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(tmp_path / "memory.json"))
    monkeypatch.setattr(auto_limit, "_memory_key", lambda key, tracer: "scene")
    probe = auto_limit._Probe(None, 0.1, 0.02, 0.01, recorded=True, compile=0.0, first=True)
    assert auto_limit._recalled_probe(("token", 4), None) is None
    auto_limit._remember_probe(("token", 4), None, probe, 10)
    assert auto_limit._recalled_probe(("token", 4), None) == 0.02
    # (a probe that compiled ran its kernels late: its run time is not kept)
    auto_limit._remember_probe(("token", 4), None, probe._replace(execute=0.5, compile=0.3), 10)
    assert auto_limit._recalled_probe(("token", 4), None) == 0.02
    # as this process's first probe would be: its time beyond the kernels, a
    # pass's guess scaled from its 10 pixels to the image's 100
    pattern = grid_pattern(10, 10, 0.1)
    line = auto_limit._recalled_line(("token", 4), None, pattern)
    assert line.grid is None and line.recorded and line.host == 0.01
    assert line.pass_s == pytest.approx(0.01 + auto_limit.PASS_OVER_GRID * 0.02 * 10)
    # a probe after other recordings lacks the first uses a fresh process pays
    auto_limit._remember_probe(("token", 4), None, probe._replace(first=False), 10)
    assert auto_limit._recalled_probe(("token", 4), None) == 0.02
    assert auto_limit._recalled_line(("token", 4), None, pattern) is None
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", "off")
    assert auto_limit._recalled_probe(("token", 4), None) is None


def test_a_new_process_takes_the_probe_an_earlier_one_remembered_and_traces_none(
        scene, tmp_path, monkeypatch):
    from mitsuba_mrt.renderer.state import clear_caches

    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(tmp_path / "memory.json"))
    monkeypatch.setattr(auto_limit, "UNPROBED_OVER_OIDN", 1e6)  # (the limit asks the probe)
    monkeypatch.setattr(auto_limit, "unmeasured_plan", lambda *args: None)  # (no MRT plan)
    monkeypatch.setattr(auto_limit, "_preview_due", lambda *args, **kw: True)  # (previews)
    clear_caches()
    first = mitsuba_mrt.render(scene, time_limit=10.0)
    assert first.auto.choice.name.startswith("fast")  # (a preview: no launch of the passes)
    clear_caches()  # the next process: the probe's line recalled, its grid traced once

    def probe(*args):
        raise AssertionError("the grid was probed")
    monkeypatch.setattr(auto_limit, "_grid_probe", probe)
    again = mitsuba_mrt.render(scene, time_limit=10.0)
    assert again.auto.choice.name == first.auto.choice.name
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", "off")  # nothing recalled: the probe is asked
    clear_caches()
    with pytest.raises(AssertionError, match="probed"):
        mitsuba_mrt.render(scene, time_limit=10.0)


def test_a_remembered_cost_is_taken_only_whole_and_of_the_same_kind_of_sampler():
    good = {"spp_compiles": False, "launches": [[2, 0.06, True, 0.03, True, 0.02],
                                                [8, 0.12, False, 0.1, False, None]]}
    cost = launch_cost.LaunchCost.from_memory(good, spp_compiles=False)
    assert cost.recalled and not cost.launched_here and cost.replayed
    assert cost.memory() == good  # (what a later process keeps again)
    # the first launch here records anew: at what the earlier first launch took
    # beyond the line (its recording and first uses, at least its recording)
    fixed, per_spp = cost._line()
    assert cost.record_s == pytest.approx(max(0.06 - fixed - 2 * per_spp, 0.02))
    assert cost(2) == pytest.approx(0.06)  # (what that launch took)
    assert cost(8) == pytest.approx(0.12 + cost.record_s)
    cost.add(4, 0.07, recorded=True, recording_s=0.01)
    assert cost.launched_here and cost.launches[-1].first and not cost.launches[-1].elsewhere
    assert cost.record_s == pytest.approx(0.01)  # (now this process's own recording)
    fixed, per_spp = cost._line()  # (a 16-spp launch replays the class recorded here)
    assert cost(16) == pytest.approx(fixed + 16 * per_spp)
    # a sampler that bakes its spp: the spp launched elsewhere are on disk; 1 spp,
    # a process's measuring first launch, stays open until this process launches
    baked = launch_cost.LaunchCost.from_memory(
        {"spp_compiles": True, "launches": [[9, 0.4, True, 0.26, True, 0.1],
                                            [9, 0.3, False, 0.29, False, None]]},
        spp_compiles=True)
    assert baked.cheapest() == 1 and baked(4) == math.inf and baked(9) < math.inf
    assert baked.first(baked(9)) == 9
    baked.add(9, 0.45, recorded=True, recording_s=0.1)
    assert baked(1) == math.inf and baked.cheapest() == 9
    for bad in (None, {}, {"spp_compiles": True, "launches": good["launches"]},
                {"spp_compiles": False, "launches": []},
                {"spp_compiles": False, "launches": [[0, 0.1, False, None, False, None]]},
                {"spp_compiles": False, "launches": [[1, -1.0, False, None, False, None]]},
                {"spp_compiles": False, "launches": [[1, "x", False, None, False, None]]},
                {"spp_compiles": False, "launches": [[1, 0.1, False]]},
                {"spp_compiles": False, "launches": [[1, float("nan"), False, None, False, None]]}):
        assert launch_cost.LaunchCost.from_memory(bad, spp_compiles=False) is None


def test_a_slow_first_round_gives_one_preview_not_previews_for_good(scene, monkeypatch):
    monkeypatch.setattr(auto_limit, "_launch_costs", {})
    monkeypatch.setattr(auto_limit, "_first_round_s", {})
    # passes: their launches are kept
    assert mitsuba_mrt.render(scene, time_limit=10.0).auto.choice.kind == "denoised"
    (key,) = auto_limit._launch_costs
    auto_limit._first_round_s[key] = 1e3  # a first round that took far longer than the limit
    slow = mitsuba_mrt.render(scene, time_limit=10.0)
    assert slow.auto.reason == auto_limit.PREVIEW_REASON and key not in auto_limit._first_round_s
    # a preview traces no round: the next render plans from the passes' launches
    again = mitsuba_mrt.render(scene, time_limit=10.0)
    assert again.auto.choice.kind == "denoised"


def test_under_a_time_limit_textures_go_unshaded_where_only_plain_oidn_fits(monkeypatch):
    # denoising textured surfaces as their shading adds SHADING_EXTRA to OIDN's
    # expected time: where that alone would end past the limit, the passes
    # denoise plainly (no surfaces looked up) rather than take the preview
    monkeypatch.setattr(auto_limit, "expected_seconds", lambda pixels, quality: 0.1)
    monkeypatch.setattr(auto_limit, "_launch_costs", {})
    monkeypatch.setattr(auto_limit, "textured_diffuse_shapes",
                        lambda scene: np.array([False, True]))
    assert not auto_limit._preview_due(1.0, 0.88, 100, "fast")
    assert auto_limit._preview_due(1.0, 0.88, 100, "fast", shading=True)
    key = ("scene", 100)
    tracer = SimpleNamespace(sensor=SimpleNamespace(sampler=lambda: "IndependentSampler[]",
                                                    film=box_film),
                             pass_recorded=lambda spp, *_: False)
    pattern = SimpleNamespace(width=10, height=10)
    params = MRTParams(time_limit=1.0)
    started = __import__("time").perf_counter()
    outcomes = {}
    for first_s in (0.5, 0.95, 1.05):  # the last first round ended this long after the start
        monkeypatch.setattr(auto_limit, "_first_round_s", {key: first_s})
        outcome, surfaces, found = auto_limit.preview_first(None, pattern, tracer, params,
                                                            started, key, [])
        outcomes[first_s] = (outcome is not None, surfaces, found)
    # (plain OIDN against PREVIEW_SLACK times the limit, 1.1 s; the shading,
    # which may go, against the limit itself)
    assert outcomes[0.5] == (False, None, False)  # shading fits: the passes look the surfaces up
    assert outcomes[0.95] == (False, None, True)  # plain OIDN alone fits
    assert outcomes[1.05][0]  # nothing fits: the preview


def test_a_replayed_probe_counts_the_passes_first_recording_until_they_have_launched(
        monkeypatch):
    monkeypatch.setattr(auto_limit, "_launch_costs", {})
    monkeypatch.setattr(auto_limit, "_probe_recording_s", {})

    def probe(recorded, host, compile=0.0):
        return auto_limit._Probe(None, host + 0.01, 0.005, host, recorded, compile)
    key = ("scene", "sensor", "integrator", 256 * 256)
    # a recording probe's own time holds a recording: nothing to add, its time is kept
    assert auto_limit._passes_recording_s(key, probe(True, 0.030)) == 0.0
    # a replayed probe's does not: the passes' first launch adds what recording took more
    assert auto_limit._passes_recording_s(key, probe(False, 0.004)) == pytest.approx(0.026)
    assert auto_limit._passes_recording_s(("other",) + key[1:], probe(False, 0.004)) == 0.0
    # a recording that compiled a kernel keeps its time less the compilation
    assert auto_limit._passes_recording_s(key, probe(True, 0.330, compile=0.300)) == 0.0
    assert auto_limit._passes_recording_s(key, probe(False, 0.004)) == pytest.approx(0.026)
    tracer = SimpleNamespace(sensor=SimpleNamespace(sampler=lambda: "IndependentSampler[]",
                                                    film=box_film),
                             pass_recorded=lambda spp, *_: False)
    auto_limit.kept_cost(key, tracer).add(1, 0.02, recorded=True)
    assert auto_limit._passes_recording_s(key, probe(False, 0.004)) == 0.0  # (they replay now)
    # another trace (a full render denoised at 1 spp) recorded the passes' first launch
    other = ("scene 2",) + key[1:]
    assert auto_limit._passes_recording_s(other, probe(True, 0.030)) == 0.0
    assert auto_limit._passes_recording_s(other, probe(False, 0.004)) == pytest.approx(0.026)
    recorded = SimpleNamespace(sensor=tracer.sensor, pass_recorded=lambda spp, *_: spp == 1)
    auto_limit.kept_cost(other, recorded)
    assert auto_limit._passes_recording_s(other, probe(False, 0.004)) == 0.0


def test_the_passes_last_oidn_call_takes_the_preset_asked_for_or_the_one_that_pays(scene):
    chosen = mitsuba_mrt.render(scene).auto.choice
    assert chosen.kind == "denoised" and chosen.quality in ("fast", "high")
    assert chosen.label.endswith(f", OIDN {chosen.quality}")
    asked = mitsuba_mrt.render(scene, denoise_quality="balanced").auto.choice
    assert asked.quality == "balanced"


def test_high_pays_where_its_extra_time_is_small_beside_the_passes():
    from mitsuba_mrt.renderer.progressive import HIGH_COST, HIGH_GAIN, final_quality

    fast_s, rate = 0.1, 0.2
    # more passes for high's extra time take exactly HIGH_GAIN off: the tie
    tie = (HIGH_COST - 1) * fast_s / (HIGH_GAIN ** (-1 / rate) - 1)
    assert final_quality(1.01 * tie, fast_s, rate) == "high"
    assert final_quality(0.99 * tie, fast_s, rate) == "fast"
    assert final_quality(10.0, fast_s, rate, high_s=0.1) == "high"  # (no extra time)
    assert final_quality(10.0, 0.0, rate) == "fast"  # OIDN's cost unknown


def test_before_any_high_call_high_is_weighed_by_fasts_measured_call(variant):
    from mitsuba_mrt.recon import denoise
    from mitsuba_mrt.renderer.progressive import Progress, _final_preset

    denoise.release()  # (no call at any preset measured)
    pixels, fast_s = 4096 * 4096, 0.01  # high's prior: seconds; HIGH_COST times fast's: 0.019
    assert _final_preset("auto", Progress(), 1.0, fast_s, None, pixels) == "high"
    # under a time limit the prior's margin is kept
    assert _final_preset("auto", Progress(), 1.0, fast_s, 100.0, pixels) == "fast"
    assert _final_preset("balanced", Progress(), 1.0, fast_s, None, pixels) == "balanced"


def test_textured_diffuse_surfaces_are_denoised_as_their_shading(variant):
    from mitsuba_mrt.renderer.scene_query import ordered_shapes, textured_diffuse_shapes

    textured_scene = mitsuba_mrt.load_scene(ROOT / "scenes_xml/gallery/spot_textures.xml",
                                            res=192, spp=64)  # (enough for a plan)
    flags = textured_diffuse_shapes(textured_scene)
    names = [shape.id() for shape in ordered_shapes(textured_scene)]
    assert dict(zip(names, flags[1:].tolist())) == {
        "globe": True, "crate": True, "back_wall": False, "floor": True}
    result = mitsuba_mrt.render(textured_scene)
    assert result.auto.choice.shading and result.auto.choice.label.endswith("textures as shading")
    assert np.isfinite(result.image).all()
    plain = mitsuba_mrt.load_scene(ROOT / "scenes_xml/gallery/cornell.xml", res=192, spp=64)
    assert not textured_diffuse_shapes(plain).any()
    assert not mitsuba_mrt.render(plain, noise_threshold=0.05).auto.choice.shading


def test_passes_of_at_most_two_spp_multiply_their_shading_by_the_albedo_denoised(variant):
    from mitsuba_mrt.modes.plan import Candidate
    from mitsuba_mrt.recon.denoise import CLEAN_TEXTURE_SPP
    from mitsuba_mrt.renderer import progressive
    from mitsuba_mrt.renderer.api import GridTracer
    from mitsuba_mrt.renderer.auto_plans import find_surfaces
    from mitsuba_mrt.renderer.scene import unwrap

    scene = mitsuba_mrt.load_scene(ROOT / "scenes_xml/gallery/spot_textures.xml", res=64)
    sensor = scene.sensors()[0]
    tracer = GridTracer(scene, sensor, unwrap(scene, None).nested, 64, 0)
    surfaces = find_surfaces(scene, tracer, 64, 64)
    cleaned = {}
    for spp in (CLEAN_TEXTURE_SPP, CLEAN_TEXTURE_SPP + 1):
        image, _, progress = progressive.run_passes(
            tracer, 64, 64, quality="fast", target_error=None, deadline=None, max_spp=spp,
            full_spp=64, area=1.0, surfaces=surfaces, fixed=True)
        assert progress.shading and np.isfinite(image).all()
        cleaned[spp] = progress.clean_texture
    assert cleaned == {CLEAN_TEXTURE_SPP: True, CLEAN_TEXTURE_SPP + 1: False}
    label = Candidate("full+oidn", "denoised", 2, shading=True, clean_texture=True).label
    assert label == "full+oidn @ 2 spp, textures as shading (texture denoised)"


def test_the_grid_marks_as_textured_only_pixels_of_surfaces_with_a_texture(variant,
                                                                           monkeypatch):
    # a plain surface's edge pixels mix two albedos; marked, their shading would
    # go through the grid's one OIDN call beside the others' radiance
    from mitsuba_mrt.recon.sampling import grid_pattern
    from mitsuba_mrt.renderer import pipeline
    from mitsuba_mrt.renderer.scene_query import ordered_shapes
    from mitsuba_mrt.types import SparseTrace

    marked = []
    monkeypatch.setattr(pipeline, "denoise_grid",
                        lambda radiance, *a, textured=None, **k: marked.append(textured) or radiance)
    params = MRTParams(denoise="oidn")
    for name, shape in (("cornell", "cbox_white"), ("spot_textures", "floor")):
        scene = mitsuba_mrt.load_scene(ROOT / f"scenes_xml/gallery/{name}.xml", res=64)
        index = 1 + [s.id() for s in ordered_shapes(scene)].index(shape)
        pattern = grid_pattern(64, 64, 0.25)
        n = pattern.count
        albedo = np.repeat(np.where(np.arange(n) % 2, 0.05, 0.8)[:, None], 3, axis=1)
        trace = SparseTrace(radiance=albedo.copy(), albedo=albedo,
                            shape_index=np.full(n, index, dtype=np.int64),
                            visible_lights=np.zeros(n, np.uint32), num_lights=0, spp=4,
                            seconds=0.0, shadow_rays=False)
        pipeline.denoise_stage(scene, pattern, trace, params)
    plain, textured = marked
    assert not plain.any() and textured.all()


def test_the_grid_is_denoised_at_high_unless_a_preset_is_named_and_a_preview_s_at_fast(
        variant, monkeypatch):
    # the grid holds a tenth of the pixels: high's call costs little of the render,
    # while a preview's time was planned at fast's
    from mitsuba_mrt.renderer import pipeline
    from mitsuba_mrt.types import SparseTrace

    presets = []
    monkeypatch.setattr(pipeline, "denoise_grid",
                        lambda radiance, *a, **k: presets.append(a[3]) or radiance)
    scene = mitsuba_mrt.load_scene(ROOT / "scenes_xml/gallery/cornell.xml", res=32)
    pattern = grid_pattern(32, 32, 0.25)
    n = pattern.count
    trace = SparseTrace(radiance=np.ones((n, 3)), albedo=np.ones((n, 3)),
                        shape_index=np.ones(n, dtype=np.int64),
                        visible_lights=np.zeros(n, np.uint32), num_lights=0, spp=4,
                        seconds=0.0, shadow_rays=False)
    auto_params = MRTParams(denoise="oidn")
    for params in (auto_params, auto_params.with_(denoise_quality="fast"),
                   auto_limit.preview_params(auto_params),
                   auto_limit.preview_params(auto_params.with_(denoise_quality="balanced"))):
        pipeline.denoise_stage(scene, pattern, trace, params)
    assert presets == ["high", "fast", auto_limit.PREVIEW_QUALITY, "balanced"]
    assert auto_limit.PREVIEW_QUALITY == "fast"


def test_a_small_textured_image_takes_the_id_pass_unless_a_surface_transmits_light(variant):
    from mitsuba_mrt.renderer.scene_query import transmits

    gallery = ROOT / "scenes_xml/gallery"
    checker = mitsuba_mrt.load_scene(gallery / "checker_border.xml", res=256, spp=32)
    assert not transmits(checker)
    assert auto_plans.unmeasured_plan(checker, 256 * 256) == (auto_plans.HOME,
                                                              auto_plans.TEXTURED_REASON)
    # few edges between ids (the border's), and the check keeps the image
    result = mitsuba_mrt.render(checker)
    assert result.mode_used == "idpass" and result.auto.reason == auto_plans.TEXTURED_REASON
    assert result.auto.choice.label == "idpass+oidn @ 16 spp, grid of 20 % of the pixels"
    assert not result.auto.notes and np.isfinite(result.image).all()
    # below 512 x 512 the grid is twice as dense, at half the spp, and the kept
    # plan keeps its grid (idpass on a textured image varies run to run: no digest)
    assert result.spp == 16 and result.traced.grid == grid_pattern(256, 256, 0.2).count
    again = mitsuba_mrt.render(checker)
    assert again.auto.passes == [] and again.auto.choice.fraction == 0.2
    assert again.spp == 16 and again.traced.grid == result.traced.grid
    # the room's glass shows what lies behind it, which no id tells apart
    room = mitsuba_mrt.load_scene(gallery / "room.xml", res=128)
    assert transmits(room) and auto_plans.unmeasured_plan(room, 128 * 128) is None
    # nor at 512 x 512
    assert auto_plans.unmeasured_plan(room, 512 * 512) is None


def test_a_small_textured_image_with_many_edges_between_ids_takes_the_passes(variant,
                                                                          monkeypatch):
    checker = mitsuba_mrt.load_scene(ROOT / "scenes_xml/gallery/checker_border.xml", res=256,
                                     spp=32)
    monkeypatch.setattr(auto_plans, "WIDE_EDGE_SHARE", 0.0)  # (not the small images' share)
    assert mitsuba_mrt.render(checker).mode_used == "idpass"
    kept_plans.clear()
    monkeypatch.setattr(auto_plans, "SMALL_EDGE_SHARE", 0.0)
    result = mitsuba_mrt.render(checker)
    assert result.mode_used == "full+oidn" and result.auto.passes
    assert any("of the pixels at an edge between ids" in n for n in result.auto.notes)


def test_an_image_with_glass_and_no_environment_map_takes_the_passes(variant):
    from mitsuba_mrt.renderer.scene_query import has_mirrors, textured_diffuse_shapes, transmits

    gallery = ROOT / "scenes_xml/gallery"
    box = mitsuba_mrt.load_scene(gallery / "cornell.xml", res=192, spp=64)
    assert has_mirrors(box) and transmits(box) and not textured_diffuse_shapes(box).any()
    assert auto_plans.unmeasured_plan(box, 192 * 192) is None
    # at 512 x 512 too: its glass shows the scene behind it, which no id tells apart
    assert auto_plans.unmeasured_plan(box, 512 * 512) is None
    # neither mirrors nor glass: the passes too
    plain = mitsuba_mrt.load_scene(gallery / "instanced.xml", res=64)
    assert not (has_mirrors(plain) or transmits(plain))
    assert auto_plans.unmeasured_plan(plain, 64 * 64) is None


def test_a_time_limit_is_filled_with_passes(scene):
    quick = mitsuba_mrt.render(scene, time_limit=1e-6)
    longer = mitsuba_mrt.render(scene, time_limit=50 * quick.timings.total)
    assert longer.spp > quick.spp and longer.spp <= 4 * 8


def test_without_oidn_auto_renders_in_full_or_in_plain_passes(scene, monkeypatch):
    monkeypatch.setattr(auto, "oidn_available", lambda: False)
    result = mitsuba_mrt.render(scene)  # (8 spp: too few for the MRT's plan)
    assert result.mode_used == "full" and "no denoiser" in result.auto.reason
    assert any("Open Image Denoise is not installed" in note for note in result.auto.notes)
    assert np.array_equal(result.image, mitsuba_mrt.render_reference(scene)[0])
    limited = mitsuba_mrt.render(scene, time_limit=1e-6)
    assert limited.mode_used == "passes" and limited.timings.denoise == 0


def test_without_oidn_the_default_is_the_checked_id_pass_where_nothing_transmits(variant):
    from mitsuba_mrt.recon.denoise import hidden

    scene = mi.load_string(scene_xml(384, spp=16))
    with hidden():
        result = mitsuba_mrt.render(scene)
    plan = result.auto
    assert result.mode_used == "idpass" and result.params.denoise == "none"
    assert plan.choice.label == "idpass @ 16 spp" and plan.reason == auto_plans.PLAIN_REASON
    assert plan.choice.error is not None and plan.target_error is not None  # (its check)
    assert plan.choice.error <= auto_plans.CHECK_SLACK * plan.target_error
    assert any("Open Image Denoise is not installed" in note for note in plan.notes)
    truth = mitsuba_mrt.render_reference(scene, spp=256)[0]
    full = mitsuba_mrt.render_reference(scene, spp=4)[0]  # (a quarter of the samples)
    assert np.mean(np.abs(result.image - truth)) < np.mean(np.abs(full - truth))
    # kept: the next render without OIDN takes it unchecked, one with OIDN plans anew
    (kept,) = kept_plans._plans.values()
    assert kept.choice.label == "idpass @ 16 spp"
    with hidden():
        again = mitsuba_mrt.render(scene)
    assert again.mode_used == "idpass" and again.auto.reason == auto.AGAIN_REASON.format(
        auto_plans.PLAIN_REASON) and again.timings.check == 0
    assert mitsuba_mrt.render(scene).auto.choice.denoise


def test_without_oidn_glass_takes_refine_and_a_missed_check_the_full_render_for_good(
        variant, tmp_path, monkeypatch):
    from mitsuba_mrt.recon.denoise import hidden
    from mitsuba_mrt.renderer.state import clear_caches

    glass = mi.load_string(scene_xml(384, spp=16).replace(
        '<bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.2, 0.2"/></bsdf>',
        '<bsdf type="dielectric"/>'))
    with hidden():
        result = mitsuba_mrt.render(glass)
    assert (result.mode_used == "refine"
            and result.auto.reason == auto_plans.PLAIN_EDGES_REASON) or (
        result.mode_used == "full" and result.auto.reason.startswith("refine missed its check"))
    monkeypatch.setattr(auto_plans, "CHECK_SLACK", -1.0)  # no estimate is kept
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(tmp_path / "memory.json"))
    scene = mi.load_string(scene_xml(384, spp=16))
    with hidden():
        missed = mitsuba_mrt.render(scene)
        again = mitsuba_mrt.render(scene)
        clear_caches()  # (the next process: the full render remembered)
        recalled = mitsuba_mrt.render(scene)
    assert missed.mode_used == "full" and missed.auto.reason.startswith("idpass missed its check")
    assert [c.name for c in missed.auto.candidates] == ["idpass"]
    reference = mitsuba_mrt.render_reference(scene)[0]
    assert np.array_equal(missed.image, reference)
    # the MRT's image and its check are counted as the plan's, within the total
    assert 0 < missed.timings.check and missed.timings.full_render > 0
    assert missed.timings.check + missed.timings.full_render <= missed.timings.total + 1e-9
    # the next render takes the full render at once: no MRT image, no check
    assert again.mode_used == "full" and again.auto.reason == auto.AGAIN_REASON.format(
        missed.auto.reason)
    assert again.timings.check == 0 and np.array_equal(again.image, reference)
    assert recalled.auto.reason == auto.RECALLED_REASON.format(missed.auto.reason)
    assert recalled.timings.check == 0 and np.array_equal(recalled.image, reference)


def test_without_oidn_a_time_limit_takes_the_id_pass_where_it_fits(variant):
    from mitsuba_mrt.recon.denoise import hidden

    scene = mi.load_string(scene_xml(384, spp=16))
    with hidden():
        mitsuba_mrt.render(scene, time_limit=100.0)  # (its traces recorded, as a user's next)
        result = mitsuba_mrt.render(scene, time_limit=100.0)
        short = mitsuba_mrt.render(scene, time_limit=1e-6)
    assert result.mode_used == "idpass" and result.params.denoise == "none"
    assert result.auto.reason == auto_limit.WITHIN_REASON.format(auto_plans.PLAIN_REASON)
    assert short.mode_used == "passes" and short.timings.denoise == 0


def test_without_oidn_a_first_render_under_the_plain_floor_traces_no_probe(variant,
                                                                             monkeypatch):
    from mitsuba_mrt.recon.denoise import hidden

    probes = []
    real = auto_limit._grid_probe
    monkeypatch.setattr(auto_limit, "_grid_probe",
                        lambda *args: probes.append(1) or real(*args))
    monkeypatch.setattr(auto_limit, "PLAIN_FLOOR", (100.0, 0.0))  # (any limit is under it)
    scene = mi.load_string(scene_xml(96, spp=16))
    with hidden():
        first = mitsuba_mrt.render(scene, time_limit=5.0)
        assert first.mode_used == "passes" and probes == []  # the passes at once
        # the scene traced in this process, its first uses paid: the next render may probe
        mitsuba_mrt.render(scene, time_limit=5.0)
        assert probes == [1]
        monkeypatch.setattr(auto_limit, "PLAIN_FLOOR", (0.0, 0.0))  # (above it: probed)
        mitsuba_mrt.render(mi.load_string(scene_xml(96, spp=16)), time_limit=5.0)
    assert probes == [1, 1]


def test_undenoised_passes_are_developed_through_the_film_s_filter(variant, monkeypatch):
    from mitsuba_mrt.recon.denoise import hidden
    from mitsuba_mrt.renderer import progressive
    from mitsuba_mrt.renderer.pixel_filter import pixel_weights

    scene = mi.load_string(scene_xml(48, spp=4, rfilter="gaussian"))
    weights = pixel_weights(scene.sensors()[0].film().rfilter())
    assert len(weights) == 5 and weights[2] > weights[1] > weights[0] > 0  # (reach 2)
    seen, real = [], progressive.through_filter

    def spy(image, w):
        seen.append(np.array_equal(w, weights))
        return real(image, w)
    monkeypatch.setattr(progressive, "through_filter", spy)
    with hidden():
        result = mitsuba_mrt.render(scene, time_limit=5.0)
    assert result.mode_used == "passes" and seen == [True, True]  # the colour, the alpha
    assert np.isfinite(result.image).all()


def test_a_noise_threshold_is_met_by_the_passes(scene):
    plan = mitsuba_mrt.render(scene, noise_threshold=0.5).auto
    assert plan.target_error == 0.5 and plan.choice.error <= 0.5
    assert plan.choice.spp == 4 and len(plan.passes) == 2  # two rounds, then met


def test_small_jobs_render_in_full_without_a_pilot(variant):
    scene = mi.load_string(scene_xml(32))
    result = mitsuba_mrt.render(scene)
    reference, _ = mitsuba_mrt.render_reference(scene)
    assert result.mode_used == "full" and not result.auto.candidates
    assert "too few samples" in result.auto.reason
    assert np.array_equal(result.image, reference)
    # one region, every pixel traced: read-only, as the image's size
    assert result.ids.shape == result.traced_mask.shape == reference.shape[:2]
    assert not result.ids.any() and result.traced_mask.all()
    assert not (result.ids.flags.writeable or result.traced_mask.flags.writeable)
    assert result.traced.full == result.ids.size


def test_small_jobs_under_a_time_limit_take_what_fits_it(variant):
    scene = mi.load_string(scene_xml(32))
    result = mitsuba_mrt.render(scene, time_limit=1e-6)
    assert result.mode_used != "full" and "too few samples" not in result.auto.reason
    assert result.spp == 1 and result.auto.time_limit == 1e-6


def test_small_jobs_under_a_noise_threshold_estimate_it(variant):
    scene = mi.load_string(scene_xml(32))
    loose = mitsuba_mrt.render(scene, noise_threshold=0.5).auto
    assert "too few samples" not in loose.reason and loose.choice.error <= 0.5
    # one no candidate meets: said so, without the MRT's pilot (a small job's would not pay)
    tight = mitsuba_mrt.render(mi.load_string(scene_xml(32, spp=64)), noise_threshold=1e-6).auto
    assert "none meets the target" in tight.reason
    assert [c.name for c in tight.candidates] == ["full", "full+oidn"]


def test_the_scalar_variant_renders_in_full(variant):
    try:
        mi.set_variant("scalar_rgb")
        result = mitsuba_mrt.render(mi.load_string(scene_xml(16)))
    finally:
        mi.set_variant(variant)
    assert result.mode_used == "full" and "scalar" in result.auto.reason


def test_strips_run_from_grid_row_to_grid_row():
    from mitsuba_mrt.recon.sampling import grid_pattern

    p = grid_pattern(400, 400, 0.1)
    strips = pilot.strips_of(p)
    assert len(strips) == pilot.STRIP_COUNT
    for s in strips:
        assert s.height >= pilot.STRIP_MIN_ROWS
        assert p.rows[s.grid_rows[0]] == s.top and p.rows[s.grid_rows[-1]] == s.top + s.height - 1
    assert strips[0].top + strips[0].height <= strips[1].top


def test_a_box_filters_samples_are_its_pixels_own(variant):
    class Box:
        def radius(self):
            return 0.5

        def eval(self, x):
            return 1.0

    class Gaussian:
        def radius(self):
            return 2.0

        def eval(self, x):
            return math.exp(-2.0 * x * x)

    assert pilot.effective_area(Box()) == pytest.approx(1.0, rel=1e-6)
    # Mitsuba's gaussian (stddev 0.5): each sample reaches pi pixels' worth
    assert pilot.effective_area(Gaussian()) == pytest.approx(math.pi, rel=1e-3)


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "mitsuba_mrt", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


def test_the_json_lists_the_plan(tmp_path, variant):
    path = tmp_path / "ball.xml"
    path.write_text(scene_xml(512))
    proc = run_cli("render", path, "-o", tmp_path / "out", "--no-reference", "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    plan = summary["auto"]
    assert summary["mode"] == "auto" and plan["choice"]["name"] in summary["why"]
    assert plan["target_error"] > 0 and plan["time_limit"] is None
    for candidate in plan["candidates"]:
        assert set(candidate) == {"name", "kind", "spp", "mode", "denoise", "seconds", "error",
                                  "compile_s"}


def test_a_samplers_rounding_of_the_passes_spp_is_not_warned_of(tmp_path, variant):
    # stratified at 64 spp: the first round's 8 spp are 9, the probe's 2 are 4
    path = tmp_path / "ball.xml"
    path.write_text(scene_xml(256, spp=64).replace('type="independent"', 'type="stratified"'))
    proc = run_cli("render", path, "-o", tmp_path / "out", "--no-reference", "--no-progress")
    assert proc.returncode == 0 and "full+oidn" in proc.stdout
    assert "WARN" not in proc.stderr + proc.stdout


def test_a_time_limit_the_render_overran_is_a_note(tmp_path):
    proc = run_cli("render", ROOT / "scenes_xml" / "paper_fig1.xml", "-o", tmp_path,
                   "--time-limit", "1e-6", "--no-reference")
    assert proc.returncode == 0
    notes = [line for line in proc.stderr.splitlines() if line.startswith("note: ")]
    assert len(notes) == 3 and "x the time limit of 1e-06 s" in notes[2]  # (after the
    # preview's: without OIDN, then the grid upsampled, as even the fast one would overrun)
    summary = json.loads(next(tmp_path.glob("*.json")).read_text())
    assert notes == ["note: " + note for note in summary["auto"]["notes"]]


@pytest.mark.parametrize("compiled", [0, 1, 12])
def test_an_overrun_note_says_what_compiled(compiled):
    from mitsuba_mrt.renderer import api

    def noted(took, choice=Candidate("full+oidn", "denoised", 1, denoise=True)):
        timings = Timings(total=took, compile=KernelCounts(compiled, 3))
        result = SimpleNamespace(auto=Plan(choice, "", time_limit=0.5), timings=timings)
        api._note_overrun(result)
        return result.auto.notes
    assert noted(0.54) == []  # (within 1.1x the limit)
    note, = noted(1.5)
    assert note.startswith("took 1.500 s, 3.0x the time limit of 0.5 s")
    assert ("compiled" in note) == (compiled > 0)
    if compiled:
        assert f": it compiled {compiled} kernel{'s' if compiled > 1 else ''}, which" in note
    note, = noted(1.5, auto_limit.PREVIEW)  # (what compiled is the reason where any did)
    assert ("the preview is the least this image costs here" in note) == (not compiled)


@pytest.mark.parametrize("option", ["--time-limit", "--noise-threshold"])
@pytest.mark.parametrize("value", ["0", "-2", "nan"])
def test_bad_control_values_exit_2_with_one_line(tmp_path, option, value):
    proc = run_cli("render", ROOT / "scenes_xml" / "paper_fig1.xml", "-o", tmp_path, option, value)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "must be a finite number > 0" in proc.stderr
    assert not any(tmp_path.iterdir())


def test_progress_hears_of_every_round_of_passes(scene):
    heard = []
    result = mitsuba_mrt.render(scene, progress=lambda stage, done: heard.append((stage, done)))
    assert heard[0] == ("passes (2 spp)", 2 / 4)  # of at most half the scene's 8 spp
    assert heard[-1][0] == f"passes ({result.spp} spp)"
    assert [done for _, done in heard] == sorted(done for _, done in heard)


def test_progress_hears_of_the_mrt_stages(variant):
    heard = []
    mitsuba_mrt.render(mi.load_string(scene_xml(64)), mode="fast",
                       progress=lambda stage, done: heard.append(stage))
    assert heard == ["trace", "reconstruct"]


@pytest.fixture
def timed_tracer(monkeypatch):
    """(Tracer class, its launches' spp): on a fake clock of the passes' module,
    a launch takes 1 s and 1 s a sample per pixel, of an independent sampler."""
    from dataclasses import dataclass

    from mitsuba_mrt.renderer import progressive
    from mitsuba_mrt.types import SparseTrace

    clock = [0.0]
    monkeypatch.setattr(progressive.time, "perf_counter", lambda: clock[0])
    launched = []

    @dataclass(frozen=True)
    class Tracer:
        spp: int = 1
        sensor = SimpleNamespace(sampler=lambda: "IndependentSampler[]", film=box_film)

        def __call__(self, xy, **_):
            launched.append(self.spp)
            clock[0] += 1 + self.spp
            n = len(xy)
            return SparseTrace(np.full((n, 3), 0.5), np.full((n, 3), 0.5), np.ones(n, np.int64),
                               np.zeros(n, np.uint32), 0, self.spp, 0.0,
                               normal=np.zeros((n, 3)), variance=np.zeros((n, 3)),
                               odd=np.full((n, 3), 0.5))

    return Tracer, launched, clock


@pytest.mark.parametrize("halves", [False, True], ids=["a half a launch", "halves in a launch"])
def test_what_a_round_cannot_fill_of_a_time_limit_smaller_launches_do(timed_tracer, halves):
    from mitsuba_mrt.renderer import progressive

    Tracer, launched, clock = timed_tracer
    xy = np.zeros((4, 2), dtype=np.int64)
    passes, progress = progressive.Passes(np.arange(4)), progressive.Progress()
    passes.add(Tracer(2)(xy), None if halves else 0, True)
    cost = launch_cost.LaunchCost([(1, 2.0, False), (2, 3.0, False)])  # the line 1 + spp
    start = clock[0]
    progressive._fill(passes, progress, Tracer(), xy, until=start + 13.0, cost=cost,
                      max_spp=64, launch=1, halves=halves, least=2 if halves else 1)
    # 13 s left, a launch at most 1 / 1.15 of what is left (the safety): 10 spp
    # (11 s), then none (2 s left, 1.74 s with the safety)
    assert launch_cost.ROUND_SAFETY == 1.15
    assert launched[1:] == [10] and clock[0] <= start + 13.0
    assert passes.count == 2 + sum(launched[1:]) and progress.spp == passes.count
    assert [launch[:3] for launch in cost.launches[2:]] == [(s, 1.0 + s, False)
                                                            for s in launched[1:]]
    # halves from a launch's odd and even samples are as large as each other
    if halves:
        assert passes.half_counts == [6, 6]


@pytest.mark.parametrize("ladder", [(), (4, 9, 16)], ids=["launched before", "ladder"])
def test_a_sampler_that_bakes_spp_fills_a_time_limit_with_the_ladder_s_counts_too(
        timed_tracer, ladder):
    from mitsuba_mrt.renderer import progressive

    Tracer, launched, clock = timed_tracer
    xy = np.zeros((4, 2), dtype=np.int64)
    passes, progress = progressive.Passes(np.arange(4)), progressive.Progress()
    passes.add(Tracer(1)(xy), 0, True)
    cost = launch_cost.LaunchCost([(1, 2.0, False), (4, 5.0, False)], spp_compiles=True,
                                  ladder=frozenset(ladder))  # the line 1 + spp
    # the line is a least-squares fit: exact up to rounding, which the BLAS varies
    assert cost(9) == (pytest.approx(10.0) if ladder else math.inf)
    start = clock[0]
    progressive._fill(passes, progress, Tracer(), xy, until=start + 13.0, cost=cost,
                      max_spp=64, launch=1, halves=False)
    # 13 s left, a launch at most 1 / 1.15 of what is left: only the spp launched before
    # (a new one might compile), 4, 4 and 1; with the ladder one launch of 9 spp
    # (its strata whole), then 1
    assert launched[1:] == ([9, 1] if ladder else [4, 4, 1]) and clock[0] <= start + 13.0


def launched_ladder_of(kind: str) -> frozenset:
    from mitsuba_mrt.renderer.auto_limit import launch_ladder

    return launch_ladder(mi.load_dict({"type": kind, "sample_count": 16}))


def test_the_ladder_is_the_squares_to_64_as_the_sampler_takes_them(monkeypatch):
    assert launched_ladder_of("stratified") == {4, 9, 16, 25, 36, 49, 64}
    assert launched_ladder_of("multijitter") == {4, 9, 16, 25, 36, 49, 64}
    assert all(spp <= 64 for spp in launched_ladder_of("ldsampler"))
    # a scene's kept launches plan it where its sampler bakes its spp, and only there
    monkeypatch.setattr(auto_limit, "_launch_costs", {})
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", "off")
    for kind, ladder in (("stratified", launched_ladder_of("stratified")),
                         ("independent", frozenset())):
        sampler = mi.load_dict({"type": kind})
        tracer = SimpleNamespace(sensor=SimpleNamespace(sampler=lambda: sampler, film=box_film),
                                 pass_recorded=lambda spp, *_: False)
        assert auto_limit.kept_cost((kind, "sensor", "integrator", 16), tracer).ladder == ladder


def test_a_time_limit_alone_fills_its_time_after_one_launch(timed_tracer):
    from mitsuba_mrt.renderer import progressive

    Tracer, launched, clock = timed_tracer
    _, _, progress = progressive.run_passes(
        Tracer(), 2, 2, quality="fast", target_error=None, deadline=30.0, max_spp=64,
        full_spp=16, area=1.0, denoise=False)
    # 2 spp (3 s: nothing tells a launch's cost, and every larger launch replays its
    # recording), then at most 1 / 1.15 of what is left: 15 spp at 1.5 s each (16 s:
    # the line is now 1 s + 1 s an spp), 8 (9 s of 11), and 2 s left hold no launch
    assert launched == [2, 15, 8] and clock[0] <= 30.0
    assert progress.spp == 25 and progress.stopped == "the time limit"


def test_a_time_limit_s_first_launch_is_sized_by_earlier_renders_launches(timed_tracer):
    from mitsuba_mrt.renderer import progressive

    Tracer, launched, clock = timed_tracer
    cost = launch_cost.LaunchCost()
    for _ in range(2):  # two renders of the same scene, one cost kept between them
        launched.clear()
        clock[0] = 0.0
        progressive.run_passes(Tracer(), 2, 2, quality="fast", target_error=None,
                               deadline=30.0, max_spp=64, full_spp=16, area=1.0,
                               denoise=False, cost=cost)
        assert clock[0] <= 30.0
    # the second knows the line (1 s + 1 s an spp): 30 s hold 29 spp at once (no
    # safety: the line is moved up until no launch took longer)
    assert launched[0] == 29 and sum(launched) >= 29


@pytest.mark.parametrize("spp_compiles", [False, True])
def test_a_first_launch_s_compilation_is_a_new_spp_s_cost_only_where_the_sampler_bakes_spp(
        spp_compiles):

    cost = launch_cost.LaunchCost(spp_compiles=spp_compiles)
    # a process's first launch compiled its kernels (0.4 s of its 0.6 s), the next replayed
    cost.add(8, 0.6, recorded=True, compile_s=0.4)
    cost.add(8, 0.16)
    # the line through the replayed launch: 0.02 s an spp; a new spp records anew, and
    # compiles again only where the sampler bakes its spp into the kernels: whether
    # Dr.Jit's disk cache holds them no launch tells, so no new spp is planned there
    assert cost.record_s == pytest.approx(0.44 if spp_compiles else 0.04)
    assert cost(1) == (math.inf if spp_compiles else pytest.approx(0.02 + cost.record_s))
    assert cost(8) == pytest.approx(0.16) and cost.cheapest() == (8 if spp_compiles else 1)
    assert cost.launches[0][1] == pytest.approx(0.6 if spp_compiles else 0.2)
    # measured, a recording's time is a new spp's cost, with its compilation where it
    # bakes spp
    cost.add(4, 0.2, recorded=True, compile_s=0.1, recording_s=0.01)
    assert cost.record_s == pytest.approx(0.11 if spp_compiles else 0.01)


def test_a_first_launch_s_recording_is_a_new_spp_s_cost_only_until_another_records():

    cost = launch_cost.LaunchCost(spp_compiles=False)
    # a process's first launch recorded, and paid for first uses too; the next replayed
    cost.add(1, 0.05, recorded=True)  # (the cost's first)
    assert cost.launches[0].first
    cost.add(1, 0.02)
    assert cost.record_s == pytest.approx(0.05 - 0.02)  # all there is to go by
    cost.add(2, 0.03, recorded=True)  # a new spp's recording: less than the line says
    assert cost.record_s == 0.0 and cost(4) == pytest.approx(0.005 + 4 * 0.015)


def test_a_recorded_launch_s_replay_time_is_on_the_line():
    from mitsuba_mrt.renderer.launch_cost import Launch

    # a time-limited render's launches (materials at 512 px): the replays were of 1 and 2
    # spp, the larger launches recorded a new spp each (recording measured)
    cost = launch_cost.LaunchCost([
        Launch(1, 0.228, True, first=True, recording=0.016), Launch(1, 0.060),
        Launch(6, 0.205, True, recording=0.016), Launch(2, 0.075),
        Launch(14, 0.429, True, recording=0.016), Launch(4, 0.114, True, recording=0.008),
        Launch(2, 0.073)])
    # a 39-spp launch then took 1.06 s; the replays alone said 0.58, a slope fitted
    # through every launch and turned until none took longer 1.69
    assert 1.0 < cost(39) < 1.2
    fixed, per_spp = cost._line()
    assert 0.026 < per_spp < 0.03 and 0 <= fixed < 0.06


def test_a_launch_s_kernels_run_time_and_the_cost_s_first_launch_are_kept(scene, monkeypatch):

    from mitsuba_mrt.renderer.replay import clear_recordings

    kept = launch_cost.LaunchCost(spp_compiles=False)
    monkeypatch.setattr(auto, "kept_cost", lambda key, tracer, guides: kept)
    clear_recordings()  # (the first launch records its replay, and measures that)
    mitsuba_mrt.render(scene, time_limit=10.0)
    first, *rest = kept.launches
    assert first.first and first.recorded and 0 < first.recording <= first.seconds
    assert not any(launch.first for launch in rest)
    assert all(0 < launch.execute < launch.seconds for launch in kept.launches)
    assert all(launch.recording is None for launch in rest if not launch.recorded)


def test_a_launch_s_odd_and_even_samples_make_the_two_halves():
    from mitsuba_mrt.renderer import progressive
    from mitsuba_mrt.types import SparseTrace

    n = 3
    radiance, odd = np.full((n, 3), 0.4), np.full((n, 3), 0.3)  # so the even mean is 0.5
    trace = SparseTrace(radiance, np.zeros((n, 3)), np.ones(n, np.int64), np.zeros(n, np.uint32),
                        0, 4, 0.0, normal=np.zeros((n, 3)), variance=np.zeros((n, 3)), odd=odd)
    passes = progressive.Passes(np.arange(n))
    passes.add(trace, None, True)
    np.testing.assert_allclose(passes.half_mean(0), 0.5)
    np.testing.assert_allclose(passes.half_mean(1), 0.3)
    np.testing.assert_allclose(passes.mean, 0.4)
    assert passes.half_counts == [2, 2] and passes.count == 4


def test_a_launch_s_cost_leaves_out_its_companion(timed_tracer):
    # a time limit alone traces no companion: the launches it plans from are the
    # passes' own, the companion's pixels' share of the launch left out
    from mitsuba_mrt.renderer import progressive

    Tracer, launched, clock = timed_tracer
    xy = np.arange(8, dtype=np.int64).reshape(4, 2)
    passes, cost = progressive.Passes(np.arange(4)), launch_cost.LaunchCost()
    passes.companion = np.array([0, 2])
    seconds = progressive._launch(passes, Tracer(2), xy, 2, 0, None, cost)
    # one launch of the 4 pixels and, after them, the companion's 2
    assert launched == [2] and seconds == 3.0
    assert [launch[:3] for launch in cost.launches] == [(2, 2.0, False)]
    assert passes.half_counts == [2, 2] and passes.count == 2


def test_under_a_time_limit_a_sampler_that_compiles_per_spp_launches_the_spp_it_has(
        timed_tracer):
    from mitsuba_mrt.renderer import progressive

    Tracer, launched, clock = timed_tracer

    stratified = mi.load_dict({"type": "stratified"})

    class Stratified(Tracer):
        sensor = SimpleNamespace(sampler=lambda: stratified, film=box_film)

        def __call__(self, xy, **kwargs):
            kinds.append((kwargs["aovs"], kwargs["halves"]))
            return super().__call__(xy, **kwargs)
    kinds = []
    # earlier renders launched 9, 4 and 36 spp (the line 1 s + 1 s an spp); a new
    # spp would compile its kernels
    cost = launch_cost.LaunchCost([(9, 10.0, False), (4, 5.0, False), (36, 37.0, True)],
                                  spp_compiles=True)
    progressive.run_passes(Stratified(), 2, 2, quality="fast", target_error=None,
                           deadline=30.0, max_spp=64, full_spp=16, area=1.0, denoise=False,
                           cost=cost)
    # 30 / 1.15 s holds 9 spp launched before (10 s), not a new 25; then 20 s left
    # hold 9 again, 10 s 4 spp (5 s), and 5 s none
    assert launched == [9, 9, 4] and clock[0] <= 30.0
    # no odd samples apart (the default rounds' estimates have companion lanes
    # of their own), and undenoised: no guides
    assert kinds == [(False, False)] * 3
    # where only 1 spp was launched before, the time fills with 1-spp launches
    launched.clear()
    clock[0] = 0.0
    progressive.run_passes(Stratified(), 2, 2, quality="fast", target_error=None,
                           deadline=10.0, max_spp=64, full_spp=16, area=1.0, denoise=False,
                           cost=launch_cost.LaunchCost([(1, 2.0, False)], spp_compiles=True))
    assert launched == [1, 1, 1, 1] and clock[0] <= 10.0


def test_passes_that_estimate_nothing_ask_their_traces_for_no_variance(timed_tracer):
    # a time limit alone and a plan an earlier render measured read no
    # variance: working it out is a few ms of a launch of every pixel
    from mitsuba_mrt.renderer import progressive

    Tracer, launched, clock = timed_tracer
    asked = []

    class Spy(Tracer):
        def __call__(self, xy, **kwargs):
            asked.append(kwargs["variance"])
            trace = super().__call__(xy, **kwargs)
            return replace(trace, variance=None) if not kwargs["variance"] else trace
    common = dict(quality="fast", max_spp=8, full_spp=8, area=1.0, denoise=False)
    progressive.run_passes(Spy(), 2, 2, target_error=None, deadline=None, fixed=True, **common)
    progressive.run_passes(Spy(), 2, 2, target_error=None, deadline=clock[0] + 20.0,
                           cost=launch_cost.LaunchCost([(1, 2.0, False), (2, 3.0, False)]),
                           **common)
    assert asked and not any(asked)
    asked.clear()
    # the estimates read it
    progressive.run_passes(Spy(), 2, 2, target_error=0.01, deadline=None, **common)
    assert asked and all(asked)
    asked.clear()
    # but not for the default target where a full render's noise is traced (the
    # halves' difference meets it)
    progressive.run_passes(Spy(), 8, 8, target_error=None, deadline=None,
                           **dict(common, denoise=True))
    assert asked and not any(asked)


def _default_render_traced(monkeypatch, sampler: str, heard):
    """The default render of a ball scene at 256 px and 64 spp with ``sampler``;
    ``heard(tracer, pixel_xy, kwargs)`` is told of each of its traces."""
    from mitsuba_mrt.renderer.api import GridTracer

    scene = mi.load_string(scene_xml(256, spp=64).replace('type="independent"',
                                                          f'type="{sampler}"'))
    original = GridTracer.__call__

    def spy(self, pixel_xy, **kwargs):
        heard(self, pixel_xy, kwargs)
        return original(self, pixel_xy, **kwargs)
    monkeypatch.setattr(GridTracer, "__call__", spy)
    return mitsuba_mrt.render(scene)


@pytest.mark.parametrize("sampler", ["independent", "stratified"])
def test_the_default_target_s_first_round_is_one_launch_of_an_eighth_of_the_spp(
        variant, monkeypatch, sampler):
    # its halves the launch's odd and even samples: one launch keeps a
    # stratifying sampler's strata whole, as the alternative's single render does
    seen = []

    def passes(tracer, pixel_xy, kwargs):
        if kwargs.get("box"):  # the passes' launches
            seen.append((tracer.spp, kwargs.get("halves", False), len(pixel_xy)))
    result = _default_render_traced(monkeypatch, sampler, passes)
    assert result.mode_used == "full+oidn"
    rounds = [s for s in seen if s[2] == 256 * 256]
    spp = [s for s, _, _ in rounds]
    if sampler == "independent":
        # the first launch also traces the target's noise, after the image's pixels
        rounds = [(s, halves, min(n, 256 * 256)) for s, halves, n in seen]
        spp = [s for s, _, _ in rounds]
        assert seen[0][2] > 256 * 256 and all(n == 256 * 256 for _, _, n in seen[1:])
        assert all(halves for _, halves, _ in seen)
        # a later round adds at most as many passes as there are
        assert spp[0] == 8 and all(s <= sum(spp[:k]) for k, s in enumerate(spp) if k)
    else:
        from mitsuba_mrt.renderer import progressive

        # a stratifying sampler's odd and even samples are no independent halves:
        # each launch traces every other row of the estimate's again, after the image
        rows = len(progressive.estimate_rows(256, 256)) // 2 * 256
        assert rounds == [] and seen == [(s, False, 256 * 256 + rows) for s, _, _ in seen]
        spp = [s for s, _, _ in seen]
        assert spp[0] == 8 and spp == sorted(spp)


@pytest.mark.parametrize("sampler", ["independent", "stratified"])
def test_the_default_target_is_a_full_render_s_noise_traced_on_the_estimate_strips(
        variant, monkeypatch, sampler):
    # the passes' samples, clipped one by one, understate a full render's noise where
    # bright paths are common; a stratifying sampler's estimates keep their old target
    from mitsuba_mrt.renderer import progressive
    from mitsuba_mrt.types import SeedStream

    traced = []

    def noise(tracer, pixel_xy, kwargs):
        if kwargs.get("box") and len(pixel_xy) > 256 * 256:
            traced.append((tracer.spp, kwargs.get("stream"), pixel_xy[256 * 256:].copy()))
    result = _default_render_traced(monkeypatch, sampler, noise)
    assert result.mode_used == "full+oidn" and result.auto.target_error > 0
    if sampler == "stratified":  # (its launches' companion: every other estimated row)
        assert all(len(xy) == len(progressive.estimate_rows(256, 256)) // 2 * 256
                   for _, _, xy in traced)
        return
    # in the first launch alone, after the image's pixels: 1024 pixels in lanes
    # of the round's 8 spp, two halves of 4 lanes, 32 spp each, half the scene's
    (spp, stream, xy), = traced
    assert spp == 8 and stream == SeedStream.LADDER and len(xy) == 8 * 1024
    assert all(np.array_equal(xy[:1024], xy[k * 1024:(k + 1) * 1024]) for k in range(8))
    assert len(np.unique(xy[:1024], axis=0)) == 1024
    assert np.isin(xy[:, 1], progressive.estimate_rows(256, 256)).all()
    assert result.timings.check > 0  # (its share of the launch among the estimates')


def test_a_stratifying_sampler_s_estimates_see_its_noise(variant):
    # its odd and even samples, strata of one set, differ by more than two
    # independent halves: on this scene their difference said 0 error at 9
    # spp and met any target; lanes of their own are independent of the round's
    scene = mitsuba_mrt.load_scene(SCENES / "gallery" / "instanced.xml", res=256)
    result = mitsuba_mrt.render(scene)
    (spp, error), = result.auto.passes
    assert spp == result.spp == 9 and 0.02 < error < result.auto.target_error


def test_near_the_target_a_round_adds_what_the_estimates_say_it_lacks(timed_tracer, monkeypatch):
    from mitsuba_mrt.renderer import progressive

    Tracer, launched, clock = timed_tracer

    def estimate(passes, progress, *_):  # a denoised half's error: 0.2 / sqrt(its spp)
        progress.history.append((passes.half_counts[0], 0.2 * passes.half_counts[0] ** -0.5))
        progress.predicted = progressive.predict(progress.history, passes.count)

    monkeypatch.setattr(progressive, "_estimate", estimate)
    _, _, progress = progressive.run_passes(
        Tracer(), 2, 2, quality="fast", target_error=0.04, deadline=None, max_spp=64,
        full_spp=64, area=1.0, denoise=False)
    # rounds double the passes while far from the target (16 predict 0.05); then, the
    # rate measured (0.5), 0.95 of the target needs 27.7 spp: 12 more, not 16
    assert launched == [2, 2, 4, 8, 12] and progress.stopped == "met the target"
    assert progress.spp == 28 and progress.predicted <= 0.04


def test_a_stratified_pilot_reference_s_noise_is_its_halves_difference():
    from mitsuba_mrt.renderer.pilot import Reference

    # strata make a pixel's mean vary less than its samples' variance over the spp says
    a = SimpleNamespace(radiance=np.full((2, 3), 0.50), variance=np.full((2, 3), 0.04), spp=4)
    b = SimpleNamespace(radiance=np.full((2, 3), 0.52), variance=np.full((2, 3), 0.04), spp=4)
    plain, stratified = Reference.of(a, b), Reference.of(a, b, stratified=True)
    assert plain.noise_b == pytest.approx(np.full((2, 3), 0.01))
    assert plain.noise_mean == pytest.approx(np.full((2, 3), 0.005))
    # the square of the halves' difference is twice a half's variance
    assert stratified.noise_b == pytest.approx(np.full((2, 3), 0.0002))
    assert stratified.noise_mean == pytest.approx(np.full((2, 3), 0.0001))


def test_a_preview_leaves_its_later_stages_what_the_last_previews_took(scene, monkeypatch):
    monkeypatch.setattr(auto_limit, "_preview_after_s", {})
    monkeypatch.setattr(auto_limit, "_preview_rate", [])
    monkeypatch.setattr(auto_limit, "_preview_due", lambda *args: True)
    for _ in range(3):  # (the grid's kernels recorded: a pooled launch replays them)
        mitsuba_mrt.render(scene, time_limit=10.0)
    (key,) = auto_limit._preview_after_s
    auto_limit._preview_after_s.clear()
    auto_limit._preview_rate.clear()
    first = mitsuba_mrt.render(scene, time_limit=10.0)
    # nothing kept: the bound per pixel, far below a 10-s limit on this image
    assert first.auto.reason == auto_limit.PREVIEW_REASON and first.spp == PREVIEW_MAX_SPP
    assert first.params.denoise_quality == auto_limit.PREVIEW_QUALITY  # (as it was planned)
    (took,) = auto_limit._preview_after_s[key]
    assert 0.0 < took < first.timings.total - first.timings.trace
    # ... and its time per pixel beyond OIDN, for other scenes' first previews
    pixels = first.image.shape[0] * first.image.shape[1]
    (rate,) = auto_limit._preview_rate
    assert rate * pixels == pytest.approx(took - first.timings.denoise)
    # previews whose stages after the grid filled the limit: no launch pooled
    auto_limit._preview_after_s[key] = [9.5, 9.6, 0.0]
    assert mitsuba_mrt.render(scene, time_limit=10.0).spp == 1


def test_a_first_preview_of_a_scene_leaves_what_other_previews_took_per_pixel(scene,
                                                                            monkeypatch):
    monkeypatch.setattr(auto_limit, "_preview_after_s", {})
    monkeypatch.setattr(auto_limit, "_preview_due", lambda *args: True)
    monkeypatch.setattr(auto_limit, "FINISH_PER_PIXEL", 1.0)  # a bound of days: never the least
    monkeypatch.setattr(auto_limit, "PREVIEW_FIRST_REST", (1e6, 0.0))
    for _ in range(2):  # (the grid's kernels recorded: a pooled launch replays them)
        mitsuba_mrt.render(scene, time_limit=10.0)
    pixels = 512 * 512
    # other previews took a few ms on such an image: launches pooled, OIDN run
    monkeypatch.setattr(auto_limit, "_preview_rate", [1e-9, 1e-8])
    auto_limit._preview_after_s.clear()
    filled = mitsuba_mrt.render(scene, time_limit=10.0)
    assert filled.auto.reason == auto_limit.PREVIEW_REASON and filled.spp == PREVIEW_MAX_SPP
    assert filled.auto.choice.denoise and len(auto_limit._preview_after_s) == 1
    # 20 s: past the limit's slack, the preview goes without OIDN; its time
    # per pixel is kept for the next, but not as the scene's denoised stages
    auto_limit._preview_after_s.clear()
    auto_limit._preview_rate[:] = [20.0 / pixels]
    bare = mitsuba_mrt.render(scene, time_limit=10.0)
    assert not bare.auto.choice.denoise and auto_limit.UNDENOISED_NOTE in bare.auto.notes
    assert not auto_limit._preview_after_s and len(auto_limit._preview_rate) == 2
    assert auto_limit._preview_rate[-1] * pixels < 10.0
    # a process that has made no preview: the bound, here without OIDN
    auto_limit._preview_rate.clear()
    assert not mitsuba_mrt.render(scene, time_limit=10.0).auto.choice.denoise


def test_a_fresh_process_s_first_preview_leaves_the_least_of_two_bounds(monkeypatch):
    monkeypatch.setattr(auto_limit, "_preview_after_s", {})
    monkeypatch.setattr(auto_limit, "_preview_rate", [])
    monkeypatch.setattr(auto_limit, "denoise_seconds", lambda *args: None)  # (no call yet)
    monkeypatch.setattr(auto_limit, "expected_seconds", lambda count, quality: 0.025)
    monkeypatch.setattr(auto_limit, "_recalled_preview_after", lambda *args: None)
    fixed, per_pixel = auto_limit.PREVIEW_FIRST_REST

    def after(side):
        return auto_limit._preview_after(("key",), grid_pattern(side, side, 0.1), "auto", None)
    # a small image: the per-pixel bound, OIDN's first call on top
    assert after(256) == pytest.approx(auto_limit.FINISH_PER_PIXEL * 256 ** 2 + 0.025)
    # a large one: what fresh previews took, less
    line = fixed + per_pixel * 768 ** 2 + auto_limit.PREVIEW_FIRST_OIDN * 0.025
    assert after(768) == pytest.approx(line)
    assert line < auto_limit.FINISH_PER_PIXEL * 768 ** 2 + 0.025


def test_a_fresh_preview_s_later_stages_are_remembered_for_later_processes(tmp_path,
                                                                          monkeypatch):
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(tmp_path / "memory.json"))
    monkeypatch.setattr(auto_limit, "_memory_key", lambda key, tracer: "scene")
    key, tracer = ("token", 4), object()
    assert auto_limit._recalled_preview_after(key, tracer, "fast", 10) is None
    for seconds in (0.05, 0.09, 0.06, 0.07):
        auto_limit._remember_preview_after(key, tracer, seconds, "fast", 10)
    # the longest of the last three a fresh process took
    assert auto_limit._recalled_preview_after(key, tracer, "fast", 10) == 0.09
    # of another preset or grid size: none; nor without the tracer that names the scene
    assert auto_limit._recalled_preview_after(key, tracer, "high", 10) is None
    assert auto_limit._recalled_preview_after(key, tracer, "fast", 11) is None
    assert auto_limit._recalled_preview_after(key, None, "fast", 10) is None
    # a value not of this kind is none, its bad entries dropped
    assert auto_limit._remembered_preview_after({"quality": "fast", "grid": 10, "seconds": [
        0.1, "x", -1.0, True, math.inf]}, "fast", 10) == [0.1]
    assert auto_limit._remembered_preview_after({"quality": "fast", "grid": 10,
                                                  "seconds": 0.1}, "fast", 10) == []
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", "off")
    assert auto_limit._recalled_preview_after(key, tracer, "fast", 10) is None


def test_a_process_s_first_preview_leaves_what_an_earlier_process_s_first_took(
        scene, tmp_path, monkeypatch):
    from mitsuba_mrt.renderer.state import clear_caches

    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(tmp_path / "memory.json"))
    monkeypatch.setattr(auto_limit, "UNPROBED_OVER_OIDN", 1e6)  # (the limit asks the probe)
    monkeypatch.setattr(auto_limit, "unmeasured_plan", lambda *args: None)  # (no MRT plan)
    monkeypatch.setattr(auto_limit, "_preview_due", lambda *args: True)
    clear_caches()  # (a process that rendered nothing: the preview makes OIDN's first call)
    first = mitsuba_mrt.render(scene, time_limit=10.0)
    assert first.auto.reason == auto_limit.PREVIEW_REASON and first.auto.choice.denoise
    # the next process: what the first took after its grid, not the bound (days)
    monkeypatch.setattr(auto_limit, "FINISH_PER_PIXEL", 1.0)
    monkeypatch.setattr(auto_limit, "PREVIEW_FIRST_REST", (1e6, 0.0))
    clear_caches()
    again = mitsuba_mrt.render(scene, time_limit=10.0)
    assert again.auto.choice.denoise and again.spp == PREVIEW_MAX_SPP
    # a later preview in that process made no first call: it is not remembered
    remembered = json.loads((tmp_path / "memory.json").read_text())["scenes"]
    (kept,) = [v["seconds"] for k, v in remembered.items() if k.endswith("/preview")]
    assert len(kept) == 2
    mitsuba_mrt.render(scene, time_limit=10.0)
    remembered = json.loads((tmp_path / "memory.json").read_text())["scenes"]
    assert [v["seconds"] for k, v in remembered.items() if k.endswith("/preview")] == [kept]
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", "off")  # nothing recalled: the bound
    clear_caches()
    assert not mitsuba_mrt.render(scene, time_limit=10.0).auto.choice.denoise


def test_a_pass_a_probe_times_must_fit_the_limit_itself(scene, monkeypatch):
    # with no pass measured in the process, the probe's guess of one is held to
    # PROBED_SLACK times the limit, not PREVIEW_SLACK's
    ends = []

    def due(end, first_end, *args):
        ends.append(end - first_end)
        return True
    monkeypatch.setattr(auto_limit, "_preview_due", due)
    monkeypatch.setattr(auto_limit, "UNPROBED_OVER_OIDN", 1e6)  # (the probe asked)
    for slack in (1.0, 3.0):
        monkeypatch.setattr(auto_limit, "_launch_costs", {})
        monkeypatch.setattr(auto_limit, "_first_round_s", {})
        monkeypatch.setattr(auto_limit, "PROBED_SLACK", slack)
        mitsuba_mrt.render(scene, time_limit=10.0)
    # (each render's start and its probe's end a second apart at most)
    assert ends[-1] - ends[0] == pytest.approx(20.0, abs=1.0)


def test_a_preview_taken_as_the_sampler_bakes_its_spp_says_so(variant, monkeypatch):
    from mitsuba_mrt.renderer.api import GridTracer

    monkeypatch.setattr(auto_limit, "_launch_costs", {})
    monkeypatch.setattr(auto_limit, "_first_round_s", {})
    scene = mi.load_string(scene_xml(64, spp=16, sampler="stratified"))
    assert mitsuba_mrt.render(scene, time_limit=10.0).auto.choice.kind == "denoised"
    (key,) = auto_limit._launch_costs  # passes launched only at 9 spp before, as a kept plan's
    cost = auto_limit._launch_costs[key] = launch_cost.LaunchCost([(9, 0.2, False)],
                                                            spp_compiles=True)
    assert cost(1) == math.inf and cost.cheapest() == 9
    auto_limit._first_round_s.clear()
    # (the first render's 1-spp launches recorded: as if they had not)
    monkeypatch.setattr(GridTracer, "pass_recorded", lambda self, spp, *_, **__: False)
    preview = mitsuba_mrt.render(scene, time_limit=1e-6)
    assert preview.auto.reason == auto_limit.PREVIEW_REASON
    assert auto_limit.BAKED_NOTE.format(cost.cheapest()) in preview.auto.notes
    # where a trace recorded the passes' 1-spp launch (its kernels exist), it is planned
    replayed = launch_cost.LaunchCost(cost.launches, spp_compiles=True, replays=frozenset([1]))
    assert replayed.cheapest() == 1 and replayed(1) < replayed(9) and replayed.fits(0.1) == 1
    # an independent sampler plans a pass of any spp: no such note
    plain = mitsuba_mrt.render(mi.load_string(scene_xml(64, spp=16)), time_limit=1e-6)
    assert not any("bakes" in note for note in plain.auto.notes)


def test_a_noise_threshold_beyond_the_scenes_spp_is_met_by_no_candidate(variant):
    # the passes' candidate is what they reach at the scene's spp, not the target
    plan = mitsuba_mrt.render(mi.load_string(scene_xml(256, spp=64)), noise_threshold=1e-6).auto
    passes = next(c for c in plan.candidates if c.name == "full+oidn")
    assert passes.spp <= 64 and passes.error > 1e-6
    assert "none meets the target" in plan.reason
    # where the passes reach the scene's spp first, they say they fell short
    few = mitsuba_mrt.render(mi.load_string(scene_xml(512)), noise_threshold=1e-6).auto
    assert few.reason == "denoised passes: reached 8 spp, short of the target"


def test_passes_the_planner_weighs_and_chooses_go_on_untraced_again(variant, monkeypatch):
    from mitsuba_mrt.modes import plan as planner
    from mitsuba_mrt.renderer import progressive

    def passes_first(candidates, **kwargs):
        chosen = planner.choose(candidates, **kwargs)
        chosen.choice = next(c for c in candidates if c.kind == "denoised")
        return chosen
    monkeypatch.setattr(auto, "choose", passes_first)
    launched = []
    launch = progressive._launch
    monkeypatch.setattr(progressive, "_launch", lambda passes, tracer, xy, spp, *rest: (
        launched.append(spp), launch(passes, tracer, xy, spp, *rest))[1])
    result = mitsuba_mrt.render(mi.load_string(scene_xml(256, spp=64)), noise_threshold=1e-6)
    plan = result.auto
    assert result.mode_used == "full+oidn" and len(plan.candidates) > 2
    assert plan.reason.startswith("more passes would cost more than a full render")
    assert sum(launched) == result.spp  # each pass traced once


def test_the_first_rounds_times_keep_the_last_scenes_only(monkeypatch):
    monkeypatch.setattr(auto_limit, "_first_round_s", {})
    for k in range(auto_limit.KEPT_COSTS + 5):
        auto_limit.note_first_round(("scene", k), 0.1 * k)
    assert list(auto_limit._first_round_s) == [("scene", k) for k in
                                               range(5, auto_limit.KEPT_COSTS + 5)]
