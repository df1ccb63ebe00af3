"""``auto --time-limit`` as a user's first render: each render in a fresh process.

    python examples/fresh_time_limit.py [SCENE ...] [--res 512] [--cold-cache] [--errors]
    python examples/fresh_time_limit.py --res 512 --errors \
        --truths docs/bench/rival512/cache --truth-spp 1024
    python examples/fresh_time_limit.py --errors --no-oidn

Per gallery scene (all nine by default) at ``--res`` a side (256 by default): the full render in three fresh processes
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

Each limit renders twice, each in a fresh process, with a memory of
earlier processes (:mod:`mitsuba_mrt.runtime.memory`) that starts empty
for every limit: ``first``, a scene's first render, measures what it
needs and remembers its launches; ``again``, the user's next render of the
scene at that limit, plans from them.

With ``--errors`` each limit's image is kept, and the alternative's ladder
(every pixel at 1-32 spp, box filter, OIDN ``fast`` and ``high``: what
``bench rival`` calls the alternative done right) is rendered once per
scene, each rung in a fresh process too: printed besides, the image's error
(the report's metric, against the converged renders ``bench rival`` keeps in
``--truths`` at ``--truth-spp``) over the lowest of the rungs that ended
within the limit.

With ``--no-oidn`` every child renders as a process without OIDN installed
does (:func:`mitsuba_mrt.recon.denoise.hidden`), and the alternative's
ladder is the full render at 1-32 spp through the film's filter.
"""

import argparse
import os
import statistics
import tempfile
from pathlib import Path

import numpy as np

from fresh_child import fresh_child
from gallery_scenes import add_truth_spp, add_truths

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
    from mitsuba_mrt.recon.denoise import hidden
    with hidden(sys.argv[5] == "no-oidn"):
        begin = time.perf_counter()
        result = mitsuba_mrt.render(scene, time_limit=float(sys.argv[2]))
        seconds = time.perf_counter() - begin
    if sys.argv[4] != "-":
        import numpy as np
        np.save(sys.argv[4], np.asarray(result.image, dtype=np.float32)[..., :3])
    print(json.dumps({"seconds": seconds, "chose": result.auto.choice.label,
                      "denoised": result.mode_used == "full+oidn"}))
"""


def _child(path: Path, limit: str, res: int, cold: bool = False, image: str = "-",
           memory: str = "off", oidn: bool = True) -> dict:
    """One render in a fresh process (``memory``: its ``MITSUBA_MRT_MEMORY``;
    without ``oidn``, as without OIDN installed)."""
    return fresh_child(CHILD, str(path), limit, str(res), image,
                       "oidn" if oidn else "no-oidn",
                       what=f"{path.name} under limit {limit}", memory=memory, cold=cold)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", help="gallery scenes (default: all nine)")
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--cold-cache", action="store_true",
                        help="each limit's process with an empty kernel cache")
    parser.add_argument("--errors", action="store_true",
                        help="also each image's error over the alternative's best within the limit")
    parser.add_argument("--no-oidn", action="store_true",
                        help="render as without OIDN installed (the alternative: the full render "
                             "at fewer spp)")
    add_truth_spp(parser)
    add_truths(parser)
    args = parser.parse_args()
    from mitsuba_mrt.bench.experiments import GALLERY_SCENES

    for name in args.scenes or GALLERY_SCENES:
        path = ROOT / "scenes_xml" / "gallery" / f"{name}.xml"
        full = statistics.median(_child(path, "full", args.res)["seconds"] for _ in range(3))
        errors = (_Errors(path, name, args.res, Path(args.truths), args.truth_spp,
                          not args.no_oidn) if args.errors else None)
        for share in LIMITS:
            with tempfile.TemporaryDirectory() as folder:
                image = os.path.join(folder, "image.npy") if errors else "-"
                remembered = os.path.join(folder, "memory.json")
                for render in ("first", "again"):
                    run = _child(path, str(share * full), args.res, args.cold_cache, image,
                                 remembered, not args.no_oidn)
                    error = "" if errors is None else errors.line(run, image, share * full)
                    print(f"{name}: full {full:.3f} s; limit {share}, {render}: "
                          f"{run['seconds'] / (share * full):.2f}x the limit{error} "
                          f"({run['chose']})", flush=True)


class _Errors:
    """``--errors``: a scene's converged renders and the alternative's ladder,
    each rung rendered once in a fresh process (:mod:`fresh_default`'s child);
    without ``oidn``, the full render's ladder."""

    def __init__(self, path: Path, name: str, res: int, truths: Path, truth_spp: int,
                 oidn: bool = True):
        import mitsuba_mrt
        from fresh_default import LADDER, _child as ladder_child
        from mitsuba_mrt.bench.experiments import gallery_defines
        from mitsuba_mrt.bench.rival import kept_truth
        from mitsuba_mrt.recon.metrics import paper_error

        mitsuba_mrt.activate("auto")
        defines = gallery_defines(name, res)
        scene = mitsuba_mrt.load_scene(str(path), **defines)
        self.truth = kept_truth(scene, name, truths, truth_spp)
        self.rungs = []  # (seconds, error)
        with tempfile.TemporaryDirectory() as folder:
            for quality in (("fast", "high") if oidn else ("plain",)):
                for spp in LADDER:
                    report, image = ladder_child(path, f"{quality}@{spp}", defines, folder)
                    kind = "box" if report["used"] == "full+oidn" else "film"
                    self.rungs.append((report["seconds"], paper_error(image, self.truth[kind])))

    def line(self, run: dict, image: str, limit: float) -> str:
        """`, error E x the alternative's best within the limit`."""
        from mitsuba_mrt.recon.metrics import paper_error

        mine = paper_error(np.load(image), self.truth["box" if run["denoised"] else "film"])
        within = [error for seconds, error in self.rungs if seconds <= limit]
        if not within:
            return f", error {mine:.5f} (no rung of the alternative within it)"
        return f", error {mine:.5f}, {mine / min(within):.2f}x the alternative's best within it"


if __name__ == "__main__":
    main()
