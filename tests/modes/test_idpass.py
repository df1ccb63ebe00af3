import mitsuba as mi
import numpy as np

import mitsuba_mrt
from mitsuba_mrt.recon.metrics import paper_error
from helpers import small_scene_xml

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
    from mitsuba_mrt.recon.compose import safe_albedo

    scene = mi.load_string(small_scene_xml(64, lights=False, extra=(
        '<emitter type="point"><point name="position" x="2" y="2" z="5"/>'
        '<rgb name="intensity" value="60"/></emitter>')))
    reference, _ = mitsuba_mrt.render_reference(scene, spp=64)
    unmixed = {}

    def recording(irradiance, albedo, ids, keep):
        image, unmixed["mask"] = unmix_edges(irradiance, albedo, ids, keep)
        return image, unmixed["mask"]

    unmix_edges = idpass.unmix_edges
    monkeypatch.setattr(idpass, "unmix_edges", recording)
    result = mitsuba_mrt.render(scene, mode="idpass", spp=16)  # 16 albedo samples a pixel
    monkeypatch.setattr(idpass, "unmix_edges", lambda irradiance, albedo, ids, keep: (
        irradiance * safe_albedo(albedo), np.zeros(ids.shape, bool)))
    plain = mitsuba_mrt.render(scene, mode="idpass", spp=16)
    mask = unmixed["mask"]
    assert mask.sum() == result.stats["unmixed_pixels"] > 20
    error = np.abs(result.image - reference)[mask].mean()
    assert error < 0.85 * np.abs(plain.image - reference)[mask].mean()
