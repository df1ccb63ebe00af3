"""The gallery of ordinary Mitsuba scenes (scenes_xml/gallery, written by tools/make_gallery.py).

Every scene loads and renders small in the session's variant, and the
committed files are exactly what the generator writes.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
GALLERY = ROOT / "scenes_xml" / "gallery"
SCENE_FILES = sorted(GALLERY.glob("*.xml"))


def _generator():
    spec = importlib.util.spec_from_file_location("make_gallery", ROOT / "tools" / "make_gallery.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_gallery_has_the_scenes():
    names = {p.stem for p in SCENE_FILES}
    assert len(names) >= 8
    assert names == set(_generator().SCENES)


@pytest.mark.parametrize("path", SCENE_FILES, ids=lambda p: p.stem)
def test_scene_loads_and_renders(path):
    import mitsuba as mi

    scene = mi.load_file(str(path), res="16", spp="4")
    assert scene.sensors(), path.name
    for k, sensor in enumerate(scene.sensors()):
        assert tuple(sensor.film().crop_size()) == (16, 16)
        img = np.array(mi.render(scene, sensor=k, spp=4))
        assert img.shape[:2] == (16, 16)
        assert np.isfinite(img).all(), (path.name, k)
        assert (img >= 0).all(), (path.name, k)
        assert img[..., :3].mean() > 0, (path.name, k)


def test_every_shape_has_an_id():
    import xml.etree.ElementTree as ET

    for path in SCENE_FILES:
        for node in ET.parse(path).getroot().iter("shape"):
            assert node.get("id"), (path.name, node.get("type"))


def test_generator_reproduces_the_committed_files(tmp_path):
    _generator().write_gallery(tmp_path)
    fresh, committed = _tree(tmp_path), _tree(GALLERY)
    assert sorted(fresh) == sorted(committed)
    changed = [rel for rel in fresh if fresh[rel] != committed[rel]]
    assert not changed, f"rerun tools/make_gallery.py: {changed} differ"


def test_instances_are_regions_of_their_own():
    # a hit on an instance of a shape group reports the group's inner shape,
    # which the scene does not list: it used to count as no shape at all, so
    # every instance merged with the background and was not demodulated
    import mitsuba_mrt
    from mitsuba_mrt.renderer.scene_query import ordered_shapes
    from mitsuba_mrt.renderer.trace import trace_pixels

    scene = mitsuba_mrt.load_scene(GALLERY / "instanced.xml", res=32, spp=1)
    instances = {k + 1 for k, s in enumerate(ordered_shapes(scene))
                 if s.class_name() == "Instance"}
    xy = np.stack(np.meshgrid(np.arange(32), np.arange(32)), -1).reshape(-1, 2)
    trace = trace_pixels(scene, scene.sensors()[0], scene.integrator(), xy, 1)
    seen = set(np.unique(trace.shape_index).tolist())
    assert len(seen & instances) >= 20  # most of the 25 cups are in view
    on_instances = np.isin(trace.shape_index, list(instances))
    # demodulated: a pixel's one sample may miss the cup its centre sees
    assert (trace.albedo[on_instances] > 0).any(axis=1).mean() > 0.8
    # and a cup and the ball in it are two regions, though one instance
    exact = trace.ids("exact")[on_instances]
    assert len(np.unique(exact)) > len(np.unique(trace.shape_index[on_instances]))


def test_a_second_load_of_a_scene_gives_the_same_ids():
    # the shapes inside a shape group were numbered process-wide, by address and
    # on first sight: a second load of the scene gave other ids in many pixels
    import mitsuba_mrt

    renders = [mitsuba_mrt.render(mitsuba_mrt.load_scene(GALLERY / "instanced.xml", res=64,
                                                         spp=4), mode="fast")
               for _ in range(2)]
    np.testing.assert_array_equal(renders[0].ids, renders[1].ids)
    np.testing.assert_array_equal(renders[0].image, renders[1].image)


def test_the_scalar_variant_numbers_inner_shapes_alike(variant):
    # the two variants report a hit inside a group by other keys (a Dr.Jit
    # pointer, a C++ address), and must find the same number for it
    import mitsuba as mi

    import mitsuba_mrt
    from mitsuba_mrt.renderer.trace import trace_pixels

    if variant.startswith("scalar"):
        pytest.skip("needs a JIT variant to compare with")
    xy = np.stack(np.meshgrid(np.arange(16), np.arange(16)), -1).reshape(-1, 2)

    def ids():
        scene = mitsuba_mrt.load_scene(GALLERY / "instanced.xml", res=16, spp=1)
        trace = trace_pixels(scene, scene.sensors()[0], scene.integrator(), xy, 1,
                             radiance=False)
        return trace.shape_index, trace.path_id

    jit = ids()
    try:
        mi.set_variant("scalar_rgb")
        scalar = ids()
    finally:
        mi.set_variant(variant)
    same = jit[0] == scalar[0]
    assert same.mean() > 0.9 and (jit[1][same] != jit[0][same]).any()  # inner shapes seen
    np.testing.assert_array_equal(jit[1][same], scalar[1][same])
