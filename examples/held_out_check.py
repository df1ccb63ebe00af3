"""Does ``auto``'s held-out check tell an MRT image's error?  Measured against the truth.

    python examples/held_out_check.py checker_border cornell crop_rgba envmap_objects \\
        instanced materials room spot_textures two_sensors --res 512

Per gallery scene at its 64 spp, the MRT image ``auto`` chooses without a
pilot (``idpass`` or ``refine``, OIDN on the grid: see
:mod:`mitsuba_mrt.renderer.auto_plans`; on a scene where it chooses none, ``idpass``)
is checked as ``auto`` checks it (:func:`mitsuba_mrt.renderer.held_out.check_image`),
and its relative RMS error is measured on every pixel against two independent
full renders of ``--ref-spp`` each (their mean's noise, a quarter of their
mean squared difference, taken off), as is a full render's at 64 spp.
Printed: the check's estimates of the image's error and of a full render's,
the truth of each, their ratios, and the check's seconds over the full
render's (warm: the second of two checks).
"""

import argparse
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def true_rms(image, a, b):
    """``image``'s relative RMS error against the mean of ``a`` and ``b``, less their noise."""
    from mitsuba_mrt.recon.metrics import relative_error
    from mitsuba_mrt.renderer.held_out import squared_error

    shown = np.clip(image, 0.0, 1.0).reshape(-1, 3)
    return relative_error(squared_error(shown, a.reshape(-1, 3), b.reshape(-1, 3))[0], shown)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--res", type=int, default=512)
    parser.add_argument("--ref-spp", type=int, default=256)
    args = parser.parse_args()

    import mitsuba_mrt
    from mitsuba_mrt.bench.experiments import gallery_defines
    from mitsuba_mrt.renderer import auto_plans
    from mitsuba_mrt.renderer.api import GridTracer
    from mitsuba_mrt.renderer.held_out import check_image
    from mitsuba_mrt.renderer.pilot import effective_area
    from mitsuba_mrt.renderer.scene import unwrap

    mitsuba_mrt.activate("auto")
    print(f"{'scene':15s} {'mode':7s} {'check':>7s} {'true':>7s} {'ratio':>6s} "
          f"{'check full':>10s} {'true full':>9s} {'ratio':>6s} {'check s / full':>14s}")
    for name in args.scenes:
        defines = {**gallery_defines(name, args.res), "spp": 64}
        scene = mitsuba_mrt.load_scene(str(ROOT / "scenes_xml" / "gallery" / f"{name}.xml"),
                                       **defines)
        sensor = scene.sensors()[0]
        tracer = GridTracer(scene, sensor, unwrap(scene, None).nested, 64, 0)
        area = effective_area(sensor.film().rfilter())
        chosen = auto_plans.unmeasured_plan(scene, args.res * args.res)
        mode = chosen[0].mode if chosen else "idpass"
        result = mitsuba_mrt.render(scene, mode=mode, denoise="oidn")
        check_image(result.image, result.traced_mask, tracer, area)  # its kernels
        begin = time.perf_counter()
        held = check_image(result.image, result.traced_mask, tracer, area)
        check_s = time.perf_counter() - begin
        full, full_s = mitsuba_mrt.render_reference(scene, seed=11)
        a, _ = mitsuba_mrt.render_reference(scene, spp=args.ref_spp, seed=101)
        b, _ = mitsuba_mrt.render_reference(scene, spp=args.ref_spp, seed=202)
        mine, theirs = true_rms(result.image, a, b), true_rms(full, a, b)
        print(f"{name:15s} {mode:7s} {held.error:7.4f} {mine:7.4f} {held.error / mine:6.2f} "
              f"{held.full_error:10.4f} {theirs:9.4f} {held.full_error / theirs:6.2f} "
              f"{check_s / full_s:14.3f}", flush=True)


if __name__ == "__main__":
    main()
