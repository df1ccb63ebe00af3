import mitsuba as mi
import numpy as np
import pytest

import mitsuba_mrt
from mitsuba_mrt.recon.metrics import edge_mask, error_map
from helpers import small_scene_xml

# A mirror facing the camera, two spheres behind the camera: they are seen
# only in the mirror.


def two_spheres(x: float, z: float, radius: float, light_z: float, intensity: float) -> str:
    """A red sphere at (-x, 0, z), a green one at (x, 0, z), a point light at (0, 0, light_z)."""
    return "".join(
        f'<shape type="sphere" id="{name}"><point name="center" x="{sign * x}" y="0" z="{z}"/>'
        f'<float name="radius" value="{radius}"/><bsdf type="diffuse">'
        f'<rgb name="reflectance" value="{colour}"/></bsdf></shape>'
        for name, sign, colour in (("b_red", -1, "0.9, 0.1, 0.1"), ("c_green", 1, "0.1, 0.9, 0.1"))
    ) + (f'<emitter type="point"><point name="position" x="0" y="0" z="{light_z}"/>'
         f'<rgb name="intensity" value="{intensity}"/></emitter>')


MIRROR_SCENE = """
  <shape type="rectangle" id="a_mirror">
    <transform name="to_world"><scale value="4"/></transform>
    <bsdf type="conductor"><string name="material" value="none"/></bsdf>
  </shape>""" + two_spheres(1.6, 12, 1.2, 9, 100)


def test_a_mirror_reflecting_two_spheres_yields_two_regions(variant):
    scene = mi.load_string(small_scene_xml(64, extra=MIRROR_SCENE, shapes=False, lights=False))
    result = mitsuba_mrt.render(scene, mode="paper", sample_fraction=1.0)
    trace = result.trace
    assert trace.curved_mirror is None  # a planar mirror: refinement as usual
    on_mirror = trace.shape_index == 1
    lit = on_mirror & (trace.radiance.sum(axis=1) > 0)
    chains = set(trace.path_id[lit].tolist())
    assert len(chains) == 2  # mirror->red and mirror->green
    reds = trace.radiance[lit & (trace.path_id == min(chains))]
    greens = trace.radiance[lit & (trace.path_id == max(chains))]
    assert (reds[:, 0] > reds[:, 1]).all() and (greens[:, 1] > greens[:, 0]).all()
    # the report's rule sees only the mirror: one id for both reflections
    assert len(set(trace.ids("paper")[lit].tolist())) == 1
    assert len(set(trace.ids("exact")[lit].tolist())) == 2
    # demodulated by the reflected albedo times the mirror's reflectance
    assert np.allclose(trace.albedo[lit & (trace.path_id == min(chains))][0], [0.9, 0.1, 0.1])


# A cut-out (a mask BSDF: opaque squares, holes between) before two spheres,
# a light between it and them.
CUTOUT_SCENE = """
  <shape type="rectangle" id="a_cutout">
    <transform name="to_world"><scale value="3"/><translate z="2"/></transform>
    <bsdf type="mask"><texture type="checkerboard" name="opacity">
        <rgb name="color0" value="0"/><rgb name="color1" value="1"/>
        <transform name="to_uv"><scale x="4" y="4"/></transform></texture>
      <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.2, 0.9"/></bsdf></bsdf>
  </shape>""" + two_spheres(1.2, 0, 1, 1.2, 10)


def test_a_cutouts_holes_take_the_ids_of_what_they_show(variant):
    # a leaf's opaque texels are the leaf's region; its holes are those of
    # what they show, as a mirror's pixels are those of what it reflects
    # (path passes the holes as a bounce: direct light at the spheres takes depth 3)
    direct = '<integrator type="path"><integer name="max_depth" value="3"/></integrator>'
    scene = mi.load_string(small_scene_xml(64, direct, extra=CUTOUT_SCENE, shapes=False,
                                           lights=False))
    trace = mitsuba_mrt.render(scene, mode="paper", sample_fraction=1.0).trace
    assert (trace.shape_index == 1).all()  # the cut-out covers the image (the report's id)
    exact = trace.ids("exact")
    red = trace.radiance[:, 0] > 2 * trace.radiance[:, 1] + 0.01
    green = trace.radiance[:, 1] > 2 * trace.radiance[:, 0] + 0.01
    assert red.sum() > 20 and green.sum() > 20
    # one region each, apart: the holes over the red sphere, those over the green one
    assert len(set(exact[red].tolist())) == 1 and len(set(exact[green].tolist())) == 1
    assert exact[red][0] != exact[green][0]
    # and the opaque squares' (the most common id: the squares are half the cut-out)
    squares = np.bincount(np.unique(exact, return_inverse=True)[1]).argmax()
    assert np.unique(exact)[squares] not in (exact[red][0], exact[green][0])


def test_refinement_resolves_reflected_edges(variant):
    from mitsuba_mrt.renderer.scene_query import ordered_shapes

    res = 200
    scene = mitsuba_mrt.load_scene("scenes_xml/paper_fig1_conductor.xml", res=res)
    mirror_index = 1 + [s.id() for s in ordered_shapes(scene)].index("obj_4_sphere")
    reference, _ = mitsuba_mrt.render_reference(scene)
    full = mitsuba_mrt.render(scene, mode="paper", sample_fraction=1.0)
    ids = full.trace.ids("exact").reshape(res, res)
    edge = edge_mask(ids)
    in_mirror = full.trace.shape_index.reshape(res, res) == mirror_index
    assert (edge & in_mirror).sum() > 100  # the reflections have edges of their own
    refined = mitsuba_mrt.render(scene, mode="refine")
    refine = error_map(refined.image, reference)
    fast = error_map(mitsuba_mrt.render(scene, mode="fast").image, reference)
    # the curved mirror's pixels are traced in full: its minified reflections
    # are thinner than the grid cells, and their corners cannot see them
    assert refined.stats["curved_mirror_samples"] > 0
    assert refined.traced_mask[in_mirror].all()
    assert refine[edge & in_mirror].mean() <= refine[edge & ~in_mirror].mean()
    assert refine[edge & in_mirror].mean() < 0.1 * fast[edge & in_mirror].mean()


def _in_a_group(shape_xml: str, group: str, instances: list[str]) -> str:
    """``shape_xml`` inside a shape group, and instances of it (each a transform's XML)."""
    return (f'<shape type="shapegroup" id="{group}">{shape_xml}</shape>'
            + "".join(f'<shape type="instance" id="{group}_{k}"><ref id="{group}"/>'
                      f'<transform name="to_world">{t}</transform></shape>'
                      for k, t in enumerate(instances)))


def test_a_mirror_inside_a_shape_group_is_followed(variant):
    from mitsuba_mrt.renderer.scene_query import ordered_shapes

    # an instance's own BSDF is a default diffuse: the mirror in its group
    # was not seen, the id pass did not follow it, and both reflections
    # were one region
    mirror = MIRROR_SCENE.split("</shape>")[0] + "</shape>"
    spheres = MIRROR_SCENE[len(mirror):]
    extra = _in_a_group(mirror, "mirror_group", ['<translate x="0"/>']) + spheres
    scene = mi.load_string(small_scene_xml(64, extra=extra, shapes=False, lights=False))
    result = mitsuba_mrt.render(scene, mode="paper", sample_fraction=1.0)
    trace = result.trace
    mirror_index = 1 + [s.id() for s in ordered_shapes(scene)].index("mirror_group_0")
    lit = (trace.shape_index == mirror_index) & (trace.radiance.sum(axis=1) > 0)
    assert lit.sum() > 50
    assert len(set(trace.path_id[lit].tolist())) == 2
    assert len(set(trace.ids("exact")[lit].tolist())) == 2


def test_instances_show_their_own_groups_bsdfs(variant):
    from mitsuba_mrt.renderer.scene_query import (_shape_groups, curved_mirror_indices,
                                                  diffuse_shapes, has_mirrors, ordered_shapes)

    matte = ('<shape type="sphere" id="m"><float name="radius" value="0.5"/>'
             '<bsdf type="diffuse"/></shape>')
    chrome = ('<shape type="cube" id="c"><transform name="to_world"><scale value="0.3"/>'
              '</transform><bsdf type="conductor"/></shape>')
    extra = (_in_a_group(matte, "a_matte", ['<translate x="-2"/>', '<translate x="-1" y="2"/>'])
             + _in_a_group(chrome, "b_chrome", ['<scale value="2"/><translate x="2"/>',
                                                '<rotate y="1" angle="30"/><translate y="-2"/>']))
    scene = mi.load_string(small_scene_xml(16, extra=extra, shapes=False))
    names = [shape.id() for shape in ordered_shapes(scene)]
    assert sorted(s.id() for _, inner in _shape_groups(scene) for s in inner) == ["c", "m"]
    assert has_mirrors(scene)
    assert diffuse_shapes(scene)[1:].tolist() == [n.startswith("a_") for n in names]
    assert curved_mirror_indices(scene).tolist() == [k + 1 for k, n in enumerate(names)
                                                     if n.startswith("b_")]


@pytest.mark.parametrize("bsdf, delta", [('<bsdf type="diffuse"/>', False),
                                         ('<bsdf type="roughconductor"/>', False),
                                         ('<bsdf type="conductor"/>', True),
                                         ('<bsdf type="dielectric"/>', True),
                                         ('<bsdf type="plastic"/>', True)])
def test_a_scene_has_delta_lobes_where_a_bsdf_may_sample_one(variant, bsdf, delta):
    # a sample's albedo follows delta bounces only in scenes that have them
    from mitsuba_mrt.renderer.scene_query import has_delta_lobes

    extra = f'<shape type="cube">{bsdf}</shape>'
    assert has_delta_lobes(mi.load_string(small_scene_xml(16, extra=extra))) is delta


def test_the_shapes_alone_are_the_ids_shape_index(variant):
    from mitsuba_mrt.recon.sampling import every_pixel
    from mitsuba_mrt.renderer.trace import trace_pixels, trace_shapes

    # instances of two groups, a mirror and the background: the one-ray
    # kernel names the same shape in every pixel as the ids' full kernel
    mirror = MIRROR_SCENE.split("</shape>")[0] + "</shape>"
    spheres = MIRROR_SCENE[len(mirror):]
    mirror = mirror.replace('<scale value="4"/>', '<scale value="2"/>')  # and the background
    extra = (_in_a_group('<shape type="sphere" id="m"><float name="radius" value="0.5"/>'
                         '<bsdf type="diffuse"/></shape>', "a_matte",
                         ['<translate x="-2"/>', '<translate x="-1" y="2"/>'])
             + mirror + spheres)
    scene = mi.load_string(small_scene_xml(32, extra=extra, shapes=False))
    sensor = scene.sensors()[0]
    xy = every_pixel(32, 32)
    ids = trace_pixels(scene, sensor, scene.integrator(), xy, 1, radiance=False,
                       albedo=False).shape_index
    assert len(set(ids.tolist())) >= 3 and (ids == 0).any()
    assert np.array_equal(trace_shapes(scene, sensor, xy), ids)
    assert np.array_equal(trace_shapes(scene, sensor, xy, replay=True), ids)
