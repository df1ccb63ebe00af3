import mitsuba as mi
import numpy as np
import pytest

import mitsuba_mrt
from mitsuba_mrt import grid_pattern
from mitsuba_mrt.metrics import paper_error
from mitsuba_mrt.refine import refine_edges
from conftest import small_scene_xml, true_ids


def disc_ids(h, w, cx, cy, radius):
    yy, xx = np.mgrid[:h, :w]
    return ((xx - cx) ** 2 + (yy - cy) ** 2 < radius ** 2).astype(np.int64)


@pytest.mark.parametrize("fraction", [0.1, 0.03])
def test_refinement_recovers_every_id_of_a_disc(fraction):
    truth = disc_ids(150, 170, 80.3, 70.7, 41.2)
    p = grid_pattern(170, 150, fraction)
    calls = []

    def trace_ids(points):
        calls.append(len(points))
        return truth[points[:, 1], points[:, 0]]

    refined, traced = refine_edges(p, truth[np.ix_(p.rows, p.cols)], trace_ids)
    ids = np.where(refined >= 0, refined, p.nearest_image(truth[np.ix_(p.rows, p.cols)]))
    assert np.array_equal(ids, truth)
    extra = sum(calls)
    assert extra < 0.1 * truth.size  # cost follows the edge, not the area
    assert len(calls) <= 6  # one launch per level


def test_refinement_traces_nothing_without_edges():
    p = grid_pattern(50, 50, 0.1)
    refined, traced = refine_edges(p, np.ones(p.grid_shape, int), lambda pts: 1 / 0)
    assert traced == []


def test_refine_mode_on_a_sphere_matches_the_full_trace(variant):
    scene = mi.load_string(small_scene_xml(64))
    refined = mitsuba_mrt.render(scene, mode="refine")
    assert (refined.ids != true_ids(scene)).mean() < 0.002  # at most features thinner than a sub-cell
    assert 0 < refined.stats["refined_fraction"] < 0.3
    reference, _ = mitsuba_mrt.render_reference(scene)
    fast = mitsuba_mrt.render(scene, mode="fast")
    assert paper_error(refined.image, reference) < 0.5 * paper_error(fast.image, reference)
    assert np.allclose(refined.image[refined.traced_mask], reference[refined.traced_mask],
                       atol=1e-6)
