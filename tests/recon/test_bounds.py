import numpy as np
import pytest

from mitsuba_mrt import grid_pattern
from mitsuba_mrt.recon import bounds
from mitsuba_mrt.recon.sampling import cell_coordinates


def brute_block(grid_ids, grid_values, cy, cx, own):
    """(lo, hi, found) of the samples of id ``own`` in the clipped 4 x 4 block of cell (cy, cx)."""
    nr, nc = grid_ids.shape
    ys = np.arange(max(cy - 1, 0), min(cy + 2, nr - 1) + 1)
    xs = np.arange(max(cx - 1, 0), min(cx + 2, nc - 1) + 1)
    block_ids = grid_ids[np.ix_(ys, xs)]
    v = grid_values[np.ix_(ys, xs)][block_ids == own]
    if len(v) == 0:
        return None
    return v.min(0), v.max(0)


def test_power_of_two_scale_divides_exactly_into_the_unit_interval():
    rng = np.random.default_rng(0)
    values = rng.uniform(-1, 1, (50, 3)) * np.array([3.0e38, 1e-30, 0.0])
    scale = bounds.power_of_two_scale(values)
    assert scale[2] == 1.0
    scaled = values / scale
    assert np.abs(scaled).max() < 1.0 and np.abs(scaled[:, :2]).max(0).min() >= 0.5
    assert np.array_equal(scaled * scale, values)  # exact
    assert np.array_equal(np.log2(scale), np.round(np.log2(scale)))


@pytest.mark.parametrize("seed", range(6))
def test_block_ranges_match_a_loop(seed):
    rng = np.random.default_rng(seed)
    nr, nc = int(rng.integers(1, 7)), int(rng.integers(1, 7))
    grid_ids = rng.integers(0, 2 + seed % 3, (nr, nc))
    grid_values = rng.normal(size=(nr, nc, 2))
    uniform, block_id, lo, hi = bounds.block_ranges(grid_ids, grid_values)
    for i in range(nr):
        for j in range(nc):
            ys = slice(max(i - 1, 0), min(i + 3, nr))
            xs = slice(max(j - 1, 0), min(j + 3, nc))
            ids = grid_ids[ys, xs]
            assert uniform[i, j] == (ids == ids.flat[0]).all()
            assert block_id[i, j] == ids.min()
            assert np.array_equal(lo[i, j], grid_values[ys, xs].reshape(-1, 2).min(0))
            assert np.array_equal(hi[i, j], grid_values[ys, xs].reshape(-1, 2).max(0))


@pytest.mark.parametrize("seed", range(4))
def test_clamp_to_samples_holds_every_pixel_to_its_ids_samples(seed):
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(1, 40)), int(rng.integers(1, 40))
    p = grid_pattern(w, h, float(rng.uniform(0.05, 0.6)))
    grid_ids = rng.integers(0, 3, p.grid_shape)
    if seed % 2:
        grid_ids[:] = 1  # uniform blocks: the gathered path
    grid_values = rng.normal(size=p.grid_shape + (3,))
    id_map = rng.integers(0, 4, (h, w))  # id 3 has no sample
    if seed % 2:
        id_map[:] = 1
    image = rng.normal(scale=3.0, size=(h, w, 3))
    clamped = image.copy()
    bounds.clamp_to_samples(p, grid_ids, grid_values, id_map, clamped)
    cy, _ = cell_coordinates(p.rows, h)
    cx, _ = cell_coordinates(p.cols, w)
    for y in range(h):
        for x in range(w):
            own = id_map[y, x]
            near = brute_block(grid_ids, grid_values, cy[y], cx[x], own)
            if near is None:
                mine = grid_values[grid_ids == own]
                if len(mine) == 0:  # no sample anywhere: left alone
                    assert np.array_equal(clamped[y, x], image[y, x])
                    continue
                near = mine.min(0), mine.max(0)
            assert np.array_equal(clamped[y, x], np.clip(image[y, x], *near)), (y, x)


def test_a_firefly_is_replaced_by_its_largest_same_id_neighbour():
    ids = np.array([[1, 1, 1, 2], [1, 1, 1, 2], [1, 1, 1, 2]])
    values = np.ones((3, 4, 2))
    values[..., 1] = 2.0
    values[:, 3] = 500.0  # another id: no neighbour of the firefly
    values[0, 0, 0] = 3.0
    values[1, 1, 0] = 40.0  # 40 > 4 x 3
    out, count = bounds.suppress_fireflies(ids, values)
    assert count == 1
    assert out[1, 1, 0] == 3.0 and out[1, 1, 1] == 2.0  # per channel
    expected = values.copy()
    expected[1, 1, 0] = 3.0
    assert np.array_equal(out, expected)
    # not 4 x its neighbours: not a firefly
    values[1, 1, 0] = 11.0
    assert bounds.suppress_fireflies(ids, values)[1] == 0


def test_fireflies_depend_on_their_id_alone_and_not_on_the_scale():
    rng = np.random.default_rng(5)
    ids = rng.integers(0, 2, (9, 9))
    values = rng.uniform(0.5, 1.0, (9, 9, 3))
    spikes = rng.random((9, 9)) < 0.1
    values[spikes] *= 100.0
    out, count = bounds.suppress_fireflies(ids, values)
    assert count > 0
    for k in (2.0 ** -90, 3e-7, 7e20):
        scaled, n = bounds.suppress_fireflies(ids, values * k)
        assert n == count and np.allclose(scaled, out * k, rtol=1e-12)
    other = values.copy()
    other[ids == 1] *= rng.uniform(0, 1000, (int((ids == 1).sum()), 3))
    again, _ = bounds.suppress_fireflies(ids, other)
    assert np.array_equal(again[ids == 0], out[ids == 0])


def test_noise_on_black_is_not_a_firefly():
    ids = np.zeros((3, 3), dtype=int)
    values = np.zeros((3, 3, 1))
    values[0, 0] = 1.0  # the id's brightest sample ...
    values[2, 2] = 1e-9  # ... and noise on black, far below the margin
    out, count = bounds.suppress_fireflies(ids, values)
    assert out[2, 2, 0] == 1e-9
    assert count == 1 and out[0, 0, 0] == 0.0  # the lone bright sample is one
