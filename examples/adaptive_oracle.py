"""Would samples where OIDN fails beat uniform samples through OIDN?  With an oracle, measured.

    python examples/adaptive_oracle.py room spot_textures cornell materials --seeds 3

Per gallery scene at 256 x 256 (box pixel filter, albedo and normal guides
from the same samples, OIDN ``fast``), against a 256-spp render:

- ``uniform``: every pixel at 8 spp, denoised;
- ``oracle``: every pixel at 4 spp, then 16 spp more on the quarter of the
  pixels where the 4-spp denoised image is furthest from the converged one
  (its error, box-blurred over 5 x 5 pixels), denoised: the same number of
  samples, placed with knowledge no renderer has;
- ``halves``: the same, the pixels chosen by the difference between one
  2-spp half denoised and the other (what a renderer can know);
- ``variance``: the same, chosen by the relative per-pixel sample variance
  (Cycles' adaptive sampling).

Printed: each one's error (the report's metric), mean over ``--seeds``.
"""

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    import mitsuba_mrt
    from scipy.ndimage import uniform_filter

    from mitsuba_mrt.recon.denoise import denoise_image
    from mitsuba_mrt.recon.metrics import paper_error
    from mitsuba_mrt.recon.sampling import every_pixel
    from mitsuba_mrt.renderer.api import GridTracer
    from mitsuba_mrt.renderer.scene import load_scene, unwrap

    mitsuba_mrt.activate("auto")
    for name in args.scenes:
        scene = load_scene(str(ROOT / "scenes_xml" / "gallery" / f"{name}.xml"), res=256)
        sensor = scene.sensors()[0]
        width, height = (int(v) for v in sensor.film().crop_size())
        tracer = GridTracer(scene, sensor, unwrap(scene, None).nested, 64, 0)
        xy = every_pixel(width, height)
        n = len(xy)
        truth = sum(tracer(xy, stream=100 + k, aovs=False, replay=True, box=True).radiance
                    for k in range(4)) / 4

        def denoised(radiance, albedo, normal):
            return denoise_image(*(v.reshape(height, width, 3) for v in (radiance, albedo, normal)),
                                 quality="fast").reshape(-1, 3)

        errors = {"uniform": [], "oracle": [], "halves": [], "variance": []}
        for seed in range(args.seeds):
            def trace(spp, pixels, stream):
                return replace(tracer, spp=spp, seed=1000 * seed)(pixels, stream=stream, box=True,
                                                                  ids=False, replay=True)

            eight = trace(8, xy, 0)
            errors["uniform"].append(paper_error(denoised(eight.radiance, eight.albedo,
                                                          eight.normal), truth))
            a, b = trace(2, xy, 1), trace(2, xy, 2)
            four = (a.radiance + b.radiance) / 2
            albedo, normal = (a.albedo + b.albedo) / 2, (a.normal + b.normal) / 2
            where = {
                "oracle": np.abs(np.clip(denoised(four, albedo, normal), 0, 1)
                                 - np.clip(truth, 0, 1)).sum(axis=1),
                "halves": np.abs(np.clip(denoised(a.radiance, a.albedo, a.normal), 0, 1)
                                 - np.clip(b.radiance, 0, 1)).sum(axis=1),
                "variance": (a.variance + b.variance).sum(axis=1) / (four.sum(axis=1) + 0.05)}
            for key, score in where.items():
                score = uniform_filter(score.reshape(height, width), 5).ravel()
                top = np.argsort(-score)[:n // 4]
                more = trace(16, xy[top], 3)
                radiance, mixed = four.copy(), albedo.copy()
                radiance[top] = (4 * four[top] + 16 * more.radiance) / 20
                mixed[top] = (4 * albedo[top] + 16 * more.albedo) / 20
                errors[key].append(paper_error(denoised(radiance, mixed, normal), truth))
        print(name, "  ".join(f"{k} {np.mean(v):.5f}" for k, v in errors.items()), flush=True)


if __name__ == "__main__":
    main()
