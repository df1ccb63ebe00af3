import mitsuba as mi
import numpy as np
import pytest

import mitsuba_mrt
from mitsuba_mrt import grid_pattern
from mitsuba_mrt.recon.metrics import paper_error
from mitsuba_mrt.modes.refine import refine_edges
from helpers import small_scene_xml


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


def test_flagged_samples_are_traced_down_to_pixels():
    # one id everywhere (no edge) and a flagged disc (a curved mirror, say):
    # the disc is traced pixel by pixel, nothing away from it
    truth = np.ones((60, 80), dtype=np.int64)
    flagged = disc_ids(60, 80, 40.0, 30.0, 12.0).astype(bool)
    p = grid_pattern(80, 60, 0.1)
    seen = np.zeros_like(flagged)

    def trace_ids(points):
        seen[points[:, 1], points[:, 0]] = True
        return truth[points[:, 1], points[:, 0]], flagged[points[:, 1], points[:, 0]]

    refine_edges(p, truth[np.ix_(p.rows, p.cols)], trace_ids, flagged[np.ix_(p.rows, p.cols)])
    seen |= p.mask
    inner = disc_ids(60, 80, 40.0, 30.0, 12.0 - 4).astype(bool)  # a cell inside the disc
    outer = disc_ids(60, 80, 40.0, 30.0, 12.0 + 5).astype(bool)  # a cell around it
    assert seen[inner].all()
    assert not seen[~outer & ~p.mask].any()
    # without the flags nothing is traced
    assert refine_edges(p, truth[np.ix_(p.rows, p.cols)], lambda pts: 1 / 0)[1] == []


def test_refine_mode_on_a_sphere_matches_the_full_trace(variant, true_ids):
    scene = mi.load_string(small_scene_xml(64))
    refined = mitsuba_mrt.render(scene, mode="refine")
    assert (refined.ids != true_ids(scene)).mean() < 0.002  # at most features thinner than a sub-cell
    assert 0 < refined.stats["refined_fraction"] < 0.3
    reference, _ = mitsuba_mrt.render_reference(scene)
    fast = mitsuba_mrt.render(scene, mode="fast")
    assert paper_error(refined.image, reference) < 0.5 * paper_error(fast.image, reference)
    assert np.allclose(refined.image[refined.traced_mask], reference[refined.traced_mask],
                       atol=1e-6)


def test_refine_traces_cells_whose_shading_the_grid_cannot_follow():
    # one id, a narrow bright stripe that a grid column crosses: ids see nothing,
    # the samples beside it disagree, and its cells are traced
    from mitsuba_mrt import MRTParams, SparseTrace, grid_pattern, reconstruct
    from mitsuba_mrt.types import SeedStream

    height, width = 40, 40
    truth = np.full((height, width, 3), 0.2)
    truth[12:20, 20:23] = 5.0  # a short stripe through grid column 21, within the budget
    pattern = grid_pattern(width, height, 0.1)

    def trace_at(xy):
        n = len(xy)
        return SparseTrace(truth[xy[:, 1], xy[:, 0]], np.ones((n, 3)), np.ones(n, np.int64),
                           np.zeros(n, np.uint32), 0, 1, 0.0, variance=np.zeros((n, 3)))

    def tracer(xy, *, stream=SeedStream.EDGES, aovs=True, radiance=True, replay=False,
               pad=False, albedo=True):
        return trace_at(xy)

    out = reconstruct(pattern, trace_at(pattern.pixel_xy), MRTParams(), "refine", tracer)
    assert out.stats["rough_cells"] > 0
    assert out.traced_mask[12:20, 20:23].all()
    assert np.allclose(out.image[12:20, 20:23], 5.0)
    assert out.stats["refined_pixels"] <= 0.3 * height * width  # ROUGH_BUDGET


def test_refine_finds_edges_along_a_single_grid_row():
    # a 1-pixel-high image: the grid is one row, its cells have no height
    from mitsuba_mrt import MRTParams, SparseTrace, grid_pattern, reconstruct
    from mitsuba_mrt.types import SeedStream

    shapes = np.array([1] * 6 + [2] * 13 + [1] * 5 + [3])  # a second stripe of shape 1
    values = np.where(shapes == 1, 1.0, np.where(shapes == 2, 100.0, 50.0))
    pattern = grid_pattern(25, 1, 4 / 25)  # one grid row of 10 columns

    def trace_at(xy):
        n = len(xy)
        return SparseTrace(np.repeat(values[xy[:, 0], None], 3, 1), np.ones((n, 3)),
                           shapes[xy[:, 0]].astype(np.int64), np.zeros(n, np.uint32), 0, 1,
                           0.0)

    def tracer(xy, *, stream=SeedStream.EDGES, aovs=True, radiance=True, replay=False,
               pad=False, albedo=True):
        return trace_at(xy)

    out = reconstruct(pattern, trace_at(pattern.pixel_xy), MRTParams(), "refine", tracer)
    every = np.stack([np.arange(25), np.zeros(25, np.int64)], axis=1)
    assert np.array_equal(out.ids[0], trace_at(every).ids("exact"))
    assert np.allclose(out.image[0, :, 0], values)
