"""``denoise="oidn"``: OIDN on the traced grid, its guides, and the missing extra."""

import sys

import numpy as np
import pytest

from mitsuba_mrt.errors import MRTError
from mitsuba_mrt.recon import denoise
from mitsuba_mrt.recon.denoise import MISSING, denoise_grid, denoise_image



@pytest.fixture
def oidn():
    return pytest.importorskip("pyoidn")


def _guides(shape, albedo=0.5):
    albedo = np.broadcast_to(np.asarray(albedo, dtype=float), shape[:2] + (3,)).copy()
    normal = np.zeros(shape[:2] + (3,))
    normal[..., 2] = 1.0
    return albedo, normal


def test_noise_goes_down_on_a_smooth_image_with_constant_albedo(oidn):
    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:48, 0:48] / 48.0
    clean = np.stack([0.5 + 0.3 * np.sin(3 * x + 2 * y)] * 3, -1) * [1.0, 0.8, 0.6]
    noisy = np.clip(clean + rng.normal(0, 0.12, clean.shape), 0, None)
    albedo, normal = _guides(clean.shape)
    out = denoise_grid(noisy, albedo, normal)
    assert out.shape == noisy.shape and out.dtype == np.float64
    before = np.sqrt(np.mean((noisy - clean) ** 2))
    after = np.sqrt(np.mean((out - clean) ** 2))
    assert after < 0.4 * before, (before, after)


def test_a_sharp_step_in_the_albedo_guide_survives(oidn):
    rng = np.random.default_rng(2)
    albedo = np.full((40, 40, 3), 0.2)
    albedo[:, 20:] = 0.8
    clean = albedo * 1.0  # constant light: radiance follows the albedo
    noisy = np.clip(clean + rng.normal(0, 0.1, clean.shape), 0, None)
    _, normal = _guides(clean.shape)
    out = denoise_grid(noisy, albedo, normal)
    left, right = out[:, 19].mean(), out[:, 20].mean()
    assert abs(left - 0.2) < 0.05 and abs(right - 0.8) < 0.08, (left, right)
    assert right - left > 0.5  # not blurred across the edge


def test_without_guides_and_qualities(oidn):
    rng = np.random.default_rng(3)
    image = np.clip(0.5 + rng.normal(0, 0.1, (16, 24, 3)), 0, None)
    for quality in denoise.QUALITIES:
        out = denoise_image(image, quality=quality)
        assert out.shape == image.shape and np.isfinite(out).all()
    # a normal alone is dropped (OIDN takes it only with an albedo)
    assert np.isfinite(denoise_image(image, None, _guides(image.shape)[1])).all()


def test_the_device_is_created_once(oidn):
    image = np.full((8, 8, 3), 0.5)
    denoise_grid(image, *_guides(image.shape))
    device = denoise._state["device"]
    denoise_grid(image * 2, *_guides(image.shape))
    assert denoise._state["device"] is device


def test_missing_extra_is_a_one_line_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyoidn", None)  # import pyoidn raises ImportError
    image = np.full((4, 4, 3), 0.5)
    with pytest.raises(MRTError) as exc:
        denoise_grid(image, *_guides(image.shape))
    assert str(exc.value) == MISSING
    assert "pip install mitsuba-mrt[denoise]" in MISSING and "\n" not in MISSING


def test_render_with_denoise_times_the_stage(oidn, variant):
    import mitsuba as mi
    from conftest import small_scene_xml

    import mitsuba_mrt

    scene = mi.load_string(small_scene_xml(32, '<integrator type="path"/>'))
    plain = mitsuba_mrt.render(scene, spp=4, mode="fast")
    result = mitsuba_mrt.render(scene, spp=4, mode="fast", denoise="oidn")
    assert result.timings.denoise > 0 and plain.timings.denoise == 0
    assert np.isfinite(result.image).all()
    # the grid the reconstruction saw is the denoised one
    assert not np.allclose(result.trace.radiance, plain.trace.radiance)
