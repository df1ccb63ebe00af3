"""Intel Open Image Denoise from ``pyoidn`` against ``mitsuba-oidn``: first call and warm calls.

    pip install pyoidn mitsuba-oidn
    python examples/oidn_backends.py --res 256 512 1000 --rounds 7

Both run OIDN's ``RT`` filter on the CPU (HDR colour, albedo and normal
guides, float32 numpy images) with filters kept between calls, as
``mitsuba_mrt.recon.denoise`` does.  First, each backend's first call
(import, device, filter, weights) in fresh processes of its own, ``--fresh``
times each, alternating; then, in one process, warm calls of both at each
``--res`` and quality, alternating, ``--rounds`` times.  Printed: medians,
the ratio mitsuba-oidn / pyoidn, and the largest difference between the two
outputs.
"""

import argparse
import importlib.util
import statistics
import subprocess
import sys
import time

import numpy as np

FIRST_CALL = """
import time, numpy as np
import drjit
image = np.random.default_rng(0).random((256, 256, 3), dtype=np.float32)
begin = time.perf_counter()
import {module}
{call}
print(time.perf_counter() - begin)
"""


class Pyoidn:
    """pyoidn with one committed filter per image size and quality."""

    name = "pyoidn"
    first = ("device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU); device.commit()\n"
             "f = pyoidn.Filter(device, pyoidn.OIDN_FILTER_TYPE_RT); f.set_bool('hdr', True)\n"
             "out = np.empty_like(image)\n"
             "for n in ('color', 'albedo', 'output'): "
             "f.set_image(n, out if n == 'output' else image, pyoidn.OIDN_FORMAT_FLOAT3)\n"
             "f.commit(); f.execute()")

    def __init__(self):
        import pyoidn
        self.lib = pyoidn
        self.device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
        self.device.commit()
        self.filters = {}

    def __call__(self, color, albedo, normal, quality):
        lib, key = self.lib, (color.shape, quality)
        flt = self.filters.get(key)
        if flt is None:
            flt = self.filters[key] = lib.Filter(self.device, lib.OIDN_FILTER_TYPE_RT)
            flt.set_bool("hdr", True)
            flt.set_int("quality", {"fast": lib.OIDN_QUALITY_FAST,
                                    "balanced": lib.OIDN_QUALITY_BALANCED}[quality])
        out = np.empty_like(color)
        for name, image in (("color", color), ("albedo", albedo), ("normal", normal),
                            ("output", out)):
            flt.set_image(name, image, lib.OIDN_FORMAT_FLOAT3)
        flt.commit()
        flt.execute()
        return out


class MitsubaOidn(Pyoidn):
    """mitsuba-oidn, the same way."""

    name = "mitsuba_oidn"
    first = ("device = mitsuba_oidn.Device(mitsuba_oidn.DeviceType.CPU); device.commit()\n"
             "f = device.new_filter('RT'); f.hdr = True\n"
             "f.set_image('color', image); f.set_image('albedo', image)\n"
             "out = np.empty_like(image); f.set_image('output', out); f.execute()")

    def __init__(self):
        import mitsuba_oidn
        self.lib = mitsuba_oidn
        self.device = mitsuba_oidn.Device(mitsuba_oidn.DeviceType.CPU)
        self.device.commit()
        self.filters = {}

    def __call__(self, color, albedo, normal, quality):
        key = (color.shape, quality)
        flt = self.filters.get(key)
        if flt is None:
            flt = self.filters[key] = self.device.new_filter("RT")
            flt.hdr = True
            flt.quality = {"fast": self.lib.Quality.Fast,
                           "balanced": self.lib.Quality.Balanced}[quality]
        out = np.empty_like(color)
        for name, image in (("color", color), ("albedo", albedo), ("normal", normal),
                            ("output", out)):
            flt.set_image(name, image)
        flt.execute()
        return out


def first_calls(count: int) -> dict:
    """Seconds of each backend's first call, each in a fresh process."""
    times = {Pyoidn.name: [], MitsubaOidn.name: []}
    for _ in range(count):
        for backend in (Pyoidn, MitsubaOidn):
            code = FIRST_CALL.format(module=backend.name, call=backend.first)
            out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                 check=True)
            times[backend.name].append(float(out.stdout.split()[-1]))
    return times


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, nargs="+", default=[256, 512, 1000])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--fresh", type=int, default=3)
    args = parser.parse_args()
    missing = [name for name in ("pyoidn", "mitsuba_oidn")
               if importlib.util.find_spec(name) is None]
    if missing:
        print(f"error: {' and '.join(missing)} not installed (pip install pyoidn mitsuba-oidn)",
              file=sys.stderr)
        sys.exit(2)
    firsts = first_calls(args.fresh)
    a, b = (statistics.median(firsts[k]) for k in (Pyoidn.name, MitsubaOidn.name))
    print(f"first call, fresh process, 256 px: pyoidn {a:.3f} s, mitsuba-oidn {b:.3f} s, "
          f"ratio {b / a:.2f}")
    backends = (Pyoidn(), MitsubaOidn())
    rng = np.random.default_rng(0)
    print("res | quality | pyoidn s | mitsuba-oidn s | ratio | largest difference")
    for res in args.res:
        color, albedo = (rng.random((res, res, 3), dtype=np.float32) for _ in range(2))
        normal = np.ascontiguousarray(rng.random((res, res, 3), dtype=np.float32) * 2 - 1)
        for quality in ("fast", "balanced"):
            outs = [backend(color, albedo, normal, quality) for backend in backends]  # warm-up
            times = ([], [])
            for _ in range(args.rounds):
                for k, backend in enumerate(backends):
                    begin = time.perf_counter()
                    backend(color, albedo, normal, quality)
                    times[k].append(time.perf_counter() - begin)
            a, b = (statistics.median(t) for t in times)
            print(f"{res} | {quality} | {a:.4f} | {b:.4f} | {b / a:.2f} | "
                  f"{float(np.abs(outs[0] - outs[1]).max()):.1e}")


if __name__ == "__main__":
    main()
