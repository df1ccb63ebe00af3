"""Time the whole reconstruction call, mode by mode, on one traced grid.

    python tools/time_reconstruct.py --res 1000 --modes paper,fast --repeats 11

Traces the grid of ``paper_fig1.xml`` (``matte``, f = 0.1) once, then times
``mitsuba_mrt.reconstruct`` for every mode in turn, ``--repeats`` rounds after
one warm-up call each (Dr.Jit compiles its kernels then), and prints the
median, fastest and slowest call and the median's throughput in Mpixel/s.
With ``--profile``, one more call per mode runs under cProfile and the
functions with the most cumulative time are printed.
Unlike ``bench`` (which sums the ``edges`` and ``interpolate`` stage timers),
this times everything ``reconstruct`` does, its checks and statistics included.
"""

import argparse
import cProfile
import pstats
import time

import numpy as np

import mitsuba_mrt
from mitsuba_mrt import MRTParams, reconstruct


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="scenes_xml/paper_fig1.xml")
    parser.add_argument("--res", type=int, default=1000)
    parser.add_argument("--modes", default="paper,fast")
    parser.add_argument("--repeats", type=int, default=11)
    parser.add_argument("--profile", action="store_true",
                        help="then profile one call per mode (cProfile, by cumulative time)")
    args = parser.parse_args()

    mitsuba_mrt.activate("auto")
    scene = mitsuba_mrt.load_scene(args.scene, res=args.res)
    traced = mitsuba_mrt.render(scene, mode="fast")
    pattern, trace = traced.pattern, traced.trace
    modes = args.modes.split(",")
    times = {mode: [] for mode in modes}
    for mode in modes:
        reconstruct(pattern, trace, MRTParams(), mode)
    for _ in range(args.repeats):
        for mode in modes:
            start = time.perf_counter()
            reconstruct(pattern, trace, MRTParams(), mode)
            times[mode].append(time.perf_counter() - start)
    pixels = pattern.width * pattern.height / 1e6
    for mode, values in times.items():
        median = float(np.median(values))
        print(f"{mode}: median {median:.4f} s ({pixels / median:.2f} Mpixel/s), "
              f"fastest {min(values):.4f} s, slowest {max(values):.4f} s, {len(values)} calls")
    if args.profile:
        for mode in modes:
            profile = cProfile.Profile()
            profile.runcall(reconstruct, pattern, trace, MRTParams(), mode)
            print(f"--- {mode}: one call under cProfile")
            pstats.Stats(profile).sort_stats("cumulative").print_stats(25)


if __name__ == "__main__":
    main()
