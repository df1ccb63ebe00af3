import numpy as np
import pytest

from mitsuba_mrt import MRTError, grid_pattern


def test_report_grid_counts_and_borders():
    p = grid_pattern(200, 200, 0.1)
    # n = 4000, a = 63 columns, b = ceil(4000 / 63) = 64 rows
    assert p.grid_shape == (64, 63)
    assert p.count == p.mask.sum() == 64 * 63
    assert p.cols[0] == 0 and p.cols[-1] == 199 and p.rows[0] == 0 and p.rows[-1] == 199
    assert np.array_equal(p.cols, np.linspace(0, 199, 63).astype(int))


def test_pixel_order_is_rows_outer_columns_inner():
    p = grid_pattern(10, 7, 0.3)
    xy = p.pixel_xy
    assert np.array_equal(xy[: len(p.cols), 0], p.cols)
    assert np.all(xy[: len(p.cols), 1] == p.rows[0])
    assert np.array_equal(p.mask[xy[:, 1], xy[:, 0]], np.ones(p.count, bool))


def test_full_fraction_traces_every_pixel():
    for w, h in [(5, 5), (3, 8), (8, 3)]:
        assert grid_pattern(w, h, 1.0).mask.all()


@pytest.mark.parametrize("f", [0, -0.1, 1.5, float("nan"), "x"])
def test_bad_fraction(f):
    with pytest.raises(MRTError, match="sample_fraction"):
        grid_pattern(10, 10, f)


def test_to_image_scatters():
    p = grid_pattern(6, 6, 0.25)
    img = p.to_image(np.arange(p.count), fill=-1)
    assert (img[p.mask] == np.arange(p.count)).all() and (img[~p.mask] == -1).all()
