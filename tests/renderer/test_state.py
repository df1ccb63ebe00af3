"""clear_caches: every cache of the process dropped, and no image changed."""

from __future__ import annotations

import mitsuba as mi
import numpy as np

import mitsuba_mrt
from helpers import small_scene_xml
from mitsuba_mrt.recon import denoise, rbf_fast
from mitsuba_mrt.renderer import develop, guides, pixel_filter, replay
from mitsuba_mrt.renderer.guides import render_guides
from mitsuba_mrt.renderer.state import clear_caches

PATH = '<integrator type="path"><integer name="max_depth" value="3"/></integrator>'


def _renders(scene) -> list:
    """Images whose making fills the caches: replayed traces, the pixel
    filter's table, the guides' integrator, OIDN's device and filter where
    it is installed."""
    images = [mitsuba_mrt.render(scene, mode=mode, seed=3).image for mode in ("fast", "refine")]
    images += list(render_guides(scene)[:2])
    if denoise.oidn_available():
        images.append(mitsuba_mrt.render(scene, mode="fast", denoise="oidn", seed=3).image)
    return images


def test_clearing_the_caches_between_renders_changes_no_image(variant):
    scene = mi.load_string(small_scene_xml(24, integrator=PATH))
    before = _renders(scene)
    clear_caches()
    assert replay.recordings() == 0 and not replay._held
    assert not (develop._BOX_FILTERS or guides._integrators or pixel_filter._TABLES
                or denoise._state)
    assert rbf_fast._tensor_weights.cache_info().currsize == 0
    after = _renders(scene)
    assert len(after) == len(before)
    for one, other in zip(before, after):
        np.testing.assert_array_equal(one, other)
