"""Render an orbit around the Fig. 1 scene as a batch on a local Dask cluster.

    python examples/orbit.py [--out out/orbit] [--res 64] [--step 15] [--workers N]

Calls :func:`mitsuba_mrt.app.batch.run_batch` (what ``python -m mitsuba_mrt
batch`` runs): one task per azimuth of ``scenes_xml/paper_fig1_orbit.xml``
from -60 to 120 degrees, the frames into ``OUT/paper_fig1_orbit_azimuth=<a>/``,
the table into ``OUT/batch.csv`` and the animation into
``OUT/paper_fig1_orbit.gif``.  A rerun skips the frames already there.
Needs the batch extra (``pip install mitsuba-mrt[batch]``).

The ``if __name__ == "__main__"`` guard is needed: the cluster's worker
processes are started by importing this file again.
"""

import argparse
from pathlib import Path

from mitsuba_mrt.app.batch import run_batch

SCENE = Path(__file__).resolve().parent.parent / "scenes_xml" / "paper_fig1_orbit.xml"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/orbit", help="output folder (default %(default)s)")
    parser.add_argument("--res", type=int, default=64, help="image side (default %(default)s)")
    parser.add_argument("--step", type=int, default=15,
                        help="degrees between frames (default %(default)s)")
    parser.add_argument("--workers", type=int, default=None,
                        help="worker processes (default: one per core)")
    args = parser.parse_args()

    result = run_batch([SCENE], args.out,
                       [("res", str(args.res)), ("azimuth", f"-60:121:{args.step}")],
                       workers=args.workers, mode="refine", reference=False)
    print(f"{len(result.rows) - result.failed} of {len(result.rows)} frames; "
          f"the batch table: {result.table}")
    for gif in result.animations:
        print(f"the animation: {gif}")


if __name__ == "__main__":
    main()
