import numpy as np
import pytest

from mitsuba_mrt import MRTError
from mitsuba_mrt.recon.compose import compose, demodulate, region_albedo, safe_albedo
from mitsuba_mrt.recon.metrics import error_map, paper_error, psnr


def test_paper_error_is_mean_abs_over_pixels_and_channels():
    ref = np.zeros((2, 2, 3))
    img = ref.copy()
    img[0, 0] = [0.3, 0.6, 0.9]  # 1.8 / (3 * 4)
    assert paper_error(img, ref) == pytest.approx(0.15)
    assert error_map(img, ref)[0, 0] == pytest.approx(0.6)


def test_metrics_clip_to_unit_range():
    ref = np.ones((1, 1, 3))
    assert paper_error(np.full((1, 1, 3), 5.0), ref) == 0.0
    assert psnr(ref, ref) == float("inf")


def test_psnr_value():
    assert psnr(np.full((4, 4, 3), 0.01), np.zeros((4, 4, 3))) == pytest.approx(40.0)


def test_metrics_reject_bad_input():
    with pytest.raises(MRTError, match="shape"):
        paper_error(np.zeros((2, 2, 3)), np.zeros((2, 3, 3)))
    with pytest.raises(MRTError, match="finite"):
        psnr(np.full((1, 1, 3), np.nan), np.zeros((1, 1, 3)))


def test_demodulation_round_trip_and_zero_albedo():
    albedo = np.array([[0.5, 0.0, 0.25]])
    radiance = np.array([[0.2, 0.3, 0.1]])
    irr = demodulate(radiance, albedo)
    assert np.allclose(irr * safe_albedo(albedo), radiance)
    assert irr[0, 1] == 0.3  # not divided by zero


def test_region_albedo_constant_and_nearest():
    ids = np.array([[1, 1, 1, 1, 2]])
    xy = np.array([[0, 0], [3, 0], [4, 0]])
    sid = np.array([1, 1, 2])
    alb = np.array([[0.2], [0.6], [0.9]])
    out = region_albedo(ids, xy, sid, alb)[0, :, 0]
    assert np.allclose(out, [0.2, 0.2, 0.6, 0.6, 0.9])


def test_compose_keeps_traced_pixels():
    mask = np.array([[True, False]])
    out = compose(np.ones((1, 2, 3)), np.full((1, 2, 3), 0.5), mask, np.array([[9.0, 9, 9]]))
    assert out[0, 0].tolist() == [9, 9, 9] and out[0, 1].tolist() == [0.5] * 3


def test_region_albedo_with_nearest_grid_sample_takes_a_nearest_sample_of_the_same_id():
    from mitsuba_mrt.recon.sampling import grid_pattern

    rng = np.random.default_rng(3)
    p = grid_pattern(37, 29, 0.1)
    sid = rng.integers(1, 4, p.count)
    alb = rng.uniform(0.1, 0.9, (p.count, 1))
    ids = p.nearest_image(sid)
    ids[rng.random(ids.shape) < 0.2] = 2  # pixels whose nearest sample has another id
    out = region_albedo(ids, p.pixel_xy, sid, alb, nearest=p.nearest_image(np.arange(p.count)))
    for r, c in np.ndindex(ids.shape):
        same = np.flatnonzero(sid == ids[r, c])
        d2 = ((p.pixel_xy[same] - (c, r)) ** 2).sum(axis=1)
        assert out[r, c, 0] in alb[same[d2 == d2.min()], 0]
