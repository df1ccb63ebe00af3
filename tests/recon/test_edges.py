import numpy as np
import pytest
from scipy import ndimage

from mitsuba_mrt import MRTError, SamplePattern, grid_pattern
from mitsuba_mrt.recon import edges
from mitsuba_mrt.recon.edges import quadtree_fill, smooth_ids


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


def test_empty_grid_rejected():
    with pytest.raises(MRTError, match="no traced pixel"):
        quadtree_fill(pattern(4, 4, [], [0, 3]), np.zeros((0, 2)))


def _quadtree_fill_reference(p, grid_ids):
    """The previous loop version of quadtree_fill, kept to check the vectorised one.

    A stack of rectangles ``(r0, r1, c0, c1)``; each is filled if its grid
    block is uniform, else split into (up to) four quadrants, of which those
    without a grid row or column take the id of the parent's grid pixel
    nearest to their outer corner.
    """
    grid_ids = np.asarray(grid_ids, dtype=np.int64)
    rows, cols = p.rows, p.cols
    nearest_rows, nearest_cols = p.nearest_rows, p.nearest_cols
    out = np.zeros((p.height, p.width), dtype=np.int64)
    stack = [(0, p.height, 0, p.width)]
    while stack:
        r0, r1, c0, c1 = stack.pop()
        i0, i1 = np.searchsorted(rows, (r0, r1))
        j0, j1 = np.searchsorted(cols, (c0, c1))
        block = grid_ids[i0:i1, j0:j1]
        first = block.flat[0]
        if (block == first).all():
            out[r0:r1, c0:c1] = first
            continue
        rm = (r0 + r1) // 2 if r1 - r0 > 1 else r1
        cm = (c0 + c1) // 2 if c1 - c0 > 1 else c1
        for qr0, qr1, qc0, qc1, corner_r, corner_c in (
                (r0, rm, c0, cm, r0, c0), (r0, rm, cm, c1, r0, c1 - 1),
                (rm, r1, c0, cm, r1 - 1, c0), (rm, r1, cm, c1, r1 - 1, c1 - 1)):
            if qr0 >= qr1 or qc0 >= qc1:
                continue
            has_rows = np.searchsorted(rows, qr1) > np.searchsorted(rows, qr0)
            has_cols = np.searchsorted(cols, qc1) > np.searchsorted(cols, qc0)
            if has_rows and has_cols:
                stack.append((qr0, qr1, qc0, qc1))
            else:
                i = min(max(nearest_rows[corner_r], i0), i1 - 1)
                j = min(max(nearest_cols[corner_c], j0), j1 - 1)
                out[qr0:qr1, qc0:qc1] = grid_ids[i, j]
    return out


def _random_lines(rng, length):
    """Sorted unique grid lines in [0, length): sparse, dense or clustered."""
    kind = rng.integers(3)
    if kind == 0:
        n = rng.integers(1, length + 1)
        lines = rng.choice(length, size=n, replace=False)
    elif kind == 1:
        lines = rng.choice(length, size=rng.integers(1, min(length, 3) + 1), replace=False)
    else:  # a cluster in one part of the axis
        lo = rng.integers(length)
        hi = rng.integers(lo, length) + 1
        lines = rng.choice(np.arange(lo, hi), size=rng.integers(1, hi - lo + 1), replace=False)
    return np.sort(lines).astype(np.int64)


def _random_ids(rng, p):
    """Grid ids: noise of few ids, a blocky image sampled at the grid, or huge ids."""
    kind = rng.integers(4)
    if kind == 0:
        return rng.integers(0, rng.integers(1, 4), p.grid_shape)
    if kind == 1:  # a few random rectangles painted over a background
        image = np.zeros((p.height, p.width), dtype=np.int64)
        for value in range(1, rng.integers(1, 6)):
            r0, c0 = rng.integers(p.height), rng.integers(p.width)
            image[r0:r0 + rng.integers(1, p.height + 1), c0:c0 + rng.integers(1, p.width + 1)] = value
        return image[np.ix_(p.rows, p.cols)]
    if kind == 2:  # a coarse random image, upsampled
        coarse = rng.integers(0, 3, (rng.integers(1, 6), rng.integers(1, 6)))
        image = coarse[np.arange(p.height) * coarse.shape[0] // p.height][
            :, np.arange(p.width) * coarse.shape[1] // p.width]
        return image[np.ix_(p.rows, p.cols)]
    values = np.array([-2 ** 63, 2 ** 62 + 1, -5, 7], dtype=np.int64)
    return values[rng.integers(0, 2, p.grid_shape) * rng.integers(1, 4)]


def test_vectorised_fill_matches_reference_loop():
    rng = np.random.default_rng(12345)
    for case in range(500):
        h, w = rng.integers(1, 61, 2)
        if case % 10 == 0:  # one-pixel-wide images
            h, w = (1, w) if case % 20 == 0 else (h, 1)
        if rng.random() < 0.5:
            p = grid_pattern(w, h, rng.choice([rng.random(), rng.random() * 0.05, 1.0]) or 1.0)
        else:
            p = SamplePattern(int(w), int(h), _random_lines(rng, h), _random_lines(rng, w))
        grid = _random_ids(rng, p)
        expected = _quadtree_fill_reference(p, grid)
        assert np.array_equal(quadtree_fill(p, grid), expected), (case, h, w, p)


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
@pytest.mark.parametrize("row_blocks", [False, True])
def test_smoothing_matches_whole_image_filter(sigma, cutoff, row_blocks, monkeypatch):
    if row_blocks:  # every rectangle blurred in row blocks on threads
        monkeypatch.setattr(edges, "PARALLEL_AREA", 1)
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
    for sigma in (-1.0, float("nan"), 101.0):
        with pytest.raises(MRTError, match="filter_sigma"):
            smooth_ids(ids, sigma, 0.05)
    with pytest.raises(MRTError, match="filter_cutoff"):
        smooth_ids(ids, 1.0, 1.5)


def test_id_swallowed_by_an_earlier_id_does_not_crash():
    ids = np.ones((10, 10), dtype=int)
    ids[5, 5] = 2  # id 2 is one pixel inside id 1
    ids[0, 0] = 3
    out = smooth_ids(ids, 1.0, 0.05)
    assert set(np.unique(out)) <= {1, 2, 3}


@pytest.mark.parametrize("sigma", [0.6, 1.0, 2.5])
@pytest.mark.parametrize("row_blocks", [False, True])
def test_blur_is_gaussian_filter_bit_for_bit(sigma, row_blocks, monkeypatch):
    # the threshold compares float32 blurs, so they must be scipy's own values
    if row_blocks:
        monkeypatch.setattr(edges, "PARALLEL_AREA", 1)
    rng = np.random.default_rng(3)
    mask = ndimage.zoom(rng.random((9, 11)) < 0.5, 7, order=0)[:, 3:]  # a strided view
    reach = int(4.0 * sigma + 0.5)
    blurred = edges._blurred_mask(mask, edges.gaussian_weights(sigma, reach))
    expected = ndimage.gaussian_filter(mask.astype(np.float32), sigma)
    assert blurred.dtype == np.float32 and np.array_equal(blurred, expected)


@pytest.mark.parametrize("with_background", [True, False])
def test_smoothing_ranks_equals_smoothing_ids(with_background):
    # the fast mode smooths int16 ranks of the ids; order and background kept
    from mitsuba_mrt.recon.ids import rank_ids

    rng = np.random.default_rng(7)
    ids = ndimage.zoom(rng.choice([0, 5, 1 << 33, 3 << 32, 9], (7, 8)), 9, order=0)
    if not with_background:
        ids[ids == 0] = 9
    labels, ranks = rank_ids(ids)
    background = int(np.searchsorted(labels, 0)) if labels[0] == 0 else -1
    smoothed = smooth_ids(ranks, 1.0, 0.05, background)
    assert smoothed.dtype == np.int16
    assert np.array_equal(labels[smoothed], smooth_ids(ids, 1.0, 0.05))


def test_threshold_without_division_selects_what_the_division_does():
    rng = np.random.default_rng(11)
    peaks = np.concatenate([rng.random(300), [1.0, 0.999999, 1e-6, 0.5]]).astype(np.float32)
    cutoffs = np.concatenate([rng.random(300), [0.0, 1.0, 0.05, 0.5]])
    for peak, cutoff in zip(peaks[peaks > 0], cutoffs.tolist()):  # a Python float, as in smooth_ids
        t = edges.least_above(cutoff, peak)
        near = np.array([t, np.nextafter(t, np.float32(0)), np.nextafter(t, np.float32(2))],
                        dtype=np.float32)
        values = np.concatenate([near, (rng.random(50) * peak).astype(np.float32), [0, peak]])
        values = values.astype(np.float32)
        assert np.array_equal(values >= t, values / peak > cutoff), (peak, cutoff)


def test_quadtree_fill_beyond_the_grid_boxes_is_smoothed_without_crash():
    # Found by the stress suite: a 1 x 4 grid on an 8 x 2 image.  The empty
    # cell of rows [1, 2) x columns [0, 4) takes id 1 from the sample at
    # column 0, although column 3 is nearer to the sample of id 2 at column
    # 2; boxes from the grid (region_boxes) end at column 2 and the
    # smoothing's masks did not fit.  id_boxes reads the map itself.
    from mitsuba_mrt.recon.edges import id_boxes

    p = grid_pattern(8, 2, 0.3)
    filled = quadtree_fill(p, np.array([[1, 2, 2, 2]]))
    assert filled[1, 3] == 1
    assert id_boxes(filled)[1] == (0, 2, 0, 4)
    assert np.array_equal(smooth_ids(filled, 1.0, 0.05, boxes=id_boxes(filled)),
                          smooth_ids(filled, 1.0, 0.05))


@pytest.mark.parametrize("seed", range(5))
def test_id_boxes_are_the_tight_boxes(seed):
    from mitsuba_mrt.recon.edges import id_boxes

    rng = np.random.default_rng(seed)
    ids = rng.integers(0, 4, (int(rng.integers(1, 9)), int(rng.integers(1, 9))))
    want = {}
    for v in np.unique(ids).tolist():
        r, c = np.nonzero(ids == v)
        want[v] = (r.min(), r.max() + 1, c.min(), c.max() + 1)
    assert id_boxes(ids) == want


def test_smoothing_in_a_geometric_order_ignores_the_numbering():
    # the report's order (increasing ids) lets the larger number grow over the
    # smaller; an order decided by the samples gives the same regions whatever
    # the numbers
    from mitsuba_mrt.recon.edges import geometric_order

    rng = np.random.default_rng(4)
    h, w = 30, 34
    yy, xx = np.mgrid[:h, :w]
    sx, sy = rng.uniform(0, w, 5), rng.uniform(0, h, 5)
    ids = np.argmin((xx[..., None] - sx) ** 2 + (yy[..., None] - sy) ** 2, axis=-1)
    order = geometric_order(ids)
    out = smooth_ids(ids, 1.5, 0.05, background=-1, order=order)
    new = np.array([40, 7, 300, 2, 11])
    again = smooth_ids(new[ids], 1.5, 0.05, background=-1, order=geometric_order(new[ids]))
    assert np.array_equal(again, new[out])
    assert not np.array_equal(smooth_ids(new[ids], 1.5, 0.05, background=-1), again)
    # the order given is the order used: the report's is the increasing one
    assert np.array_equal(smooth_ids(ids, 1.5, 0.05, -1, order=np.unique(ids)),
                          smooth_ids(ids, 1.5, 0.05, -1))
