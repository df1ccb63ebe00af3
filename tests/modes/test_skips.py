"""Each "skip what a scene doesn't need" shortcut fires, and is counted."""

import mitsuba as mi
import numpy as np

import mitsuba_mrt
from mitsuba_mrt.recon.metrics import paper_error
from helpers import small_scene_xml

SPHERE_ONLY = """<shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.6, 0.9"/></bsdf></shape>
  <emitter type="point"><point name="position" x="3" y="2" z="4"/><rgb name="intensity" value="50"/></emitter>"""


def sphere_scene(res=48):
    return mi.load_string(small_scene_xml(res, extra=SPHERE_ONLY, shapes=False, lights=False))


def test_single_sphere_needs_no_shadow_rays_and_ids_match_traced_ones(variant):
    scene = sphere_scene()
    result = mitsuba_mrt.render(scene, mode="fast")
    assert result.skips.shadow_rays == 1
    # the same visibility as shadow rays find: add a far-away second shape to force rays
    extra = '<shape type="sphere"><point name="center" x="0" y="0" z="-50"/></shape>'
    forced = mi.load_string(small_scene_xml(48, extra=SPHERE_ONLY + extra, shapes=False,
                                            lights=False))
    forced_result = mitsuba_mrt.render(forced, mode="fast")
    assert forced_result.skips.shadow_rays == 0
    on_sphere = result.trace.shape_index > 0
    assert np.array_equal(result.trace.visible_lights[on_sphere],
                          forced_result.trace.visible_lights[on_sphere])


def test_no_lights_need_no_shadow_rays(variant):
    scene = mi.load_string(small_scene_xml(24, lights=False))
    assert mitsuba_mrt.render(scene, mode="paper").skips.shadow_rays == 1


def test_black_background_is_filled_not_interpolated(variant):
    scene = sphere_scene()
    reference, _ = mitsuba_mrt.render_reference(scene)
    for mode in ("paper", "fast"):
        result = mitsuba_mrt.render(scene, mode=mode)
        assert result.skips.background == 1
        assert (result.image[result.ids == 0] == 0).all()
        assert paper_error(result.image, reference) < 0.02


def test_constant_ids_are_filled_in_paper_mode(variant):
    # the background and the sphere's unlit side are both black
    result = mitsuba_mrt.render(sphere_scene(), mode="paper")
    assert result.skips.constant_ids == 2
    assert result.skips.background == 1
    assert result.stats["regions"] == len(np.unique(result.ids))  # counted, not re-found


def test_one_id_skips_edge_finding(variant):
    plane = """<shape type="rectangle"><transform name="to_world"><scale value="50"/></transform></shape>
      <emitter type="point"><point name="position" x="0" y="0" z="3"/><rgb name="intensity" value="10"/></emitter>"""
    scene = mi.load_string(small_scene_xml(32, extra=plane, shapes=False, lights=False))
    for mode in ("paper", "fast"):
        result = mitsuba_mrt.render(scene, mode=mode)
        assert result.skips.edge_finding == 1
        assert result.skips.shadow_rays == 1  # a single plane never shadows itself
        assert len(np.unique(result.ids)) == 1


def test_constant_albedo_skips_demodulation(variant, monkeypatch):
    scene = mi.load_string(small_scene_xml(32))
    for mode in ("fast", "paper"):
        assert mitsuba_mrt.render(scene, mode=mode).skips.albedo_division == 1
    # paper mode: interpolating radiance is interpolating irradiance x albedo
    skipped = mitsuba_mrt.render(scene, mode="paper")
    from mitsuba_mrt.modes import paper
    monkeypatch.setattr(paper, "albedo_constant_per_id", lambda ids, albedo: False)
    divided = mitsuba_mrt.reconstruct(skipped.pattern, skipped.trace, mode="paper")
    assert divided.skips.albedo_division == 0
    assert np.allclose(skipped.image, divided.image, rtol=1e-9, atol=1e-12)


def test_skips_reach_the_json(tmp_path):
    from mitsuba_mrt.app.job import RenderJob, run_render_job

    scene = tmp_path / "sphere.xml"
    scene.write_text(small_scene_xml(32, extra=SPHERE_ONLY, shapes=False, lights=False))
    summary = run_render_job(RenderJob(str(scene), str(tmp_path / "out"), mode="fast",
                                       reference=False))
    assert summary.mode_used == "fast"
    assert summary.skipped.shadow_rays == 1 and summary.skipped.background == 1
