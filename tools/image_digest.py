#!/usr/bin/env python3
"""Print a SHA-256 digest of the MRT image of every bundled scene in every mode.

Run it before and after a change that must not change any image, and diff
the two outputs::

    python tools/image_digest.py > before.txt
    ... change ...
    python tools/image_digest.py > after.txt && diff before.txt after.txt

Every ``scenes_xml/*.xml`` is rendered at ``--res`` with the deterministic
``matte`` integrator in each explicit mode, and ``paper_fig1.xml`` also with
``path`` (jittered, ``--spp``), which exercises the stochastic trace; with
``--gallery`` also the gallery's scenes (textures, mirrors, instances, filters)
at their own integrators and ``--spp``.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MODES = ("paper", "fast", "refine", "idpass", "nearest", "bicubic")


def digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--variant", default="auto")
    parser.add_argument("--gallery", action="store_true", help="add scenes_xml/gallery")
    args = parser.parse_args(argv)
    import mitsuba_mrt
    from mitsuba_mrt.bench.experiments import gallery_defines

    variant = mitsuba_mrt.activate(args.variant)
    print(f"# variant {variant}, res {args.res}")
    jobs = [(path, {"res": args.res}) for path in sorted((ROOT / "scenes_xml").glob("*.xml"))]
    jobs.append((ROOT / "scenes_xml" / "paper_fig1.xml",
                 {"res": args.res, "integrator": "path", "spp": args.spp, "jitter": "true"}))
    if args.gallery:
        jobs += [(path, {**gallery_defines(path.stem, args.res), "spp": args.spp})
                 for path in sorted((ROOT / "scenes_xml" / "gallery").glob("*.xml"))]
    for path, defines in jobs:
        scene = mitsuba_mrt.load_scene(path, **defines)
        for mode in MODES:
            result = mitsuba_mrt.render(scene, mode=mode)
            tag = ",".join(f"{k}={v}" for k, v in defines.items())
            print(f"{path.name} {tag} {mode} {digest(result.image, result.ids, result.traced_mask)}",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
