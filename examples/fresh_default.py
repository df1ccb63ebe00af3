"""The default ``auto`` as a user's first render: each render in a fresh process.

    python examples/fresh_default.py [--rounds 3] [--res 256] [--scenes NAME ...] \
        [--out docs/bench --name fresh_default]

``bench rival`` measures warm, in one process, where ``auto`` may take the
plan an earlier render of the scene kept.  A user who runs the CLI renders
once per process: the plan is made anew, and the kernels come from Dr.Jit's
disk cache.  Per scene (the gallery at ``--res`` a side and ``paper_fig1``
with ``path`` at 400 px, as ``bench rival`` renders them), every round
starts, in turn, one fresh process for the full render, one for the default
``auto`` and one per rung of the alternative's ladder (every pixel with a
box filter through OIDN, at its ``fast`` and ``high`` presets: what
``bench rival`` calls the alternative done right).  Each child reports its
render call's seconds (imports and scene loading left out: every method pays
them alike) and saves its image; errors are the report's metric (and the
noise-free MSE) against the converged renders ``bench rival`` uses (read
from, or kept in, ``--truths``).  Printed per scene: ``auto``'s time over
the full render's (medians), its plan, and its error over the
alternative's at that time (interpolated on the alternative's curve, as
``bench rival`` does).  Modules' bytecode is kept as for a user's Python.

``auto`` renders twice per round, each in a fresh process, with a memory
of earlier processes (:mod:`mitsuba_mrt.runtime.memory`) that starts empty
every round: ``auto``, a scene's first render, chooses its plan and
remembers it; ``auto-again``, the user's next render of the scene, takes
it.  Every other child runs with the memory off.

With ``--no-oidn`` ``auto`` renders as in a process without OIDN installed
(:func:`mitsuba_mrt.recon.denoise.hidden`), and the alternative's ladder is
the full render at 1-32 spp through the film's filter (``full@N``).
"""

import argparse
import csv
import json
import os
import statistics
import tempfile
from pathlib import Path

import numpy as np

from fresh_child import fresh_child
from gallery_scenes import add_truths

ROOT = Path(__file__).resolve().parents[1]
#: The alternative's ladder here: ``bench rival``'s up to 32 spp (``auto``
#: takes less than half a full render on every scene).
LADDER = (1, 2, 4, 8, 16, 32)

#: The child's program: one render; its seconds and plan as one JSON line, its image saved.
CHILD = """
import json, sys, time
import numpy as np
import mitsuba_mrt
from mitsuba_mrt import runtime
runtime.configure()
mitsuba_mrt.activate("auto")
path, method, defines, image_path = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), sys.argv[4]
scene = mitsuba_mrt.load_scene(path, **defines)
begin = time.perf_counter()
if method == "full":
    image = mitsuba_mrt.render_reference(scene)[0]
    used, chose = "full", "full"
elif method == "auto":
    from mitsuba_mrt.recon.denoise import hidden
    with hidden(sys.argv[5] == "no-oidn"):
        result = mitsuba_mrt.render(scene)
    image, used, chose = result.image, result.mode_used, result.auto.choice.label
elif method.startswith("plain@"):  # (the full render at fewer spp: no OIDN)
    image = mitsuba_mrt.render_reference(scene, spp=int(method.split("@")[1]))[0]
    used, chose = "full", method
else:
    quality, spp = method.split("@")
    image = mitsuba_mrt.render_denoised(scene, spp=int(spp), quality=quality)[0]
    used, chose = "full+oidn", method
seconds = time.perf_counter() - begin
np.save(image_path, np.asarray(image, dtype=np.float32)[..., :3])
print(json.dumps({"seconds": seconds, "used": used, "chose": chose}))
"""


def _child(path: Path, method: str, defines: dict, folder: str,
           memory: str = "off", oidn: bool = True) -> tuple[dict, np.ndarray]:
    """One render in a fresh process (``memory``: its ``MITSUBA_MRT_MEMORY``;
    without ``oidn``, ``auto`` as without OIDN installed)."""
    image_path = os.path.join(folder, "image.npy")
    report = fresh_child(CHILD, str(path), method, json.dumps(defines), image_path,
                         "oidn" if oidn else "no-oidn",
                         what=f"{method} render of {path.name}", memory=memory)
    return report, np.load(image_path)


def measure(path: Path, name: str, defines: dict, rounds: int, truths: Path,
            oidn: bool = True) -> list:
    """``bench rival``'s rows of the full render, the default ``auto`` and
    the alternative's ladder (without ``oidn``, ``bench rival --no-oidn``'s),
    each render in a fresh process; the converged renders kept in ``truths``
    (made and kept there if missing)."""
    from mitsuba_mrt.bench.rival import ALTERNATIVE, PLAIN, Row, kept_truth, noise_free_mse
    from mitsuba_mrt.recon.metrics import paper_error
    from mitsuba_mrt.renderer.scene import load_scene

    scene = load_scene(str(path), **defines)
    truth = kept_truth(scene, name, truths)
    qualities = ALTERNATIVE if oidn else ("plain",)
    methods = ["full", "auto", "auto-again"] + [f"{q}@{s}" for q in qualities for s in LADDER]
    runs = {m: [] for m in methods}
    with tempfile.TemporaryDirectory() as folder:
        remembered = os.path.join(folder, "memory.json")
        for _ in range(rounds):
            if os.path.exists(remembered):  # (each round's first render remembers nothing)
                os.remove(remembered)
            for method in methods:
                auto = method.startswith("auto")
                report, image = _child(path, "auto" if auto else method, defines, folder,
                                       remembered if auto else "off", oidn)
                kind = "box" if report["used"] == "full+oidn" else "film"
                runs[method].append((report["seconds"], paper_error(image, truth[kind]),
                                     report["chose"],
                                     noise_free_mse(image, truth[kind], truth.variances[kind])))
    full = statistics.median(r[0] for r in runs["full"])
    rows = []
    for method, rs in runs.items():
        seconds = statistics.median(r[0] for r in rs)
        chose = max(set(r[2] for r in rs), key=[r[2] for r in rs].count)
        label = method
        if "@" in method:  # (bench rival's names of the alternative's rungs)
            quality, spp = method.split("@")
            label = f"{ALTERNATIVE.get(quality, PLAIN)}{spp}"
        rows.append(Row(name, label, 0, seconds, seconds / full,
                        float(np.mean([r[1] for r in rs])), float("nan"), chose,
                        mse=float(np.mean([r[3] for r in rs]))))
    return rows


def main():
    from mitsuba_mrt.bench.experiments import GALLERY_SCENES, gallery_defines
    from mitsuba_mrt.bench.rival import FIG1_DEFINES, alternative_at

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--scenes", nargs="+", default=[*GALLERY_SCENES, "paper_fig1"])
    parser.add_argument("--out", help="also write NAME.csv here (--name)")
    parser.add_argument("--name", default="fresh_default")
    parser.add_argument("--no-oidn", action="store_true",
                        help="auto as without OIDN installed, against the full render at "
                             "fewer spp")
    add_truths(parser)
    args = parser.parse_args()
    if args.out:  # (made now: not a lost run at the end)
        Path(args.out).mkdir(parents=True, exist_ok=True)
    import mitsuba_mrt
    mitsuba_mrt.activate("auto")
    rows = []
    for name in args.scenes:
        if name == "paper_fig1":
            path = ROOT / "scenes_xml" / "paper_fig1.xml"
            defines = FIG1_DEFINES
        else:
            path = ROOT / "scenes_xml" / "gallery" / f"{name}.xml"
            defines = gallery_defines(name, args.res)
        mine = measure(path, name, defines, args.rounds, Path(args.truths), not args.no_oidn)
        rows += mine
        full = next(r for r in mine if r.method == "full")
        for auto in (r for r in mine if r.method.startswith("auto")):
            ratio = auto.error / alternative_at(mine, auto.relative_time)
            mse = auto.mse / alternative_at(mine, auto.relative_time, "mse")
            print(f"{name}: full {full.seconds:.3f} s; {auto.method} {auto.relative_time:.2f} "
                  f"of it, error {ratio:.2f}x (noise-free MSE {mse:.2f}x) the alternative's at "
                  f"that time ({auto.chose})", flush=True)
    if args.out:
        with open(Path(args.out) / f"{args.name}.csv", "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["scene", "method", "seconds", "relative_time", "error", "mse",
                             "chose"])
            writer.writerows([r.scene, r.method, f"{r.seconds:.4f}", f"{r.relative_time:.4f}",
                              f"{r.error:.5f}", f"{r.mse:.4g}", r.chose] for r in rows)


if __name__ == "__main__":
    main()
