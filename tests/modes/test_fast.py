import numpy as np
import pytest

from mitsuba_mrt import MRTParams, SparseTrace, grid_pattern, reconstruct
from mitsuba_mrt.recon import llvm_arrays
from mitsuba_mrt.recon import within_region as fast
from mitsuba_mrt.runtime import threads
from mitsuba_mrt.recon.compose import ALBEDO_EPS, albedo_constant_per_id
from mitsuba_mrt.recon.edges import id_boxes, quadtree_fill, region_boxes, smooth_ids
from mitsuba_mrt.recon.within_region import interpolate_within_ids, local_poly_fit, separable_cubic


def trace_from(pattern, values, shape_index=None, albedo=None):
    n = pattern.count
    values = np.asarray(values, dtype=float).reshape(n, -1)
    values = np.repeat(values, 3, axis=1) if values.shape[1] == 1 else values
    return SparseTrace(values, np.ones((n, 3)) if albedo is None else albedo,
                       np.ones(n, int) if shape_index is None else shape_index,
                       np.zeros(n, np.uint32), 0, 1, 0.0)


def test_cubic_is_exact_for_cubic_fields():
    p = grid_pattern(60, 50, 0.1)
    f = lambda x, y: 1 + 0.01 * x - 0.002 * y ** 2 + 1e-5 * x ** 3 + 1e-5 * x * y ** 2
    x, y = p.pixel_xy[:, 0] * 1.0, p.pixel_xy[:, 1] * 1.0
    out = separable_cubic(p, f(x, y).reshape(p.grid_shape + (1,)))
    yy, xx = np.mgrid[:50, :60]
    assert np.allclose(out[..., 0], f(xx * 1.0, yy * 1.0), atol=1e-9)


def test_near_edges_quadratic_fields_stay_exact_on_each_side():
    p = grid_pattern(64, 64, 0.1)
    x, y = p.pixel_xy[:, 0] * 1.0, p.pixel_xy[:, 1] * 1.0
    left = x < 30
    values = np.where(left, 0.5 + 0.01 * x + 1e-4 * y * y, 3.0 - 0.02 * y + 1e-4 * x * x)
    ids = np.where(left, 1, 2)
    id_map = p.nearest_image(ids)
    out, edge_pixels = interpolate_within_ids(p, ids.reshape(p.grid_shape),
                                              values.reshape(p.grid_shape + (1,)), id_map)
    yy, xx = np.mgrid[:64, :64] * 1.0
    truth = np.where(id_map == 1, 0.5 + 0.01 * xx + 1e-4 * yy * yy, 3.0 - 0.02 * yy + 1e-4 * xx * xx)
    assert edge_pixels > 0
    # the ridge on the quadric's curvature (see fast._RIDGE) costs ~1e-3
    # relative at one-sided corners; mixing the two sides would cost ~2.5.
    # Pixels beyond the last grid column of their id are extrapolated, and
    # held to the range of their samples nearby: compare the others.
    between = np.where(id_map == 1, xx <= x[left].max(), xx >= x[~left].min())
    assert np.allclose(out[..., 0][between], truth[between], rtol=1e-3, atol=2e-3)
    for value, side in ((1, left), (2, ~left)):
        pixels = out[..., 0][id_map == value]
        assert values[side].min() - 1e-6 <= pixels.min() and pixels.max() <= values[side].max() + 1e-6


def test_interpolation_never_crosses_an_edge():
    p = grid_pattern(50, 40, 0.1)
    ids = (p.pixel_xy[:, 0] + p.pixel_xy[:, 1] > 40).astype(int) + 1
    values = np.where(ids == 1, 0.0, 1.0)
    id_map = p.nearest_image(ids)
    out, _ = interpolate_within_ids(p, ids.reshape(p.grid_shape),
                                    values.reshape(p.grid_shape + (1,)), id_map)
    assert np.allclose(out[..., 0][id_map == 1], 0.0, atol=1e-9)
    assert np.allclose(out[..., 0][id_map == 2], 1.0, atol=1e-9)


@pytest.mark.parametrize("fill", ["nearest", "quadtree"])
@pytest.mark.parametrize("seed", range(4))
def test_region_boxes_hold_every_pixel_of_each_id(fill, seed):
    # region_boxes (from the grid) for the nearest-sample fill, id_boxes
    # (from the map) for the quadtree's
    rng = np.random.default_rng(seed)
    p = grid_pattern(int(rng.integers(20, 90)), int(rng.integers(20, 90)), rng.uniform(0.03, 0.3))
    ids = rng.integers(0, 5, p.grid_shape)
    if seed % 2:  # blocky ids, as real regions are
        ids = np.repeat(np.repeat(ids, 4, axis=0), 4, axis=1)[:p.grid_shape[0], :p.grid_shape[1]]
    id_map = p.nearest_image(ids) if fill == "nearest" else quadtree_fill(p, ids)
    boxes = region_boxes(p, ids) if fill == "nearest" else id_boxes(id_map)
    for value, (r0, r1, c0, c1) in boxes.items():
        inside = np.zeros_like(id_map, dtype=bool)
        inside[r0:r1, c0:c1] = True
        assert not ((id_map == value) & ~inside).any()
        if fill == "quadtree":  # and tight
            assert ((id_map == value) & inside).any(axis=1)[r0] and \
                ((id_map == value) & inside).any(axis=0)[c1 - 1]
    assert np.array_equal(smooth_ids(id_map, 1.5, 0.1, boxes=boxes),
                          smooth_ids(id_map, 1.5, 0.1))


def test_skips_fire_and_are_counted():
    p = grid_pattern(32, 32, 0.2)
    one_id = reconstruct(p, trace_from(p, np.ones(p.count)), mode="fast")
    assert one_id.skips.edge_finding == 1
    assert one_id.skips.albedo_division == 1
    textured = np.where((p.pixel_xy[:, :1] // 8) % 2 == 0, 0.2, 0.8) * np.ones((1, 3))
    radiance = textured * (1 + p.pixel_xy[:, :1] / 32.0)
    out = reconstruct(p, trace_from(p, radiance, albedo=textured), mode="fast")
    assert out.skips.albedo_division == 0


def test_traced_pixels_are_exact():
    p = grid_pattern(30, 30, 0.15)
    rng = np.random.default_rng(0)
    radiance = rng.random((p.count, 3)).astype(np.float32).astype(float)  # as Mitsuba gives
    t = trace_from(p, radiance, shape_index=rng.integers(1, 4, p.count))
    out = reconstruct(p, t, MRTParams(id_rule="exact"), mode="fast")
    assert np.array_equal(out.image[p.mask], t.radiance)
    assert np.isfinite(out.image).all()


@pytest.mark.parametrize("shape", [(3, 40), (40, 3), (2, 2)])
def test_tiny_grids(shape):
    h, w = shape
    p = grid_pattern(w, h, 0.5)
    out = reconstruct(p, trace_from(p, np.arange(p.count, dtype=float)), mode="fast")
    assert np.isfinite(out.image).all()


@pytest.mark.skipif(not llvm_arrays.available(), reason="needs Dr.Jit's LLVM backend")
@pytest.mark.parametrize("channels", [1, 6])
def test_jit_and_numpy_near_edge_fits_agree(channels):
    # random ids make every kind of stencil: full, partial, one-sample and
    # empty (the pixel's id is absent from its block: nearest-value fallback)
    p = grid_pattern(90, 70, 0.1)
    rng = np.random.default_rng(7)
    grid_ids = rng.integers(0, 4, p.grid_shape).astype(np.int64) << 33
    values = rng.normal(size=p.grid_shape + (channels,)).astype(np.float32)
    py, px = np.nonzero(rng.random((70, 90)) < 0.5)
    own = rng.integers(0, 5, len(py)).astype(np.int64) << 33
    jit = local_poly_fit(p, grid_ids, values, py, px, own, use_jit=True)
    ref = local_poly_fit(p, grid_ids, values, py, px, own, use_jit=False)
    assert jit.shape == ref.shape == (len(py), channels)
    assert np.allclose(jit, ref, rtol=1e-5, atol=1e-5)


def test_albedo_constancy_is_the_spread_per_id_not_neighbour_steps():
    # a slow ramp: each step is below ALBEDO_EPS, the whole spread is not
    ids = np.repeat([3, 5], 50)
    albedo = np.full((100, 3), 0.5)
    assert albedo_constant_per_id(ids, albedo)
    albedo[:50, 1] += np.arange(50) * 0.5 * ALBEDO_EPS
    assert not albedo_constant_per_id(ids, albedo)
    albedo[:50, 1] = 0.5 + 0.5 * ALBEDO_EPS  # within tolerance
    albedo[50:, 2] = 0.9  # another id, another (constant) albedo
    assert albedo_constant_per_id(ids, np.asfortranarray(albedo))


def test_grouped_fits_equal_one_fit_per_pixel():
    # the fits are shared by the pixels of a (cell, id); fitting every pixel on
    # its own, with its own id, must give the same values
    p = grid_pattern(90, 70, 0.1)
    rng = np.random.default_rng(11)
    grid_ids = rng.integers(0, 3, p.grid_shape).astype(np.int64)
    values = rng.normal(size=p.grid_shape + (3,))
    py, px = np.nonzero(rng.random((70, 90)) < 0.6)
    own = rng.integers(0, 4, len(py)).astype(np.int64)  # id 3 is in no block
    grouped = local_poly_fit(p, grid_ids, values, py, px, own, use_jit=False)

    nr, nc = p.grid_shape
    cy, _ = fast.cell_coordinates(p.rows, p.height)
    cx, _ = fast.cell_coordinates(p.cols, p.width)
    gy0, gx0 = cy[py], cx[px]
    centre_y = 0.5 * (p.rows[gy0] + p.rows[np.minimum(gy0 + 1, nr - 1)])
    centre_x = 0.5 * (p.cols[gx0] + p.cols[np.minimum(gx0 + 1, nc - 1)])
    spacing = max(p.height / (nr - 1), p.width / (nc - 1))
    coeffs = fast.quadric_coefficients(p.rows, p.cols, grid_ids, values, gy0, gx0, own,
                                       centre_y, centre_x, spacing, fast._RIDGE)
    ox, oy = (px - centre_x) / spacing, (py - centre_y) / spacing
    basis = np.stack([np.ones_like(ox), ox, oy, ox * ox, ox * oy, oy * oy], axis=1)
    per_pixel = np.einsum("mk,mkc->mc", basis, coeffs)
    block = [(gy0 + dy >= 0) & (gy0 + dy < nr) & (gx0 + dx >= 0) & (gx0 + dx < nc)
             & (grid_ids[np.clip(gy0 + dy, 0, nr - 1), np.clip(gx0 + dx, 0, nc - 1)] == own)
             for dy in range(-1, 3) for dx in range(-1, 3)]
    lost = ~np.any(block, axis=0)
    assert lost.any() and not lost.all()
    # each fit is clamped to the range of the samples it was fitted to
    near = np.stack([values[np.clip(gy0 + dy, 0, nr - 1), np.clip(gx0 + dx, 0, nc - 1)]
                     for dy in range(-1, 3) for dx in range(-1, 3)])
    used = np.array(block)[..., None]
    per_pixel = np.clip(per_pixel, np.where(used, near, np.inf).min(0),
                        np.where(used, near, -np.inf).max(0))
    # no sample of their id in the block: the nearest sample of their id
    # (ties aside), and for id 3, which no sample carries, of any id
    gy, gx = np.divmod(np.arange(p.count), nc)
    for i in np.flatnonzero(lost):
        if own[i] == 3:
            per_pixel[i] = values[p.nearest_rows[py[i]], p.nearest_cols[px[i]]]
            continue
        mine = grid_ids.ravel() == own[i]
        d2 = (p.rows[gy[mine]] - py[i]) ** 2 + (p.cols[gx[mine]] - px[i]) ** 2
        assert np.sum(d2 == d2.min()) == 1
        k = np.argmin(d2)
        per_pixel[i] = values[gy[mine][k], gx[mine][k]]
    assert (own[lost] != 3).any()
    assert np.allclose(grouped, per_pixel, rtol=1e-12, atol=1e-12)


def test_values_beside_the_ids_equal_one_thread(monkeypatch):
    # the cubic runs on a worker while the ids are smoothed; on one core it
    # runs first, in line, and the image must not change
    p = grid_pattern(48, 40, 0.15)
    rng = np.random.default_rng(2)
    shapes = 1 + (p.pixel_xy[:, 0] > 20) + (p.pixel_xy[:, 1] > 25)
    t = trace_from(p, rng.random((p.count, 3)), shape_index=shapes)
    pooled = reconstruct(p, t, MRTParams(id_rule="exact"), mode="fast")
    monkeypatch.setattr(threads, "_pool", lambda: (None, 1))
    inline = reconstruct(p, t, MRTParams(id_rule="exact"), mode="fast")
    assert np.array_equal(pooled.image, inline.image)
    assert pooled.stats == inline.stats


@pytest.mark.parametrize("height, width, fraction", [(200, 160, 0.1), (67, 301, 0.2),
                                                      (24, 30, 0.1), (9, 9, 0.1)])
@pytest.mark.parametrize("channels", [3, 6])
def test_fused_cubic_radiance_is_the_whole_image_one(height, width, fraction, channels):
    # early_radiance makes the cubic, its clamp and its radiance a block of
    # rows at a time: the same numbers as the whole image's, bit for bit
    # (the last shape's grid is under 4 x 4: no cubic, zeros)
    p = grid_pattern(width, height, fraction)
    rng = np.random.default_rng(channels)
    grid_ids = (rng.random(p.grid_shape) < 0.1).astype(np.int64)
    grid = fast.GridValues.from_samples(p, grid_ids, rng.random((p.count, channels)) * 7.0)
    whole = grid.radiance(fast.early_values(p, grid_ids, grid.values).image)
    fused = fast.early_radiance(p, grid_ids, grid)
    assert np.array_equal(fused.view(np.uint64), whole.view(np.uint64))


def test_an_error_before_the_hand_over_reaches_finish(monkeypatch):
    # the values' thread hands the grid over before its cubic; an error
    # before that must come out of finish, not leave it waiting
    p = grid_pattern(48, 40, 0.15)
    t = trace_from(p, np.ones((p.count, 3)))

    def broken(*args):
        raise FloatingPointError("broken grid")
    monkeypatch.setattr(fast.GridValues, "from_samples", broken)
    values = fast.TracedGridValues.start(p, t.radiance, t.albedo, t.shape_index, 0)
    with pytest.raises(FloatingPointError, match="broken grid"):
        values.finish(np.ones((40, 48), dtype=int))


def test_worker_errors_come_out_of_the_result(monkeypatch):
    future = threads.beside(np.linalg.cholesky, -np.eye(2))
    with pytest.raises(np.linalg.LinAlgError):
        future.result()
    monkeypatch.setattr(threads, "_pool", lambda: (None, 1))
    with pytest.raises(np.linalg.LinAlgError):
        threads.beside(np.linalg.cholesky, -np.eye(2)).result()


@pytest.mark.parametrize("seed", range(4))
def test_traced_pixels_keep_their_ids_and_numbering_does_not_matter(seed):
    # Found by the stress suite: the report's smoothing dilates the ids in
    # increasing order, so the larger id took traced pixels of the smaller,
    # and renumbering the shapes changed the image.
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(12, 40)), int(rng.integers(12, 40))
    p = grid_pattern(w, h, float(rng.uniform(0.1, 0.6)))
    yy, xx = np.mgrid[:h, :w]
    k = int(rng.integers(2, 6))
    sx, sy = rng.uniform(0, w, k), rng.uniform(0, h, k)
    labels = np.argmin((xx[..., None] - sx) ** 2 + (yy[..., None] - sy) ** 2, axis=-1)
    shapes = labels if seed % 2 else labels + 1  # with and without a background
    values = rng.uniform(0.1, 2.0, (k, 3))[labels] * (1 + 0.01 * xx[..., None])
    xy = p.pixel_xy

    def run(shape_index):
        trace = SparseTrace(values[xy[:, 1], xy[:, 0]], np.ones((p.count, 3)),
                            shape_index[xy[:, 1], xy[:, 0]], np.zeros(p.count, np.uint32),
                            0, 1, 0.0)
        return reconstruct(p, trace, MRTParams(sample_fraction=0.3), "fast")

    out = run(shapes)
    assert np.array_equal(out.ids[p.mask], (shapes[p.mask].astype(np.int64) << 32))
    new = np.zeros(k + 1, np.int64)
    new[1:] = rng.permutation(np.arange(1, k + 1)) * 5 + 2
    other = run(new[shapes])
    assert np.array_equal(other.image, out.image)
