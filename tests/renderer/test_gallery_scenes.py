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
