"""How far one render's error moves from seed to seed: the width of "level" in ``bench rival``.

    python examples/seed_spread.py materials cornell room instanced crop_rgba envmap_objects \
        [--spp 16] [--seeds 8] [--res 256]

Where ``auto`` takes the passes it renders what the alternative renders
(every pixel at some spp, box filter, OIDN with guides of the same samples),
on seeds of its own: its error and the alternative's differ by the seeds
alone.  Per gallery scene, the alternative at ``--spp`` with OIDN ``high``
is rendered on ``--seeds`` seeds; printed: the mean error (the report's
metric, against the box-filtered converged renders ``bench rival`` keeps in
``--truths``), its relative standard deviation from render to render, and
the lowest and highest over the mean.
"""

import argparse

import numpy as np

from gallery_scenes import add_truths, with_truths


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--res", type=int, default=256)
    add_truths(parser)
    args = parser.parse_args()

    from mitsuba_mrt.recon.metrics import paper_error
    from mitsuba_mrt.renderer.api import render_denoised

    for name, scene, truths in with_truths(args.scenes, args.res, args.truths):
        truth = truths["box"]
        errors = np.array([paper_error(render_denoised(scene, spp=args.spp, quality="high",
                                                       seed=seed)[0], truth)
                           for seed in range(args.seeds)])
        mean = errors.mean()
        print(f"{name} at {args.spp} spp: error {mean:.5f}, relative SD "
              f"{errors.std(ddof=1) / mean:.3f}, range {errors.min() / mean:.3f}-"
              f"{errors.max() / mean:.3f}", flush=True)


if __name__ == "__main__":
    main()
