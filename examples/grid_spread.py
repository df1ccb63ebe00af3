"""The MRT's grid spread over more pixels at fewer spp, against the alternative at equal time.

    python examples/grid_spread.py cornell envmap_objects materials --modes refine \
        [--res 256] [--spread 1 2] [--spp 64] [--repeats 3]

Per gallery scene (``paper_fig1`` with ``path`` at 64 spp), warm, in this
process: the full render, the alternative (every pixel at 2-32 spp, box
filter, OIDN ``fast`` and ``high`` with guides of the same samples), and
each ``--modes`` mode with its grid denoised, at ``sample_fraction`` 0.1
times each ``--spread`` and ``--spp`` over it, so that every spread traces
the same samples on its grid.  Methods alternate over ``--repeats`` seeds
(times: medians; errors: means of the report's metric, and of the
noise-free MSE, against the converged renders ``bench rival`` uses, read
from or kept in ``--truths``).  Printed per method: its time over the full
render's, its error, over the full render's, and over the alternative's at
equal time (log-log interpolation on its lower curve), which is what
``auto_plans.SMALL_IMAGE_SPREAD`` was chosen by, and its MSE over the
alternative's.
"""

import argparse
import statistics
from pathlib import Path

import numpy as np

from gallery_scenes import add_truths, with_truths

ROOT = Path(__file__).resolve().parents[1]
LADDER = (2, 4, 8, 16, 32)


def at_equal_time(curve: list[tuple[float, float]], seconds: float) -> float:
    """The error of the lower envelope of ``curve`` (seconds, error) at ``seconds``."""
    envelope = []
    for t, e in sorted(curve):
        if not envelope or e < envelope[-1][1]:
            envelope.append((t, e))
    if seconds <= envelope[0][0]:
        return envelope[0][1]
    for (t0, e0), (t1, e1) in zip(envelope, envelope[1:]):
        if seconds <= t1:
            a = np.log(seconds / t0) / np.log(t1 / t0)
            return float(np.exp(np.log(e0) + a * np.log(e1 / e0)))
    return envelope[-1][1]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--modes", nargs="+", default=["refine", "idpass"])
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--spread", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=3)
    add_truths(parser)
    args = parser.parse_args()

    import time

    from mitsuba_mrt.bench.rival import noise_free_mse
    from mitsuba_mrt.recon.metrics import paper_error
    from mitsuba_mrt.renderer.api import render, render_denoised, render_reference

    for name, scene, truth in with_truths(args.scenes, args.res, args.truths):
        methods = {"full": lambda seed: (render_reference(scene, seed=seed)[0], "film")}
        for quality in ("fast", "high"):
            for spp in LADDER:
                methods[f"alternative {quality} @ {spp}"] = (
                    lambda seed, s=spp, q=quality:
                    (render_denoised(scene, spp=s, quality=q, seed=seed)[0], "box"))
        for mode in args.modes:
            for k in args.spread:
                fraction, spp = 0.1 * k, max(1, args.spp // k)
                methods[f"{mode}+oidn, {fraction:.2g} @ {spp} spp"] = (
                    lambda seed, m=mode, f=fraction, s=spp:
                    (render(scene, mode=m, denoise="oidn", spp=s, sample_fraction=f,
                            seed=seed).image, "film"))
        times = {k: [] for k in methods}
        errors = {k: [] for k in methods}
        squares = {k: [] for k in methods}
        for run in methods.values():  # warm-up: kernels recorded
            run(0)
        for seed in range(args.repeats):
            for k, run in methods.items():
                begin = time.perf_counter()
                image, reference = run(seed)
                times[k].append(time.perf_counter() - begin)
                errors[k].append(paper_error(image, truth[reference]))
                squares[k].append(noise_free_mse(image, truth[reference],
                                                 truth.variances[reference]))
        seconds = {k: statistics.median(v) for k, v in times.items()}
        error = {k: float(np.mean(v)) for k, v in errors.items()}
        mse = {k: float(np.mean(v)) for k, v in squares.items()}
        curve = [(seconds[k], error[k]) for k in methods if k.startswith("alternative")]
        mse_curve = [(seconds[k], mse[k]) for k in methods if k.startswith("alternative")]
        full = seconds["full"]
        print(f"{name} at {args.res} px: full render {full:.3f} s, error {error['full']:.5f}")
        for k in methods:
            if k.startswith("alternative"):
                continue
            print(f"  {k:28s} time {seconds[k] / full:.3f}, error {error[k]:.5f}, "
                  f"{error[k] / error['full']:.2f}x the full render's, "
                  f"{error[k] / at_equal_time(curve, seconds[k]):.3f}x the alternative's; "
                  f"MSE {mse[k] / at_equal_time(mse_curve, seconds[k]):.3f}x", flush=True)


if __name__ == "__main__":
    main()
