"""Would OIDN's prefiltered guides help the alternative done right?  Measured.

    python examples/prefiltered_guides.py cornell materials room envmap_objects --spp 8 --seeds 2

OIDN's documentation gets its best quality from noisy guides by denoising
the albedo and the normal first, each with an ``RT`` filter of its own, and
then the colour with ``cleanAux``.  Per gallery scene at 256 x 256: every
pixel at ``--spp`` with a box pixel filter and the albedo and normal of the
same samples (as :func:`mitsuba_mrt.render_denoised` traces them), then

- ``fast``, ``high``: OIDN on the noisy guides, as ``auto`` denoises;
- ``high, prefiltered``: both guides prefiltered (preset ``fast``), then
  ``high`` with ``cleanAux``;
- ``high, albedo prefiltered``: the albedo alone, no normal.

Printed per scene: the trace's median seconds, and each method's error (the
report's metric, against the box-filtered converged render ``bench rival``
keeps in ``--truths``), the mean over ``--seeds``, with the median seconds
of its OIDN calls (each timed at its second call: filters made and warmed).
"""

import argparse
import statistics
import time
from dataclasses import replace

import numpy as np

from gallery_scenes import add_truths, with_truths


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--spp", type=int, default=8)
    parser.add_argument("--seeds", type=int, default=2)
    add_truths(parser)
    args = parser.parse_args()
    import mitsuba_oidn as oidn

    from mitsuba_mrt.recon.denoise import denoise_image
    from mitsuba_mrt.recon.metrics import paper_error
    from mitsuba_mrt.recon.sampling import every_pixel
    from mitsuba_mrt.renderer.api import GridTracer
    from mitsuba_mrt.renderer.scene import unwrap

    device = oidn.Device(oidn.DeviceType.CPU)
    device.commit()
    guide_filters = {}

    def prefiltered(kind, image):
        """``image``, an albedo or normal guide, through an RT filter of its own."""
        flt = guide_filters.get((kind, image.shape))
        if flt is None:
            flt = guide_filters[kind, image.shape] = device.new_filter("RT")
            flt.quality = oidn.Quality.Fast
        source = np.ascontiguousarray(image, dtype=np.float32)
        output = np.empty_like(source)
        flt.set_image(kind, source)
        flt.set_image("output", output)
        flt.commit()
        flt.execute()
        flt.unset_image(kind)
        flt.unset_image("output")
        return output

    methods = {
        "fast": lambda c, a, n: denoise_image(c, a, n, quality="fast"),
        "high": lambda c, a, n: denoise_image(c, a, n, quality="high"),
        "high, prefiltered": lambda c, a, n: denoise_image(
            c, prefiltered("albedo", a), prefiltered("normal", n), quality="high",
            clean_aux=True),
        "high, albedo prefiltered": lambda c, a, n: denoise_image(
            c, prefiltered("albedo", a), None, quality="high", clean_aux=True),
    }
    for name, scene, truth in with_truths(args.scenes, 256, args.truths):
        sensor = scene.sensors()[0]
        width, height = (int(v) for v in sensor.film().crop_size())
        tracer = GridTracer(scene, sensor, unwrap(scene, None).nested, args.spp, 0)
        errors = {method: [] for method in methods}
        seconds = {method: [] for method in methods}
        traced = []
        for seed in range(args.seeds):
            start = time.perf_counter()
            trace = replace(tracer, seed=seed)(every_pixel(width, height), stream=0,
                                               aovs=True, ids=False, replay=True, box=True)
            traced.append(time.perf_counter() - start)
            guides = [v.reshape(height, width, 3)
                      for v in (trace.radiance, trace.albedo, trace.normal)]
            for method, denoise in methods.items():
                denoise(*guides)  # (its filters made and warmed)
                start = time.perf_counter()
                image = denoise(*guides)
                seconds[method].append(time.perf_counter() - start)
                errors[method].append(paper_error(image, truth.images["box"]))
        print(f"{name} at {args.spp} spp, trace {statistics.median(traced):.3f} s: " + "; ".join(
            f"{method} {np.mean(errors[method]):.5f} ({statistics.median(seconds[method]):.3f} s)"
            for method in methods), flush=True)


if __name__ == "__main__":
    main()
