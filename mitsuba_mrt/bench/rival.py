"""``bench rival``: ``auto`` against what a careful user does instead.

The alternative: every pixel at a few spp with a box pixel filter, through
Intel Open Image Denoise with albedo and normal guides from the same
samples, along an spp ladder at OIDN's ``fast`` and ``high`` presets (its
time-error curve: at each time the lower of the two).  Per scene this
experiment measures, warm and alternating in one process, each round of
repeats with its own seed (times: the median; errors: the mean): the full
render at the scene's spp (time 1), the alternative's ladder, the default
``auto`` (planned anew, then taking that plan again), ``auto`` under time limits of
:data:`LIMITS` of the full render (each warmed up once too, once the full
render's median sets it), and each MRT configuration.  Errors are
against converged renders (:data:`CONVERGED_SPP`, kept in the output
folder's :data:`CACHE_DIR` for the next run): the film's own filter for
the full render and the MRT, a box filter for the denoised renders; their
own error, the floor of every error measured against them, is reported
beside.  Then, at ``auto``'s own time, the alternative's error
(interpolated on its curve) and the best configuration's in hindsight.
Beside the report's metric, the field's: relative MSE, NVIDIA's FLIP where
the ``flip-evaluator`` package is installed (``pip install
mitsuba-mrt[bench]``), and the MSE with the converged renders' own noise
removed (:func:`noise_free_mse`).

With ``oidn=False`` (``bench rival --no-oidn``) every method runs as in a
process without OIDN installed (:func:`~mitsuba_mrt.recon.denoise.hidden`):
the alternative is then the full render at the ladder's spp through the
film's own filter (methods ``full@4``), and the MRT's configurations go
undenoised.
"""

from __future__ import annotations

import csv
import math
import statistics
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import MRTError
from ..imageio import OutputSet, atomic_path
from ..recon.metrics import paper_error
from ..recon.sampling import every_pixel
from .experiments import check_repeats

#: spp of the alternative's ladder.
LADDER = (1, 2, 4, 8, 16, 32, 64)
#: OIDN's presets the alternative runs its ladder at, and the prefix of each
#: one's methods (``oidn@4``, ``oidn-high@4``).
ALTERNATIVE = {"fast": "oidn@", "high": "oidn-high@"}
#: The prefix of the alternative's methods without OIDN (``full@4``): the
#: full render at fewer spp, through the film's filter.
PLAIN = "full@"
#: The default ``auto`` with no plan kept from an earlier render of the scene
#: (:mod:`~mitsuba_mrt.renderer.kept_plans`): probes, check and estimates
#: included.  Each round runs it just before ``auto``, which takes its plan.
PLANNED = "auto (planned anew)"
#: ``auto --time-limit`` as shares of the full render's time.
LIMITS = (0.1, 0.25, 0.5)
#: The MRT configurations measured beside ``auto``: (mode, denoise).
CONFIGS = tuple((m, d) for d in ("none", "oidn") for m in ("fast", "refine", "idpass"))
#: ``paper_fig1``'s ``-D`` values in this experiment (``--quick``: ``res`` 64).
FIG1_DEFINES = {"res": 400, "integrator": "path", "spp": 64, "jitter": "true"}
#: Samples per pixel of the converged renders errors are measured against
#: (rendered as several passes of 64 averaged): enough that their own error
#: is well below the denoised images' (at 512 spp it was as large as theirs
#: on ``cornell``, ``envmap_objects`` and ``materials``).
CONVERGED_SPP = 4096
QUICK_CONVERGED_SPP = 256
#: The row of a scene's converged renders: their own error (film filter; box's as its ``chose``).
CONVERGED = "converged"
#: Where ``bench rival`` keeps its converged renders, within its output folder.
CACHE_DIR = "cache"


@dataclass
class Row:
    """One method on one scene."""

    scene: str
    method: str
    spp: int
    seconds: float
    relative_time: float
    error: float
    rel_mse: float
    chose: str = ""
    flip: float = math.nan
    mse: float = math.nan  # (:func:`noise_free_mse`)


def rel_mse(image: np.ndarray, reference: np.ndarray) -> float:
    """The field's relative MSE: ``mean((x - r)^2 / (r^2 + 0.01))`` over pixels and channels.

    Examples
    --------
    >>> rel_mse(np.ones((1, 1, 3)), np.ones((1, 1, 3)))
    0.0
    """
    return float(np.mean((image - reference) ** 2 / (reference ** 2 + 0.01)))


def noise_free_mse(image: np.ndarray, reference: np.ndarray, variance: np.ndarray) -> float:
    """The squared error of the colours a display shows (clipped to [0, 1])
    against the image a converged ``reference`` of per-pixel ``variance``
    converges to: its squared error against the reference less the
    reference's own (where the reference is within (0, 1): clipped beyond).

    Examples
    --------
    >>> ref, var = np.full((1, 1, 3), 0.5), np.full((1, 1, 3), 0.01)
    >>> round(noise_free_mse(np.full((1, 1, 3), 0.7), ref, var), 4)
    0.03
    """
    inside = (reference > 0.0) & (reference < 1.0)
    shown = np.clip(image, 0.0, 1.0) - np.clip(reference, 0.0, 1.0)
    return float(np.mean(shown * shown) - np.mean(np.where(inside, variance, 0.0)))


def flip_error(image: np.ndarray, reference: np.ndarray) -> float:
    """NVIDIA's FLIP (mean over the image) of the linear images as a display
    shows them (clipped to [0, 1]); NaN without the ``flip-evaluator`` package."""
    try:
        import flip_evaluator
    except ImportError:
        return math.nan
    shown = [np.ascontiguousarray(np.clip(x, 0.0, 1.0), dtype=np.float32)
             for x in (reference, image)]
    return float(flip_evaluator.evaluate(*shown, "LDR", inputsRGB=False, applyMagma=False,
                                         computeMeanError=True)[1])


@dataclass(frozen=True)
class Truth:
    """A scene's converged renders, per filter (``"film"``: its film's, the
    full render's and the MRT's; ``"box"``: the denoised renders'): each
    the mean of passes of 64 spp (``truth["box"]``), the variance of that
    mean per pixel and channel (the passes' spread over their number), and
    its own error: the report's metric of the mean against the image it
    converges to, half that between the means of its even and odd passes
    (for noise symmetric about the image)."""

    images: dict
    variances: dict
    own_errors: dict

    def __getitem__(self, kind: str) -> np.ndarray:
        return self.images[kind]


def _converged(tracer, width: int, height: int, spp: int,
               box: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """(the mean of passes of 64 spp over every pixel, box-filtered with
    ``box``; the variance of that mean; its own error): see :class:`Truth`."""
    xy = every_pixel(width, height)
    passes = max(1, spp // 64)
    one = replace(tracer, spp=min(spp, 64))
    total = squares = 0.0
    halves = [0.0, 0.0]
    for k in range(passes):
        x = one(xy, stream=100 + k, aovs=False, replay=True, box=box).radiance.astype(np.float64)
        total, squares = total + x, squares + x * x
        halves[k % 2] = halves[k % 2] + x
    mean = total / passes
    variance = (np.maximum(squares / passes - mean * mean, 0.0) / (passes - 1) if passes > 1
                else np.zeros_like(mean))
    own = (paper_error(halves[0] / (passes // 2), halves[1] / (passes // 2)) / 2
           if passes > 1 and passes % 2 == 0 else math.nan)
    shape = (height, width, 3)
    return mean.reshape(shape), variance.reshape(shape), own


def converged_truth(scene, spp: int = CONVERGED_SPP, cache: Path | None = None) -> Truth:
    """The scene's converged renders errors are measured against, at ``spp``
    (:class:`Truth`), kept in (and read back from) the file ``cache`` where given."""
    from ..renderer.api import GridTracer
    from ..renderer.scene import unwrap

    sensor = scene.sensors()[0]
    width, height = (int(v) for v in sensor.film().crop_size())
    kept = _read_truth(cache, (height, width, 3))
    if kept is not None:
        return kept
    tracer = GridTracer(scene, sensor, unwrap(scene, None).nested,
                        int(sensor.sampler().sample_count()), 0)
    parts = {kind: _converged(tracer, width, height, spp, kind == "box")
             for kind in ("film", "box")}
    truth = Truth(*({kind: part[i] for kind, part in parts.items()} for i in range(3)))
    if cache is not None:
        Path(cache).parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(Path(cache)) as tmp, open(tmp, "wb") as f:
            np.savez(f, **{f"{kind}_{field}": np.asarray(getattr(truth, f"{field}s")[kind])
                           for kind in parts for field in ("image", "variance", "own_error")})
    return truth


def truth_file(folder: Path | None, name: str, scene, spp: int) -> Path | None:
    """The file in ``folder`` (None: none) that keeps scene ``name``'s
    converged renders at ``spp`` at its film's size."""
    if folder is None:
        return None
    width, height = (int(v) for v in scene.sensors()[0].film().crop_size())
    return Path(folder) / f"rival_{name}_{width}x{height}_{spp}.npz"


def kept_truth(scene, name: str, folder: Path | None, spp: int = CONVERGED_SPP) -> Truth:
    """Scene ``name``'s converged renders at ``spp``, read from ``folder``
    where ``bench rival`` kept them (:func:`truth_file`), else made and kept
    there (:func:`converged_truth`)."""
    return converged_truth(scene, spp, truth_file(folder, name, scene, spp))


def _read_truth(cache: Path | None, shape: tuple) -> Truth | None:
    """The :class:`Truth` kept in ``cache`` if it is there, whole and of ``shape``."""
    if cache is None or not Path(cache).is_file():
        return None
    try:
        with np.load(cache) as f:
            data = {key: f[key] for key in f.files}
    except (OSError, ValueError):
        return None
    kinds = ("film", "box")
    if not all(data.get(f"{k}_{x}", np.zeros(0)).shape == shape and np.isfinite(
            data[f"{k}_{x}"]).all() for k in kinds for x in ("image", "variance")):
        return None
    return Truth({k: data[f"{k}_image"] for k in kinds}, {k: data[f"{k}_variance"] for k in kinds},
                 {k: float(data.get(f"{k}_own_error", math.nan)) for k in kinds})


def measure_scene(path: str, name: str, defines: dict, repeats: int, quick: bool,
                  truth_spp: int = CONVERGED_SPP, cache: Path | None = None,
                  oidn: bool = True) -> list[Row]:
    """Every method of the module on one scene, as :class:`Row` s; its
    converged renders at ``truth_spp`` (kept in the folder ``cache``);
    without ``oidn``, as in a process without OIDN (see the module)."""
    from ..recon.denoise import hidden

    with hidden(not oidn):
        return _measure_scene(path, name, defines, repeats, quick, truth_spp, cache, oidn)


def _measure_scene(path: str, name: str, defines: dict, repeats: int, quick: bool,
                   truth_spp: int, cache: Path | None, oidn: bool) -> list[Row]:
    """:func:`measure_scene`'s work."""
    from ..renderer import kept_plans
    from ..renderer.api import render, render_denoised, render_reference
    from ..renderer.scene import load_scene

    scene = load_scene(path, **defines)
    spp = int(scene.sensors()[0].sampler().sample_count())
    truth_spp = QUICK_CONVERGED_SPP if quick else truth_spp
    truth = kept_truth(scene, name, cache, truth_spp)
    ladder = [s for s in LADDER if s <= spp] if not quick else [1, 4]

    def alternative(s, quality):
        return lambda seed: render_denoised(scene, spp=s, quality=quality, seed=seed)

    def plain(s):
        return lambda seed: render_reference(scene, spp=s, seed=seed)

    methods = {"full": plain(spp)}
    if oidn:
        for quality, prefix in ALTERNATIVE.items():
            methods.update({f"{prefix}{s}": alternative(s, quality) for s in ladder})
    else:  # (the full render's spp too: the curve is its rungs)
        methods.update({f"{PLAIN}{s}": plain(s) for s in ladder + [spp] * (spp not in ladder)})

    def planned(seed):  # the plan chosen anew, as in a process's first render of the scene
        kept_plans.clear()
        return render(scene, mode="auto", seed=seed)
    methods[PLANNED] = planned
    methods["auto"] = lambda seed: render(scene, mode="auto", seed=seed)  # (the plan kept)
    for m, d in (CONFIGS if oidn else [(m, d) for m, d in CONFIGS if d == "none"]):
        methods[f"{m}+{d}" if d != "none" else m] = (
            lambda seed, m=m, d=d: render(scene, mode=m, denoise=d, seed=seed))
    times = {k: [] for k in methods}
    scores = {k: [] for k in methods}
    for run in methods.values():  # warm-up: kernels compiled, caches filled
        run(0)
    for seed in range(repeats):  # alternating rounds, each with its own seed
        for k, run in methods.items():
            begin = time.perf_counter()
            out = run(seed)
            times[k].append(time.perf_counter() - begin)
            scores[k].append(_score(k, out, spp, truth))
    full_s = statistics.median(times["full"])
    for share in LIMITS:  # each limit is relative to this process's full render
        key = f"auto --time-limit {share}"
        times[key], scores[key] = [], []
        # warmed up as every method above: the process has rendered it once
        # (traces recorded, OIDN's filters made at the sizes the plan uses)
        render(scene, mode="auto", time_limit=share * full_s, seed=repeats)
        for seed in range(repeats):
            begin = time.perf_counter()
            out = render(scene, mode="auto", time_limit=share * full_s, seed=seed)
            times[key].append(time.perf_counter() - begin)
            scores[key].append(_score(key, out, spp, truth))
    rows = [Row(name, CONVERGED, truth_spp, math.nan, math.nan, truth.own_errors["film"],
                math.nan, f"{truth.own_errors['box']:.5f}")]
    for k, runs in scores.items():
        seconds = statistics.median(times[k])
        chose, spp_used = _most_common([(r.chose, r.spp) for r in runs])
        error, relative, flip, mse = (float(np.mean([getattr(r, m) for r in runs]))
                                      for m in ("error", "rel_mse", "flip", "mse"))
        rows.append(Row(name, k, spp_used, seconds, seconds / full_s, error, relative, chose,
                        flip, mse))
    return rows


class _Score(NamedTuple):
    """One render's errors against the converged render, its plan and spp."""

    error: float
    rel_mse: float
    flip: float
    chose: str
    spp: int
    mse: float


def _score(method: str, out, spp: int, truth: Truth) -> _Score:
    """The :class:`_Score` of one render's ``out`` against ``truth`` (the
    converged renders, film and box filter)."""
    if isinstance(out, tuple):  # render_reference's, render_denoised's
        image, used = out[0], "full+oidn" if _alternative(method) else "full"
    else:
        image, used = out.image, out.mode_used
    kind = "box" if used == "full+oidn" else "film"
    reference = truth[kind]
    chose = ""
    if not isinstance(out, tuple) and out.auto is not None:
        chose = out.auto.choice.label
    spp_used = int(method.split("@")[1]) if _ladder(method) else (
        spp if method == "full" else int(out.spp))
    return _Score(paper_error(image, reference), rel_mse(image, reference),
                  flip_error(image, reference), chose, spp_used,
                  noise_free_mse(image, reference, truth.variances[kind]))


def _most_common(choices: list[tuple[str, int]]) -> tuple[str, int]:
    """The (plan, spp) most of the repeats took, the plan's label saying
    how many took it where they differ (``"... (2 of 3)"``).

    Examples
    --------
    >>> _most_common([("a", 8), ("b", 16), ("a", 8)])
    ('a (2 of 3)', 8)
    """
    best = max(set(choices), key=lambda c: (choices.count(c), -choices.index(c)))
    count = choices.count(best)
    label = best[0] if count == len(choices) or not best[0] else (
        f"{best[0]} ({count} of {len(choices)})")
    return label, best[1]


def at_time(rows: list[Row], prefix: str, seconds: float, metric: str = "error",
            before: float | None = None) -> float:
    """The ``metric`` (a :class:`Row` field) of the methods named ``prefix...``
    at ``seconds``, interpolated on their curve (log time, log metric); their
    extreme beyond its ends, or ``before`` (if given) before its first."""
    curve = sorted((r.relative_time, getattr(r, metric)) for r in rows
                   if r.method.startswith(prefix))
    if before is not None and seconds < curve[0][0]:
        return before
    t = np.log([c[0] for c in curve])
    e = np.log([max(c[1], 1e-12) for c in curve])
    return float(np.exp(np.interp(np.log(seconds), t, e)))


def alternative_at(rows: list[Row], seconds: float, metric: str = "error") -> float:
    """The alternative's ``metric`` at ``seconds``: the lower of its presets'
    curves (:func:`at_time`; the ``fast`` curve's 1-spp end stands for any
    shorter time, the others count only from their first point), or without
    OIDN the full render's curve (:data:`PLAIN`)."""
    prefixes = [p for p in (*ALTERNATIVE.values(), PLAIN)
                if any(r.method.startswith(p) for r in rows)]
    return min(at_time(rows, p, seconds, metric, None if p == prefixes[0] else math.inf)
               for p in prefixes)


def _alternative(method: str) -> bool:
    """Whether ``method`` is a rung of the alternative denoised by OIDN."""
    return method.startswith(tuple(ALTERNATIVE.values()))


def _ladder(method: str) -> bool:
    """Whether ``method`` is a rung of the alternative, with OIDN or without."""
    return method.startswith((*ALTERNATIVE.values(), PLAIN))


def verdicts(rows: list[Row]) -> list[dict]:
    """Per scene: default ``auto``'s error against the alternative's at its time and
    the best configuration's in hindsight, and each time limit's outcome."""
    out = []
    for scene in dict.fromkeys(r.scene for r in rows):
        mine = [r for r in rows if r.scene == scene]
        auto = next(r for r in mine if r.method == "auto")
        alt = alternative_at(mine, auto.relative_time)
        planned = next((r for r in mine if r.method == PLANNED), None)
        planned_ratio = (math.nan if planned is None else
                         planned.error / alternative_at(mine, planned.relative_time))
        field = {m: alternative_at(mine, auto.relative_time, m)
                 for m in ("rel_mse", "flip", "mse")}
        best = min((r.error for r in mine if r.relative_time <= auto.relative_time
                    and not r.method.startswith("auto")), default=float("nan"))
        limits = {}
        for r in mine:
            if r.method.startswith("auto --time-limit"):
                share = float(r.method.rsplit(" ", 1)[1])
                best_in = min((x.error for x in mine if _ladder(x.method)
                               and x.relative_time <= share), default=float("nan"))
                limits[share] = (r.relative_time / share, r.error, best_in)
        out.append(dict(scene=scene, auto=auto, alternative=alt, best=best, limits=limits,
                        planned=planned, planned_ratio=planned_ratio,
                        field_ratios={m: getattr(auto, m) / v if v > 0 else math.nan
                                      for m, v in field.items()}))
    return out


def write_report(out_dir: Path, rows: list[Row], command: str) -> Path:
    """``rival.csv``, ``rival.md`` (the verdict table) and ``rival.png`` into
    ``out_dir``, together or not at all; returns the table's path."""
    with OutputSet(out_dir) as out:  # the three files together or none
        _write_files(out, rows, command)
    return out_dir / "rival.md"


def _write_files(out: OutputSet, rows: list[Row], command: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with open(out.path("rival.csv"), "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["scene", "method", "spp", "seconds", "relative_time", "error",
                         "rel_mse", "flip", "mse", "chose"])
        for r in rows:
            writer.writerow([r.scene, r.method, r.spp, f"{r.seconds:.4f}",
                             f"{r.relative_time:.4f}", f"{r.error:.5f}", f"{r.rel_mse:.5f}",
                             f"{r.flip:.5f}", f"{r.mse:.4g}", r.chose])
    lines = [f"Command: `{command}`", "",
             "| scene | auto chose | auto time | auto error | alternative at that time | "
             "ratio | relMSE ratio | FLIP ratio | MSE ratio, noise removed | best in hindsight | "
             "planned anew: time, ratio | "
             "limits 0.1 / 0.25 / 0.5: time / limit, error / alternative's best within | "
             "converged renders' own error, film / box |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|"]
    floors = {r.scene: f"{r.error:.4f} / {float(r.chose):.4f} ({r.spp} spp)"
              for r in rows if r.method == CONVERGED}
    for v in verdicts(rows):
        a = v["auto"]
        limits = "; ".join(f"{t:.2f}, {e / b:.2f}" if b == b else f"{t:.2f}, -"
                           for t, e, b in v["limits"].values())
        lines.append(f"| {v['scene']} | {a.chose} | {a.relative_time:.2f} | {a.error:.4f} | "
                     f"{v['alternative']:.4f} | {a.error / v['alternative']:.2f} | "
                     f"{v['field_ratios']['rel_mse']:.2f} | {v['field_ratios']['flip']:.2f} | "
                     f"{v['field_ratios']['mse']:.2f} | "
                     f"{v['best']:.4f} | {_planned(v)} | {limits} | "
                     f"{floors.get(v['scene'], '-')} |")
    Path(out.path("rival.md")).write_text("\n".join(lines) + "\n")
    scenes = list(dict.fromkeys(r.scene for r in rows))
    fig, axes = plt.subplots(1, len(scenes), figsize=(3.2 * len(scenes), 3.0), squeeze=False)
    for ax, scene in zip(axes[0], scenes):
        mine = [r for r in rows if r.scene == scene]
        curves = [(prefix, f"full + OIDN {quality} (box)")
                  for quality, prefix in ALTERNATIVE.items()] + [(PLAIN, "full render")]
        for (prefix, label), shade in zip(curves, ("0.5", "0.75", "0.5")):
            alt = sorted((r.relative_time, r.error) for r in mine if r.method.startswith(prefix))
            if alt:
                ax.plot(*zip(*alt), "o-", color=shade, label=label)
        for r in mine:
            if r.method.startswith("auto"):
                marker = {"auto": "r*", PLANNED: "r+"}.get(r.method, "rx")
                ax.plot(r.relative_time, r.error, marker)
            elif r.method == CONVERGED:  # the errors' floor: the converged renders' own
                for floor in (r.error, float(r.chose)):
                    ax.axhline(floor, ls=":", lw=0.8, color="0.6")
            elif not _ladder(r.method):
                ax.plot(r.relative_time, r.error, "b." if r.method != "full" else "ks")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(scene, fontsize=9)
        ax.set_xlabel("time / full render")
    axes[0][0].set_ylabel("error (report's metric)")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out.path("rival.png"), dpi=90, format="png")
    plt.close(fig)


def _planned(verdict: dict) -> str:
    """The table's cell of ``auto`` planned anew: its time, its error's ratio."""
    row = verdict["planned"]
    return "-" if row is None else f"{row.relative_time:.2f}, {verdict['planned_ratio']:.2f}"


def check_truth_spp(spp) -> int:
    """``spp`` (the converged renders' samples per pixel), refused where it is
    not a multiple of 128 (an even number of passes of 64: their halves
    tell the renders' own error).

    Examples
    --------
    >>> check_truth_spp(1024)
    1024
    """
    if int(spp) != spp or spp < 128 or spp % 128:
        raise MRTError(f"--truth-spp must be a multiple of 128, got {spp}")
    return int(spp)


def run_rival(out_dir, scenes: list[tuple[str, str, dict]], repeats: int = 2,
              quick: bool = False, command: str = "", echo=print,
              truth_spp: int = CONVERGED_SPP, oidn: bool = True) -> Path:
    """Measure every (path, name, defines) of ``scenes``; write the report.
    The converged renders (``truth_spp``) are kept in ``out_dir``'s
    :data:`CACHE_DIR` and read back by the next run.  Without ``oidn``, as
    in a process without OIDN (see the module)."""
    repeats = check_repeats(repeats)
    rows = []
    for path, name, defines in scenes:
        begin = time.perf_counter()
        rows += measure_scene(path, name, defines, repeats, quick, truth_spp,
                              Path(out_dir) / CACHE_DIR, oidn)
        echo(f"rival: {name} in {time.perf_counter() - begin:.0f} s")
    return write_report(Path(out_dir), rows, command)
