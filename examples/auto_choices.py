"""What ``auto``'s passes gain from their two choices of OIDN's use, each against the same passes without it.

    python examples/auto_choices.py spot_textures room crop_rgba materials instanced --res 256

Per gallery scene (its 64 spp), warm, in this process, against the
box-filtered converged renders ``bench rival`` uses (the report's metric;
read from or kept in ``--truths``), three ``auto`` renders, each planned anew,
of the default target alternate ``--repeats`` times:

- ``plain``: OIDN ``fast`` on every pixel (``denoise_quality="fast"``, the
  textured surfaces not as their shading);
- ``+shading``: the same, textured diffuse surfaces denoised as their
  shading (``progressive.SHADING``);
- ``+high`` (the default): the same, the last OIDN call at the preset
  :func:`~mitsuba_mrt.renderer.progressive.final_quality` picks.

The passes' seeds are the same in all three, so their errors differ by the
choices alone.  Printed: each one's median time and error as ratios to
``plain``'s, with the spp and the preset used.
"""

import argparse
import os
import statistics

from gallery_scenes import add_truths, with_truths


def main():
    # (a benchmark plans from what its own process measures, not what earlier renders remembered)
    os.environ.setdefault("MITSUBA_MRT_MEMORY", "off")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=3)
    add_truths(parser)
    args = parser.parse_args()

    import mitsuba_mrt
    from mitsuba_mrt.recon.metrics import paper_error
    from mitsuba_mrt.renderer import progressive
    from mitsuba_mrt.renderer.state import clear_caches

    methods = {"plain": (False, "fast"), "+shading": (True, "fast"), "+high": (True, "auto")}
    for name, scene, truths in with_truths(args.scenes, args.res, args.truths):
        truth = truths["box"]

        def run(shading, quality):
            progressive.SHADING = shading
            clear_caches()  # (each planned anew: a kept plan would be another method's)
            try:
                return mitsuba_mrt.render(scene, denoise_quality=quality)
            finally:
                progressive.SHADING = True

        times, last = {k: [] for k in methods}, {}
        for m in methods.values():  # warm-up
            run(*m)
        for _ in range(args.repeats):  # alternating
            for k, m in methods.items():
                last[k] = run(*m)
                times[k].append(last[k].timings.total)
        seconds = {k: statistics.median(v) for k, v in times.items()}
        error = {k: paper_error(r.image, truth) for k, r in last.items()}
        cells = [f"{k} {seconds[k] / seconds['plain']:.2f}x time, "
                 f"{error[k] / error['plain']:.3f}x error ({last[k].auto.choice.label})"
                 for k in list(methods)[1:]]
        print(f"{name}: plain {seconds['plain']:.3f} s, error {error['plain']:.5f} "
              f"({last['plain'].auto.choice.label}); " + "; ".join(cells), flush=True)


if __name__ == "__main__":
    main()
