"""The cheapest run of the MRT and of OIDN per scene, from ``bench denoise``'s CSV.

    python tools/denoise_headline.py docs/bench/denoise.csv

For each scene: the full render's error at the top of its ladder, and the
lowest relative time of any MRT run (every mode, with and without
``denoise``; the rows of a noise-free trace have no time) and of any
``oidn`` / ``oidn-noaux`` run, with the method and spp of each.  Below the
cheaper of the two only that one has a run, which target (a) counts
against the other.
"""

import argparse
import csv
import math


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv")
    args = parser.parse_args()
    with open(args.csv, newline="") as f:
        rows = list(csv.DictReader(f))
    print(f"{'scene':24s} {'full error':>10s}  {'cheapest MRT (time, method, spp, f)':44s} "
          f"cheapest OIDN (time, method, spp)")
    for scene in dict.fromkeys(r["scene"] for r in rows):
        mine = [r for r in rows if r["scene"] == scene
                and math.isfinite(float(r["relative_time"] or "nan"))]
        full = max((r for r in mine if r["method"] == "full"), key=lambda r: int(r["spp"]))

        def cheapest(which):
            runs = [r for r in mine if which(r["method"])]
            best = min(runs, key=lambda r: float(r["relative_time"]))
            fraction = best["setting"].split(",")[0]  # f=0.05, or quality= for OIDN
            return (f"{float(best['relative_time']):.3f} {best['method']} {best['spp']} spp"
                    + (f" {fraction}" if fraction.startswith("f=") else ""))

        print(f"{scene.removesuffix('.xml'):24s} {float(full['error_converged']):10.4f}  "
              f"{cheapest(lambda m: m.startswith('mrt-')):44s} "
              f"{cheapest(lambda m: m.split('+')[0] in ('oidn', 'oidn-noaux'))}")


if __name__ == "__main__":
    main()
