"""What the noise-aware smoothing of the traced grid buys, scene by scene.

    python examples/noise_smoothing.py --scenes scenes_xml/gallery --res 128 --seeds 3

Renders every scene with ``fast``, ``refine`` and ``idpass``, with the
default ``noise_smoothing`` and with it off (0), on the same seeds, and
prints each one's error against a converged reference (the mean of 16
full renders at 16x the scene's spp, other seeds; taken from
``docs/bench/cache`` when ``bench gallery`` left one there), with
``bicubic`` of the same grid for scale.  Errors only: no times.
"""

import argparse
from pathlib import Path
from statistics import median

import numpy as np

import mitsuba_mrt
from mitsuba_mrt.recon.metrics import paper_error
from mitsuba_mrt.types import MRTParams

MODES = ("fast", "refine", "idpass")
FACTOR = 16  # the converged reference's spp over the scene's


def converged(scene, name: str, res: int, spp: int, cache: Path) -> np.ndarray:
    path = cache / f"{name}_{res}_{FACTOR * spp}.npy"
    if path.is_file():
        return np.load(path)
    return np.mean([mitsuba_mrt.render_reference(scene, seed=1000 + k)[0]
                    for k in range(FACTOR)], axis=0)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="scenes_xml/gallery")
    parser.add_argument("--res", type=int, default=128)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--cache", default="docs/bench/cache")
    args = parser.parse_args()

    mitsuba_mrt.activate("auto")
    default = MRTParams().noise_smoothing
    print(f"error against converged, median of {args.seeds} seeds; "
          f"noise_smoothing {default} / 0 (off)")
    print(f"{'scene':16s} {'bicubic':>8s} " + " ".join(f"{m:>17s}" for m in MODES))
    for path in sorted(Path(args.scenes).glob("*.xml")):
        scene = mitsuba_mrt.load_scene(str(path), res=args.res)
        spp = int(scene.sensors()[0].sampler().sample_count())
        reference = converged(scene, path.stem, args.res, spp, Path(args.cache))

        def error(mode, **params):
            return median(paper_error(mitsuba_mrt.render(scene, mode=mode, seed=seed,
                                                         **params).image, reference)
                          for seed in range(args.seeds))

        cells = [f"{error(m):.4f} / {error(m, noise_smoothing=0.0):.4f}" for m in MODES]
        print(f"{path.stem:16s} {error('bicubic'):8.4f} " + " ".join(f"{c:>17s}" for c in cells),
              flush=True)


if __name__ == "__main__":
    main()
