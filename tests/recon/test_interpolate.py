import numpy as np
import pytest

from mitsuba_mrt import MRTError
from mitsuba_mrt.recon.interpolate import interpolate_regions, select_centres


def grid_xy(n, step=1):
    xx, yy = np.meshgrid(np.arange(0, n, step), np.arange(0, n, step))
    return np.stack([xx.ravel(), yy.ravel()], axis=1)


def test_capstones_are_kept_when_subsampling():
    xy = grid_xy(60)
    bright = -((xy[:, 0] - 30.0) ** 2 + (xy[:, 1] - 30.0) ** 2)
    chosen = select_centres(xy, bright, max_inpoints=200, num_cappoints=10)
    assert len(chosen) <= 200
    order = np.argsort(bright, kind="stable")
    brightest, darkest = order[-10:], order[:10]
    assert set(brightest) <= set(chosen) and set(darkest) <= set(chosen)
    corners = {0, 59, 60 * 59, 60 * 60 - 1}
    assert corners <= set(chosen)  # convex hull vertices


def test_all_samples_below_max_inpoints():
    xy = grid_xy(10)
    assert len(select_centres(xy, xy[:, 0] * 1.0, max_inpoints=2000)) == 100


def test_collinear_samples_hull_fallback():
    xy = np.stack([np.arange(50), np.arange(50)], axis=1)
    chosen = select_centres(xy, np.zeros(50), max_inpoints=10, num_cappoints=1)
    assert 0 in chosen and 49 in chosen and len(chosen) <= 10


def test_regions_use_only_their_own_samples():
    ids = np.zeros((10, 10), dtype=int)
    ids[:, 5:] = 1
    xy = grid_xy(10, 3)
    sid = (xy[:, 0] >= 5).astype(int)
    vals = np.where(sid == 1, 100.0, 1.0)[:, None] + xy[:, :1] * 0.01
    out = interpolate_regions(ids, xy, sid, vals, rbf_degree=1).values[..., 0]
    assert out[:, :5].max() < 2 and out[:, 5:].min() > 99


@pytest.mark.parametrize("n_samples", [1, 2])
def test_one_or_two_samples_give_finite_values(n_samples):
    ids = np.ones((6, 6), dtype=int)
    xy = np.array([[1, 1], [4, 4]])[:n_samples]
    res = interpolate_regions(ids, xy, np.ones(n_samples, int), np.arange(1.0, n_samples + 1)[:, None])
    assert np.isfinite(res.values).all()
    if n_samples == 1:
        assert (res.values == 1.0).all() and res.counts["constant"] == 1


def test_collinear_samples_give_finite_values():
    ids = np.ones((8, 8), dtype=int)
    xy = np.stack([np.arange(8), np.full(8, 3)], axis=1)
    res = interpolate_regions(ids, xy, np.ones(8, int), np.arange(8.0)[:, None], rbf_degree=1)
    assert np.isfinite(res.values).all()
    assert np.allclose(res.values[3, :, 0], np.arange(8.0))


def test_all_equal_samples_fill_without_rbf():
    ids = np.ones((8, 8), dtype=int)
    xy = grid_xy(8, 2)
    res = interpolate_regions(ids, xy, np.ones(len(xy), int), np.full((len(xy), 3), 0.25))
    assert (res.values == 0.25).all()
    assert res.counts == {"constant": 1}


def test_id_without_samples_takes_the_nearest_sample():
    ids = np.ones((6, 6), dtype=int)
    ids[0, 0] = 9  # e.g. an id that appears only after smoothing
    xy = np.array([[1, 1], [5, 5]])
    res = interpolate_regions(ids, xy, np.array([1, 1]), np.array([[2.0], [4.0]]))
    assert res.values[0, 0, 0] == 2.0 and res.counts["no_samples"] == 1
    assert np.isfinite(res.values).all()


def test_linear_field_is_reproduced_with_degree_one():
    ids = np.zeros((30, 30), dtype=int)
    xy = grid_xy(30, 3)
    f = lambda p: 1.0 + 0.1 * p[:, 0] + 0.2 * p[:, 1]
    res = interpolate_regions(ids, xy, np.zeros(len(xy), int), f(xy)[:, None], rbf_degree=1)
    full = grid_xy(30)
    assert np.allclose(res.values.reshape(-1), f(full), atol=1e-8)


def test_rejects_non_finite_values_and_empty_input():
    ids = np.zeros((4, 4), dtype=int)
    with pytest.raises(MRTError, match="finite"):
        interpolate_regions(ids, np.array([[0, 0]]), np.array([0]), np.array([[np.inf]]))
    with pytest.raises(MRTError, match="zero samples"):
        interpolate_regions(ids, np.zeros((0, 2)), np.zeros(0, int), np.zeros((0, 1)))


def test_constant_regions_are_found_at_every_scale():
    # Found by the stress suite: the spread was compared with
    # CONSTANT_RTOL * max(1, |max|), so at 1e-6 samples 1 and 1.5 counted as
    # all equal (filled with their mean) and at 1 they did not (interpolated).
    ids = np.ones((1, 4), dtype=int)
    xy = np.array([[0, 0], [3, 0]])
    values = np.array([[1.0], [1.5]])
    base = interpolate_regions(ids, xy, np.ones(2, int), values)
    for k in (1e-6, 1e-30, 3e30):
        scaled = interpolate_regions(ids, xy, np.ones(2, int), values * k)
        assert scaled.counts == base.counts == {"rbf": 1}
        assert np.allclose(scaled.values, base.values * k, rtol=1e-12)
    tiny = interpolate_regions(ids, xy, np.ones(2, int), np.array([[1e-30], [1e-30 * (1 + 1e-9)]]))
    assert tiny.counts == {"constant": 1}


def test_rbf_of_huge_values_is_finite():
    ids = np.ones((12, 12), dtype=int)
    xy = grid_xy(12)
    values = np.random.default_rng(0).uniform(0.5, 1.0, (len(xy), 3)) * 3.0e38
    res = interpolate_regions(ids, xy, np.ones(len(xy), int), values, rbf_degree=1)
    assert np.isfinite(res.values).all()
    assert np.allclose(res.values.reshape(-1, 3), values, rtol=1e-9)


def test_an_rbf_too_large_for_the_memory_is_refused_before_its_solve(monkeypatch):
    # --max-inpoints 1e8 on a 1000-px image: an id of 40,000 samples would
    # allocate 19 GB for its solve (a MemoryError or the kernel's OOM killer)
    from mitsuba_mrt.recon import interpolate
    monkeypatch.setattr(interpolate, "CHECKED_CENTRES", 0)
    monkeypatch.setattr(interpolate, "available_memory", lambda: 2 * 12 * 50 * 50)
    ids = np.zeros((20, 20), dtype=int)
    xy = np.stack(np.meshgrid(np.arange(0, 20, 2), np.arange(0, 20, 2)), -1).reshape(-1, 2)
    values = (xy[:, :1] + 1.0) * np.ones((1, 3))
    interpolate_regions(ids, xy, np.zeros(len(xy), int), values, max_inpoints=50)
    with pytest.raises(MRTError, match="an RBF through 100 centres needs .* lower max_inpoints"):
        interpolate_regions(ids, xy, np.zeros(len(xy), int), values, max_inpoints=100)
