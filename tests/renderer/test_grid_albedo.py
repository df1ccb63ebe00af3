"""A traced pixel's albedo from a few samples where every shape's albedo is one colour."""

import mitsuba as mi
import numpy as np
import pytest

from helpers import small_scene_xml
from mitsuba_mrt.renderer import trace as trace_module
from mitsuba_mrt.renderer.lanes import is_jit
from mitsuba_mrt.renderer.scene_query import albedo_per_shape

RES, SPP = 32, 16
SAMPLER = '<sampler type="independent"><integer name="sample_count" value="16"/></sampler>'


def _scene(extra: str = ""):
    xml = small_scene_xml(RES, extra=extra)
    start = xml.index('<sampler type="stratified">')
    stop = xml.index("</sampler>", start) + len("</sampler>")
    return mi.load_string(xml[:start] + SAMPLER + xml[stop:])


def _shape(bsdf: str) -> str:
    return (f'<shape type="sphere" id="extra"><point name="center" x="2" y="1" z="0"/>'
            f'<float name="radius" value="0.5"/>{bsdf}</shape>')


@pytest.mark.parametrize("bsdf, one_colour", [
    ('<bsdf type="diffuse"><rgb name="reflectance" value="0.3"/></bsdf>', True),
    ('<bsdf type="twosided"><bsdf type="diffuse"/></bsdf>', True),
    ('<bsdf type="diffuse"><texture type="checkerboard" name="reflectance"/></bsdf>', False),
    ('<bsdf type="roughplastic"/>', False),
    ('<bsdf type="twosided"><bsdf type="roughplastic"/></bsdf>', False),
    ('<bsdf type="conductor"/>', False),
])
def test_the_albedo_is_one_colour_per_shape_only_for_plain_diffuse_bsdfs(variant, bsdf,
                                                                        one_colour):
    assert albedo_per_shape(_scene(_shape(bsdf))) is one_colour


def _all_but_one() -> np.ndarray:
    # every pixel but the first: a set of pixels traced each from its own samples
    xy = np.stack(np.meshgrid(np.arange(RES), np.arange(RES)), -1).reshape(-1, 2)
    return xy[1:]


def _traced(scene, monkeypatch, samples: int):
    monkeypatch.setattr(trace_module, "ALBEDO_FIRST_SAMPLES", samples)
    sensor = scene.sensors()[0]
    return trace_module.trace_pixels(scene, sensor, scene.integrator(), _all_but_one(), SPP,
                                     seed=3, replay=True)


def _near_another_shape(shape_index: np.ndarray) -> np.ndarray:
    """Pixels of ``_all_but_one`` with a shape (or none) of another index in
    their 3 x 3 neighbourhood: a straight edge through a box-filtered pixel
    passes between its centre and one of its neighbours' centres."""
    ids = np.concatenate([[-1], shape_index]).reshape(RES, RES)
    padded = np.pad(ids, 1, mode="edge")
    near = np.zeros((RES, RES), dtype=bool)
    for dy in range(3):
        for dx in range(3):
            near |= padded[dy:dy + RES, dx:dx + RES] != ids
    return near.ravel()[1:]


def test_a_few_samples_give_the_albedo_where_they_agree(variant, monkeypatch):
    if not is_jit():
        pytest.skip("the scalar variant traces every sample's albedo")
    scene = _scene()
    assert albedo_per_shape(scene)
    every, few = _traced(scene, monkeypatch, 0), _traced(scene, monkeypatch, 4)
    # the radiance is the same samples', untouched; CUDA compiles the two
    # kernels' arithmetic apart (fused multiply-adds), so there to 1e-6
    exact = not mi.variant().startswith("cuda")
    for name in ("radiance", "variance", "alpha", "shape_index", "normal"):
        if exact or name == "shape_index":
            np.testing.assert_array_equal(getattr(few, name), getattr(every, name))
        else:
            np.testing.assert_allclose(getattr(few, name), getattr(every, name),
                                       rtol=1e-6, atol=1e-6)
    differs = np.abs(few.albedo - every.albedo).max(axis=1) > 1e-6
    near = _near_another_shape(every.shape_index)
    # only pixels across an edge were traced again, from samples of their own
    assert differs.any() and not (differs & ~near).any()
    # and their albedo is still a mixture of the two sides'
    assert (few.albedo >= 0.0).all() and (few.albedo <= 0.8 + 1e-6).all()


def test_pixels_whose_first_samples_disagree_trace_their_albedo_again(variant, monkeypatch):
    if not is_jit():
        pytest.skip("the scalar variant traces every sample's albedo")
    from mitsuba_mrt.renderer.develop import _develop_jit

    scene = _scene()
    sensor = scene.sensors()[0]
    sampler = sensor.sampler().clone()
    first = _develop_jit(scene, sensor, scene.integrator(), sampler, _all_but_one(), SPP, 3,
                         True, False, normals=False, albedo_samples=4)
    traced = _traced(scene, monkeypatch, 4)
    varies = first.albedo_varies
    assert varies.any() and not (varies & ~_near_another_shape(traced.shape_index)).any()
    # elsewhere the first samples' albedo is the pixel's; there, another trace's
    kept = ~varies & (traced.shape_index > 0)
    np.testing.assert_array_equal(traced.albedo[kept], first.albedo[kept])
    assert (np.abs(traced.albedo[varies] - first.albedo[varies]).max(axis=1) > 0).mean() > 0.5


def test_as_many_first_samples_as_the_spp_are_every_samples_albedo(variant, monkeypatch):
    scene = _scene()
    every, few = _traced(scene, monkeypatch, 0), _traced(scene, monkeypatch, SPP)
    np.testing.assert_allclose(few.albedo, every.albedo, rtol=0, atol=1e-6)


def test_a_textured_scene_traces_every_samples_albedo(variant, monkeypatch):
    textured = _shape('<bsdf type="diffuse"><texture type="checkerboard" '
                      'name="reflectance"/></bsdf>')
    scene = _scene(textured)
    every, few = _traced(scene, monkeypatch, 0), _traced(scene, monkeypatch, 4)
    np.testing.assert_array_equal(few.albedo, every.albedo)


def test_in_a_spectral_variant_every_sample_has_its_own_albedo(variant):
    # each sample's albedo is that of its own wavelengths: a few would not do
    try:
        mi.set_variant("scalar_spectral")
        assert not albedo_per_shape(_scene())
    finally:
        mi.set_variant(variant)
    assert albedo_per_shape(_scene())


@pytest.mark.parametrize("mode", ["fast", "refine"])
def test_one_colour_per_shape_needs_no_division_by_albedo(variant, mode):
    # the grid's pixels across the ball's silhouette mix two albedos, so the
    # samples alone would not show every id's albedo to be one colour
    import mitsuba_mrt
    from mitsuba_mrt.recon.compose import albedo_constant_per_id

    result = mitsuba_mrt.render(_scene(), mode=mode, sample_fraction=0.3)
    trace = result.trace
    assert trace.albedo_per_shape
    assert not albedo_constant_per_id(trace.ids("exact"), trace.albedo)
    assert result.skips.albedo_division == 1
    textured = mitsuba_mrt.render(_scene(_shape('<bsdf type="diffuse"><texture '
                                                'type="checkerboard" name="reflectance"/>'
                                                '</bsdf>')), mode=mode, sample_fraction=0.3)
    assert not textured.trace.albedo_per_shape and textured.skips.albedo_division == 0


def test_a_filter_with_negative_lobes_keeps_every_samples_albedo(variant, monkeypatch):
    # a negative lobe weighs its samples -1: the squares' spread says nothing there
    from mitsuba_mrt.renderer.pixel_filter import filter_table

    assert filter_table(mi.load_dict({"type": "lanczos"})).negative
    assert not filter_table(mi.load_dict({"type": "gaussian"})).negative
    xml = small_scene_xml(RES).replace('<rfilter type="box"/>', '<rfilter type="lanczos"/>')
    start = xml.index('<sampler type="stratified">')
    stop = xml.index("</sampler>", start) + len("</sampler>")
    scene = mi.load_string(xml[:start] + SAMPLER + xml[stop:])
    every, few = _traced(scene, monkeypatch, 0), _traced(scene, monkeypatch, 4)
    np.testing.assert_array_equal(few.albedo, every.albedo)
