"""Render the report's Fig. 1 scene with the MRT and draw reference | MRT | error.

    python examples/render_fig1.py [--res 400] [--mode paper] [--out docs/images/fig1_triptych.png]

Uses the Python API: load a scene, render with the MRT, render the full
reference, compare.
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import mitsuba_mrt  # noqa: E402
from mitsuba_mrt.imageio import atomic_path, srgb_encode  # noqa: E402
from mitsuba_mrt.recon.metrics import error_map, paper_error, psnr  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, default=400)
    parser.add_argument("--sample-fraction", type=float, default=0.1)
    parser.add_argument("--mode", default="paper",
                        help="reconstruction mode (default: paper, the report's method)")
    parser.add_argument("--out", default="fig1_triptych.png")
    args = parser.parse_args()

    variant = mitsuba_mrt.activate("auto")
    scene = mitsuba_mrt.load_scene("scenes_xml/paper_fig1.xml", res=args.res)
    result = mitsuba_mrt.render(scene, sample_fraction=args.sample_fraction, mode=args.mode)
    reference, ref_seconds = mitsuba_mrt.render_reference(scene)
    err = error_map(result.image, reference)

    fig, axes = plt.subplots(1, 3, figsize=(12, 4.3))
    axes[0].imshow(srgb_encode(reference))
    axes[0].set_title(f"full render ({ref_seconds:.2f} s)")
    axes[1].imshow(srgb_encode(result.image))
    axes[1].set_title(f"MRT ({args.mode}), f = {args.sample_fraction} "
                      f"({result.timings.total:.2f} s)")
    shown = axes[2].imshow(np.log10(np.clip(err, 1e-4, 1)), cmap="inferno", vmin=-4, vmax=0)
    axes[2].set_title(f"error {paper_error(result.image, reference):.4f}, "
                      f"PSNR {psnr(result.image, reference):.1f} dB")
    fig.colorbar(shown, ax=axes[2], fraction=0.046, label="log10 |MRT - ref| / 3")
    for ax in axes:
        ax.axis("off")
    fig.suptitle(f"Report Fig. 1 scene, {args.res} x {args.res}, matte, {variant}")
    fig.tight_layout()
    with atomic_path(args.out) as tmp:
        fig.savefig(tmp, dpi=80, format="png")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
