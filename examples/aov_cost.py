"""What the MRT's AOVs add to a traced pixel: the grid traced with and without them.

    python examples/aov_cost.py scenes_xml/gallery/*.xml --res 256 --spp 64
    python examples/aov_cost.py scenes_xml/paper_fig1.xml --res 1000 --spp 64 \\
        -D integrator=path -D jitter=true

The grid of every scene (``--fraction`` of the pixels) is traced with the
nested integrator alone and with the AOVs the MRT adds (each sample's albedo
and normal, one ray through each pixel's centre for its ids), in turn,
``--rounds`` times after a warm-up (kernels recorded and compiled); printed
per scene: the median seconds of each and their ratio.
"""

import argparse
import statistics
import time
from pathlib import Path

import mitsuba_mrt
from mitsuba_mrt import grid_pattern
from mitsuba_mrt.bench.experiments import gallery_defines
from mitsuba_mrt.renderer.trace import trace_pixels


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--fraction", type=float, default=0.1)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("-D", dest="defines", action="append", default=[],
                        metavar="NAME=VALUE")
    args = parser.parse_args()
    defines = dict(d.split("=", 1) for d in args.defines)

    variant = mitsuba_mrt.activate("auto")
    print(f"[{variant}] {args.res} px, {args.spp} spp, f = {args.fraction}, "
          f"median of {args.rounds}")
    print(f"{'scene':28s} {'radiance s':>10s} {'with AOVs s':>11s} {'ratio':>6s}")
    for path in args.scenes:
        scene = mitsuba_mrt.load_scene(path, **gallery_defines(Path(path).stem, args.res),
                                       spp=args.spp, **defines)
        sensor = scene.sensors()[0]
        xy = grid_pattern(*(int(v) for v in sensor.film().crop_size()), args.fraction).pixel_xy
        times = {False: [], True: []}
        for k in range(args.rounds + 1):
            for aovs in ((False, True) if k % 2 else (True, False)):
                start = time.perf_counter()
                trace_pixels(scene, sensor, scene.integrator(), xy, args.spp, k, aovs=aovs,
                             replay=True)
                if k:  # the first round records and compiles
                    times[aovs].append(time.perf_counter() - start)
        plain, full = (statistics.median(times[a]) for a in (False, True))
        name = path.rsplit("/", 1)[-1][:-4]
        print(f"{name:28s} {plain:10.3f} {full:11.3f} {full / plain:6.2f}")


if __name__ == "__main__":
    main()
