import numpy as np
import pytest

from mitsuba_mrt import grid_pattern
from mitsuba_mrt.modes import reconstruct, smoothed_trace
from mitsuba_mrt.recon import llvm_arrays
from mitsuba_mrt.recon.smooth import smooth_grid
from mitsuba_mrt.runtime.jit import counting_kernels
from mitsuba_mrt.types import MRTParams, SparseTrace


def noisy_grid(shape=(40, 40), sigma=0.05, seed=0):
    rng = np.random.default_rng(seed)
    truth = np.ones(shape + (3,))
    return truth, truth + rng.normal(0, sigma, truth.shape), np.full(truth.shape, sigma ** 2)


def test_noise_on_a_smooth_region_goes_down():
    truth, values, noise = noisy_grid()
    out = smooth_grid(np.zeros(truth.shape[:2], int), values, noise)
    before, after = np.abs(values - truth).mean(), np.abs(out - truth).mean()
    assert after < 0.6 * before


def test_a_step_far_beyond_the_noise_stays_sharp():
    truth, values, noise = noisy_grid()
    truth[:, 20:] += 1.0
    values[:, 20:] += 1.0
    out = smooth_grid(np.zeros(truth.shape[:2], int), values, noise)
    # columns next to the step keep their side's level: no blur across it
    assert np.abs(out[:, 19].mean() - 1.0) < 0.01 and np.abs(out[:, 20].mean() - 2.0) < 0.01


def test_other_ids_are_never_mixed_in():
    truth, values, noise = noisy_grid()
    ids = np.zeros(truth.shape[:2], int)
    ids[:, 20:] = 1
    values[:, 20:] += 0.01  # within the noise, but another object
    out = smooth_grid(ids, values, noise)
    lone = smooth_grid(ids[:, 20:], values[:, 20:], noise[:, 20:])
    assert np.array_equal(out[:, 20:], lone)


def test_noise_free_and_fixed_samples_are_unchanged_bit_for_bit():
    truth, values, noise = noisy_grid()
    noise[:10] = 0.0
    fixed = np.zeros(truth.shape[:2], bool)
    fixed[30, 30] = True
    values[30, 30] = 50.0  # a firefly: it is not spread into its neighbours
    out = smooth_grid(np.zeros(truth.shape[:2], int), values, noise, fixed=fixed)
    assert np.array_equal(out[:10], values[:10]) and out[30, 30, 0] == 50.0
    assert out[29:32, 29:32].reshape(-1, 3)[[0, 1, 2, 3, 5, 6, 7, 8]].max() < 1.5


def test_results_stay_within_the_neighbourhood_range():
    rng = np.random.default_rng(3)
    values = rng.uniform(0, 1, (30, 30, 3))
    ids = rng.integers(0, 3, (30, 30))
    out = smooth_grid(ids, values, np.full(values.shape, 0.1))
    assert out.min() >= values.min() and out.max() <= values.max()


def test_a_far_noisier_neighbour_does_not_pull_a_quiet_sample():
    # beside a light, a sample whose filter reaches it is bright and very noisy:
    # within its own noise of its neighbours, it was averaged in with weight ~1
    values = np.array([[[1.0], [1.0], [50.0]]])
    noise = np.array([[[0.01], [0.01], [1e4]]])
    out = smooth_grid(np.zeros((1, 3), int), values, noise)
    assert abs(out[0, 1, 0] - 1.0) < 0.01


def test_strength_zero_is_off():
    _, values, noise = noisy_grid()
    assert np.array_equal(smooth_grid(np.zeros(values.shape[:2], int), values, noise, 0.0),
                          values)


def _by_the_formula(ids, values, noise, strength, fixed):
    """smooth_grid's docstring, one sample at a time."""
    nr, nc, channels = values.shape
    out = values.copy()
    for y in range(nr):
        for x in range(nc):
            if fixed[y, x] or noise[y, x].max() <= 0:
                continue
            total, weight = values[y, x].copy(), 1.0
            for v in range(max(y - 1, 0), min(y + 2, nr)):
                for u in range(max(x - 1, 0), min(x + 2, nc)):
                    if (v, u) == (y, x) or fixed[v, u] or ids[v, u] != ids[y, x]:
                        continue
                    d = values[y, x] - values[v, u]
                    both = noise[y, x] + noise[v, u]
                    ratio = [dc * dc / bc if bc > 0 else (0.0 if dc == 0 else np.inf)
                             for dc, bc in zip(d, both)]
                    w = np.exp(-sum(ratio) / (2 * strength ** 2 * channels))
                    here, there = noise[y, x].mean(), noise[v, u].mean()
                    w *= min(here / there, 1.0) if there > 0 else 1.0
                    total += w * values[v, u]
                    weight += w
            out[y, x] = total / weight
    return out


def test_the_smoothing_is_its_formula():
    rng = np.random.default_rng(7)
    for _ in range(20):
        nr, nc = rng.integers(1, 9, 2)
        values = np.round(rng.normal(1, 0.2, (nr, nc, 3)), 1)  # (some equal samples)
        noise = np.abs(rng.normal(0, 0.05, (nr, nc, 3))) * rng.integers(0, 2, (nr, nc, 3))
        ids, fixed = rng.integers(0, 2, (nr, nc)), rng.random((nr, nc)) < 0.2
        np.testing.assert_allclose(smooth_grid(ids, values, noise, 1.5, fixed),
                                   _by_the_formula(ids, values, noise, 1.5, fixed), rtol=1e-12)


def trace_of(pattern, radiance, variance, spp=16):
    n = pattern.count
    return SparseTrace(radiance.reshape(-1, 3), np.full((n, 3), 0.5), np.ones(n, np.int64),
                       np.zeros(n, np.uint32), 0, spp, 0.0, variance=variance.reshape(-1, 3))


@pytest.mark.parametrize("mode", ["fast"])
def test_modes_smooth_between_traced_pixels_and_keep_the_traced_ones(mode):
    pattern = grid_pattern(90, 90, 0.1)
    rng = np.random.default_rng(1)
    radiance = 0.5 + rng.normal(0, 0.05, pattern.grid_shape + (3,))
    trace = trace_of(pattern, radiance, np.full(radiance.shape, 0.05 ** 2 * 16))
    smooth = reconstruct(pattern, trace, MRTParams(), mode).image
    plain = reconstruct(pattern, trace, MRTParams(noise_smoothing=0), mode).image
    traced = np.ix_(pattern.rows, pattern.cols)
    assert np.array_equal(smooth[traced], radiance) and np.array_equal(plain[traced], radiance)
    between = ~pattern.mask
    assert np.abs(smooth[between] - 0.5).mean() < 0.7 * np.abs(plain[between] - 0.5).mean()


def test_smoothing_skips_what_does_not_apply():
    pattern = grid_pattern(30, 30, 0.1)
    radiance = np.full(pattern.grid_shape + (3,), 0.5)
    trace = trace_of(pattern, radiance, np.full(radiance.shape, 0.01))
    assert smoothed_trace(pattern, trace, MRTParams(), "paper") is trace
    assert smoothed_trace(pattern, trace, MRTParams(noise_smoothing=0), "fast") is trace
    assert smoothed_trace(pattern, trace, MRTParams(denoise="oidn"), "fast") is trace
    no_variance = trace_of(pattern, radiance, radiance)
    no_variance.variance = None
    assert smoothed_trace(pattern, no_variance, MRTParams(), "fast") is no_variance


@pytest.mark.parametrize("value", [-1.0, float("nan"), float("inf")])
def test_bad_strength_is_one_clear_error(value):
    from mitsuba_mrt.errors import MRTError
    with pytest.raises(MRTError, match="noise_smoothing must be a finite number >= 0"):
        MRTParams(noise_smoothing=value)


@pytest.mark.skipif(not llvm_arrays.available(), reason="needs Dr.Jit's LLVM backend")
@pytest.mark.parametrize("channels", [1, 3])
def test_jit_and_numpy_smoothing_agree(channels):
    # random ids, fixed samples, noise-free channels and equal samples: every branch
    rng = np.random.default_rng(11)
    for nr, nc in [(1, 1), (1, 7), (9, 2), (40, 33)]:
        values = np.round(rng.normal(1, 0.2, (nr, nc, channels)), 1)
        noise = np.abs(rng.normal(0, 0.05, values.shape)) * rng.integers(0, 2, values.shape)
        ids, fixed = rng.integers(0, 3, (nr, nc)) << 40, rng.random((nr, nc)) < 0.2
        jit = smooth_grid(ids, values, noise, 1.5, fixed, use_jit=True)
        ref = smooth_grid(ids, values, noise, 1.5, fixed, use_jit=False)
        np.testing.assert_allclose(jit, ref, rtol=1e-13)
        unchanged = fixed | (noise.max(axis=-1) <= 0)
        assert np.array_equal(jit[unchanged], values[unchanged])


@pytest.mark.skipif(not llvm_arrays.available(), reason="needs Dr.Jit's LLVM backend")
def test_the_smoothing_kernel_replays_for_another_grid_and_strength():
    rng = np.random.default_rng(2)

    def smooth(shape, strength):
        values = rng.normal(1, 0.1, shape + (3,))
        smooth_grid(np.zeros(shape, int), values, np.full(values.shape, 0.01), strength,
                    use_jit=True)

    smooth((20, 30), 1.5)
    with counting_kernels() as counts:
        smooth((31, 17), 0.7)
    assert counts == [0, 0]
