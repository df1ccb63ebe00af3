import numpy as np
import pytest
import scipy.linalg
from scipy.spatial.distance import cdist

from mitsuba_mrt.recon import rbf_solve

rng = np.random.default_rng(7)


def pixel_system(n, degree, seed=0):
    """A linear-RBF system like the paper mode's: n distinct pixels of a sparse grid, scaled."""
    r = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(np.arange(0, 600, 3), np.arange(0, 300, 3)), -1).reshape(-1, 2)
    xy = grid[r.choice(len(grid), n, replace=False)].astype(float)
    xy = (xy - xy.mean(0)) / (np.ptp(xy, 0).max() / 2)
    poly = np.zeros((n, 0)) if degree < 0 else np.hstack([np.ones((n, 1)), xy])[:, :1 + 2 * degree]
    values = np.stack([np.sin(4 * xy[:, 0]), xy[:, 1] ** 2, np.ones(n)], axis=1)
    return cdist(xy, xy), poly, values


def lu_reference(distances, poly, values):
    n, m = poly.shape
    system = np.block([[distances, poly], [poly.T, np.zeros((m, m))]])
    out = scipy.linalg.solve(system, np.vstack([values, np.zeros((m, values.shape[1]))]))
    return out[:n], out[n:]


#: The residual the refinement leaves, over TOLERANCE x the data's largest
#: value: the colour channels are refined less their share of the largest,
#: which adds that share of its residual back to theirs.
RESIDUAL_SLACK = 4.0


def interpolant(xy, weights, coeffs, degree, at):
    """The RBF of centres ``xy`` with ``weights`` and polynomial ``coeffs`` at points ``at``."""
    poly = np.hstack([np.ones((len(at), 1)), at])[:, :max(1 + 2 * degree, 0)]
    return cdist(at, xy) @ weights + poly @ coeffs


@pytest.mark.parametrize("degree", [-1, 0, 1])
@pytest.mark.parametrize("n", [150, 900])
def test_refined_cholesky_interpolates_as_float64_lu_does(degree, n):
    system = pixel_system(n, degree, seed=n)
    solved = rbf_solve._refined_cholesky(*system)
    assert solved is not None  # the fast path was taken, not the LU fallback
    distances, poly, values = system
    bound = RESIDUAL_SLACK * rbf_solve.TOLERANCE * np.abs(values).max()
    # at the centres it meets the data within the tolerance ...
    assert np.abs(distances @ solved[0] + poly @ solved[1] - values).max() <= bound
    assert np.abs(poly.T @ solved[0]).max(initial=0.0) <= bound
    # ... and between them it is float64 LU's interpolant within as much
    xy = pixel_centres(n, seed=n)
    between = np.random.default_rng(n).uniform(xy.min(0), xy.max(0), (500, 2))
    ours = interpolant(xy, *solved, degree, between)
    theirs = interpolant(xy, *lu_reference(*system), degree, between)
    assert np.abs(ours - theirs).max() <= bound


def test_repeated_centres_fall_back_and_raise():
    distances, poly, values = pixel_system(200, 0)
    xy_dup = np.vstack([np.zeros((1, 2)), np.zeros((1, 2)), rng.uniform(-1, 1, (198, 2))])
    distances = cdist(xy_dup, xy_dup)
    assert rbf_solve._refined_cholesky(distances, poly, values) is None
    with pytest.raises((np.linalg.LinAlgError, scipy.linalg.LinAlgError)):
        rbf_solve.solve_linear_rbf(distances, poly, values)


def test_small_systems_use_lu_and_agree():
    system = pixel_system(rbf_solve.MIN_SIZE - 1, 1)
    ours = rbf_solve.solve_linear_rbf(*system)
    ref = lu_reference(*system)
    assert np.allclose(ours[0], ref[0], rtol=0, atol=1e-12 * np.abs(ref[0]).max())


@pytest.mark.parametrize("layout", ["clusters", "near_line", "wide_and_dense"])
@pytest.mark.parametrize("degree", [-1, 1])
def test_ill_conditioned_layouts_still_match_lu(layout, degree):
    """Badly spread centres: the refinement either converges or hands over to LU."""
    r = np.random.default_rng(11)
    if layout == "clusters":  # two tight clusters far apart
        xy = np.vstack([r.normal(0, 1e-3, (150, 2)), r.normal(0, 1e-3, (150, 2)) + 1.0])
    elif layout == "near_line":  # almost collinear
        t = np.linspace(-1, 1, 300)
        xy = np.stack([t, 1e-6 * r.standard_normal(300)], axis=1)
    else:  # a few far points around a dense patch of pixels
        patch = np.stack(np.meshgrid(np.arange(16), np.arange(16)), -1).reshape(-1, 2) * 1e-3
        xy = np.vstack([patch, r.uniform(-1, 1, (40, 2))])
    n = len(xy)
    poly = np.zeros((n, 0)) if degree < 0 else np.hstack([np.ones((n, 1)), xy[:, :1]])
    values = np.stack([np.cos(3 * xy[:, 0]), xy[:, 1], np.ones(n)], axis=1)
    system = (cdist(xy, xy), poly, values)
    weights, coeffs = rbf_solve.solve_linear_rbf(*system)
    distances = system[0]
    residual = distances @ weights + poly @ coeffs - values
    ref = lu_reference(*system)
    lu_residual = distances @ ref[0] + poly @ ref[1] - values
    # within the refinement's tolerance, or as good an interpolant as float64 LU's
    bound = RESIDUAL_SLACK * rbf_solve.TOLERANCE * np.abs(values).max()
    assert np.abs(residual).max() <= max(bound, 10 * np.abs(lu_residual).max())
    assert np.allclose(poly.T @ weights, 0.0, atol=1e-8 * np.abs(weights).max())


def test_a_refinement_that_stalls_above_the_tolerance_hands_over_to_lu(monkeypatch):
    system = pixel_system(300, -1)
    monkeypatch.setattr(rbf_solve, "TOLERANCE", 0.0)  # unreachable: the residual stalls
    assert rbf_solve._refined_cholesky(*system) is None
    ours = rbf_solve.solve_linear_rbf(*system)
    ref = lu_reference(*system)
    assert np.array_equal(ours[0], ref[0])  # the LU answer itself


def pixel_centres(n, seed=0):
    r = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(np.arange(0, 600, 3), np.arange(0, 300, 3)), -1).reshape(-1, 2)
    xy = grid[r.choice(len(grid), n, replace=False)].astype(float)
    return (xy - xy.mean(0)) / (np.ptp(xy, 0).max() / 2)


@pytest.mark.parametrize("n", [5, 700])  # one block, and row blocks on threads
def test_distance_triangles_are_cdist_above_the_diagonal(n, monkeypatch):
    monkeypatch.setattr(rbf_solve, "CHUNK_ROWS", 7)  # chunks that do not divide the rows
    xy = pixel_centres(n, seed=n)
    distances, negated = rbf_solve.distance_triangles(xy)
    upper = np.triu(np.ones((n, n), dtype=bool))
    full = cdist(xy, xy)
    assert np.array_equal(distances[upper], full[upper])
    assert negated.dtype == np.float32
    assert np.array_equal(negated[upper], -full[upper].astype(np.float32))


@pytest.mark.parametrize("degree", [-1, 1])
def test_the_solver_reads_only_the_upper_triangles(degree):
    xy = pixel_centres(600, seed=degree + 5)
    values = pixel_system(600, degree, seed=degree + 5)[2]
    distances = cdist(xy, xy)
    poly = np.zeros((600, 0)) if degree < 0 else np.hstack([np.ones((600, 1)), xy])
    tri, negated = rbf_solve.distance_triangles(xy)
    lower = np.tril(np.ones((600, 600), dtype=bool), -1)
    tri[lower] = np.nan  # anything read from below the diagonal would show
    negated[lower] = np.nan
    ours = rbf_solve._refined_cholesky(tri, poly, values, negated)
    theirs = rbf_solve._refined_cholesky(distances, poly, values)
    assert ours is not None and theirs is not None
    for a, b in zip(ours, theirs):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("n", [rbf_solve.MIN_SIZE - 1, 400])
@pytest.mark.parametrize("stalls", [False, True])
def test_solving_from_centres_equals_solving_from_the_matrix(n, stalls, monkeypatch):
    if stalls:  # the float32 path gives up: LU on the mirrored triangle
        monkeypatch.setattr(rbf_solve, "TOLERANCE", 0.0)
    xy = pixel_centres(n, seed=3)
    poly = np.hstack([np.ones((n, 1)), xy])
    values = np.stack([np.sin(4 * xy[:, 0]), xy[:, 1] ** 2], axis=1)
    ours = rbf_solve.solve_linear_rbf_at(xy, poly, values)
    theirs = rbf_solve.solve_linear_rbf(cdist(xy, xy), poly, values)
    for a, b in zip(ours, theirs):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("degree", [-1, 0, 1])
def test_values_near_float32_max_are_refined_not_raised(degree):
    # Found by the stress suite: data near float32's largest value overflowed
    # in the refinement and scipy's solve_triangular raised a raw ValueError.
    # The refinement now works on the data over a power of two, exactly.
    distances, poly, values = pixel_system(150, degree)
    big = (1.0 + np.abs(values)) * 1.5e38
    solved = rbf_solve._refined_cholesky(distances, poly, big)
    assert solved is not None
    small = rbf_solve._refined_cholesky(distances, poly, big * 2.0 ** -130)
    assert np.array_equal(solved[0] * 2.0 ** -130, small[0])
    w, c = rbf_solve.solve_linear_rbf(distances, poly, big)
    bound = RESIDUAL_SLACK * rbf_solve.TOLERANCE * big.max()
    assert np.abs(distances @ w + poly @ c - big).max() <= bound


def test_a_value_error_inside_the_refinement_falls_back(monkeypatch):
    distances, poly, values = pixel_system(150, 1)

    def refuse(*args, **kwargs):
        raise ValueError("array must not contain infs or NaNs")

    monkeypatch.setattr(rbf_solve, "_refine", refuse)
    assert rbf_solve._refined_cholesky(distances, poly, values) is None
    w, c = rbf_solve.solve_linear_rbf(distances, poly, values)  # by LU
    assert np.allclose(distances @ w + poly @ c, values)
