"""The package's thread pool: row blocks, work beside the caller, and both nested."""

import numpy as np

from mitsuba_mrt.runtime.threads import beside, for_row_blocks, for_row_blocks_of, use_threads


def test_row_blocks_inside_work_beside_do_not_wait_on_each_other():
    # every pool thread runs work started beside the caller that itself splits rows:
    # were its blocks queued behind it, each would wait on the others for good
    use_threads(2)
    try:
        outs = [np.zeros(4096) for _ in range(4)]

        def split(out):
            def fill(a, b):
                out[a:b] = np.arange(a, b)
            for_row_blocks(fill, len(out), min_rows=8)
            return out

        futures = [beside(split, out) for out in outs]
        for future in futures:
            assert np.array_equal(future.result(timeout=60), np.arange(4096.0))
    finally:
        use_threads(None)


def test_blocks_with_a_halo_give_the_whole_stencil():
    rng = np.random.default_rng(3)
    grid = rng.random((300, 7))

    def box3(lo, hi):  # the mean of each row and its neighbours (ends: of those there are)
        part = grid[lo:hi]
        padded = np.pad(part, ((1, 1), (0, 0)), mode="edge")
        return (padded[:-2] + padded[1:-1] + padded[2:]) / 3

    out = np.empty_like(grid)
    for_row_blocks_of(box3, out, halo=1, min_rows=8)
    assert np.array_equal(out, box3(0, len(grid)))
