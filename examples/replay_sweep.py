"""A sweep's renders: how often their traces are recorded anew, and what a round costs.

    python examples/replay_sweep.py scenes_xml/gallery/instanced.xml --res 128

Renders every combination of ``--fractions`` x ``--spp`` x ``--modes`` in turn,
``--rounds`` times, as a parameter sweep or ``bench denoise`` does. Each round
prints its time, how many recordings of the trace kernels it made
(:mod:`mitsuba_mrt.renderer.replay`; after the first round, each one is a
layout recorded again instead of replayed) and the process's resident memory.
"""

import argparse
import time

import mitsuba_mrt
from mitsuba_mrt.renderer.replay import recordings


def resident_mb() -> int:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS"):
                return int(line.split()[1]) // 1024
    return -1


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--res", type=int, default=128)
    parser.add_argument("--spp", type=int, nargs="+", default=[1, 4, 9, 16])
    parser.add_argument("--fractions", type=float, nargs="+", default=[0.05, 0.1, 0.2])
    parser.add_argument("--modes", nargs="+", default=["fast", "idpass"])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("-D", dest="defines", action="append", default=[],
                        metavar="NAME=VALUE", help="scene parameter, repeatable")
    args = parser.parse_args()

    variant = mitsuba_mrt.activate("auto")
    scene = mitsuba_mrt.load_scene(args.scene, res=args.res,
                                   **dict(d.split("=", 1) for d in args.defines))
    layouts = [(f, spp, mode) for f in args.fractions for mode in args.modes
               for spp in args.spp]
    print(f"[{variant}] {args.scene} at {args.res} px: {len(layouts)} renders a round")
    for k in range(args.rounds):
        before, start = recordings(), time.perf_counter()
        for f, spp, mode in layouts:
            mitsuba_mrt.render(scene, spp=spp, mode=mode, sample_fraction=f)
        print(f"round {k}: {time.perf_counter() - start:.2f} s, "
              f"{recordings() - before} recordings, {resident_mb()} MB resident", flush=True)


if __name__ == "__main__":
    main()
