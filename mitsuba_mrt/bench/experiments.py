"""The ``bench`` command: the report's experiments on Mitsuba, MRT against the alternatives.

Every experiment sweeps one parameter of the report (its Figs. 6-10) or, for
``tradeoff``, every method and setting as a (time, error) point. For each
*point* (a scene file with its ``<default>`` values and spp) the scene is
loaded once; every method is called once to warm up (Dr.Jit compiles its
kernels then; that first-call time is the ``warmup_s`` column), and then,
``repeats`` times, the full render and every method in turn, alternating, in
this process; a point whose full render is fast gets more rounds, until the
full render's timed runs add up to ``MIN_TIMED_SECONDS`` (a median of three
millisecond runs on a busy machine is noise), at most ``MAX_REPEATS`` rounds
and ``EXTRA_ROUNDS_SECONDS`` of extra wall time (none with ``quick``; the
``repeats`` column holds the rounds run). The row of a method holds the lower
median of its totals (and the stage times of that same run).

Methods, by name: ``full`` (the plain Mitsuba render with the same
integrator and spp, the reference: relative time 1), ``mrt-<mode>`` for each
reconstruction mode of :data:`mitsuba_mrt.modes.MODES` at run time, except
the scene-agnostic baselines, which keep their names (``nearest``,
``bicubic``). All of them trace the same grid with the same seed.

For a stochastic integrator (found by rendering with a second seed) every
row's ``error_converged`` is measured against a converged reference (the
mean of ``CONVERGED_FACTOR`` full renders with other seeds), and for every
method a ``full-equal-time`` row gives the full render at the spp whose
median time is closest to that method's.

Outputs in the output folder, each written atomically: ``<experiment>.csv``
(one row per method and setting, :data:`CSV_COLUMNS`), ``<experiment>.png``
(error and relative time against the swept parameter; for ``tradeoff`` time
against error), ``<experiment>_triptych.png`` (reference | MRT | error of one
setting, with the MRT mode of lowest error) and ``<experiment>.md`` (the
tables, headed by the command and the environment).
"""

from __future__ import annotations

import csv
import math
import os
import platform
import shlex
import sys
import time
import tracemalloc
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..app.imageio import atomic_path, srgb_encode
from ..errors import MRTError

#: The experiments, in the order ``all`` runs them.
EXPERIMENTS = ("fraction", "filter", "pixels", "objects", "lights", "tradeoff")

#: Modes that are scene-agnostic upsampling of the grid keep their own names.
BASELINES = ("nearest", "bicubic")

FULL = "full"
EQUAL_TIME = "full-equal-time"

#: Converged reference of a stochastic point: the mean of this many full
#: renders (other seeds), so it has this factor times the point's spp.
#: Timed seconds of the full render below which a point gets more rounds.
MIN_TIMED_SECONDS = 1.0
#: Most timed rounds of one point.
MAX_REPEATS = 25
#: Wall seconds after which a point gets no more extra rounds.
EXTRA_ROUNDS_SECONDS = 10.0

CONVERGED_FACTOR = 16

#: Columns of every CSV, in order.
CSV_COLUMNS = (
    "experiment", "scene", "group", "method", "mode", "setting", "x_name", "x",
    "sample_fraction", "filter_sigma", "filter_cutoff", "integrator", "spp", "defines",
    "width", "height", "traced_pixels", "repeats",
    "trace_s", "edges_s", "interpolate_s", "total_s", "total_min_s", "total_max_s",
    "warmup_s", "reference_s", "relative_time", "error", "psnr_db",
    "stochastic", "converged_spp", "error_converged", "psnr_converged_db", "matched_method",
    "peak_memory_mb", "memory_delta_mb", "peak_memory_source", "status",
    "variant", "mitsuba", "drjit", "cpu_count", "cpu_model", "machine", "platform", "python",
)

#: Columns that hold a finite number in every row whose status is ``ok``.
FINITE_COLUMNS = ("width", "height", "traced_pixels", "trace_s", "edges_s", "interpolate_s",
                  "total_s", "warmup_s", "reference_s", "relative_time", "error",
                  "peak_memory_mb")

_FIGURES = {"fraction": "Fig. 6", "filter": "Fig. 7", "pixels": "Fig. 8", "objects": "Fig. 9",
            "lights": "Fig. 10", "tradeoff": "none (a user's choice of setting)"}


# --------------------------------------------------------------------------- methods

def method_name(mode: str) -> str:
    """CSV name of a reconstruction mode: baselines keep theirs, others get ``mrt-``."""
    return mode if mode in BASELINES else f"mrt-{mode}"


#: ``auto`` runs a pilot and may render in full, so it is compared on request
#: (``--methods auto``) rather than by default.
AUTO = "mrt-auto"


def available_methods() -> dict[str, str | None]:
    """Every method name now available -> its mode (``None`` for ``full``)."""
    from ..modes import MODES

    return {FULL: None, **{method_name(m): m for m in MODES}, AUTO: "auto"}


def resolve_methods(names=None) -> list[str]:
    """The methods to run, ``full`` first; ``names`` is a list or a comma list.

    A mode's bare name (``paper``) is accepted for its method (``mrt-paper``).
    ``full`` always runs: it is the reference.
    """
    methods = available_methods()
    if names is None:
        return [name for name in methods if name != AUTO]
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    if not names:
        raise MRTError("--methods is empty")
    by_mode = {mode: name for name, mode in methods.items() if mode is not None}
    chosen = [FULL]
    for name in names:
        name = name if name in methods else by_mode.get(name, name)
        if name not in methods:
            raise MRTError(f"unknown method {name!r}; choose from {', '.join(methods)}")
        if name not in chosen:
            chosen.append(name)
    return chosen


# --------------------------------------------------------------------------- experiments

@dataclass
class Setting:
    """One set of MRT parameters at a point: ``x`` is its swept value."""

    params: dict
    x: float = math.nan
    label: str = ""
    group: str = ""


@dataclass
class Point:
    """One scene file with its defines and spp; the full render is shared by its settings."""

    scene: str
    defines: dict
    spp: int
    settings: list
    x: float = math.nan
    group: str = ""

    @property
    def integrator(self) -> str:
        return str(self.defines.get("integrator", "matte"))


@dataclass
class Experiment:
    """A sweep: its points, the name of the swept value and the setting drawn in the triptych."""

    name: str
    title: str
    x_name: str
    x_label: str
    points: list
    representative: tuple = (0, 0)
    log_x: bool = False
    full_spp_sweep: bool = False


def _fraction_settings(fractions, sigma=1.0, cutoff=0.05, group=""):
    return [Setting({"sample_fraction": f, "filter_sigma": sigma, "filter_cutoff": cutoff},
                    x=f, label=f"f={f:g}", group=group) for f in fractions]


def _closest(values, target) -> int:
    return int(np.argmin([abs(v - target) for v in values]))


def build_experiment(name: str, quick: bool = False, res: int | None = None) -> Experiment:
    """The points of experiment ``name``; ``quick``: a reduced sweep at low resolution.

    ``res`` overrides the image side of every experiment but ``pixels``.
    """
    if name not in EXPERIMENTS:
        raise MRTError(f"unknown experiment {name!r}; choose one of {', '.join(EXPERIMENTS)}, all")
    if res is not None and name == "pixels":
        raise MRTError("--res does not apply to the pixels experiment (it sweeps the resolution)")
    if res is not None and res < 8:
        raise MRTError(f"--res must be >= 8, got {res}")
    side = res or (64 if quick else 200)
    matte = {"integrator": "matte", "spp": 1}

    if name == "fraction":
        fractions = (0.05, 0.1, 0.2) if quick else tuple(round(0.025 * k, 3) for k in range(1, 11))
        settings = _fraction_settings(fractions)
        point = Point("paper_fraction.xml", {"res": side, **matte}, 1, settings)
        return Experiment(name, "MRT against the sample fraction", "sample_fraction",
                          "sample fraction f", [point], (0, _closest(fractions, 0.1)))
    if name == "filter":
        sigmas = (1.0, 4.0) if quick else (1.0, 2.0, 4.0, 8.0)
        cutoffs = (0.05, 0.25) if quick else (0.05, 0.10, 0.15, 0.20, 0.25)
        settings = [Setting({"sample_fraction": 0.1, "filter_sigma": s, "filter_cutoff": c},
                            x=c, label=f"sigma={s:g} cutoff={c:g}", group=f"sigma={s:g}")
                    for s in sigmas for c in cutoffs]
        point = Point("paper_fraction.xml", {"res": side, **matte}, 1, settings)
        return Experiment(name, "MRT against the Gaussian filter's sigma and cutoff (f = 0.1)",
                          "filter_cutoff", "normalised cutoff", [point], (0, 0))
    if name == "pixels":
        scales = (0.1, 0.15, 0.2) if quick else tuple(0.5 + 0.25 * k for k in range(11))
        points = []
        for a in scales:
            side_a = int(400 * a)
            points.append(Point("paper_fig1.xml", {"res": side_a, **matte}, 1,
                                _fraction_settings((0.1,)), x=side_a))
            points[-1].settings[0].x = side_a
            points[-1].settings[0].label = f"{side_a}x{side_a}"
        return Experiment(name, "MRT against the number of pixels (f = 0.1)", "pixels",
                          "pixels a side", points,
                          (_closest([p.x for p in points], 400), 0))
    if name in ("objects", "lights"):
        counts = {"objects": (0, 5, 10) if quick else tuple(range(11)),
                  "lights": (1, 9, 19) if quick else tuple(range(1, 20, 2))}[name]
        points = []
        for n in counts:
            settings = _fraction_settings((0.1,))
            settings[0].x, settings[0].label = n, f"N={n}"
            points.append(Point(f"paper_{name}_{n}.xml", {"res": side, **matte}, 1, settings, x=n))
        what = "spheres" if name == "objects" else "point lights"
        return Experiment(name, f"MRT against the number of {what} (f = 0.1)", "N",
                          f"number of {what}", points, (len(points) - 1, 0))
    # tradeoff
    side = res or (64 if quick else 400)
    spp = 4 if quick else 64
    fractions = (0.1, 0.2) if quick else (0.05, 0.1, 0.2)
    path_group, matte_group = f"path {spp} spp", "matte 1 spp"
    points = [
        Point("paper_fig1.xml", {"res": side, "integrator": "path", "spp": spp, "jitter": "true"},
              spp, _fraction_settings(fractions, group=path_group), group=path_group),
        Point("paper_fig1.xml", {"res": side, **matte}, 1,
              _fraction_settings(fractions, group=matte_group), group=matte_group),
    ]
    return Experiment(name, "Time against error: every method and setting on the Fig. 1 scene",
                      "sample_fraction", "total time (s)", points,
                      (0, _closest(fractions, 0.1)), log_x=True, full_spp_sweep=True)


# --------------------------------------------------------------------------- measuring

def _proc_status_kb(field_name: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field_name + ":"):
                return int(line.split()[1])
    raise OSError(f"no {field_name} in /proc/self/status")


class MemoryMeter:
    """Peak memory of one call.

    On Linux: the process's peak resident set (``VmHWM``), reset before the
    call by writing 5 to ``/proc/self/clear_refs`` (source ``vmhwm``).
    Elsewhere: the peak of Python's own allocations, numpy's included, from
    :mod:`tracemalloc` (source ``tracemalloc``; Dr.Jit's memory is missed).
    """

    def __init__(self):
        self.source = "tracemalloc"
        try:
            self._reset()
            _proc_status_kb("VmHWM")
            self.source = "vmhwm"
        except (OSError, ValueError):
            pass

    @staticmethod
    def _reset():
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")

    @contextmanager
    def measure(self):
        """Yield a dict that gets ``peak_mb`` and ``delta_mb`` when the block ends."""
        out = {}
        if self.source == "vmhwm":
            self._reset()
            base = _proc_status_kb("VmRSS")
            yield out
            peak = _proc_status_kb("VmHWM")
            out["peak_mb"], out["delta_mb"] = peak / 1024.0, max(peak - base, 0) / 1024.0
        else:
            started = not tracemalloc.is_tracing()
            if started:
                tracemalloc.start()
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            try:
                yield out
                peak = tracemalloc.get_traced_memory()[1]
            finally:
                if started:
                    tracemalloc.stop()
            out["peak_mb"], out["delta_mb"] = peak / 2**20, max(peak - base, 0) / 2**20


@dataclass
class _Runs:
    """Every timed run of one method at one setting."""

    totals: list = field(default_factory=list)
    stages: list = field(default_factory=list)
    peaks: list = field(default_factory=list)
    deltas: list = field(default_factory=list)
    warmup: float = math.nan
    image: np.ndarray | None = None
    traced: int = 0
    spp: int = 0

    def median_index(self) -> int:
        order = np.argsort(self.totals, kind="stable")
        return int(order[(len(order) - 1) // 2])


def _no_tick():
    """The progress bar counts the requested rounds only."""


def _failure(exc: BaseException) -> str:
    """The status of a run that raised: one line."""
    if isinstance(exc, KeyboardInterrupt):
        raise exc
    message = str(exc).strip().splitlines()
    return f"failed: {type(exc).__name__}: {message[0] if message else ''}"


def _paper_error(image, reference):
    from ..recon.metrics import paper_error

    return paper_error(image, reference)


def _psnr(image, reference):
    from ..recon.metrics import psnr

    return psnr(image, reference)


class _PointRunner:
    """Runs every method of one point; yields rows and the triptych images."""

    def __init__(self, experiment: Experiment, point: Point, methods: list, repeats: int,
                 scenes_dir: Path, meter: MemoryMeter, env: dict, tick,
                 min_seconds: float = MIN_TIMED_SECONDS):
        self.exp, self.point, self.methods = experiment, point, methods
        self.repeats, self.scenes_dir, self.meter, self.env = repeats, scenes_dir, meter, env
        self.tick = tick
        self.min_seconds = min_seconds  # timed seconds of the full render to reach

    # one call, timed and metered
    def _full(self, scene, spp, seed=0):
        from ..renderer.api import render_reference

        with self.meter.measure() as mem:
            image, seconds = render_reference(scene, spp=spp, seed=seed)
        return image, seconds, {"trace": seconds, "edges": 0.0, "interpolate": 0.0,
                                "total": seconds}, mem

    def _mrt(self, scene, mode, setting):
        from ..renderer.api import render

        with self.meter.measure() as mem:
            result = render(scene, spp=self.point.spp, seed=0, mode=mode, **setting.params)
        return result, mem

    def run(self, keep_images_for: int | None):
        from ..renderer.scene import load_scene

        point = self.point
        path = self.scenes_dir / point.scene
        scene = load_scene(path, **point.defines)
        width, height = (int(v) for v in scene.sensors()[0].film().crop_size())
        mrt_methods = [m for m in self.methods if m != FULL]
        modes = available_methods()
        full = _Runs()
        runs = {(s, m): _Runs() for s in range(len(point.settings)) for m in mrt_methods}
        failed = {}

        # warm-up: the first call of everything (Dr.Jit compiles here)
        image, seconds, _, _ = self._full(scene, point.spp)
        full.warmup = seconds
        self.tick()
        for (s, m), r in runs.items():
            try:
                result, _ = self._mrt(scene, modes[m], point.settings[s])
                r.warmup = result.timings.total
            except Exception as exc:  # noqa: BLE001 - a broken mode must not end the sweep
                failed[(s, m)] = _failure(exc)
            self.tick()

        # timed runs, alternating: full, then every method at every setting; runs
        # of milliseconds get more rounds, until the full render has min_seconds
        # (at most MAX_REPEATS rounds or EXTRA_ROUNDS_SECONDS of wall time), since a
        # median of 3 is noise at that scale
        rounds, begin = 0, time.perf_counter()
        while rounds < self.repeats or (
                sum(full.totals) < self.min_seconds and rounds < MAX_REPEATS
                and time.perf_counter() - begin < EXTRA_ROUNDS_SECONDS):
            tick = self.tick if rounds < self.repeats else _no_tick
            rounds += 1
            image, seconds, stages, mem = self._full(scene, point.spp)
            full.totals.append(seconds), full.stages.append(stages)
            full.peaks.append(mem["peak_mb"]), full.deltas.append(mem["delta_mb"])
            full.image = image
            tick()
            for (s, m), r in runs.items():
                if (s, m) in failed:
                    tick()
                    continue
                try:
                    result, mem = self._mrt(scene, modes[m], point.settings[s])
                except Exception as exc:  # noqa: BLE001
                    failed[(s, m)] = _failure(exc)
                    tick()
                    continue
                r.totals.append(result.timings.total), r.stages.append(asdict(result.timings))
                r.peaks.append(mem["peak_mb"]), r.deltas.append(mem["delta_mb"])
                r.traced, r.spp = int(result.traced_mask.sum()), int(result.spp)
                r.image = result.image
                tick()
        reference = full.image
        full.traced, full.spp = width * height, point.spp

        # stochastic? then a converged reference and the full render at lower spp
        second, *_ = self._full(scene, point.spp, seed=1)
        stochastic = not np.allclose(second, reference, rtol=0.0, atol=1e-6)
        converged = None
        candidates = {point.spp: full}
        if stochastic:
            converged = np.mean([self._full(scene, point.spp, seed=1000 + k)[0]
                                 for k in range(CONVERGED_FACTOR)], axis=0)
            # spp = 1, 4, 16 ... (squares: what the stratified sampler takes): every one
            # below the point's spp, then up until one is as slow as the slowest method
            slowest = max((r.totals[r.median_index()] for r in runs.values() if r.totals),
                          default=0.0)
            spp = 1
            while spp <= CONVERGED_FACTOR * point.spp:
                if spp not in candidates:
                    cand = _Runs(spp=spp, traced=width * height)
                    cand.warmup = self._full(scene, spp)[1]
                    for _ in range(self.repeats):
                        img, seconds, stages, mem = self._full(scene, spp)
                        cand.totals.append(seconds), cand.stages.append(stages)
                        cand.peaks.append(mem["peak_mb"]), cand.deltas.append(mem["delta_mb"])
                        cand.image = img
                    candidates[spp] = cand
                cand = candidates[spp]
                if spp >= point.spp and cand.totals[cand.median_index()] >= slowest:
                    break
                spp *= 4
        self.tick()

        # rows
        ref_median = full.totals[full.median_index()]
        base = {"experiment": self.exp.name, "scene": point.scene, "x_name": self.exp.x_name,
                "integrator": point.integrator,
                "defines": ";".join(f"{k}={v}" for k, v in point.defines.items()),
                "width": width, "height": height, "repeats": rounds,
                "reference_s": ref_median, "stochastic": stochastic,
                "converged_spp": CONVERGED_FACTOR * point.spp if stochastic else "",
                "peak_memory_source": self.meter.source, **self.env}

        def row(method, mode, runs_, setting, **extra):
            out = dict(base, method=method, mode=mode or "", group=setting.group or point.group,
                       setting=setting.label, x=setting.x, spp=runs_.spp or point.spp,
                       sample_fraction=setting.params.get("sample_fraction", math.nan),
                       filter_sigma=setting.params.get("filter_sigma", math.nan),
                       filter_cutoff=setting.params.get("filter_cutoff", math.nan),
                       traced_pixels=runs_.traced, warmup_s=runs_.warmup, status="ok",
                       matched_method="")
            if runs_.totals:
                k = runs_.median_index()
                stages = runs_.stages[k]
                out.update(trace_s=stages["trace"], edges_s=stages["edges"],
                           interpolate_s=stages["interpolate"], total_s=runs_.totals[k],
                           total_min_s=min(runs_.totals), total_max_s=max(runs_.totals),
                           relative_time=runs_.totals[k] / ref_median,
                           peak_memory_mb=max(runs_.peaks), memory_delta_mb=max(runs_.deltas))
                bad = int((~np.isfinite(runs_.image)).any(axis=-1).sum())
                if bad:  # timed, but no error: say so in the status
                    out["status"] = f"failed: {bad} pixels of the image are NaN or Inf"
                    out.update(extra)
                    return out
                out.update(error=_paper_error(runs_.image, reference),
                           psnr_db=_psnr(runs_.image, reference))
                if converged is not None:
                    out.update(error_converged=_paper_error(runs_.image, converged),
                               psnr_converged_db=_psnr(runs_.image, converged))
            out.update(extra)
            return out

        rows = []
        first = point.settings[0]
        full_setting = Setting(first.params if len(point.settings) == 1 else {},
                               first.x if len(point.settings) == 1 else point.x,
                               "full render", point.group)
        rows.append(row(FULL, None, full, full_setting))
        if stochastic and self.exp.full_spp_sweep:
            for spp, cand in sorted(candidates.items()):
                if spp != point.spp:
                    rows.append(row(FULL, None, cand, Setting({}, math.nan, f"spp={spp}",
                                                              point.group)))
        for (s, m), r in runs.items():
            setting = point.settings[s]
            if (s, m) in failed:
                rows.append(row(m, modes[m], r, setting, status=failed[(s, m)]))
                continue
            rows.append(row(m, modes[m], r, setting))
            if stochastic and rows[-1]["status"] == "ok":
                t = rows[-1]["total_s"]
                spp = min(candidates, key=lambda c: abs(math.log(
                    candidates[c].totals[candidates[c].median_index()] / t)))
                rows.append(row(EQUAL_TIME, None, candidates[spp], setting, matched_method=m))

        for (s, m), status in failed.items():
            print(f"warning: {m} at {point.scene} {point.settings[s].label}: {status}",
                  file=sys.stderr)
        images = None
        if keep_images_for is not None:
            images = {"reference": converged if converged is not None else reference,
                      "converged": converged is not None,
                      "methods": {m: runs[(keep_images_for, m)].image for m in mrt_methods
                                  if (keep_images_for, m) not in failed
                                  and runs[(keep_images_for, m)].image is not None}}
        return rows, images


# --------------------------------------------------------------------------- outputs

def _fmt(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return f"{value:.6g}"
    return "" if value is None else str(value)


def write_csv(path, rows) -> None:
    """Write ``rows`` (dicts) with :data:`CSV_COLUMNS`; missing values are ``nan``."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(CSV_COLUMNS)
            for r in rows:
                writer.writerow([_fmt(r.get(c, math.nan)) for c in CSV_COLUMNS])


def read_csv(path) -> list[dict]:
    """Rows of a bench CSV as dicts of strings."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _num(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _ok(rows):
    return [r for r in rows if r.get("status", "ok") == "ok"]


def _error_of(r) -> float:
    """The error a plot shows: against the converged reference when there is one."""
    conv = _num(r.get("error_converged"))
    return conv if math.isfinite(conv) else _num(r.get("error"))


def _series(rows, experiment_name):
    """Lines of a sweep plot: {(method, group): sorted [(x, row)]}; baselines once."""
    lines = {}
    groups = sorted({r["group"] for r in rows if r["method"] != FULL}, key=_group_key)
    for r in rows:
        m = r["method"]
        if m in (FULL, EQUAL_TIME) or not math.isfinite(_num(r["x"])):
            continue
        if m in BASELINES and groups and r["group"] != groups[0]:
            continue
        key = (m, "" if m in BASELINES else r["group"])
        lines.setdefault(key, []).append((_num(r["x"]), r))
    return {k: sorted(v, key=lambda p: p[0]) for k, v in lines.items()}


def _group_key(g: str):
    try:
        return (0, float(g.split("=", 1)[1]))
    except (IndexError, ValueError):
        return (1, g)


def _figure(width, height):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    return fig


def _plain_ticks(axis):
    """Tick labels of a log axis as plain numbers (0.02, not 2 x 10^-2)."""
    from matplotlib.ticker import FuncFormatter

    fmt = FuncFormatter(lambda v, _pos: f"{v:g}")
    axis.set_major_formatter(fmt)
    axis.set_minor_formatter(FuncFormatter(
        lambda v, _pos: f"{v:g}" if f"{v:.0e}"[0] in "25" else ""))


def _save(fig, path, dpi=80, palette=False):
    """Save ``fig`` as PNG; ``palette``: 256 dithered colours (noisy renders stay small)."""
    with atomic_path(path) as tmp:
        if palette:
            try:
                from PIL import Image  # matplotlib's own dependency
            except ImportError:  # pragma: no cover
                palette = False
        if not palette:
            fig.savefig(tmp, format="png", dpi=dpi)
            return
        fig.set_dpi(dpi)
        fig.canvas.draw()
        rgb = np.asarray(fig.canvas.buffer_rgba())[..., :3]
        image = Image.fromarray(np.ascontiguousarray(rgb))
        # an adaptive palette, then Floyd-Steinberg dithering: no banding in gradients
        palette_image = image.quantize(colors=256, method=Image.Quantize.MEDIANCUT)
        image.quantize(palette=palette_image, dither=Image.Dither.FLOYDSTEINBERG).save(
            tmp, format="PNG", optimize=True)


def plot_sweep(rows, path, experiment: Experiment) -> None:
    """Error and relative time against the swept value (headless).

    One colour per method; with groups (the filter test's sigma) one line
    style per group.
    """
    from matplotlib.lines import Line2D

    rows = _ok(rows)
    series = _series(rows, experiment.name)
    methods = list(dict.fromkeys(m for m, _ in series))
    groups = list(dict.fromkeys(g for _, g in series if g))
    styles = ("-", "--", ":", "-.")
    markers = "os^Dv<>ph*"
    fig = _figure(10.0, 3.6)
    ax_err, ax_time = fig.subplots(1, 2)
    for (method, group), pts in series.items():
        k = methods.index(method)
        g = groups.index(group) if group else 0
        style = dict(color=f"C{k % 10}", ls=styles[g % len(styles)],
                     marker=markers[g % len(markers)], ms=3, lw=1.2)
        xs = [p[0] for p in pts]
        ax_err.plot(xs, [_error_of(p[1]) for p in pts], **style)
        ax_time.plot(xs, [_num(p[1]["relative_time"]) for p in pts], **style)
    ax_time.axhline(1.0, color="k", lw=1, ls="--")
    ax_err.set_ylabel("error (report's metric)")
    ax_time.set_ylabel("relative time (method / full)")
    ax_time.set_yscale("log")
    _plain_ticks(ax_time.yaxis)
    for ax in (ax_err, ax_time):
        ax.set_xlabel(experiment.x_label)
        ax.grid(True, alpha=0.3)
    ax_err.set_ylim(bottom=0)
    handles = [Line2D([], [], color=f"C{k % 10}", lw=2, label=m) for k, m in enumerate(methods)]
    handles += [Line2D([], [], color="gray", ls=styles[g % len(styles)],
                       marker=markers[g % len(markers)], ms=3, label=group)
                for g, group in enumerate(groups)]
    handles.append(Line2D([], [], color="k", ls="--", lw=1, label="full render"))
    fig.legend(handles=handles, loc="center right", fontsize=7, frameon=False)
    fig.suptitle(f"{experiment.name}: {experiment.title}", fontsize=9)
    fig.tight_layout(rect=(0, 0, 0.83, 1))
    _save(fig, path)


def plot_tradeoff(rows, path, experiment: Experiment) -> None:
    """Total time (log) against error (log), one panel per group, one marker per method."""
    rows = _ok(rows)
    groups = list(dict.fromkeys(r["group"] for r in rows))
    fig = _figure(4.6 * max(len(groups), 1), 3.8)
    axes = np.atleast_1d(fig.subplots(1, max(len(groups), 1)))
    methods = list(dict.fromkeys(r["method"] for r in rows
                                 if r["method"] not in (FULL, EQUAL_TIME)))
    markers = "osD^v<>ph*"
    for ax, group in zip(axes, groups):
        grows = [r for r in rows if r["group"] == group]
        full = sorted([r for r in grows if r["method"] == FULL], key=lambda r: _num(r["total_s"]))
        errs = [_error_of(r) for r in full]
        if full and all(e > 0 for e in errs):
            ax.plot([_num(r["total_s"]) for r in full], errs, "k-o", ms=4, label="full (spp)")
            for r, e in zip(full, errs):
                ax.annotate(f"{r['spp']} spp", (_num(r["total_s"]), e), fontsize=6,
                            xytext=(3, 3), textcoords="offset points")
        for r in full:
            if _error_of(r) <= 0:
                ax.axvline(_num(r["total_s"]), color="k", ls="--", lw=1,
                           label="full (exact)")
        for k, m in enumerate(methods):
            pts = sorted([r for r in grows if r["method"] == m],
                         key=lambda r: _num(r["sample_fraction"]))
            if not pts:
                continue
            xs, ys = [_num(r["total_s"]) for r in pts], [_error_of(r) for r in pts]
            ax.plot(xs, ys, marker=markers[k % len(markers)], ms=4, lw=0.8, label=m,
                    color=f"C{k % 10}")
            for r, x, y in zip(pts, xs, ys):
                ax.annotate(f"{_num(r['sample_fraction']):g}", (x, y), fontsize=6,
                            xytext=(3, -8), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        _plain_ticks(ax.xaxis), _plain_ticks(ax.yaxis)
        conv = any(math.isfinite(_num(r.get("error_converged"))) for r in grows)
        ax.set_ylabel("error vs converged reference" if conv else "error vs full render")
        ax.set_xlabel("total time (s), median")
        ax.set_title(group, fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6, loc="best")
    fig.suptitle(f"{experiment.name}: {experiment.title}; labels: sample fraction", fontsize=8)
    fig.tight_layout()
    _save(fig, path)


def plot_triptych(path, reference, image, title: str, reference_title="reference") -> None:
    """Reference | MRT | error map (log10 of the report's per-pixel error)."""
    from ..recon.metrics import error_map

    fig = _figure(9.0, 3.3)
    axes = fig.subplots(1, 3)
    axes[0].imshow(srgb_encode(reference))
    axes[0].set_title(reference_title, fontsize=8)
    axes[1].imshow(srgb_encode(image))
    axes[1].set_title(title, fontsize=8)
    errors = np.log10(np.clip(error_map(image, reference), 1e-4, 1.0))
    im = axes[2].imshow(errors, vmin=-4, vmax=0, cmap="inferno")
    axes[2].set_title("error, log10", fontsize=8)
    fig.colorbar(im, ax=axes[2], fraction=0.046, pad=0.04)
    for ax in axes:
        ax.set_xticks([]), ax.set_yticks([])
    fig.tight_layout()
    _save(fig, path, palette=True)


def _md_number(value, digits=4) -> str:
    v = _num(value)
    if not math.isfinite(v):
        return "-" if math.isnan(v) else _fmt(v)
    return f"{v:.{digits}g}"


def markdown_tables(rows, experiment: Experiment) -> str:
    """The experiment's tables as markdown (no heading, no command)."""
    ok = _ok(rows)
    out = []
    failed = [r for r in rows if r.get("status", "ok") != "ok"]
    if experiment.name == "tradeoff":
        stoch = any(r.get("stochastic") in (True, "true") for r in ok)
        head = ["group", "method", "setting", "spp", "total s", "relative time",
                "error vs full"] + (["error vs converged", "PSNR vs converged dB"] if stoch
                                    else ["PSNR dB"])
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + " --- |" * len(head))
        for r in ok:
            label = r["setting"] + (f" (time of {r['matched_method']})"
                                    if r["method"] == EQUAL_TIME else "")
            cells = [r["group"], r["method"], label, r["spp"], _md_number(r["total_s"]),
                     _md_number(r["relative_time"], 3), _md_number(r["error"])]
            cells += ([_md_number(r["error_converged"]), _md_number(r["psnr_converged_db"], 4)]
                      if stoch else [_md_number(r["psnr_db"], 4)])
            out.append("| " + " | ".join(str(c) for c in cells) + " |")
    else:
        lines = _series(ok, experiment.name)
        xs = sorted({x for pts in lines.values() for x, _ in pts})
        head = "| method | " + " | ".join(f"{x:g}" for x in xs) + " |"
        sep = "| --- |" + " ---: |" * len(xs)
        full = {}
        for r in ok:
            if r["method"] == FULL and math.isfinite(_num(r["x"])):
                full[_num(r["x"])] = r
        if not full:  # one point, several settings: the full render is shared
            shared = [r for r in ok if r["method"] == FULL]
            full = {x: shared[0] for x in xs} if shared else {}
        for title, column, digits in (
                (f"Error (the report's metric, against the full render) by {experiment.x_label}",
                 "error", 4),
                ("Relative time (median method total / median full render)", "relative_time", 3),
                ("Relative time of the fastest runs (fewest interruptions: min method total / "
                 "min full render)", "relative_min", 3),
                ("Median total time (s)", "total_s", 3)):
            out += [f"{title}:", "", head, sep]
            for (method, group), pts in lines.items():
                by_x = {x: dict(r, relative_min=_num(r.get("total_min_s")) / _num(
                    (full.get(x) or {}).get("total_min_s"))) for x, r in pts}
                label = method if not group else f"{method} {group}"
                out.append(f"| {label} | " + " | ".join(
                    _md_number(by_x[x][column], digits) if x in by_x else "-" for x in xs) + " |")
            if column == "total_s" and full:
                out.append("| full | " + " | ".join(
                    _md_number(full[x]["total_s"], digits) if x in full else "-" for x in xs)
                    + " |")
            out.append("")
        warm = [r for r in ok if r["method"] != EQUAL_TIME]
        if warm:
            first_scene = warm[0].get("scene"), warm[0].get("defines")
            seen = {}
            for r in warm:
                if (r.get("scene"), r.get("defines")) == first_scene and r["method"] not in seen:
                    seen[r["method"]] = (r.get("warmup_s"), r["total_s"])
            out.append("First call at the first point (kernel compilation included; excluded "
                       "from the medians above), s: " + ", ".join(
                           f"{m} {_md_number(w, 3)} (then {_md_number(t, 3)})"
                           for m, (w, t) in seen.items()) + ".")
    if failed:
        out.append("")
        out.append("Failed runs: " + "; ".join(f"{r['method']} {r['setting']}: {r['status']}"
                                               for r in failed))
    return "\n".join(out).rstrip() + "\n"


def environment_line(env: dict) -> str:
    return (f"{env['variant']}, Mitsuba {env['mitsuba']}, Dr.Jit {env['drjit']}, "
            f"{env['cpu_count']} CPUs ({env['cpu_model']}, {env['machine']}), "
            f"{env['platform']}, Python {env['python']}")


# --------------------------------------------------------------------------- driver

def _scenes_dir(scenes_dir=None) -> Path:
    if scenes_dir is not None:
        path = Path(scenes_dir)
    else:
        path = Path(__file__).resolve().parents[2] / "scenes_xml"
    if not (path / "paper_fig1.xml").is_file():
        raise MRTError(f"the report's scenes are not in {path}: pass --scenes DIR "
                       "(the repository's scenes_xml folder)")
    return path


def _progress(total: int, desc: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="run", file=sys.stderr, disable=not enabled,
                dynamic_ncols=True, leave=True)


def run_experiment(name: str, out_dir="out/bench", *, quick: bool = False,
                   repeats: int | None = None, variant: str = "auto", methods=None,
                   res: int | None = None, scenes_dir=None, progress: bool = True,
                   command: str | None = None) -> dict:
    """Run experiment ``name`` (or ``all``) and write its outputs into ``out_dir``.

    Parameters
    ----------
    name : str
        One of :data:`EXPERIMENTS`, or ``all``.
    out_dir : path
    quick : bool
        A reduced sweep at low resolution (repeats 1 unless given).
    repeats : int, optional
        Timed runs of every method at every point (default 3, quick 1).
    variant : str
        Mitsuba variant (``auto``: LLVM when usable).
    methods : list or comma-separated str, optional
        Method names (``mrt-paper``, ``nearest``...); default all, ``full`` always.
    res : int, optional
        Image side for every experiment but ``pixels``.
    scenes_dir : path, optional
        Folder of the report's scenes (default: the repository's ``scenes_xml``).
    progress : bool
        Show a progress bar on stderr.
    command : str, optional
        The command line written at the top of the markdown table.

    Returns
    -------
    dict
        ``experiment -> {"rows", "csv", "png", "triptych", "md", "seconds"}``
        (for ``all``: one entry per experiment).
    """
    if name == "all":
        out = {}
        for exp in EXPERIMENTS:
            out.update(run_experiment(exp, out_dir, quick=quick, repeats=repeats,
                                      variant=variant, methods=methods,
                                      res=None if exp == "pixels" else res,
                                      scenes_dir=scenes_dir, progress=progress,
                                      command=command))
        return out
    if repeats is None:
        repeats = 1 if quick else 3
    if int(repeats) != repeats or repeats < 1:
        raise MRTError(f"--repeats must be an integer >= 1, got {repeats}")
    experiment = build_experiment(name, quick=quick, res=res)
    from ..renderer.variants import activate, environment

    variant = activate(variant)
    method_list = resolve_methods(methods)
    scenes = _scenes_dir(scenes_dir)
    for point in experiment.points:
        if not (scenes / point.scene).is_file():
            raise MRTError(f"scene file not found: {scenes / point.scene}")
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise MRTError(f"cannot create output folder {out}: {exc.strerror}") from None
    if command is None:
        command = "python -m mitsuba_mrt bench " + shlex.join(
            [name, "-o", os.fspath(out_dir)] + (["--quick"] if quick else [])
            + ["--repeats", str(repeats), "--variant", variant]
            + (["--res", str(res)] if res is not None else [])
            + (["--methods", ",".join(method_list[1:])] if methods is not None else []))

    env = environment(variant)
    meter = MemoryMeter()
    started = time.perf_counter()
    per_point = [(1 + len(p.settings) * (len(method_list) - 1)) * (repeats + 1) + 1
                 for p in experiment.points]
    rows, images = [], None
    csv_path = out / f"{name}.csv"
    rep_point, rep_setting = experiment.representative
    with _progress(sum(per_point), name, progress) as bar:
        for k, point in enumerate(experiment.points):
            bar.set_postfix_str(f"{point.scene} {point.defines.get('res')}px", refresh=False)
            runner = _PointRunner(experiment, point, method_list, repeats, scenes, meter, env,
                                  lambda: bar.update(1), 0.0 if quick else MIN_TIMED_SECONDS)
            point_rows, point_images = runner.run(rep_setting if k == rep_point else None)
            rows += point_rows
            if point_images is not None:
                images = (point_images, point, point.settings[rep_setting])
            write_csv(csv_path, rows)  # after every point: a crash keeps what was measured
    seconds = time.perf_counter() - started

    png = out / f"{name}.png"
    text_rows = read_csv(csv_path)
    (plot_tradeoff if name == "tradeoff" else plot_sweep)(text_rows, png, experiment)
    triptych = None
    if images is not None and images[0]["methods"]:
        found, point, setting = images
        candidates = [r for r in _ok(rows) if r["scene"] == point.scene
                      and r["setting"] == setting.label and r["method"] in found["methods"]
                      and r["defines"] == ";".join(f"{k}={v}" for k, v in point.defines.items())]
        mrt = [r for r in candidates if r["method"].startswith("mrt-")] or candidates
        if mrt:
            best = min(mrt, key=_error_of)
            triptych = out / f"{name}_triptych.png"
            ref_title = (f"converged reference ({CONVERGED_FACTOR * point.spp} spp)"
                         if found["converged"] else f"full render ({point.spp} spp)")
            plot_triptych(triptych, found["reference"], found["methods"][best["method"]],
                          f"{best['method']}, {setting.label}: error {_error_of(best):.4f}, "
                          f"time x{best['relative_time']:.2f}", ref_title)

    md = out / f"{name}.md"
    text = (f"Command: `{command}`\n\n"
            f"Environment: {environment_line(env)}; repeats {repeats}, more where the full "
            f"render is fast (lower median); "
            f"wall time of the whole experiment {seconds:.0f} s.\n\n"
            + markdown_tables(text_rows, experiment))
    with atomic_path(md) as tmp:
        Path(tmp).write_text(text)
    return {name: {"rows": text_rows, "csv": csv_path, "png": png, "triptych": triptych,
                   "md": md, "seconds": seconds}}


def summary_line(name: str, result: dict) -> str:
    """One terminal line per experiment."""
    files = [result["csv"], result["png"], result["md"]] + (
        [result["triptych"]] if result["triptych"] else [])
    return (f"{name}: {len(result['rows'])} rows in {result['seconds']:.1f} s -> "
            + ", ".join(os.fspath(f) for f in files))
