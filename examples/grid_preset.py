"""The MRT's grid through OIDN ``fast`` against ``high``: what ``denoise_quality="auto"`` takes.

    python examples/grid_preset.py checker_border:idpass:0.2:32 two_sensors:idpass:0.2:32 \\
        paper_fig1:idpass:0.1:64 cornell:idpass:0.2:32 materials:refine:0.1:64 [--res 256]
    python examples/grid_preset.py envmap_objects:refine:0.1:64 materials:refine:0.1:64 \\
        crop_rgba:idpass:0.1:64 checker_border:idpass:0.1:64 spot_textures:idpass:0.1:64 \\
        --res 512 --truths docs/bench/rival512/cache --truth-spp 1024

Per ``SCENE:MODE:FRACTION:SPP`` (a gallery scene at ``--res``, or
``paper_fig1`` with ``path`` at 400 px, as ``bench rival`` renders them), warm,
in this process: the MRT in that mode with ``denoise="oidn"``, its grid of
that fraction traced at that spp, once with ``denoise_quality`` ``fast`` (the
grid and any whole image through ``fast``), once with ``auto`` (the grid
through :data:`~mitsuba_mrt.recon.denoise.GRID_QUALITY`, whole images through
``fast``) and, for ``refine``, once with ``high`` (its whole image too),
alternating with the full render over ``--seeds`` seeds.  Printed per
setting: the median time over the full render's and the mean error (the
report's metric against the converged renders ``bench rival`` keeps in
``--truths``).
"""

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from gallery_scenes import add_truth_spp, add_truths, load


def case(text: str) -> tuple:
    """A ``SCENE:MODE:FRACTION:SPP`` argument (argparse reports a ValueError)."""
    name, mode, fraction, spp = text.split(":")
    return name, mode, float(fraction), int(spp)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="+", type=case, metavar="SCENE:MODE:FRACTION:SPP")
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--seeds", type=int, default=3)
    add_truth_spp(parser)
    add_truths(parser)
    args = parser.parse_args()

    import mitsuba_mrt
    from mitsuba_mrt import runtime
    from mitsuba_mrt.bench.rival import kept_truth
    from mitsuba_mrt.recon.metrics import paper_error

    runtime.configure()
    mitsuba_mrt.activate("auto")
    for name, mode, fraction, spp in args.cases:
        scene = load(name, 400 if name == "paper_fig1" else args.res)
        truth = kept_truth(scene, name, Path(args.truths), args.truth_spp)["film"]
        settings = ["fast", "auto"] + (["high"] if mode == "refine" else [])

        def run(quality, seed):
            return mitsuba_mrt.render(scene, mode=mode, denoise="oidn", denoise_quality=quality,
                                      sample_fraction=fraction, spp=spp, seed=seed)
        mitsuba_mrt.render_reference(scene)
        for quality in settings:  # warm-up: kernels recorded, OIDN's filters made
            run(quality, args.seeds)
        times = {q: [] for q in ["full", *settings]}
        errors = {q: [] for q in settings}
        for seed in range(args.seeds):
            times["full"].append(mitsuba_mrt.render_reference(scene)[1])
            for quality in settings:
                begin = time.perf_counter()
                image = run(quality, seed).image
                times[quality].append(time.perf_counter() - begin)
                errors[quality].append(paper_error(np.asarray(image)[..., :3], truth))
        full = statistics.median(times["full"])
        print(f"{name} {mode}, grid {fraction} at {spp} spp (full render {full:.2f} s): " + "; ".join(
            f"{q}: time {statistics.median(times[q]) / full:.3f}, error {np.mean(errors[q]):.5f}"
            for q in settings), flush=True)


if __name__ == "__main__":
    main()
