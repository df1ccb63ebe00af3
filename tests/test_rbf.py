import numpy as np
import pytest
from scipy.interpolate import Rbf, RBFInterpolator

from mitsuba_mrt import MRTError
from mitsuba_mrt.rbf import LinearRBF

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
    import mitsuba_mrt.rbf as rbf_module

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
