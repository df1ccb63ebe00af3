"""A fresh process's first OIDN call and first pass, over OIDN's first-call prior.

    python examples/first_calls.py [--sizes 64 128 256 400 512] [--rounds 2]
    python examples/first_calls.py --passes 256 512
    python examples/first_calls.py --previews 256 384 512 768

A time-limited render in a fresh process plans its first OIDN call from a
prior (:func:`mitsuba_mrt.recon.denoise.prior_seconds`), which is meant to
be no faster than the call will be on the machine it was measured on.  Per
image size (a side, square) and preset, ``--rounds`` fresh processes each
time a first call of :func:`~mitsuba_mrt.recon.denoise.denoise_image` (both
guides) and four more; printed: the prior, the first calls (median and longest), the warm
call, the longest first call over the prior, and the warm call's seconds
per pixel and worker thread (what ``PRIOR_SECONDS`` holds).

With ``--passes RES ...``: per gallery scene at each size, a fresh
process's first pass over every pixel (1 spp, box filter, guides; kernels
from Dr.Jit's disk cache: run it twice after a change) over the ``fast``
prior, which ``auto --time-limit`` compares the time left with before it
asks the grid probe (``UNPROBED_OVER_OIDN``).

With ``--previews RES ...``: per gallery scene at each size, a fresh
process's first preview (mode ``fast`` at 1 spp, its grid through OIDN at
the preview's preset): the seconds of its stages after the grid other than
OIDN, and its OIDN call over that call's expected time, which a fresh
process's first preview plans from (``auto_limit.PREVIEW_FIRST_REST``,
``PREVIEW_FIRST_OIDN``).  The memory of earlier processes is off in every child.
"""

import argparse
import statistics
from pathlib import Path

from fresh_child import fresh_child

ROOT = Path(__file__).resolve().parents[1]

#: One process's first OIDN call and four more, as one JSON line.
OIDN_CHILD = """
import json, statistics, sys, time
import drjit as dr
import numpy as np
import mitsuba_mrt
from mitsuba_mrt import runtime
runtime.configure()
mitsuba_mrt.activate("auto")
from mitsuba_mrt.recon import denoise
n, quality = int(sys.argv[1]), sys.argv[2]
rows, cols = np.mgrid[0:n, 0:n] / n
albedo = np.stack([cols, rows, np.full_like(cols, 0.5)], axis=-1)
color = albedo * np.abs(1.0 + 0.5 * np.random.default_rng(0).standard_normal(albedo.shape))
normal = np.zeros_like(albedo)
normal[..., 2] = 1.0
prior = denoise.prior_seconds(n * n, quality)
calls = []
for _ in range(5):
    start = time.perf_counter()
    denoise.denoise_image(color, albedo, normal, quality)
    calls.append(time.perf_counter() - start)
print(json.dumps({"prior": prior, "first": calls[0], "warm": statistics.median(calls[1:]),
                  "threads": max(int(dr.thread_count()), 1)}))
"""

#: One process's first pass over every pixel of a gallery scene, as one JSON line.
PASS_CHILD = """
import json, sys, time
import numpy as np
import mitsuba_mrt
from mitsuba_mrt import runtime
runtime.configure()
mitsuba_mrt.activate("auto")
from mitsuba_mrt.bench.experiments import gallery_defines
from mitsuba_mrt.recon import denoise
from mitsuba_mrt.recon.sampling import every_pixel
from mitsuba_mrt.renderer.trace import trace_pixels
name, res = sys.argv[1], int(sys.argv[2])
scene = mitsuba_mrt.load_scene(f"scenes_xml/gallery/{name}.xml", **gallery_defines(name, res))
sensor = scene.sensors()[0]
width, height = (int(v) for v in sensor.film().crop_size())
start = time.perf_counter()
trace_pixels(scene, sensor, scene.integrator(), every_pixel(width, height), 1, 0, aovs=True,
             ids=False, replay=True, box=True, variance=False)
print(json.dumps({"first": time.perf_counter() - start,
                  "prior": denoise.prior_seconds(width * height, "fast")}))
"""

#: One process's first preview of a gallery scene: its stages after the grid, as one JSON line.
PREVIEW_CHILD = """
import json, sys
import mitsuba_mrt
from mitsuba_mrt import runtime
runtime.configure()
mitsuba_mrt.activate("auto")
from mitsuba_mrt.bench.experiments import gallery_defines
from mitsuba_mrt.recon.denoise import expected_seconds
from mitsuba_mrt.recon.sampling import grid_pattern
from mitsuba_mrt.renderer.auto_limit import PREVIEW_QUALITY
name, res = sys.argv[1], int(sys.argv[2])
scene = mitsuba_mrt.load_scene(f"scenes_xml/gallery/{name}.xml", **gallery_defines(name, res))
width, height = (int(v) for v in scene.sensors()[0].film().crop_size())
expected = expected_seconds(grid_pattern(width, height, 0.1).count, PREVIEW_QUALITY)
t = mitsuba_mrt.render(scene, mode="fast", denoise="oidn", denoise_quality=PREVIEW_QUALITY,
                       spp=1).timings
print(json.dumps({"rest": t.total - t.trace - t.trace_more - t.denoise, "oidn": t.denoise,
                  "expected": expected, "pixels": width * height}))
"""


def first_previews(sizes: list) -> None:
    from mitsuba_mrt.bench.experiments import GALLERY_SCENES

    for res in sizes:
        runs = [fresh_child(PREVIEW_CHILD, name, str(res), what=f"{name}'s first preview",
                            cwd=ROOT) for name in GALLERY_SCENES]
        for name, run in zip(GALLERY_SCENES, runs):
            print(f"{name:16s} {res:4d} px: after the grid {run['rest']:.4f} s and OIDN "
                  f"{run['oidn']:.4f} s, {run['oidn'] / run['expected']:.2f} x expected")
        print(f"{res} px: the rest {min(r['rest'] for r in runs):.4f}-"
              f"{max(r['rest'] for r in runs):.4f} s, OIDN "
              f"{min(r['oidn'] / r['expected'] for r in runs):.2f}-"
              f"{max(r['oidn'] / r['expected'] for r in runs):.2f} x expected")


def oidn_calls(sizes: list, rounds: int) -> None:
    print(f"{'px':>4s} {'preset':9s} {'prior s':>8s} {'first s':>8s} {'longest':>8s} "
          f"{'warm s':>8s} {'longest/prior':>13s} {'warm us/px/thread':>17s}")
    for n in sizes:
        for quality in ("fast", "balanced", "high"):
            runs = [fresh_child(OIDN_CHILD, str(n), quality, what=f"OIDN at {n} px, {quality}",
                                cwd=ROOT) for _ in range(rounds)]
            prior, longest = runs[0]["prior"], max(r["first"] for r in runs)
            warm = statistics.median(r["warm"] for r in runs)
            per_pixel = warm * runs[0]["threads"] / (n * n) * 1e6
            print(f"{n:4d} {quality:9s} {prior:8.3f} "
                  f"{statistics.median(r['first'] for r in runs):8.3f} {longest:8.3f} "
                  f"{warm:8.3f} {longest / prior:13.2f} {per_pixel:17.2f}")


def first_passes(sizes: list) -> None:
    from mitsuba_mrt.bench.experiments import GALLERY_SCENES

    for res in sizes:
        ratios = []
        for name in GALLERY_SCENES:
            run = fresh_child(PASS_CHILD, name, str(res), what=f"{name}'s first pass",
                              cwd=ROOT)
            ratios.append(run["first"] / run["prior"])
            print(f"{name:16s} {res:4d} px: first pass {run['first']:.3f} s, "
                  f"{ratios[-1]:.2f} x the prior")
        print(f"{res} px: {min(ratios):.2f}-{max(ratios):.2f} x the prior")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128, 256, 400, 512])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--passes", type=int, nargs="+", metavar="RES",
                        help="first passes of the gallery at these sizes instead")
    parser.add_argument("--previews", type=int, nargs="+", metavar="RES",
                        help="first previews of the gallery at these sizes instead")
    args = parser.parse_args()
    if args.previews:
        first_previews(args.previews)
    elif args.passes:
        first_passes(args.passes)
    else:
        oidn_calls(args.sizes, args.rounds)


if __name__ == "__main__":
    main()
