"""A denoised cheap full render corrected by the MRT's grid: measured, not kept.

    python examples/denoised_base.py --scenes paper_fig1,cornell,instanced,checker_border

For each scene (Fig. 1 at 400 x 400 with ``path`` at 64 spp, jittered; a
gallery scene at 128 x 128 and its own 64 spp) it prints the error against
the converged reference (from ``docs/bench/cache``, where ``bench denoise``
leaves it) of:

- ``idpass`` at 64 spp without and with ``denoise="oidn"`` (what is kept);
- a *denoised base corrected by the grid*: OIDN (quality ``fast``, with the
  ``aov`` integrator's albedo and normal) on a full render at 1 and 4 spp,
  corrected by the difference (or the ratio) between ``idpass``'s traced
  grid (raw, and denoised by the MRT's own stage) and that base at the grid
  pixels, interpolated within the ids; the smallest and largest error of
  those eight images;
- the base alone at 4 spp (OIDN on a 4-spp render).

Errors only, one seed: no times (docs/BENCHMARKS.md has what each costs).
"""

import argparse
from pathlib import Path

import numpy as np

import mitsuba_mrt
from mitsuba_mrt.recon.metrics import paper_error

FACTOR = 16  # the converged reference's spp over the scene's


def load(name: str):
    if name == "paper_fig1":
        scene = mitsuba_mrt.load_scene("scenes_xml/paper_fig1.xml", res=400, integrator="path",
                                       spp=64, jitter="true")
        return scene, 400
    return mitsuba_mrt.load_scene(f"scenes_xml/gallery/{name}.xml", res=128, spp=64), 128


#: Keeps the ratio of two dark pixels finite.
EPS = 1e-3


def corrected(result, base, how: str) -> np.ndarray:
    """``base`` corrected by ``result``'s traced grid: their difference
    (``how="difference"``) or ratio (``"ratio"``) at the grid pixels,
    interpolated within the ids, added to (multiplied into) the base."""
    from mitsuba_mrt.recon.within_region import interpolate_within_ids

    pattern = result.pattern
    at = np.ix_(pattern.rows, pattern.cols)
    grid = result.trace.radiance.reshape(pattern.grid_shape + (3,))
    values = grid - base[at] if how == "difference" else (grid + EPS) / (base[at] + EPS)
    field, _ = interpolate_within_ids(pattern, result.ids[at], values.astype(np.float32),
                                      result.ids)
    image = base + field if how == "difference" else (base + EPS) * field - EPS
    return np.maximum(image, 0.0)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="paper_fig1,cornell,instanced,checker_border")
    parser.add_argument("--cache", default="docs/bench/cache")
    args = parser.parse_args()

    names = args.scenes.split(",")
    for name in names:  # every scene's converged reference, before any rendering
        res = 400 if name == "paper_fig1" else 128
        if not (Path(args.cache) / f"{name}_{res}_{FACTOR * 64}.npy").is_file():
            parser.exit(2, f"denoised_base.py: no converged reference of {name!r} in "
                           f"{args.cache}: run `python -m mitsuba_mrt bench denoise` first\n")
    mitsuba_mrt.activate("auto")
    from mitsuba_mrt.recon.denoise import denoise_image
    from mitsuba_mrt.renderer.guides import render_guides

    print("error against converged; idpass 64 spp: plain / denoise | denoised base + grid "
          "(min-max of 8) | base alone (4 spp)")
    for name in names:
        scene, res = load(name)
        reference = np.load(Path(args.cache) / f"{name}_{res}_{FACTOR * 64}.npy")
        albedo, normal, _ = render_guides(scene)
        bases = [denoise_image(mitsuba_mrt.render_reference(scene, spp=b, seed=7)[0],
                               albedo, normal, quality="fast") for b in (1, 4)]
        plain = mitsuba_mrt.render(scene, spp=64, mode="idpass")
        denoised = mitsuba_mrt.render(scene, spp=64, mode="idpass", denoise="oidn")
        errors = [paper_error(corrected(result, base, how), reference)
                  for result in (plain, denoised) for base in bases
                  for how in ("difference", "ratio")]
        print(f"{name:15s} {paper_error(plain.image, reference):.4f} / "
              f"{paper_error(denoised.image, reference):.4f} | "
              f"{min(errors):.4f}-{max(errors):.4f} | {paper_error(bases[1], reference):.4f}",
              flush=True)


if __name__ == "__main__":
    main()
