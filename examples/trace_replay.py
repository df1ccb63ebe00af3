"""What replaying the grid's trace kernels saves, render by render.

    python examples/trace_replay.py scenes_xml/gallery/cornell.xml --res 128 --spp 1 4 64

In this process, after three warm-up calls of each (kernels compiled,
traces recorded), alternating rounds of: the full render (``mi.render``), the
same full render frozen with ``drjit.freeze`` (what a user can do for the
rival too), and each MRT mode with its traces replayed and traced anew
(:func:`mitsuba_mrt.renderer.replay.replaying`). Prints each one's median
time over the full render's, per spp.
"""

import argparse
import statistics
import time

import drjit as dr
import mitsuba as mi
import numpy as np

import mitsuba_mrt
from mitsuba_mrt.renderer.replay import replaying
from mitsuba_mrt.renderer.scene import unwrap


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--res", type=int, default=128)
    parser.add_argument("--spp", type=int, nargs="+", default=[1, 4, 64])
    parser.add_argument("--modes", nargs="+", default=["fast", "refine", "idpass"])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("-D", dest="defines", action="append", default=[],
                        metavar="NAME=VALUE", help="scene parameter, repeatable")
    args = parser.parse_args()

    variant = mitsuba_mrt.activate("auto")
    scene = mitsuba_mrt.load_scene(args.scene, res=args.res,
                                   **dict(d.split("=", 1) for d in args.defines))
    integrator = unwrap(scene, None).nested  # the integrator mi.render would run

    @dr.freeze
    def frozen_render(scene, seed, spp):
        return mi.render(scene, integrator=integrator, seed=seed, spp=spp)

    print(f"[{variant}] {args.scene} at {args.res} px: median of {args.rounds} "
          f"alternating rounds, as a share of the full render's")
    for spp in args.spp:
        def full(seed, spp=spp):
            return mitsuba_mrt.render_reference(scene, spp=spp, seed=seed)[1]

        def frozen(seed, spp=spp):  # timed as render_reference times mi.render
            start = time.perf_counter()
            image = frozen_render(scene, dr.opaque(mi.UInt32, seed), spp)
            np.array(image)
            return time.perf_counter() - start

        cases = {"full": full, "full, frozen": frozen}
        for mode in args.modes:
            def mrt(seed, mode=mode, replay=True, spp=spp):
                with replaying(replay):
                    return mitsuba_mrt.render(scene, spp=spp, mode=mode,
                                              seed=seed).timings.total
            cases[f"{mode} replayed"] = mrt
            cases[f"{mode} traced"] = lambda seed, mrt=mrt: mrt(seed, replay=False)
        for seed in range(3):
            for run in cases.values():
                run(seed)
        times = {name: [] for name in cases}
        for k in range(args.rounds):
            order = list(cases.items())
            for name, run in (order if k % 2 == 0 else order[::-1]):
                times[name].append(run(3 + k))
        base = statistics.median(times["full"])
        print(f"spp {spp}: full {base * 1000:.1f} ms; " + "; ".join(
            f"{name} {statistics.median(t) / base:.3f}" for name, t in times.items()
            if name != "full"))


if __name__ == "__main__":
    main()
