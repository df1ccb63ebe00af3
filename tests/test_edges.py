import numpy as np
import pytest
from scipy import ndimage

from mitsuba_mrt import MRTError, SamplePattern, grid_pattern
from mitsuba_mrt.edges import quadtree_fill, smooth_ids


def pattern(h, w, rows, cols):
    return SamplePattern(w, h, np.array(rows), np.array(cols))


def test_uniform_grid_fills_everything():
    p = pattern(5, 5, [0, 2, 4], [0, 2, 4])
    out = quadtree_fill(p, np.full((3, 3), 7))
    assert (out == 7).all()


def test_two_halves_worked_by_hand():
    # 4 x 4 image, known pixels at rows/cols {0, 3}; left column id 1, right id 2.
    # Root splits at row 2 / col 2: each quadrant holds one known corner pixel,
    # so each 2 x 2 quadrant takes its corner's id.
    p = pattern(4, 4, [0, 3], [0, 3])
    out = quadtree_fill(p, np.array([[1, 2], [1, 2]]))
    expected = np.array([[1, 1, 2, 2]] * 4)
    assert np.array_equal(out, expected)


def test_empty_quadrant_takes_id_nearest_to_its_outer_corner():
    # 4 x 4 image, known pixels only in rows {0, 1} and cols {0, 1}.
    # Root: ids differ -> split at (2, 2).  Top-left quadrant holds all four
    # known pixels; the other three are empty and take the known pixel
    # nearest to their outer corner: (0, 3) -> (0, 1); (3, 0) -> (1, 0);
    # (3, 3) -> (1, 1).
    p = pattern(4, 4, [0, 1], [0, 1])
    grid = np.array([[1, 2], [3, 4]])
    out = quadtree_fill(p, grid)
    assert np.array_equal(out[:2, :2], grid)
    assert (out[:2, 2:] == 2).all() and (out[2:, :2] == 3).all() and (out[2:, 2:] == 4).all()


def test_one_pixel_wide_rectangles_split_in_two():
    p = pattern(1, 6, [0], [0, 1, 2, 3, 4, 5])
    grid = np.array([[1, 1, 1, 2, 2, 2]])
    assert np.array_equal(quadtree_fill(p, grid), grid)


def test_disc_is_found_up_to_grid_spacing():
    h = w = 120
    yy, xx = np.mgrid[:h, :w]
    truth = ((xx - 60) ** 2 + (yy - 50) ** 2 < 30 ** 2).astype(int) + 2 * (yy > 100)
    p = grid_pattern(w, h, 0.1)
    out = quadtree_fill(p, truth[np.ix_(p.rows, p.cols)])
    assert (out[p.mask] == truth[p.mask]).all()  # known pixels keep their ids
    assert (out != truth).mean() < 0.03
    # every wrong pixel lies within one grid spacing of an edge
    edge = ndimage.binary_dilation(ndimage.morphological_gradient(truth, size=3) > 0,
                                   iterations=4)
    assert not ((out != truth) & ~edge).any()


def test_grid_shape_checked():
    with pytest.raises(MRTError, match="grid_ids"):
        quadtree_fill(pattern(4, 4, [0, 3], [0, 3]), np.zeros((3, 3)))


def naive_smooth(ids, sigma, cutoff):
    out = ids.copy()
    for v in np.unique(ids):
        if v == 0:
            continue
        g = ndimage.gaussian_filter((out == v).astype(float), sigma)
        if g.max() > 0:
            out[g / g.max() > cutoff] = v
    return out


@pytest.mark.parametrize("sigma,cutoff", [(1.0, 0.05), (2.0, 0.2), (4.0, 0.15)])
def test_smoothing_matches_whole_image_filter(sigma, cutoff):
    rng = np.random.default_rng(1)
    ids = ndimage.zoom(rng.integers(0, 4, (6, 7)), 10, order=0)
    ids[:3, :5] = 9  # a small id at the border
    assert np.array_equal(smooth_ids(ids, sigma, cutoff), naive_smooth(ids, sigma, cutoff))


def test_smoothing_grows_a_point_by_the_cutoff_radius():
    ids = np.zeros((9, 9), dtype=int)
    ids[4, 4] = 3
    out = smooth_ids(ids, 1.0, 0.05)
    # exp(-r^2 / 2) > 0.05 for r^2 < 5.99: the 21 pixels with dx^2 + dy^2 <= 5
    assert (out == 3).sum() == 21 and out[4, 4] == 3


def test_zero_sigma_is_identity_and_bad_values_rejected():
    ids = np.arange(16).reshape(4, 4)
    assert np.array_equal(smooth_ids(ids, 0.0, 0.05), ids)
    with pytest.raises(MRTError, match="filter_sigma"):
        smooth_ids(ids, -1.0, 0.05)
    with pytest.raises(MRTError, match="filter_cutoff"):
        smooth_ids(ids, 1.0, 1.5)


def test_id_swallowed_by_an_earlier_id_does_not_crash():
    ids = np.ones((10, 10), dtype=int)
    ids[5, 5] = 2  # id 2 is one pixel inside id 1
    ids[0, 0] = 3
    out = smooth_ids(ids, 1.0, 0.05)
    assert set(np.unique(out)) <= {1, 2, 3}
