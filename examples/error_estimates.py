"""Can ``auto`` estimate the report's error (mean absolute) without a reference?  Measured.

    python examples/error_estimates.py checker_border spot_textures cornell room --ref-spp 8

The planner must rank its candidates by the error a user is shown, but it
has only noisy references: two independent renders of ``--ref-spp`` each.
Against such a reference a squared error can be corrected exactly (subtract
the reference's noise, known from the two halves' difference), and ``auto``
does so; a mean absolute error cannot: small errors vanish in the reference's
noise while large ones (an edge the MRT misses) are counted in full.  This
script prints, per gallery scene at 256 x 256 and candidate (the full render,
the usual alternative at 4-32 spp, the MRT modes with OIDN):

- ``true L1``: the report's metric against ``bench rival``'s converged renders
  (read from or kept in ``--truths``; the film's filter for the full render
  and the MRT, a box filter for denoised renders);
- ``naive``: the mean absolute difference to the reference, less its noise's;
- ``two-part``: each pixel's difference beyond 3 sigma of the reference's
  noise counted as it is, the others' squared error (less the noise) summed
  per 8 x 8 tile and turned into a mean absolute error as for a normal
  distribution, ``sqrt(2 / pi)`` times its root;
- ``RMS est`` and ``true RMS``: the squared error corrected, and the truth.

And the warm cost of ``auto``'s pilot (:func:`mitsuba_mrt.renderer.pilot.run_pilot`),
as a share of the full render's: what measuring the MRT's candidates costs.
"""

import argparse
import statistics
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from gallery_scenes import add_truths, load

ROOT = Path(__file__).resolve().parents[1]
TILE = 8


def estimates(image, a, b, variance, xy, width):
    """(naive, two-part, RMS) estimates of ``image``'s error (see the module)
    against the independent references ``a`` and ``b`` (n, 3), all clipped as
    displayed; ``variance`` a single sample's per pixel over the halves' spp."""
    e = image - 0.5 * (a + b)
    noise = (a - b) ** 2 / 4  # unbiased squared noise of the mean, independent of it
    naive = np.abs(e).mean() - np.sqrt(2 / np.pi) * np.sqrt(noise).mean()
    rms = np.sqrt(max(float((e * e - noise).mean()), 0.0))
    sigma = np.sqrt(variance * noise.sum() / max(variance.sum(), 1e-30))  # calibrated
    large = np.abs(e) > 3 * sigma
    squared = np.where(large, 0.0, e * e - 0.973 * noise)  # 0.973: a normal's, cut at 3 sigma
    tile = (xy[:, 1] // TILE) * (-(-width // TILE)) + xy[:, 0] // TILE
    count = np.bincount(tile, weights=(~large).sum(axis=1))
    total = np.bincount(tile, weights=squared.sum(axis=1))
    small = count * np.sqrt(2 / np.pi) * np.sqrt(np.maximum(total, 0) / np.maximum(count, 1))
    return naive, (np.abs(e[large]).sum() + small.sum()) / e.size, rms


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--ref-spp", type=int, default=8)
    add_truths(parser)
    args = parser.parse_args()
    import mitsuba_mrt
    from mitsuba_mrt.bench.rival import kept_truth
    from mitsuba_mrt.recon.metrics import paper_error
    from mitsuba_mrt.recon.sampling import every_pixel, grid_pattern
    from mitsuba_mrt.renderer import pilot
    from mitsuba_mrt.renderer.api import (GridTracer, render, render_denoised,
                                          render_reference)
    from mitsuba_mrt.renderer.scene import unwrap
    from mitsuba_mrt.types import MRTParams

    mitsuba_mrt.activate("auto")
    print("scene candidate true-L1 naive two-part RMS-est true-RMS")
    for name in args.scenes:
        scene = load(name, 256)
        sensor = scene.sensors()[0]
        width, height = (int(v) for v in sensor.film().crop_size())
        spp = int(sensor.sampler().sample_count())
        tracer = GridTracer(scene, sensor, unwrap(scene, None).nested, spp, 0)
        xy = every_pixel(width, height)
        truth = kept_truth(scene, name, Path(args.truths))
        refs = {}
        for kind in ("film", "box"):
            one = replace(tracer, spp=args.ref_spp)
            # the last pixel apart: a trace of every pixel would splat the film's filter
            halves = [[one(part, stream=300 + 10 * k, aovs=False, replay=True, box=kind == "box")
                       for part in (xy[:-1], xy[-1:])] for k in range(2)]
            radiance = [np.clip(np.concatenate([p.radiance for p in h]), 0, 1) for h in halves]
            variance = sum(np.concatenate([p.variance for p in h]) for h in halves) / (
                2 * args.ref_spp) / 2
            refs[kind] = (radiance[0], radiance[1], variance)
        candidates = [("full", "film", render_reference(scene, spp=spp)[0])]
        candidates += [(f"oidn@{s}", "box", render_denoised(scene, spp=s)[0])
                       for s in (4, 8, 16, 32)]
        candidates += [(f"{m}+oidn", "film", render(scene, mode=m, denoise="oidn").image)
                       for m in ("fast", "refine", "idpass")]
        for label, kind, image in candidates:
            shown = np.clip(image.reshape(-1, 3), 0, 1)
            naive, two_part, rms = estimates(shown, *refs[kind], xy, width)
            true_rms = np.sqrt(np.mean((shown - np.clip(truth[kind].reshape(-1, 3), 0, 1)) ** 2))
            print(f"{name} {label} {paper_error(image, truth[kind]):.5f} {naive:.5f} "
                  f"{two_part:.5f} {rms:.5f} {true_rms:.5f}", flush=True)
        params, pattern = MRTParams(), grid_pattern(width, height, MRTParams().sample_fraction)
        shares = []
        for k in range(4):  # the first compiles and warms up
            begin = time.perf_counter()
            pilot.run_pilot(scene, pattern, tracer, params)
            pilot_s = time.perf_counter() - begin
            begin = time.perf_counter()
            render_reference(scene, spp=spp)
            shares.append(pilot_s / (time.perf_counter() - begin))
        print(f"{name} pilot {statistics.median(shares[1:]):.3f} of the full render (warm)",
              flush=True)


if __name__ == "__main__":
    main()
