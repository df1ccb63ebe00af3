"""The least time the report's RBF algebra can take: a bound for paper mode.

    python tools/paper_solve_floor.py --res 1000

Runs the paper mode's stages on ``paper_fig1.xml`` (``matte``, f = 0.1) to get
the number of RBF centres of every region, times a Cholesky and an LU
factorisation of a 2000 x 2000 system here (best of ``--repeats``), and sums
the Cholesky time over the regions, scaled by (n / 2000)^3: no float64 direct
solver of the report's systems can be faster than that on this machine.  The
same sum for a float32 Cholesky is the floor of :mod:`mitsuba_mrt.recon.rbf_solve`,
which factors in float32 and refines in float64.
"""

import argparse
import time

import numpy as np
import scipy.linalg

import mitsuba_mrt
from mitsuba_mrt.recon.compose import demodulate
from mitsuba_mrt.recon.edges import quadtree_fill, smooth_ids
from mitsuba_mrt.recon.interpolate import interpolate_regions


def best_of(repeats, function, *args):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function(*args)
        times.append(time.perf_counter() - start)
    return min(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="scenes_xml/paper_fig1.xml")
    parser.add_argument("--res", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    mitsuba_mrt.activate("auto")
    scene = mitsuba_mrt.load_scene(args.scene, res=args.res)
    result = mitsuba_mrt.render(scene, mode="paper")
    pattern, trace = result.pattern, result.trace
    sample_ids = trace.ids("paper")
    ids = smooth_ids(quadtree_fill(pattern, sample_ids.reshape(pattern.grid_shape)))
    interp = interpolate_regions(ids, pattern.pixel_xy, sample_ids,
                                 demodulate(trace.radiance, trace.albedo))
    sizes = sorted(interp.centres.values(), reverse=True)
    system = np.random.default_rng(0).random((2000, 2000))
    system = system @ system.T + 2000 * np.eye(2000)  # positive definite
    cholesky = best_of(args.repeats, scipy.linalg.cho_factor, system)
    cholesky32 = best_of(args.repeats, scipy.linalg.cho_factor, system.astype(np.float32))
    lu = best_of(args.repeats, scipy.linalg.lu_factor, system)
    floor = sum(cholesky * (n / 2000) ** 3 for n in sizes)
    floor32 = sum(cholesky32 * (n / 2000) ** 3 for n in sizes)
    print(f"{args.scene} {args.res}x{args.res}: {len(sizes)} RBF regions, centres {sizes}")
    print(f"2000 x 2000 factorisation, best of {args.repeats}: Cholesky {cholesky * 1e3:.1f} ms, "
          f"LU {lu * 1e3:.1f} ms, float32 Cholesky {cholesky32 * 1e3:.1f} ms")
    print(f"summed over the regions: float32 Cholesky {floor32:.2f} s, Cholesky {floor:.2f} s "
          f"(paper mode's reconstruction here: {result.timings.edges + result.timings.interpolate:.2f} s)")


if __name__ == "__main__":
    main()
