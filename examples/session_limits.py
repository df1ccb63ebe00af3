"""A user's session: a scene's default render, then time-limited renders, in one process.

    python examples/session_limits.py [SCENE ...] [--res 256] [--no-oidn]

Per gallery scene (all nine by default), in a fresh process of its own: the
full render three times (the median is the limits' base), the default
``auto`` render (its plan checked and kept, as a user's first render of the
scene), then two renders under each limit of 0.1, 0.25 and 0.5 of the full
render.  The later renders plan from what the process measured before them
(:mod:`mitsuba_mrt.renderer.kept_plans`, the passes' launches), which neither
``bench rival`` (each method warmed up first) nor ``fresh_time_limit.py`` (one
render a process) shows.  Printed per scene: the default's time over the full
render's, and each limited render's wall time over its limit and its plan.
With ``--no-oidn`` every render is as without OIDN installed
(:func:`mitsuba_mrt.recon.denoise.hidden`).  The memory of earlier processes
is off.
"""

import argparse
import json
from pathlib import Path

from fresh_child import fresh_child

ROOT = Path(__file__).resolve().parents[1]
LIMITS = (0.1, 0.25, 0.5)

#: The child's program: the session, its figures as one JSON line.
CHILD = """
import json, statistics, sys, time
import mitsuba_mrt
from mitsuba_mrt import runtime
runtime.configure()
mitsuba_mrt.activate("auto")
from mitsuba_mrt.bench.experiments import gallery_defines
from mitsuba_mrt.recon.denoise import hidden
name, res, limits = sys.argv[1], int(sys.argv[2]), json.loads(sys.argv[4])
scene = mitsuba_mrt.load_scene(f"scenes_xml/gallery/{name}.xml", **gallery_defines(name, res))
full = statistics.median(mitsuba_mrt.render_reference(scene)[1] for _ in range(3))
with hidden(sys.argv[3] == "no-oidn"):
    default = mitsuba_mrt.render(scene)
    runs = []
    for share in limits:
        for seed in range(2):
            begin = time.perf_counter()
            result = mitsuba_mrt.render(scene, time_limit=share * full, seed=seed)
            runs.append([share, (time.perf_counter() - begin) / (share * full),
                         result.auto.choice.label])
print(json.dumps({"full": full, "default": default.timings.total / full,
                  "chose": default.auto.choice.label, "runs": runs}))
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", help="gallery scenes (default: all nine)")
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--no-oidn", action="store_true")
    args = parser.parse_args()
    from mitsuba_mrt.bench.experiments import GALLERY_SCENES

    for name in args.scenes or GALLERY_SCENES:
        out = fresh_child(CHILD, name, str(args.res), "no-oidn" if args.no_oidn else "oidn",
                          json.dumps(LIMITS), what=f"the session of {name}", memory="off",
                          cwd=ROOT)
        runs = "; ".join(f"{share}: {x:.2f}x ({chose})" for share, x, chose in out["runs"])
        print(f"{name}: full {out['full']:.3f} s; default {out['default']:.2f} "
              f"({out['chose']}); {runs}", flush=True)


if __name__ == "__main__":
    main()
