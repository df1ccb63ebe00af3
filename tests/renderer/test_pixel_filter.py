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
