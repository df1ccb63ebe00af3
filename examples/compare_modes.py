"""Render one scene with every reconstruction mode and print error and time.

    python examples/compare_modes.py scenes_xml/paper_fig1.xml --res 400
    python examples/compare_modes.py scenes_xml/paper_fig1_conductor.xml -D integrator=path -D spp=16 -D jitter=true

One quick look at what each mode buys; docs/BENCHMARKS.md has the careful,
repeated measurements.
"""

import argparse
import time

import mitsuba_mrt
from mitsuba_mrt.recon.metrics import paper_error, psnr


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--res", type=int, default=None)
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="NAME=VALUE")
    args = parser.parse_args()

    mitsuba_mrt.activate("auto")
    defines = dict(d.split("=", 1) for d in args.defines)
    if args.res:
        defines["res"] = args.res
    scene = mitsuba_mrt.load_scene(args.scene, **defines)
    mitsuba_mrt.render_reference(scene)  # compile the kernels once, untimed
    reference, full_s = mitsuba_mrt.render_reference(scene)
    print(f"{'mode':8s} {'used':8s} {'error':>9s} {'PSNR dB':>8s} {'seconds':>8s} {'vs full':>8s}")
    print(f"{'full':8s} {'full':8s} {0.0:9.5f} {'inf':>8s} {full_s:8.3f} {1.0:8.2f}")
    for mode in ["auto", *mitsuba_mrt.MODES]:
        mitsuba_mrt.render(scene, mode=mode)  # warm-up
        start = time.perf_counter()
        result = mitsuba_mrt.render(scene, mode=mode)
        seconds = time.perf_counter() - start
        used = result.mode_used
        print(f"{mode:8s} {used:8s} {paper_error(result.image, reference):9.5f} "
              f"{psnr(result.image, reference):8.2f} {seconds:8.3f} {seconds / full_s:8.2f}")


if __name__ == "__main__":
    main()
