"""Rewrite ``bench rival``'s table and plot from its CSV (after a change to the report's layout).

    python tools/rival_report.py docs/bench --command "python -m mitsuba_mrt bench rival -o docs/bench"
"""

import argparse
import csv
import math
from pathlib import Path

from mitsuba_mrt.bench.rival import Row, write_report


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--command", default="")
    args = parser.parse_args()
    with open(args.folder / "rival.csv", newline="") as f:
        rows = [Row(r["scene"], r["method"], int(r["spp"]), float(r["seconds"]),
                    float(r["relative_time"]), float(r["error"]), float(r["rel_mse"]),
                    r["chose"], float(r.get("flip") or math.nan))
                for r in csv.DictReader(f)]
    print(write_report(args.folder, rows, args.command))


if __name__ == "__main__":
    main()
