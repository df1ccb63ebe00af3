import mitsuba as mi
import numpy as np
from scipy import ndimage

import mitsuba_mrt
from mitsuba_mrt.recon.metrics import paper_error
from helpers import path_camera_xml, small_scene_xml

CHECKER_PLANE = """<shape type="rectangle">
    <transform name="to_world"><scale value="4"/></transform>
    <bsdf type="diffuse"><texture type="checkerboard" name="reflectance">
      <rgb name="color0" value="0.1, 0.2, 0.3"/><rgb name="color1" value="0.9, 0.8, 0.6"/>
      <transform name="to_uv"><scale x="7" y="7"/></transform></texture></bsdf>
  </shape>
  <emitter type="point"><point name="position" x="1" y="2" z="5"/><rgb name="intensity" value="40"/></emitter>"""


def test_checkerboard_is_reproduced_by_the_albedo_of_the_id_pass(variant):
    scene = mi.load_string(small_scene_xml(96, extra=CHECKER_PLANE, shapes=False, lights=False))
    reference, _ = mitsuba_mrt.render_reference(scene)
    result = mitsuba_mrt.render(scene, mode="idpass")
    plane = result.ids != 0
    # one light, no occluder: irradiance is smooth, so only float error remains
    rel = np.abs(result.image - reference)[plane] / np.maximum(reference[plane], 1e-3)
    assert rel.max() < 2e-3
    fast = mitsuba_mrt.render(scene, mode="fast")
    assert paper_error(result.image, reference) < 0.05 * paper_error(fast.image, reference)


def test_id_pass_ids_are_exact_and_slivers_are_traced(variant, true_ids):
    scene = mi.load_string(small_scene_xml(64))
    result = mitsuba_mrt.render(scene, mode="idpass")
    assert np.array_equal(result.ids, true_ids(scene))
    assert result.traced_mask.sum() == result.pattern.count + result.stats["sliver_pixels"]
    reference, _ = mitsuba_mrt.render_reference(scene)
    assert np.allclose(result.image[result.traced_mask], reference[result.traced_mask], atol=1e-6)


def test_refine_demodulates_a_texture_like_fast(variant):
    # refine and fast share one value stage: albedo that varies within an id
    # is demodulated in both.  Without a full-resolution albedo (idpass) a
    # grid-scale checkerboard still blurs, which the idpass test shows fixed.
    scene = mi.load_string(small_scene_xml(96, extra=CHECKER_PLANE, shapes=False, lights=False))
    reference, _ = mitsuba_mrt.render_reference(scene)
    refine = mitsuba_mrt.render(scene, mode="refine")
    fast = mitsuba_mrt.render(scene, mode="fast")
    assert "skipped_albedo_division" not in refine.stats  # albedo varies within the plane
    assert paper_error(refine.image, reference) <= paper_error(fast.image, reference) + 1e-6


def test_silhouette_pixels_are_unmixed_by_the_id_pass_albedo(variant, monkeypatch):
    # a pixel on the sphere's outline shows the sphere and the plane; from its
    # own region's light alone it was off by the other's share
    from mitsuba_mrt.modes import idpass

    scene = mi.load_string(small_scene_xml(64, lights=False, extra=(
        '<emitter type="point"><point name="position" x="2" y="2" z="5"/>'
        '<rgb name="intensity" value="60"/></emitter>')))
    reference, _ = mitsuba_mrt.render_reference(scene, spp=64)
    unmixed = {}

    def recording(irradiance, albedo, ids, keep, modulation):
        image, unmixed["mask"] = unmix_edges(irradiance, albedo, ids, keep, modulation)
        return image, unmixed["mask"]

    unmix_edges = idpass.unmix_edges
    monkeypatch.setattr(idpass, "unmix_edges", recording)
    result = mitsuba_mrt.render(scene, mode="idpass", spp=16)  # 16 albedo samples a pixel
    monkeypatch.setattr(idpass, "unmix_edges", lambda irradiance, albedo, ids, keep, modulation: (
        irradiance * modulation, np.zeros(ids.shape, bool)))
    plain = mitsuba_mrt.render(scene, mode="idpass", spp=16)
    mask = unmixed["mask"]
    assert mask.sum() == result.stats["unmixed_pixels"] > 20
    error = np.abs(result.image - reference)[mask].mean()
    assert error < 0.85 * np.abs(plain.image - reference)[mask].mean()


GLASS_BALL = path_camera_xml(64, 16, "gaussian") + """
  <shape type="sphere"><float name="radius" value="1.2"/><bsdf type="dielectric"/></shape>
  <shape type="rectangle">
    <transform name="to_world"><scale value="20"/><rotate x="1" angle="-90"/><translate y="-1.2"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.9"/></bsdf></shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>"""


def test_glass_beside_a_diffuse_surface_is_not_divided_by_its_albedo(variant):
    # glass shows the floor (its albedo: the floor's) and the sky (albedo 0):
    # a glass pixel with a little of the floor in its footprint divided its
    # radiance by that little albedo, interpolated with the sky's, taken as radiance
    scene = mi.load_string(GLASS_BALL)
    reference, _ = mitsuba_mrt.render_reference(scene, spp=256)
    for mode in ("idpass", "fast"):
        result = mitsuba_mrt.render(scene, mode=mode)
        glass = (result.ids == result.ids[32, 32]) & ~result.traced_mask
        assert result.image[glass].max() <= 1.5 * reference[glass].max(), mode


LIGHT_ON_A_WALL = path_camera_xml(64, 16, "tent", max_depth=3) + """
  <shape type="rectangle">
    <transform name="to_world"><scale value="10"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf></shape>
  <shape type="rectangle">
    <transform name="to_world"><scale value="0.6"/><translate z="0.5"/></transform>
    <emitter type="area"><rgb name="radiance" value="60"/></emitter></shape>
  <emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
</scene>"""


def test_a_wall_beyond_the_filters_reach_of_a_light_is_not_lit_by_its_halo(variant):
    # the tent filter mixes the wall's pixels next to the light with its light;
    # interpolated (and smoothed, their noise being large) with the rest of the
    # wall, those samples lit it far beyond: 9.7x the truth's brightest before
    scene = mi.load_string(LIGHT_ON_A_WALL)
    reference, _ = mitsuba_mrt.render_reference(scene, spp=256)
    result = mitsuba_mrt.render(scene, mode="idpass")  # (fast's own ids draw the light smaller)
    light = result.ids == result.ids[32, 32]
    near = ndimage.binary_dilation(light, np.ones((3, 3), bool))  # the tent's reach: one pixel
    wall = ~near & (result.ids == result.ids[2, 2]) & ~result.traced_mask
    assert result.image[wall].max() <= 1.5 * reference[wall].max()
