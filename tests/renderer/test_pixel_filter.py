"""The tabulated filter distribution: a sample's cell found from the guide table."""

import mitsuba as mi
import numpy as np
import pytest

from mitsuba_mrt.renderer.develop import filter_cell, filter_offset
from mitsuba_mrt.renderer.pixel_filter import GUIDE_BINS, FilterTable, filter_table
from mitsuba_mrt.renderer.lanes import is_jit


def _uniform_numbers(table: FilterTable) -> np.ndarray:
    """Random numbers in [0, 1), and the hard ones: the bins' and the cells'
    edges and their float32 neighbours, 0 and the largest float32 below 1."""
    edges = np.concatenate([np.arange(GUIDE_BINS) / GUIDE_BINS, table.cdf[:-1]]).astype(np.float32)
    near = np.concatenate([edges, np.nextafter(edges, np.float32(0)),
                           np.nextafter(edges, np.float32(1))])
    random = np.random.default_rng(5).random(20000).astype(np.float32)
    u = np.concatenate([near, random, [0.0, np.nextafter(np.float32(1), np.float32(0))]])
    return u[(u >= 0) & (u < 1)].astype(np.float32)


@pytest.mark.parametrize("name", ["box", "tent", "gaussian", "lanczos", "mitchell",
                                  "catmullrom"])
def test_the_guide_table_finds_the_cell_a_bisection_of_the_whole_table_finds(variant, name):
    if not is_jit():
        pytest.skip("the kernels' search: JIT variants")
    table = filter_table(mi.load_dict({"type": name}))
    first, steps = table.guide
    cells = len(table.pdf)
    cdf = mi.Float(table.cdf.astype(np.float32))
    u = _uniform_numbers(table)
    found = filter_cell(mi.Float(u), cdf, mi.UInt32(first), steps, cells).numpy()
    import drjit as dr
    whole = dr.binary_search(0, cells - 1,
                             lambda i: dr.gather(mi.Float, cdf, i + 1) <= mi.Float(u)).numpy()
    assert np.array_equal(found, whole)
    assert steps < cells // 8  # the guide narrows the search


def test_a_uniform_filters_guide_leaves_one_step():
    first, steps = FilterTable.from_values(0.5, np.ones(8)).guide
    assert steps == 1
    assert first[0] == 0 and first[-1] == 7


def test_a_box_filters_offsets_need_no_search_and_are_the_searched_ones_bit_for_bit(variant):
    if not is_jit():
        pytest.skip("the kernels' search: JIT variants")
    table = filter_table(mi.load_dict({"type": "box"}))
    assert table.uniform and not filter_table(mi.load_dict({"type": "tent"})).uniform
    first, steps = table.guide
    u = mi.Float(_uniform_numbers(table))
    args = (mi.Float(table.cdf.astype(np.float32)), mi.UInt32(first))
    direct = filter_offset(u, *args, None, len(table.pdf), table.radius).numpy()
    searched = filter_offset(u, *args, steps, len(table.pdf), table.radius).numpy()
    assert np.array_equal(direct, searched)


@pytest.mark.parametrize("name", ["box", "tent", "gaussian", "lanczos"])
def test_pixel_weights_are_the_filter_over_a_pixel_and_a_box_s_are_one(variant, name):
    from mitsuba_mrt.renderer.pixel_filter import filter_reach, pixel_weights

    rfilter = mi.load_dict({"type": name})
    weights = pixel_weights(rfilter)
    assert len(weights) == 2 * filter_reach(float(rfilter.radius())) + 1
    assert np.allclose(weights, weights[::-1])  # (Mitsuba's filters are symmetric)
    assert weights.argmax() == len(weights) // 2
    if name == "box":
        assert weights.tolist() == [1.0]
    if name == "lanczos":  # a negative lobe
        assert weights.min() < 0


def test_through_filter_keeps_a_uniform_image_and_spreads_a_pixel_as_its_weights(variant):
    from mitsuba_mrt.renderer.pixel_filter import pixel_weights, through_filter

    weights = pixel_weights(mi.load_dict({"type": "gaussian"}))
    assert np.allclose(through_filter(np.full((6, 7, 3), 0.3), weights), 0.3)
    image = np.zeros((9, 9, 1))
    image[4, 4] = 1.0
    spread = through_filter(image, weights)[..., 0]
    assert np.allclose(spread[2:7, 2:7], np.outer(weights, weights) / weights.sum() ** 2)
    assert through_filter(image, np.array([1.0])) is not image  # (a box: the same values)
    assert np.array_equal(through_filter(image, np.array([1.0])), image)
