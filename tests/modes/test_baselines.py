import numpy as np

from mitsuba_mrt import SparseTrace, grid_pattern, reconstruct
from mitsuba_mrt.recon.upsample import upsample_nearest, upsample_spline


def test_nearest_copies_the_nearest_traced_pixel():
    p = grid_pattern(30, 20, 0.1)
    vals = np.arange(p.count, dtype=float)[:, None]
    img = upsample_nearest(p, vals)[..., 0]
    yy, xx = np.mgrid[:20, :30]
    d2 = (xx[..., None] - p.pixel_xy[:, 0]) ** 2 + (yy[..., None] - p.pixel_xy[:, 1]) ** 2
    assert np.array_equal(np.take_along_axis(d2, img.astype(int)[..., None], -1)[..., 0],
                          d2.min(axis=-1))


def test_bicubic_reproduces_a_cubic_surface():
    p = grid_pattern(40, 40, 0.1)
    f = lambda x, y: 0.5 + 1e-3 * x ** 3 - 2e-3 * x * y ** 2
    vals = f(p.pixel_xy[:, 0] * 1.0, p.pixel_xy[:, 1] * 1.0)[:, None]
    yy, xx = np.mgrid[:40, :40]
    assert np.allclose(upsample_spline(p, vals)[..., 0], f(xx * 1.0, yy * 1.0), atol=1e-6)


def test_baseline_modes_keep_traced_pixels():
    p = grid_pattern(16, 16, 0.2)
    rng = np.random.default_rng(0)
    t = SparseTrace(rng.random((p.count, 3)), np.ones((p.count, 3)), np.ones(p.count, int),
                    np.zeros(p.count, np.uint32), 0, 1, 0.0)
    for mode in ("nearest", "bicubic"):
        out = reconstruct(p, t, mode=mode)
        assert np.array_equal(out.image[p.mask], t.radiance)
