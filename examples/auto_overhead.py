"""``auto`` against the full render on every bundled scene.

    python examples/auto_overhead.py --res 200 400

For each scene of ``scenes_xml/`` (with its own integrator and spp) and each
resolution, the full render and ``render(mode="auto")`` run alternately, each
first in every other round, ``--rounds`` times in this process after a warm-up;
the lower medians, their ratio and the mode ``auto`` used are printed, the worst
ratio last.
"""

import argparse
import os
import statistics
from pathlib import Path

import mitsuba_mrt


def main():
    # (a benchmark plans from what its own process measures, not what earlier renders remembered)
    os.environ.setdefault("MITSUBA_MRT_MEMORY", "off")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="scenes_xml")
    parser.add_argument("--res", type=int, nargs="+", default=[200, 400])
    parser.add_argument("--rounds", type=int, default=25)
    args = parser.parse_args()

    variant = mitsuba_mrt.activate("auto")
    print(f"[{variant}] lower median of {args.rounds} alternating rounds")
    print(f"{'scene':34s} {'res':>5s} {'full s':>9s} {'auto s':>9s} {'ratio':>6s}  used")
    worst = (0.0, "")
    for path in sorted(Path(args.scenes).glob("*.xml")):
        for res in args.res:
            scene = mitsuba_mrt.load_scene(path, res=res)
            mitsuba_mrt.render_reference(scene)
            mitsuba_mrt.render(scene)  # warm-up
            full, auto = [], []
            for k in range(args.rounds):
                if k % 2:  # which goes first alternates too: no order effect
                    result = mitsuba_mrt.render(scene)
                    auto.append(result.timings.total)
                full.append(mitsuba_mrt.render_reference(scene)[1])
                if not k % 2:
                    result = mitsuba_mrt.render(scene)
                    auto.append(result.timings.total)
            f, a = statistics.median_low(full), statistics.median_low(auto)
            used = result.mode_used
            print(f"{path.name:34s} {res:5d} {f:9.4f} {a:9.4f} {a / f:6.3f}  {used}")
            worst = max(worst, (a / f, f"{path.name} at {res}"))
    print(f"worst ratio {worst[0]:.3f} ({worst[1]})")


if __name__ == "__main__":
    main()
