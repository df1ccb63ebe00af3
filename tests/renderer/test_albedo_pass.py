"""The id pass's albedo in two steps: one sample per pixel, then the pixels where it varies."""

import mitsuba as mi
import numpy as np
import pytest

from helpers import small_scene_xml
from mitsuba_mrt.renderer import albedo_pass as ap
from mitsuba_mrt.renderer.develop import _develop_jit, _develop_scalar
from mitsuba_mrt.renderer.lanes import is_jit
from mitsuba_mrt.renderer.trace import trace_pixels

RES = 40
CHECKER = ('<shape type="rectangle"><transform name="to_world"><scale value="3"/>'
           '<translate z="0.5"/></transform><bsdf type="diffuse">'
           '<texture type="checkerboard" name="reflectance"><rgb name="color0" value="0.1"/>'
           '<rgb name="color1" value="0.9"/><transform name="to_uv"><scale value="4"/>'
           '</transform></texture></bsdf></shape>')


def _scene(filter_xml: str = '<rfilter type="gaussian"/>'):
    xml = small_scene_xml(RES, extra=CHECKER).replace('<rfilter type="box"/>', filter_xml)
    return mi.load_string(xml.replace('value="1"/><boolean name="jitter" value="false"/>',
                                      'value="16"/>'))


def _every():
    return np.stack(np.meshgrid(np.arange(RES), np.arange(RES)), -1).reshape(-1, 2)


def _id_pass(scene, spp, seed):
    sensor = scene.sensors()[0]
    return trace_pixels(scene, sensor, scene.integrator(), _every(), spp, seed,
                        radiance=False, replay=True)


def _one_step(scene, spp, seed):
    sensor = scene.sensors()[0]
    sampler = sensor.sampler().clone()
    sampler.set_sample_count(spp)
    develop = _develop_jit if is_jit() else _develop_scalar
    return ap.albedo_pass(develop, scene, sensor, sampler, _every(), seed, True, False, None)


@pytest.mark.parametrize("filter_xml", ['<rfilter type="gaussian"/>', '<rfilter type="box"/>'])
def test_two_steps_are_as_close_to_the_converged_albedo_as_one(variant, filter_xml):
    # the second step splats its samples as the one-step pass does: its pixels
    # are as exact as a one-step pass's (a pixel developed from its own 16
    # samples alone would be twice as far off through the gaussian filter)
    scene = _scene(filter_xml)
    if not is_jit():
        pytest.skip("the scalar variant's pass is slow; the code path is the same")
    converged = np.mean([_one_step(scene, 16, 100 + k).albedo for k in range(8)], axis=0)
    two = np.mean([np.abs(_id_pass(scene, 16, s).albedo - converged).mean() for s in range(3)])
    one = np.mean([np.abs(_one_step(scene, 16, s).albedo - converged).mean()
                   for s in range(3)])
    assert two < 1.25 * one


def test_only_pixels_near_a_change_take_the_second_step(variant, monkeypatch):
    scene = _scene()
    marked = []
    real = ap.varied_pixels
    monkeypatch.setattr(ap, "varied_pixels", lambda *a: marked.append(real(*a)) or marked[-1])
    trace = _id_pass(scene, 16, 0)
    again = marked[-1]
    assert 0 < again.mean() < 1
    # a pixel left with its one sample sees one diffuse colour: its albedo is exact
    flat = trace.albedo[~again & (trace.shape_index > 0)]
    colours = {0.1, 0.9, 0.5, 0.8, 0.2}  # checker squares, floor, the sphere's channels
    assert len(flat) and np.isin(np.round(flat, 5), list(colours)).all()


def test_through_a_box_filter_the_second_step_is_the_splatted_one_without_a_block(variant):
    # no sample leaves its pixel: each pixel's own sums give what the image
    # block's splat gives (same samples; float32 sums added in another order)
    scene = _scene('<rfilter type="box"/>')
    sensor = scene.sensors()[0]
    sampler = sensor.sampler().clone()
    sampler.set_sample_count(16)
    develop = _develop_jit if is_jit() else _develop_scalar
    xy = _every()[::7]
    own = ap._second_step(develop, scene, sensor, sampler, xy, 0, 16, 5, False, False)
    splat = develop(scene, sensor, None, sampler, xy, 16, 5, True, False, False, xy)
    assert own.albedo.shape == (len(xy), 3)
    np.testing.assert_allclose(own.albedo, splat.albedo, rtol=1e-5, atol=1e-6)
    assert 0.05 < own.albedo.mean() < 0.95


# -- where every surface is one colour: the first step from the scene --------------------------

#: Two cards seen from behind (rotated to face away from the camera): a
#: ``twosided`` one, which shows its second BSDF there, and a one-sided one,
#: black from behind.
CARDS = ''.join(
    f'<shape type="rectangle" id="card_{k}"><transform name="to_world">'
    f'<rotate y="1" angle="180"/><translate x="{x}" y="1.5" z="1"/></transform>{bsdf}</shape>'
    for k, (x, bsdf) in enumerate([
        (-1.8, '<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" '
               'value="0.3, 0.6, 0.9"/></bsdf><bsdf type="diffuse"><rgb name="reflectance" '
               'value="0.7, 0.4, 0.1"/></bsdf></bsdf>'),
        (1.8, '<bsdf type="diffuse"><rgb name="reflectance" value="0.9, 0.9, 0.2"/></bsdf>')]))


def _passes_with_and_without_the_table(scene, monkeypatch):
    from mitsuba_mrt.renderer import trace as trace_module

    marked, traces = [], []
    real = ap.varied_pixels
    monkeypatch.setattr(ap, "varied_pixels", lambda *a: marked.append(real(*a)) or marked[-1])
    traces.append(_id_pass(scene, 16, 0))
    monkeypatch.setattr(trace_module, "shape_albedos", lambda s: None)  # the step traced
    traces.append(_id_pass(scene, 16, 0))
    return traces, marked


def test_one_colour_surfaces_give_the_first_step_without_tracing_it(variant, monkeypatch):
    from mitsuba_mrt.renderer.scene_query import shape_albedos

    scene = mi.load_string(small_scene_xml(RES, extra=CARDS).replace(
        'value="1"/><boolean name="jitter" value="false"/>', 'value="16"/>'))
    table = shape_albedos(scene)
    assert table is not None and table.shape == (5, 2, 3)
    (mine, traced), (again, again_traced) = _passes_with_and_without_the_table(scene, monkeypatch)
    assert np.array_equal(mine.shape_index, traced.shape_index)
    # away from a change of surface one sample's albedo is the table's, bit for bit
    flat = ~again & ~again_traced & (mine.shape_index > 0)
    assert flat.sum() > RES * RES // 2
    assert np.array_equal(mine.albedo[flat], traced.albedo[flat])
    seen = {tuple(np.round(a, 5)) for a in mine.albedo[flat]}
    assert (0.7, 0.4, 0.1) in seen  # the two-sided card's back
    card = np.round(table[3, 0], 5)  # (id order: ball, card_0, card_1, floor)
    assert tuple(card) == (0.9, 0.9, 0.2) and tuple(card) not in seen  # one-sided: black behind
    assert mine.albedo[flat].min() == 0.0


@pytest.mark.parametrize("extra", [CHECKER, '<shape type="shapegroup" id="group"><shape type='
                                   '"sphere"><bsdf type="diffuse"/></shape></shape><shape type='
                                   '"instance"><ref id="group"/></shape>'],
                         ids=["a texture", "an instance"])
def test_the_table_is_only_for_shapes_of_one_colour_each(variant, extra):
    from mitsuba_mrt.renderer.scene_query import shape_albedos

    assert shape_albedos(mi.load_string(small_scene_xml(RES, extra=extra))) is None
