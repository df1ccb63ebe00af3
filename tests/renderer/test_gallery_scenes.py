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
