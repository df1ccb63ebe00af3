"""End-to-end MRT time against a full render for an expensive integrator.

    python examples/end_to_end.py --res 1000 -D integrator=path -D spp=64 -D jitter=true
    python examples/end_to_end.py --res 1000 -D integrator=direct -D spp=16 -D jitter=true

The full render and each mode run alternately in one process, ``--repeats``
times after a warm-up; the median times are reported, with the error (the
report's metric) against the full render of the same spp.

With ``--noise-floor N`` it also renders N full renders with other seeds and
reports the error of their mean (the converged image, up to its own
1/sqrt(N) noise) against the full render: the error that even the exact
image has against a noisy reference, below which no method can go.
"""

import argparse
import statistics
import time

import mitsuba_mrt
from mitsuba_mrt.recon.metrics import paper_error


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="scenes_xml/paper_fig1.xml")
    parser.add_argument("--res", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--modes", default="auto,fast,idpass,refine,bicubic")
    parser.add_argument("--noise-floor", type=int, default=0, metavar="N",
                        help="also report the error of the mean of N other-seed renders")
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="NAME=VALUE")
    args = parser.parse_args()

    variant = mitsuba_mrt.activate("auto")
    defines = dict(d.split("=", 1) for d in args.defines)
    scene = mitsuba_mrt.load_scene(args.scene, res=args.res, **defines)
    modes = args.modes.split(",")
    reference, _ = mitsuba_mrt.render_reference(scene)  # warm-up
    for mode in modes:
        mitsuba_mrt.render(scene, mode=mode)
    full_times, times, errors, used = [], {m: [] for m in modes}, {}, {}
    for _ in range(args.repeats):
        reference, seconds = mitsuba_mrt.render_reference(scene)
        full_times.append(seconds)
        for mode in modes:
            start = time.perf_counter()
            result = mitsuba_mrt.render(scene, mode=mode)
            times[mode].append(time.perf_counter() - start)
            errors[mode] = paper_error(result.image, reference)
            used[mode] = result.mode_used
    full = statistics.median(full_times)
    print(f"{args.scene} {args.res}x{args.res} {defines} [{variant}], median of {args.repeats}")
    print(f"{'mode':8s} {'used':8s} {'seconds':>8s} {'vs full':>8s} {'error vs full':>14s}")
    print(f"{'full':8s} {'full':8s} {full:8.3f} {1.0:8.3f} {0.0:14.5f}")
    for mode in modes:
        t = statistics.median(times[mode])
        print(f"{mode:8s} {used[mode]:8s} {t:8.3f} {t / full:8.3f} {errors[mode]:14.5f}")
    if args.noise_floor > 0:
        renders = [mitsuba_mrt.render_reference(scene, seed=1000 + k)[0]
                   for k in range(args.noise_floor)]
        converged = sum(renders) / len(renders)
        print(f"noise floor: one other-seed render {paper_error(renders[0], reference):.5f}, "
              f"mean of {len(renders)} {paper_error(converged, reference):.5f}")


if __name__ == "__main__":
    main()
