"""``auto --time-limit`` as a user's first render: each render in a fresh process.

    python examples/fresh_time_limit.py checker_border cornell crop_rgba envmap_objects \
        instanced materials room spot_textures two_sensors [--res 512] [--cold-cache]

Per gallery scene at ``--res`` a side (256 by default): the full render in three fresh processes
(median), then one fresh process per limit of 0.1, 0.25 and 0.5 of it, each
rendering once with ``time_limit``.  Printed: each render call's wall time
over its limit and the plan it chose.  Kernels come from Dr.Jit's disk cache and
modules from Python's bytecode cache, as for a user (run it twice after a
change: the first run fills both); the process has no earlier render to
learn OIDN's or a pass's cost from.

With ``--cold-cache`` every limit's process gets an empty Dr.Jit kernel
cache (its own ``HOME``) and compiles every kernel it uses: what a first run
on a new machine pays.  The full renders keep the cache, so that the limits
are the same shares of a full render's usual time.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMITS = (0.1, 0.25, 0.5)

#: The child's program: one render, its seconds (and plan) as one JSON line.
CHILD = """
import json, sys, time
import mitsuba_mrt
from mitsuba_mrt import runtime
runtime.configure()
mitsuba_mrt.activate("auto")
res = int(sys.argv[3])
defines = {"res": res, **({"film_res": res + 128} if "crop_rgba" in sys.argv[1] else {})}
scene = mitsuba_mrt.load_scene(sys.argv[1], **defines)  # (crop_rgba's film holds its crop)
if sys.argv[2] == "full":
    print(json.dumps({"seconds": mitsuba_mrt.render_reference(scene)[1], "chose": "full"}))
else:
    begin = time.perf_counter()
    result = mitsuba_mrt.render(scene, time_limit=float(sys.argv[2]))
    print(json.dumps({"seconds": time.perf_counter() - begin, "chose": result.auto.choice.label}))
"""


def _child(path: Path, limit: str, res: int, cold: bool = False) -> dict:
    env = dict(os.environ)
    # as a user's Python: the package's modules compiled once, their bytecode
    # kept (a shell with PYTHONDONTWRITEBYTECODE compiles them in every process)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    with tempfile.TemporaryDirectory() as home:
        if cold:  # (Dr.Jit keeps its kernel cache under HOME)
            env["HOME"] = home
        out = subprocess.run([sys.executable, "-c", CHILD, str(path), limit, str(res)],
                             env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--cold-cache", action="store_true",
                        help="each limit's process with an empty kernel cache")
    args = parser.parse_args()
    for name in args.scenes:
        path = ROOT / "scenes_xml" / "gallery" / f"{name}.xml"
        full = statistics.median(_child(path, "full", args.res)["seconds"] for _ in range(3))
        for share in LIMITS:
            run = _child(path, str(share * full), args.res, args.cold_cache)
            print(f"{name}: full {full:.3f} s; limit {share}: "
                  f"{run['seconds'] / (share * full):.2f}x the limit ({run['chose']})", flush=True)


if __name__ == "__main__":
    main()
