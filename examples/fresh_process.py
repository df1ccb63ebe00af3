"""Each mode's first render in a fresh process, against ``mi.render``'s in its own.

    python examples/fresh_process.py scenes_xml/paper_fig1.xml --modes fast refine idpass \\
        -D res=1000 -D integrator=path -D spp=64 -D jitter=true --rounds 3
    python examples/fresh_process.py scenes_xml/gallery/cornell.xml ... -D res=256 -D spp=64 \\
        --out docs/bench --name fresh_gallery

A user runs one ``render`` per process: its kernels come from Dr.Jit's
on-disk cache or are compiled, its imports and first allocations are part of
the render.  Each process is set up as the command line sets up its own
(:func:`mitsuba_mrt.runtime.configure`: malloc keeps freed memory for reuse).
Every round starts one process for the full render
(``render_reference``) and one per mode (``render(mode=...)``), in turn; each
reports its render call's seconds (scene loading and imports left out: both
pay them alike), and the mode's split into trace and the rest.  Printed per
mode: the medians, the ratio to the full render's median, the non-trace part's
throughput (pixels over the seconds that are neither the grid's trace nor
``trace_more``), and the kernels compiled and loaded from disk.

With ``--cold-cache`` every process gets an empty Dr.Jit kernel cache (its own
``HOME``): what a first run on a new machine pays.
"""

import argparse
import csv
import json
import statistics
from pathlib import Path

from mitsuba_mrt.renderer.variants import VARIANT_CHOICES

from fresh_child import fresh_child

#: The child's program: one render, its figures as one JSON line.
CHILD = """
import json, sys, time
import mitsuba_mrt
from mitsuba_mrt import runtime
runtime.configure()  # (as the command line sets up its process)
path, mode, defines = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
mitsuba_mrt.activate(sys.argv[4])
scene = mitsuba_mrt.load_scene(path, **defines)
if mode == "full":
    image, seconds = mitsuba_mrt.render_reference(scene)
    print(json.dumps({"total": seconds, "trace": seconds, "trace_more": 0.0}))
else:
    result = mitsuba_mrt.render(scene, mode=mode)
    t = result.timings
    print(json.dumps({"total": t.total, "trace": t.trace, "trace_more": t.trace_more,
                      "compiled": t.compile.compiled, "from_disk": t.compile.from_disk,
                      "pixels": int(result.ids.size), "used": result.mode_used}))
"""


def _child(scene: str, mode: str, defines: dict, cold: bool, variant: str) -> dict:
    return fresh_child(CHILD, scene, mode, json.dumps(defines), variant,
                       what=f"{mode} render of {scene}", memory=None, cold=cold)


def measure(scene: str, modes: list, defines: dict, rounds: int, cold: bool,
            variant: str = "auto") -> list[dict]:
    """One row per method (``full`` first): medians over ``rounds`` fresh processes."""
    runs = {mode: [] for mode in ["full", *modes]}
    for _ in range(rounds):
        for mode in runs:
            runs[mode].append(_child(scene, mode, defines, cold, variant))
    full = statistics.median(r["total"] for r in runs["full"])
    rows = []
    for mode, rs in runs.items():
        total = statistics.median(r["total"] for r in rs)
        rest = statistics.median(r["total"] - r["trace"] - r["trace_more"] for r in rs)
        row = {"scene": Path(scene).stem, "mode": mode, "render_s": total,
               "x_full": total / full,
               "trace_s": statistics.median(r["trace"] + r["trace_more"] for r in rs)}
        if mode != "full":
            row.update(rest_s=rest, rest_mpx_s=rs[0]["pixels"] / rest / 1e6 if rest else None,
                       compiled=statistics.median(r["compiled"] for r in rs),
                       from_disk=statistics.median(r["from_disk"] for r in rs))
        rows.append(row)
    return rows


def _plot(rows: list, path: Path, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    modes = [m for m in dict.fromkeys(r["mode"] for r in rows) if m != "full"]
    fig, ax = plt.subplots(figsize=(max(6, 1.2 * len(scenes) + 2), 3.6))
    width = 0.8 / len(modes)
    for k, mode in enumerate(modes):
        values = [next(r["x_full"] for r in rows if r["scene"] == s and r["mode"] == mode)
                  for s in scenes]
        ax.bar([i + (k - (len(modes) - 1) / 2) * width for i in range(len(scenes))], values,
               width, label=mode)
    ax.axhline(1.0, color="black", lw=0.8)
    ax.set_xticks(range(len(scenes)), scenes, rotation=20, ha="right")
    ax.set_ylabel("render time / full render")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--modes", nargs="+", default=["fast", "refine", "idpass"])
    parser.add_argument("-D", dest="defines", action="append", default=[],
                        metavar="NAME=VALUE")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--cold-cache", action="store_true")
    parser.add_argument("--variant", default="auto", choices=VARIANT_CHOICES,
                        help="Mitsuba variant (default auto)")
    parser.add_argument("--out", help="also write NAME.csv and NAME.png here (--name)")
    parser.add_argument("--name", default="fresh_process")
    args = parser.parse_args()
    defines = dict(d.split("=", 1) for d in args.defines)

    title = (f"{' '.join(args.defines)}, median of {args.rounds} fresh processes"
             f"{', cold kernel cache' if args.cold_cache else ''}")
    print(title)
    print(f"{'scene':16s} {'mode':8s} {'render s':>9s} {'x full':>7s} {'trace s':>8s} "
          f"{'rest s':>7s} {'rest Mpx/s':>10s} {'compiled':>8s} {'from disk':>9s}")
    rows = []
    for scene in args.scenes:
        for r in measure(scene, args.modes, defines, args.rounds, args.cold_cache,
                         args.variant):
            rows.append(r)
            line = (f"{r['scene'][:16]:16s} {r['mode']:8s} {r['render_s']:9.3f} "
                    f"{r['x_full']:7.3f} {r['trace_s']:8.3f}")
            if r["mode"] != "full":
                line += (f" {r['rest_s']:7.3f} {r['rest_mpx_s'] or float('inf'):10.1f}"
                         f" {r['compiled']:8.0f} {r['from_disk']:9.0f}")
            print(line, flush=True)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        columns = ["scene", "mode", "render_s", "x_full", "trace_s", "rest_s", "rest_mpx_s",
                   "compiled", "from_disk"]
        with open(out / f"{args.name}.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, columns)
            writer.writeheader()
            writer.writerows(rows)
        _plot(rows, out / f"{args.name}.png", title)


if __name__ == "__main__":
    main()
