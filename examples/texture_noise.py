"""What cleaning the texture gives a render that denoises textures as their shading, per spp.

    python examples/texture_noise.py room spot_textures checker_border two_sensors crop_rgba

Per gallery scene at ``--res``, every pixel is traced at 1, 2, 4 and 8 spp
(box pixel filter, guides from the same samples, ``--seeds`` seeds) and
denoised three ways: OIDN ``fast`` on the colour (``plain``), the textured
diffuse surfaces as their shading multiplied back by the samples' own
albedo (``shading``), and by the albedo denoised too (``+clean``,
:func:`mitsuba_mrt.recon.denoise.denoise_shading`'s ``clean_texture``).
Printed: each one's mean error (the report's metric, against the box-filtered
converged renders ``bench rival`` uses, read from or kept in ``--truths``).  ``auto``'s passes clean the
texture at up to :data:`~mitsuba_mrt.recon.denoise.CLEAN_TEXTURE_SPP` spp.
"""

import argparse

import numpy as np

from gallery_scenes import add_truths, with_truths


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--seeds", type=int, default=4)
    add_truths(parser)
    args = parser.parse_args()

    from mitsuba_mrt.recon.denoise import denoise_image, denoise_shading, textured_pixels
    from mitsuba_mrt.recon.metrics import paper_error
    from mitsuba_mrt.recon.sampling import every_pixel
    from mitsuba_mrt.renderer.api import GridTracer
    from mitsuba_mrt.renderer.auto_plans import find_surfaces
    from mitsuba_mrt.renderer.scene import unwrap
    from mitsuba_mrt.types import SeedStream

    for name, scene, truths in with_truths(args.scenes, args.res, args.truths):
        truth = truths["box"]
        sensor = scene.sensors()[0]
        width, height = (int(v) for v in sensor.film().crop_size())
        xy = every_pixel(width, height)
        integrator = unwrap(scene, None).nested
        surfaces = find_surfaces(scene, GridTracer(scene, sensor, integrator, 1, 0), width, height)
        if surfaces is None:
            print(f"{name}: no textured diffuse surface")
            continue
        for spp in (1, 2, 4, 8):
            errors = {"plain": [], "shading": [], "+clean": []}
            for seed in range(args.seeds):
                trace = GridTracer(scene, sensor, integrator, spp, 10 + seed)(
                    xy, stream=SeedStream.GRID, aovs=True, ids=False, replay=True, box=True)
                color, albedo, normal = (v.reshape(height, width, 3)
                                         for v in (trace.radiance, trace.albedo, trace.normal))
                textured = textured_pixels(surfaces[0], trace.albedo,
                                           surfaces[1]).reshape(height, width)
                images = {"plain": denoise_image(color, albedo, normal, quality="fast"),
                          "shading": denoise_shading(color, albedo, normal, textured, "fast"),
                          "+clean": denoise_shading(color, albedo, normal, textured, "fast",
                                                    clean_texture=True)}
                for key, image in images.items():
                    errors[key].append(paper_error(image, truth))
            mean = {key: float(np.mean(v)) for key, v in errors.items()}
            print(f"{name} {spp} spp: plain {mean['plain']:.5f}, shading {mean['shading']:.5f}, "
                  f"+clean {mean['+clean']:.5f} ({mean['+clean'] / mean['shading']:.3f}x)",
                  flush=True)


if __name__ == "__main__":
    main()
