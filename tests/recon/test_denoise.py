"""``denoise="oidn"``: OIDN on the traced grid, its guides, and the missing extra."""

import sys

import numpy as np
import pytest

from mitsuba_mrt.errors import MRTError
from mitsuba_mrt.recon import denoise
from mitsuba_mrt.recon.denoise import MISSING, denoise_grid, denoise_image



@pytest.fixture
def oidn():
    return pytest.importorskip("mitsuba_oidn")


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


def test_its_cost_is_known_after_a_call(oidn):
    denoise.release()
    assert denoise.denoise_seconds(100, "fast") is None
    image = np.full((8, 8, 3), 0.5)
    denoise_image(image, *_guides(image.shape), quality="fast")
    one = denoise.denoise_seconds(100, "fast")
    assert one > 0 and denoise.denoise_seconds(200, "fast") == pytest.approx(2 * one)  # one size
    assert denoise.denoise_seconds(100, "high") is None
    # a small image's fixed costs do not change what a large one is expected to take
    large = denoise.denoise_seconds(64 * 64, "fast")
    denoise_image(np.full((64, 64, 3), 0.5), *_guides((64, 64, 3)), quality="fast")
    measured = denoise.denoise_seconds(64 * 64, "fast")
    denoise_image(image, *_guides(image.shape), quality="fast")
    assert denoise.denoise_seconds(64 * 64, "fast") == measured != large
    # two sizes: a fixed cost and one per pixel, through both
    denoise._state["recent"]["fast"] = {100: [1.0], 400: [2.5]}
    assert denoise.denoise_seconds(1000, "fast") == pytest.approx(2.5 + 0.005 * 600)
    # a size not called yet: its first call makes the filter's buffers
    assert denoise.expected_seconds(1000, "fast") == pytest.approx(
        denoise.denoise_seconds(1000, "fast") * (1 + denoise.FIRST_CALL_SHARE))
    assert denoise.expected_seconds(400, "fast") == 2.5
    denoise.release()


def test_one_slow_call_does_not_set_what_a_size_is_expected_to_take():
    denoise.release()
    denoise._record("fast", (256, 256), 0.08)  # a size's first call (its buffers made)
    denoise._record("fast", (256, 256), 0.05)
    assert denoise.denoise_seconds(256 * 256, "fast") == 0.05  # the lower of two
    denoise._record("fast", (256, 256), 0.30)  # the machine's noise
    assert denoise.denoise_seconds(256 * 256, "fast") == 0.08  # the median of three
    denoise._record("fast", (256, 256), 0.06)  # the last three: 0.05, 0.30, 0.06
    assert denoise.denoise_seconds(256 * 256, "fast") == 0.06
    denoise.release()


def test_a_new_process_expects_its_first_call_to_take_what_earlier_first_calls_took(
        tmp_path, monkeypatch):
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", str(tmp_path / "memory.json"))
    denoise.release()
    formula = denoise.prior_seconds(256 * 256, "fast")
    assert formula > 0.04  # (the remembered calls below are quicker)
    # a process's first call at a preset is remembered whole, set-up included
    denoise._record("fast", (256, 256), 0.04, setup=0.01, first=True)
    denoise._record("fast", (256, 256), 0.9)  # (not the process's first: not remembered)
    denoise.release()  # the next process
    assert denoise.prior_seconds(256 * 256, "fast") == pytest.approx(0.04)
    assert denoise.expected_seconds(256 * 256, "fast") == pytest.approx(0.04)
    assert denoise.prior_seconds(128 * 128, "fast") != 0.04  # (another size: the formula's)
    denoise._record("fast", (256, 256), 0.035, first=True)
    denoise.release()
    assert denoise.prior_seconds(256 * 256, "fast") == pytest.approx(0.04)  # (the longest)
    denoise._record("fast", (256, 256), formula * 2, first=True)
    denoise.release()  # (a slower first call: no more than the prior)
    assert denoise.prior_seconds(256 * 256, "fast") == pytest.approx(formula)
    monkeypatch.setenv("MITSUBA_MRT_MEMORY", "off")
    denoise.release()
    assert denoise.prior_seconds(256 * 256, "fast") == pytest.approx(formula)
    denoise.release()


def test_a_filters_first_call_counts_as_what_a_later_one_takes(oidn):
    denoise.release()
    image = np.full((8, 8, 3), 0.5)
    # the first call on a size makes its filter (and the filter its buffers)
    firsts = [denoise._run_filter(image, *_guides(image.shape), "fast", False)[2]
              for _ in range(2)]
    assert firsts == [True, False]
    denoise.release()
    denoise._record("fast", (256, 256), 0.05 * (1 + denoise.FIRST_CALL_SHARE), first=True)
    assert denoise.denoise_seconds(256 * 256, "fast") == pytest.approx(0.05)
    assert denoise.expected_seconds(256 * 256, "fast") == pytest.approx(0.05)
    denoise.release()


def test_before_any_call_its_cost_is_the_prior_on_drjits_threads(oidn):
    import drjit as dr

    denoise.release()
    threads = max(dr.thread_count(), 1)
    for quality, per_pixel in denoise.PRIOR_SECONDS.items():
        assert denoise.expected_seconds(10_000, quality) == pytest.approx(
            (denoise.PRIOR_FIXED[quality] + per_pixel * 10_000 / threads)
            * (1 + denoise.FIRST_CALL_SHARE))


def test_missing_extra_is_a_one_line_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "mitsuba_oidn", None)  # import mitsuba_oidn raises ImportError
    image = np.full((4, 4, 3), 0.5)
    with pytest.raises(MRTError) as exc:
        denoise_grid(image, *_guides(image.shape))
    assert str(exc.value) == MISSING
    assert "pip install mitsuba-mrt[denoise]" in MISSING and "\n" not in MISSING


def test_within_hidden_oidn_is_missing_and_after_it_is_back(oidn):
    from mitsuba_mrt.recon import denoise

    image = np.full((4, 4, 3), 0.5)
    with denoise.hidden():
        assert not denoise.oidn_available()
        with pytest.raises(MRTError) as exc:
            denoise_image(image, *_guides(image.shape))
        assert str(exc.value) == MISSING
        with denoise.hidden(False):  # (the innermost block's say)
            assert denoise.oidn_available()
    assert denoise.oidn_available() and np.isfinite(denoise_image(image)).all()


def test_render_with_denoise_times_the_stage(oidn, variant):
    import mitsuba as mi
    from helpers import small_scene_xml

    import mitsuba_mrt

    scene = mi.load_string(small_scene_xml(32, '<integrator type="path"/>'))
    plain = mitsuba_mrt.render(scene, spp=4, mode="fast")
    result = mitsuba_mrt.render(scene, spp=4, mode="fast", denoise="oidn")
    assert result.timings.denoise > 0 and plain.timings.denoise == 0
    assert np.isfinite(result.image).all()
    # the grid the reconstruction saw is the denoised one
    assert not np.allclose(result.trace.radiance, plain.trace.radiance)


def test_textured_pixels_are_the_diffuse_surfaces_whose_albedo_varies():
    ids = np.repeat([1, 2, 3, 4], 12)
    level = np.concatenate([np.tile([0.03, 0.8], 6),    # 1: a diffuse checker
                            np.full(12, 0.5),            # 2: diffuse, one colour
                            np.tile([0.1, 0.9], 6),      # 3: a mirror seeing a checker
                            np.tile([0.03, 0.8], 6)])    # 4: a checker, too few pixels below
    albedo = np.repeat(level[:, None], 3, axis=1)
    diffuse = np.array([False, True, True, False, True])
    out = denoise.textured_pixels(ids, albedo, diffuse)
    assert out[:12].all() and not out[12:36].any() and out[36:].all()
    few = ids.copy()
    few[40:] = 0  # shape 4 keeps 4 pixels: too few to tell a texture
    assert not denoise.textured_pixels(few, albedo, diffuse)[36:].any()
    # no pixel lit, or an index beyond the table: not textured
    assert not denoise.textured_pixels(ids, np.zeros_like(albedo), diffuse).any()
    assert not denoise.textured_pixels(ids + 10, albedo, diffuse).any()


def test_a_fine_dark_texture_is_denoised_as_shading_times_albedo(oidn):
    # a sparse grid sees a checker of near-black and white texels as a pattern
    # finer than any the denoiser keeps: denoised as radiance, a dark texel takes
    # some of its bright neighbours' light; as shading, nothing is mixed
    rng = np.random.default_rng(4)
    y, x = np.mgrid[0:40, 0:40]
    texture = np.where((x + y) % 2 == 0, 0.02, 0.8)
    albedo = np.repeat(texture[..., None], 3, axis=-1)
    shading = (0.6 + 0.3 * np.sin(x / 9.0 + y / 13.0))[..., None]
    clean = albedo * shading
    noisy = np.clip(clean * (1 + rng.normal(0, 0.3, clean.shape)), 0, None)
    _, normal = _guides(clean.shape)
    dark = texture < 0.1

    def shading_error(image, where=dark):
        return np.abs(image / albedo - shading)[where].mean()

    plain = denoise_grid(noisy, albedo, normal)
    textured = denoise_grid(noisy, albedo, normal, textured=np.ones(texture.shape, bool))
    assert shading_error(textured) < 0.5 * shading_error(plain), (
        shading_error(textured), shading_error(plain))
    assert shading_error(textured) < 0.5 * shading_error(noisy)
    # half marked, in one OIDN call: that half as shading, the other as radiance
    half = np.zeros(texture.shape, bool)
    half[:, :20] = True
    mixed = denoise_grid(noisy, albedo, normal, textured=half)
    assert shading_error(mixed, dark & half) < 0.5 * shading_error(plain, dark & half)
    unmarked = np.abs(mixed - clean)[~half].mean()
    assert unmarked <= 1.1 * np.abs(plain - clean)[~half].mean()


def test_a_grid_with_textured_pixels_takes_one_oidn_call(oidn, monkeypatch):
    # OIDN's time grows with the pixels it filters: the textured pixels'
    # shading goes through the same call as the others, not a second one
    from mitsuba_mrt.recon import denoise

    calls = []
    run = denoise._run_filter
    monkeypatch.setattr(denoise, "_run_filter", lambda *a: calls.append(a) or run(*a))
    image = np.random.default_rng(6).random((16, 16, 3))
    albedo, normal = _guides(image.shape)
    albedo[:, :8] = np.where(np.arange(8) % 2, 0.1, 0.9)[None, :, None]
    marked = np.zeros(image.shape[:2], bool)
    marked[:, :8] = True
    denoise_grid(image, albedo, normal, textured=marked)
    assert len(calls) == 1


def test_pixels_whose_samples_agreed_keep_their_values(oidn):
    rng = np.random.default_rng(5)
    clean = np.full((24, 24, 3), 0.4)
    noisy = np.clip(clean + rng.normal(0, 0.1, clean.shape), 0, None)
    noisy[:, :8] = 0.3  # a constant background: every sample gave 0.3
    albedo, normal = _guides(clean.shape)
    albedo[:, :8] = 0.0
    exact = np.zeros(clean.shape[:2], bool)
    exact[:, :8] = True
    out = denoise_grid(noisy, albedo, normal, exact=exact)
    np.testing.assert_array_equal(out[:, :8], noisy[:, :8])
    np.testing.assert_array_equal(out[:, 8:], denoise_grid(noisy, albedo, normal)[:, 8:])


def test_denoise_quality_is_a_parameter_of_python_and_xml(oidn, variant):
    import mitsuba as mi
    from helpers import small_scene_xml

    import mitsuba_mrt
    from mitsuba_mrt.types import MRTParams

    scene = mi.load_string(small_scene_xml(32, '<integrator type="path"/>'))
    fast, balanced = (mitsuba_mrt.render(scene, spp=4, mode="fast", denoise="oidn",
                                         denoise_quality=q) for q in ("fast", "balanced"))
    assert fast.params.denoise_quality == "fast" and balanced.params.denoise_quality == "balanced"
    assert not np.array_equal(fast.trace.radiance, balanced.trace.radiance)
    with pytest.raises(MRTError) as exc:
        MRTParams(denoise_quality="best")
    assert str(exc.value) == ("denoise_quality must be one of auto, fast, balanced, high, "
                              "got 'best'")
    xml = small_scene_xml(16, '<integrator type="mrt"><string name="denoise" value="oidn"/>'
                              '<string name="denoise_quality" value="balanced"/>'
                              '<integrator type="path"/></integrator>')
    assert mi.load_string(xml).integrator().params.denoise_quality == "balanced"


def test_a_texture_denoised_as_its_shading_keeps_its_detail(oidn):
    from mitsuba_mrt.recon.denoise import denoise_shading

    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:64, 0:64]
    texture = np.where((x // 2 + y // 2) % 2, 0.9, 0.1)[..., None].repeat(3, -1)
    clean = texture * (0.3 + 0.4 * x / 63)[..., None]  # a texture times a smooth shading
    noisy = np.maximum(clean * (1 + 0.5 * rng.standard_normal(clean.shape)), 0.0)
    normal = np.zeros_like(clean)
    normal[..., 2] = 1.0
    everywhere, nowhere = np.ones((64, 64), bool), np.zeros((64, 64), bool)
    plain = denoise_image(noisy, texture, normal, quality="fast")
    shading = denoise_shading(noisy, texture, normal, everywhere, "fast")
    assert np.abs(shading - clean).mean() < 0.5 * np.abs(plain - clean).mean()
    # nothing textured: OIDN's own call
    np.testing.assert_array_equal(denoise_shading(noisy, texture, normal, nowhere, "fast"), plain)


def test_a_texture_finer_than_a_pixel_is_denoised_before_the_shading_is_multiplied_back(oidn):
    from mitsuba_mrt.recon.denoise import denoise_shading

    # one sample a pixel of a texture of 0.1 and 0.9 texels finer than the pixels:
    # each pixel's albedo is one texel's, its true colour half of the shading
    rng = np.random.default_rng(5)
    y, x = np.mgrid[0:64, 0:64]
    shading = (0.3 + 0.4 * x / 63)[..., None].repeat(3, -1)
    texel = rng.choice([0.1, 0.9], size=(64, 64))[..., None].repeat(3, -1)
    noisy = np.maximum(texel * shading * (1 + 0.3 * rng.standard_normal(shading.shape)), 0.0)
    normal = np.zeros_like(shading)
    normal[..., 2] = 1.0
    everywhere = np.ones((64, 64), bool)
    truth = 0.5 * shading
    as_sampled = denoise_shading(noisy, texel, normal, everywhere, "fast")
    cleaned = denoise_shading(noisy, texel, normal, everywhere, "fast", clean_texture=True)
    assert np.abs(cleaned - truth).mean() < 0.5 * np.abs(as_sampled - truth).mean()
