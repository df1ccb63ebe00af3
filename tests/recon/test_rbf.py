import numpy as np
import pytest
from scipy.interpolate import Rbf, RBFInterpolator

from mitsuba_mrt import MRTError
from mitsuba_mrt.recon import rbf_fast
from mitsuba_mrt.recon.rbf import LinearRBF

rng = np.random.default_rng(0)
CENTRES = rng.uniform(0, 100, (200, 2))
VALUES = np.sin(CENTRES[:, 0] / 9) + CENTRES[:, 1] / 40
QUERY = rng.uniform(-10, 110, (500, 2))


def test_degree_minus_one_is_the_legacy_scipy_rbf():
    legacy = Rbf(CENTRES[:, 0], CENTRES[:, 1], VALUES, function="linear")
    ours = LinearRBF(CENTRES, VALUES, degree=-1)
    assert np.allclose(ours(QUERY), legacy(QUERY[:, 0], QUERY[:, 1]), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("degree", [0, 1])
def test_degree_zero_and_one_match_rbfinterpolator(degree):
    ref = RBFInterpolator(CENTRES, VALUES, kernel="linear", degree=degree)
    assert np.allclose(LinearRBF(CENTRES, VALUES, degree)(QUERY), ref(QUERY), atol=1e-9)


@pytest.mark.parametrize("degree", [-1, 0, 1])
def test_exact_at_centres(degree):
    assert np.allclose(LinearRBF(CENTRES, VALUES, degree)(CENTRES), VALUES, atol=1e-9)


@pytest.mark.parametrize("degree", [0, 1])
def test_exact_for_constant_fields(degree):
    rbf = LinearRBF(CENTRES, np.full(len(CENTRES), 2.5), degree)
    assert np.allclose(rbf(QUERY), 2.5, atol=1e-10)


def linear_field(xy):
    return 3.0 + 0.5 * xy[:, 0] - 2.0 * xy[:, 1]


def test_degree_one_is_exact_for_linear_fields():
    rbf = LinearRBF(CENTRES, linear_field(CENTRES), degree=1)
    assert np.allclose(rbf(QUERY), linear_field(QUERY), atol=1e-8)


def test_collinear_centres_stay_solvable_and_exact_along_the_line():
    t = np.arange(12.0)
    line = np.stack([t, 2 * t + 1], axis=1)
    rbf = LinearRBF(line, linear_field(line), degree=1)
    on_line = np.stack([t + 0.5, 2 * (t + 0.5) + 1], axis=1)
    assert np.allclose(rbf(on_line), linear_field(on_line), atol=1e-9)
    assert np.isfinite(rbf(QUERY)).all()


@pytest.mark.parametrize("n", [1, 2])
def test_one_or_two_centres(n):
    rbf = LinearRBF(CENTRES[:n], VALUES[:n], degree=1)
    assert np.allclose(rbf(CENTRES[:n]), VALUES[:n])
    assert np.isfinite(rbf(QUERY)).all()


def test_vector_values_share_the_system():
    vals = np.stack([VALUES, 2 * VALUES, -VALUES], axis=1)
    out = LinearRBF(CENTRES, vals, -1)(QUERY)
    single = LinearRBF(CENTRES, VALUES, -1)(QUERY)
    assert out.shape == (len(QUERY), 3)
    assert np.allclose(out, single[:, None] * [1, 2, -1])


def test_chunked_evaluation_is_seamless(monkeypatch):
    import mitsuba_mrt.recon.rbf as rbf_module

    full = LinearRBF(CENTRES, VALUES)(QUERY)
    monkeypatch.setattr(rbf_module, "EVAL_BLOCK_ELEMENTS", 1000)
    assert np.allclose(LinearRBF(CENTRES, VALUES)(QUERY), full, rtol=1e-12, atol=1e-12)


def test_large_coordinates_keep_precision():
    # pixel coordinates of a 4000 x 4000 image, a smooth field
    c = rng.uniform(3500, 4000, (300, 2))
    v = np.cos(c[:, 0] / 50)
    rbf = LinearRBF(c, v, degree=1)
    assert np.allclose(rbf(c), v, atol=1e-8)


def test_bad_input_messages():
    with pytest.raises(MRTError, match="distinct"):
        LinearRBF([[0, 0], [0, 0]], [1.0, 2.0])
    with pytest.raises(MRTError, match="finite"):
        LinearRBF([[0, 0], [1, 0]], [1.0, np.nan])
    with pytest.raises(MRTError, match="degree"):
        LinearRBF([[0, 0]], [1.0], degree=3)
    with pytest.raises(MRTError, match="3 centres but 2 values"):
        LinearRBF([[0, 0], [1, 0], [2, 0]], [1.0, 2.0])


# --- the fast evaluation on integer pixel grids (mitsuba_mrt.rbf_fast) -------

def dense_reference(rbf, points, monkeypatch):
    """``rbf(points)`` by the exact dense path."""
    with monkeypatch.context() as m:
        m.setattr(rbf_fast, "pays_off", lambda *args, **kwargs: False)
        return rbf(points)


def fast_calls(monkeypatch):
    """Count the calls of the fast kernel made through LinearRBF."""
    calls = []
    real = rbf_fast.grid_distance_sum

    def spy(*args, **kwargs):
        calls.append(len(args[2]))
        return real(*args, **kwargs)

    monkeypatch.setattr(rbf_fast, "grid_distance_sum", spy)
    return calls


def fast_matches_dense(rbf, points, monkeypatch):
    """``rbf(points)``, checked to take the fast kernel once and to agree with
    the dense path; returned for further checks."""
    calls = fast_calls(monkeypatch)
    fast = rbf(points)
    assert calls == [len(points)]
    assert_close(fast, dense_reference(rbf, points, monkeypatch))
    return fast


def assert_close(fast, exact, rtol=1e-4):
    """max |fast - exact| <= rtol * max |exact|, channel by channel."""
    fast, exact = np.atleast_2d(fast.T).T, np.atleast_2d(exact.T).T
    err = np.abs(fast - exact).max(axis=0)
    assert (err <= rtol * np.abs(exact).max(axis=0)).all(), err / np.abs(exact).max(axis=0)


def pixel_grid(h, w, lo=(0, 0)):
    yy, xx = np.mgrid[lo[0]:lo[0] + h, lo[1]:lo[1] + w]
    return np.stack([xx.ravel(), yy.ravel()], axis=1)


def jittered_centres(size, n, gen):
    side = int(np.ceil(np.sqrt(n)))
    step = size / side
    grid = (np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2) + 0.5) * step
    grid = np.round(grid + gen.uniform(-step / 3, step / 3, grid.shape)).astype(np.int64)
    return np.clip(grid, 0, size - 1)[gen.choice(len(grid), n, replace=False)]


def noisy_colours(c, gen):
    smooth = np.stack([np.sin(c[:, 0] / 37.0) + c[:, 1] / 300.0,
                       np.cos(c[:, 1] / 23.0) * c[:, 0] / 600.0,
                       0.5 + 0.2 * np.sin((c[:, 0] + c[:, 1]) / 11.0)], axis=1)
    return smooth + gen.normal(0.0, 0.05, smooth.shape)


@pytest.mark.parametrize("degree", [-1, 0, 1])
def test_fast_path_matches_dense_on_a_600_pixel_image(degree, monkeypatch):
    gen = np.random.default_rng(7)
    centres = jittered_centres(600, 2000, gen)
    rbf = LinearRBF(centres, noisy_colours(centres, gen), degree)
    pixels = pixel_grid(600, 600)
    calls = fast_calls(monkeypatch)
    fast = rbf(pixels)
    assert calls == [len(pixels)] and fast.shape == (len(pixels), 3)
    # the dense reference on a sample of pixels: random ones, a row, a column
    pick = np.concatenate([gen.choice(len(pixels), 12000, replace=False),
                           np.arange(600) + 600 * 311, 600 * np.arange(600) + 17])
    exact = dense_reference(rbf, pixels[pick], monkeypatch)
    assert_close(fast[pick], exact)
    big = np.abs(exact) > 1e-2 * np.abs(exact).max()
    assert (np.abs(fast[pick] - exact)[big] / np.abs(exact)[big]).max() < 1e-3


def test_grid_distance_sum_matches_the_direct_sum():
    gen = np.random.default_rng(3)
    centres = gen.integers(-50, 150, (400, 2))
    weights = gen.normal(size=(400, 2))
    points = pixel_grid(120, 200, lo=(-30, -60))
    exact = np.hypot(*(points[:, None, :] - centres[None]).transpose(2, 0, 1)) @ weights
    assert_close(rbf_fast.grid_distance_sum(centres, weights, points), exact, rtol=1e-5)


def test_fast_path_with_centres_in_a_corner_and_points_far_away(monkeypatch):
    gen = np.random.default_rng(11)
    centres = jittered_centres(60, 300, gen)                 # all in [0, 60)^2
    rbf = LinearRBF(centres, noisy_colours(centres, gen), degree=-1)
    pixels = pixel_grid(150, 120, lo=(700, 900))             # no centre nearby
    fast_matches_dense(rbf, pixels, monkeypatch)


def test_fast_path_on_a_thin_region(monkeypatch):
    gen = np.random.default_rng(5)
    t = np.arange(0, 900)
    band = np.concatenate([np.stack([t, t // 3 + d], axis=1) for d in range(-2, 3)])
    band = np.concatenate([band, np.stack([np.full(400, 899 - 2), np.arange(300, 700)], axis=1)])
    band = np.unique(band, axis=0)
    centres = band[gen.choice(len(band), 700, replace=False)]
    rbf = LinearRBF(centres, noisy_colours(centres, gen), degree=1)
    fast_matches_dense(rbf, band, monkeypatch)


def test_fast_path_for_grey_and_scalar_values(monkeypatch):
    gen = np.random.default_rng(2)
    centres = jittered_centres(200, 600, gen)
    grey = noisy_colours(centres, gen)[:, :1] * np.ones(3)  # three equal channels
    pixels = pixel_grid(200, 200)
    for values in (grey, grey[:, 0]):
        rbf = LinearRBF(centres, values, degree=0)
        fast = fast_matches_dense(rbf, pixels, monkeypatch)
        assert fast.shape == (len(pixels),) + values.shape[1:]
    assert np.array_equal(fast, rbf(pixels.astype(np.float64)))  # integral floats too


def test_non_integer_or_small_problems_stay_dense(monkeypatch):
    gen = np.random.default_rng(4)
    centres = jittered_centres(200, 600, gen)
    rbf = LinearRBF(centres, noisy_colours(centres, gen))
    calls = fast_calls(monkeypatch)
    rbf(pixel_grid(200, 200) + 0.5)            # half-pixel points
    rbf(pixel_grid(3, 3))                      # too few points to pay off
    LinearRBF(centres + 0.25, noisy_colours(centres, gen))(pixel_grid(200, 200))
    assert calls == []


def test_points_of_the_wrong_shape_are_rejected():
    rbf = LinearRBF(CENTRES, VALUES)
    with pytest.raises(MRTError, match="points"):
        rbf(np.zeros((4, 3)))
    with pytest.raises(MRTError, match="points"):
        rbf(np.zeros(4))


def test_grid_distance_sum_bad_input_messages():
    c, w, x = np.zeros((2, 2), int), np.ones((2, 1)), np.zeros((3, 2), int)
    with pytest.raises(MRTError, match="centres"):
        rbf_fast.grid_distance_sum(np.zeros((2, 3), int), w, x)
    with pytest.raises(MRTError, match="points"):
        rbf_fast.grid_distance_sum(c, w, np.zeros((0, 2), int))
    with pytest.raises(MRTError, match="weights"):
        rbf_fast.grid_distance_sum(c, np.ones((3, 1)), x)
    with pytest.raises(MRTError, match="power of two"):
        rbf_fast.grid_distance_sum(c, w, x, h=3)
